"""The exceptions implc raises on purpose."""


class CompileError(ValueError):
    """The compiler rejected an expression or its bounds; the message names the offending part."""


def shorten(value, limit: int = 80, *, quoted: bool = False) -> str:
    """How ``value`` appears in an error message: ``str`` (``repr`` if ``quoted``), cut to ``limit``
    characters; a value too large to print (a SymPy integer of more than 4,300 digits) is named by type."""
    try:
        text = repr(value) if quoted else str(value)
    except ValueError:
        return f"<a {type(value).__name__} too large to print>"
    return text if len(text) <= limit else text[: limit - 3] + "..."

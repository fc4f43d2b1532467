"""The exceptions implc raises on purpose."""


class CompileError(ValueError):
    """The compiler rejected an expression or its bounds; the message names the offending part."""

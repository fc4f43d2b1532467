"""What implc reads from outside: regular files only, reads bounded by the file's own length, decimal
numbers whose size is bounded before they are built, and text made safe to print on a terminal.

Every reader of a file (``.vm`` models, voxel files, meshes, scene files) opens it through
:func:`regular_file` first: a folder, a FIFO, a device or a link to one is refused in one line before any
read, so nothing blocks or reads without end. Numbers written as decimals (``.vm`` constants, header
options) go through :func:`decimal`, which refuses texts longer than :data:`DECIMAL_DIGITS` and clamps
exponents past :data:`EXPONENT_LIMIT` before building the exact rational (``1e999999999`` would otherwise
be a billion-digit integer). Text taken from a file and printed (metadata, comments, names) goes through
:func:`printable`.
"""

from __future__ import annotations

import os
import re
import stat
import unicodedata
from fractions import Fraction
from pathlib import Path

DECIMAL_DIGITS = 1000
"""The longest decimal text accepted (a double needs at most 767 significant digits to be written exactly)."""
EXPONENT_LIMIT = 4000
"""Decimal exponents beyond ±this are clamped: the value is then far beyond the doubles' range either way
(above 1.8e308, or below 4.9e-324), and its enclosure is the same."""
_DECIMAL = re.compile(r"([+-]?)(\d*)(?:\.(\d*))?(?:[eE]([+-]?\d+))?")


def regular_file(path, error=ValueError, what: str = "file") -> int:
    """The size of ``path`` if it is a regular file (links followed); otherwise ``error`` with one line
    saying what it is instead (missing, a folder, a FIFO, a device, unreadable)."""
    path = Path(path)
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise error(f"cannot read {path}: no such {what}") from None
    except OSError as exc:
        raise error(f"cannot read {path}: {exc.strerror or exc}") from None
    if stat.S_ISDIR(info.st_mode):
        raise error(f"cannot read {path}: it is a folder, not a {what}")
    if not stat.S_ISREG(info.st_mode):
        kind = ("a FIFO" if stat.S_ISFIFO(info.st_mode) else "a device" if stat.S_ISCHR(info.st_mode)
                or stat.S_ISBLK(info.st_mode) else "a socket" if stat.S_ISSOCK(info.st_mode) else "a special file")
        raise error(f"cannot read {path}: it is {kind}, not a regular {what}")
    if not os.access(path, os.R_OK):
        raise error(f"cannot read {path}: permission denied")
    return info.st_size


def read_text(path, limit: int, error=ValueError, what: str = "file") -> str:
    """The text of a regular file of at most ``limit`` bytes (UTF-8); ``error`` otherwise."""
    size = regular_file(path, error, what)
    if size > limit:
        raise error(f"cannot read {path}: {size / 2**20:.1f} MiB, more than the {limit / 2**20:.0f} MiB a {what} "
                    "may have")
    try:
        with open(path, "rb") as f:
            data = f.read(limit + 1)
    except OSError as exc:
        raise error(f"cannot read {path}: {exc.strerror or exc}") from None
    if len(data) > limit:
        raise error(f"cannot read {path}: it grew past {limit / 2**20:.0f} MiB while being read")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"cannot read {path}: not UTF-8 text (byte {exc.start})") from None


def decimal(text: str) -> Fraction:
    """The exact value of a decimal number (``-1.5e-3``, ``.5``, ``7``); ValueError for anything else or
    for a text longer than :data:`DECIMAL_DIGITS`. An exponent past ±:data:`EXPONENT_LIMIT` is clamped
    there (see that constant)."""
    if len(text) > DECIMAL_DIGITS:
        raise ValueError(f"a number of {len(text)} characters (at most {DECIMAL_DIGITS})")
    found = _DECIMAL.fullmatch(text)
    if not found or not (found.group(2) or found.group(3)):
        raise ValueError(f"'{printable(text)}' is not a decimal number")
    sign, whole, fraction, exponent = found.group(1), found.group(2), found.group(3) or "", found.group(4)
    digits = (whole + fraction).lstrip("0")
    if not digits:
        return Fraction(0)
    power = int(exponent or 0) - len(fraction)
    # the value is digits × 10^power; its decimal magnitude is len(digits) + power
    magnitude = len(digits) + power
    if magnitude > EXPONENT_LIMIT:
        power = EXPONENT_LIMIT - len(digits)
    elif magnitude < -EXPONENT_LIMIT:
        power = -EXPONENT_LIMIT - len(digits)
    value = Fraction(int(digits)) * (Fraction(10) ** power)
    return -value if sign == "-" else value


def printable(text: str, limit: int = 200) -> str:
    """``text`` with control and format characters escaped (``\\x1b``, ``\\n``, ``\\u202e``) and cut to
    ``limit`` characters: what a file says cannot move the cursor, forge a line or recolour the terminal."""
    out = []
    for ch in text[:limit]:
        if ch == "\\" or (unicodedata.category(ch)[0] in "CZ" and ch != " "):
            out.append(ch.encode("unicode_escape").decode("ascii") if ch != "\\" else "\\\\")
        else:
            out.append(ch)
    return "".join(out) + ("..." if len(text) > limit else "")


PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
             "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}
"""Bytes per value of each PLY property type."""


PLY_HEADER_BYTES = 1 << 20
"""The longest PLY header read (comments and properties included)."""


def ply_header(path, error=ValueError) -> tuple[list[str], int]:
    """A PLY file's header lines (within its first :data:`PLY_HEADER_BYTES`, each read with a bound) and the
    offset where its body starts; ``error`` if there is no ``end_header`` within them."""
    lines: list[str] = []
    offset = 0
    with open(path, "rb") as f:
        while offset < PLY_HEADER_BYTES:
            raw = f.readline(1 << 12)  # bounded: a body without line breaks is not read whole
            if not raw:
                break
            offset += len(raw)
            lines.append(raw.decode("ascii", errors="replace").strip())
            if lines[-1] == "end_header":
                break
    if lines[-1:] != ["end_header"]:
        raise error(f"{path}: damaged PLY header")
    return lines, offset


def ply_elements(path, lines: list[str], body: int, error=ValueError) -> list[tuple[str, int, int]]:
    """The elements a PLY header declares as (name, count, least bytes per item: fixed properties in
    full, a list property's count alone), ``error`` where a count is not a number or the counts need
    more bytes than the body has (a forged count is refused before anything is allocated for it)."""
    elements: list[list] = []
    for line in lines:
        words = line.split()
        if words[:1] == ["element"]:
            if len(words) != 3 or not words[2].isdigit() or len(words[2]) > 18:
                raise error(f"{path}: damaged PLY header ('{printable(line, 60)}')")
            elements.append([words[1], int(words[2]), 0])
        elif words[:1] == ["property"] and elements:
            kind = words[2] if words[1:2] == ["list"] and len(words) == 5 else words[1] if len(words) == 3 else None
            if kind not in PLY_SIZES:
                raise error(f"{path}: damaged PLY header ('{printable(line, 60)}')")
            elements[-1][2] += PLY_SIZES[kind]
    size = os.stat(path).st_size - body
    binary = any(line.startswith("format binary") for line in lines)
    least = sum(count * (row if binary else 2) for _, count, row in elements)  # ASCII: a digit and a break
    if least > size:
        raise error(f"{path}: damaged PLY: its header declares "
                    f"{', '.join(f'{count} {printable(name, 20)}' for name, count, _ in elements)}, which need "
                    f"{least} bytes or more; the file has {size} after the header")
    return [tuple(e) for e in elements]

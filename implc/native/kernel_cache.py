"""The on-disk cache of compiled kernel objects: where it lives, what a key covers, how big it may grow.

One file per key, ``<key>.o``, holding its content's SHA-256 and then the content (a module's object files,
bundled by :mod:`implc.native.jit`), so that a damaged entry is recompiled rather than loaded (LLVM would crash
on a bad object file). Writes go to a temporary file
in the same folder and are renamed into place: a concurrent reader sees the old entry or the whole new one.

A key covers what decides the machine code: the source key of the module (the tapes and the compile
options), the source of every module of the ``implc`` package (editing any of them, even a comment,
makes every entry unreachable), llvmlite's version and the host CPU with its features. A stale entry
can therefore not be loaded; unreachable entries age out.

Settings, read at each use:

- ``IMPLC_CACHE_DIR``: the folder (default ``~/.cache/implc``); ``off`` disables the cache.
- ``IMPLC_CACHE_MAX_MB``: the size bound in MiB (default 256). After each store, the least recently
  used entries (by modification time, which a load refreshes) are removed until the cache fits.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import llvmlite

DEFAULT_MAX_MB = 256
PACKAGE_ROOT = Path(__file__).resolve().parents[1]
"""The implc package's folder: every module under it is in the key, wherever it moves."""
SUFFIX = ".o"


def source_fingerprint(root: Path) -> str:
    """SHA-256 of the source of every module of the implc package under ``root`` (paths and contents), in
    every subpackage."""
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    return h.hexdigest()


@cache
def package_fingerprint() -> str:
    """:func:`source_fingerprint` of the implc package this module belongs to."""
    return source_fingerprint(PACKAGE_ROOT)


def key(source_key: str, cpu: str, features: str, opt_level: int | str) -> str:
    """The cache key of a module: see the module docstring for what it covers."""
    text = "|".join((source_key, f"O{opt_level}", package_fingerprint(), llvmlite.__version__, cpu, features))
    return hashlib.sha256(text.encode()).hexdigest()


def directory() -> Path | None:
    """The cache folder, or None when the cache is off."""
    setting = os.environ.get("IMPLC_CACHE_DIR", "")
    if setting.lower() == "off":
        return None
    return Path(setting).expanduser() if setting else Path.home() / ".cache" / "implc"


def max_bytes() -> int:
    """The size bound (``IMPLC_CACHE_MAX_MB``, default 256 MiB); a bad setting is an error, not a guess."""
    setting = os.environ.get("IMPLC_CACHE_MAX_MB", "")
    try:
        mb = float(setting) if setting else DEFAULT_MAX_MB
    except ValueError:
        raise ValueError(f"IMPLC_CACHE_MAX_MB must be a number of MiB, got {setting!r}") from None
    if not mb >= 0:
        raise ValueError(f"IMPLC_CACHE_MAX_MB must be >= 0, got {setting!r}")
    return int(mb * 2**20)


def load(entry_key: str) -> bytes | None:
    """The cached object, or None when absent, damaged or the cache is off; a hit counts as a use."""
    folder = directory()
    if folder is None:
        return None
    path = folder / f"{entry_key}{SUFFIX}"
    try:
        data = path.read_bytes()
    except OSError:
        return None
    digest, obj = data[:32], data[32:]
    if len(data) <= 32 or hashlib.sha256(obj).digest() != digest:
        return None
    try:
        os.utime(path)  # most recently used
    except OSError:
        pass
    return obj


def store(entry_key: str, obj: bytes) -> None:
    """Write an entry atomically, then evict the least recently used entries past the bound; a read-only
    or full disk only costs the next process a compile."""
    folder = directory()
    if folder is None:
        return
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".tmp-", suffix=".part", delete=False) as tmp:
            tmp.write(hashlib.sha256(obj).digest() + obj)
        os.replace(tmp.name, folder / f"{entry_key}{SUFFIX}")
    except OSError:
        return
    evict(folder, max_bytes(), keep=entry_key)


def _entries(folder: Path) -> list[tuple[float, int, Path]]:
    """(last use, size, path) of every entry."""
    out = []
    for path in folder.glob(f"*{SUFFIX}"):
        try:
            st = path.stat()
        except OSError:  # removed meanwhile by another process
            continue
        out.append((st.st_mtime, st.st_size, path))
    return out


def evict(folder: Path, limit: int, keep: str | None = None) -> int:
    """Remove the least recently used entries until the total fits ``limit`` bytes (never ``keep``, the
    entry just written); returns how many were removed."""
    entries = sorted(_entries(folder))
    total = sum(size for _, size, _ in entries)
    removed = 0
    for _, size, path in entries:
        if total <= limit:
            break
        if path.stem == keep:
            continue
        try:
            path.unlink()
        except OSError:
            continue
        total -= size
        removed += 1
    return removed


@dataclass(frozen=True)
class CacheInfo:
    directory: Path | None
    entries: int
    bytes: int
    limit: int


def info() -> CacheInfo:
    """Where the cache is, how many entries and bytes it holds, and its bound."""
    folder = directory()
    entries = _entries(folder) if folder is not None and folder.is_dir() else []
    return CacheInfo(folder, len(entries), sum(size for _, size, _ in entries), max_bytes())


def clear() -> int:
    """Remove every entry (and leftover temporary files); returns how many entries were removed."""
    folder = directory()
    if folder is None or not folder.is_dir():
        return 0
    removed = 0
    for path in [*folder.glob(f"*{SUFFIX}"), *folder.glob(".tmp-*.part")]:
        try:
            path.unlink()
            removed += path.suffix == SUFFIX
        except OSError:
            pass
    return removed

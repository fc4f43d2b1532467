"""Where a Zarr store's objects live: a local folder, or any fsspec URL (``s3://bucket/run.zarr``,
``gs://…``, ``az://…``, ``memory://…``) through the object-store filesystems (s3fs, gcsfs, adlfs: the
``implc[s3]``, ``implc[gcs]``, ``implc[azure]`` extras).

The writers and readers of :mod:`implc.files.zarr_writer` and :mod:`implc.files.zarr_store` name every
object they write themselves (a part, its checksum, a full shard) relative to the store's root and hand
the rest to zarr with :attr:`StorePlace.url`. The two kinds differ in how an object comes into being:

- a **folder** writes each file under a temporary name and renames it (a reader never sees half a file);
  the whole store is built under ``NAME.partial`` and renamed into place
  (:func:`implc.common.atomic_file.resumable_folder`);
- an **object store** has neither folders nor renames, but a PUT is atomic: an object is absent until its
  upload completes, then whole. Each object is written once, by its one owner, under its final name; the
  manifest in the group's ``zarr.json``, written last, is what makes the store complete.

Credentials come from the environment, as the filesystem libraries read them (``AWS_ACCESS_KEY_ID``,
``AWS_ENDPOINT_URL``, a profile, an instance role…); a URL that carries them (``s3://key:secret@…``) is
refused, so that none reaches a command line, a log or a store's own records.
"""

from __future__ import annotations

import contextlib
import os
import re
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from ..common.untrusted import printable, regular_file
from ..errors import StoreError

URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*://")
"""A target named by a URL (``protocol://…``) rather than a path."""

EXTRAS = {"s3": "s3", "s3a": "s3", "gs": "gcs", "gcs": "gcs", "az": "azure", "abfs": "azure", "abfss": "azure"}
"""The implc extra that installs each protocol's filesystem."""


def is_url(target: Any) -> bool:
    """Whether ``target`` names an object store (a URL other than ``file://``) rather than a local path."""
    return isinstance(target, str) and bool(URL.match(target)) and not target.lower().startswith("file://")


def local_path(target: Any) -> Path:
    """A local target as a path (``file://`` URLs as their path)."""
    text = os.fspath(target)
    return Path(urlsplit(text).path) if isinstance(text, str) and text.lower().startswith("file://") else Path(text)


def target_of(path: Any) -> Path | str:
    """A store's target as the writers take it: a URL as given, a local one as a path."""
    return str(path) if is_url(path) else local_path(path)


class StorePlace:
    """The objects of one store: read, written whole, listed and removed by their names relative to the
    store's root (``zarr.json``, ``_parts/00000003.npz``, ``occupancy/c/0/1/2``)."""

    url: str
    """What zarr opens the store's group by (a local path, or the URL)."""

    def read(self, name: str) -> bytes:
        raise NotImplementedError

    def write(self, name: str, data: bytes) -> None:
        """The object ``name`` with ``data``, all of it or (a crash in the middle) none of it."""
        raise NotImplementedError

    def open(self, name: str) -> Any:
        """The object ``name`` as a seekable binary file, read as it is asked for."""
        raise NotImplementedError

    def exists(self, name: str = "") -> bool:
        raise NotImplementedError

    def names(self, folder: str) -> list[str]:
        """The names of the objects directly under ``folder`` (empty where there is none)."""
        raise NotImplementedError

    def remove(self, name: str) -> None:
        """Remove the object ``name`` (nothing where it is absent)."""
        raise NotImplementedError

    def remove_all(self, folder: str = "") -> None:
        """Remove every object under ``folder`` (the whole store for "")."""
        raise NotImplementedError


class FolderPlace(StorePlace):
    """A store in a local folder (the files are untrusted input: links and FIFOs are refused)."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.url = str(self.folder)

    def _path(self, name: str) -> Path:
        return self.folder / name if name else self.folder

    def read(self, name: str) -> bytes:
        path = self._path(name)
        regular_file(path, StoreError, "store file")
        return path.read_bytes()

    def open(self, name: str) -> Any:
        path = self._path(name)
        regular_file(path, StoreError, "store file")
        return open(path, "rb")

    def write(self, name: str, data: bytes) -> None:
        path = self._path(name)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, path)

    def exists(self, name: str = "") -> bool:
        path = self._path(name)
        return path.exists() or path.is_symlink()

    def names(self, folder: str) -> list[str]:
        path = self._path(folder)
        return sorted(p.name for p in path.iterdir()) if path.is_dir() and not path.is_symlink() else []

    def remove(self, name: str) -> None:
        with contextlib.suppress(FileNotFoundError):
            self._path(name).unlink()

    def remove_all(self, folder: str = "") -> None:
        import shutil
        shutil.rmtree(self._path(folder), ignore_errors=True)


class ObjectPlace(StorePlace):
    """A store under a URL of an fsspec filesystem (an object store, or ``memory://`` in tests)."""

    def __init__(self, url: str):
        parts = urlsplit(url)
        if "@" in parts.netloc:
            raise StoreError(f"{printable(parts.scheme, 20)}:// URLs carry no credentials: give them in the "
                             "environment (AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY, a profile, …) as the "
                             "filesystem library reads them")
        try:
            import fsspec
        except ImportError:
            raise StoreError(f"writing and reading {printable(url, 80)} needs fsspec: pip install "
                             f"'implc[{EXTRAS.get(parts.scheme.lower(), 's3')}]'") from None
        try:
            self.fs, root = fsspec.core.url_to_fs(url)
        except (ImportError, ValueError) as exc:  # an unknown protocol, or its library missing
            extra = EXTRAS.get(parts.scheme.lower())
            hint = f": pip install 'implc[{extra}]'" if extra else ""
            raise StoreError(f"cannot reach {printable(url, 80)} ({printable(str(exc), 120)}){hint}") from None
        self.root = root.rstrip("/")
        self.url = url.rstrip("/")

    def _path(self, name: str) -> str:
        return f"{self.root}/{name}" if name else self.root

    @contextlib.contextmanager
    def _named(self):
        """The filesystem's errors as one :class:`StoreError` naming the store's URL ("Access Denied" alone
        names nothing; the libraries raise their own kinds too: botocore's EndpointConnectionError and
        NoCredentialsError are not OSErrors); a missing object stays a FileNotFoundError."""
        try:
            yield
        except FileNotFoundError:
            raise
        except Exception as exc:  # noqa: BLE001 - whatever the object store's library raises, named
            kind = "" if isinstance(exc, OSError) else f"{type(exc).__name__}: "
            raise StoreError(f"{self.url}: {kind}{printable(str(exc), 200)}") from None

    def check_bucket(self) -> None:
        """Refuse, naming it, a bucket (the URL's first component, on the stores that have buckets) that
        does not exist or that these credentials cannot see."""
        if self.root.startswith("/") or self.fs.protocol in ("memory", "file", "local"):
            return
        bucket = self.root.split("/", 1)[0]
        with self._named():
            found = self.fs.exists(bucket)
        if not found:
            raise StoreError(f"cannot write {self.url}: bucket {printable(bucket, 80)!r} does not exist, or these "
                             "credentials cannot see it")

    def read(self, name: str) -> bytes:
        with self._named():
            return self.fs.cat_file(self._path(name))

    def open(self, name: str) -> Any:
        with self._named():
            return self.fs.open(self._path(name), "rb")

    def write(self, name: str, data: bytes) -> None:
        with self._named():
            self.fs.pipe_file(self._path(name), data)  # one PUT: the object appears whole when it completes

    def exists(self, name: str = "") -> bool:
        self.fs.invalidate_cache()  # other processes (the workers) write here: no listing is kept
        with self._named():
            return bool(self.fs.exists(self._path(name)))

    def names(self, folder: str) -> list[str]:
        self.fs.invalidate_cache()
        try:
            with self._named():
                entries = self.fs.ls(self._path(folder), detail=False)
        except FileNotFoundError:
            return []
        return sorted(str(e).rstrip("/").rsplit("/", 1)[-1] for e in entries)

    def remove(self, name: str) -> None:
        with contextlib.suppress(FileNotFoundError), self._named():
            self.fs.rm_file(self._path(name))

    def remove_all(self, folder: str = "") -> None:
        with contextlib.suppress(FileNotFoundError), self._named():
            self.fs.rm(self._path(folder), recursive=True)
        self.fs.invalidate_cache()


def place_of(target: Any) -> StorePlace:
    """The place a target names: an fsspec URL, or a local folder (a path or ``file://`` URL)."""
    return ObjectPlace(target) if is_url(target) else FolderPlace(local_path(target))

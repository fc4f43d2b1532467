"""JIT compilation of kernel modules for the host CPU, with an on-disk object cache.

:class:`NativeModule` owns one MCJIT execution engine for its whole life: it optimises LLVM IR with the
new pass manager, emits a host object file (or loads one from the cache), and hands out ctypes function
pointers that stay valid as long as the NativeModule lives. Calls through those pointers release the GIL.

The cache lives in ``$IMPLC_CACHE_DIR`` (default ``~/.cache/implc``), one object file per key, stored
behind its SHA-256 so that a damaged entry is recompiled rather than loaded; the key
covers the kernel source, the code generator's own source, llvmlite's version and the host CPU, so a
stale entry cannot be loaded. Set ``IMPLC_CACHE_DIR=off`` to disable it.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import tempfile
from functools import cache
from pathlib import Path

import llvmlite
import llvmlite.binding as llvm


@cache
def _host() -> tuple[str, str]:
    """(cpu name, cpu features), after initialising LLVM's native target (idempotent)."""
    llvm.initialize_native_target()
    llvm.initialize_native_asmprinter()
    return llvm.get_host_cpu_name(), llvm.get_host_cpu_features().flatten()


def host_has_avx512() -> bool:
    """Whether this CPU has AVX-512F (and with it instructions that round toward ±inf by themselves)."""
    return "+avx512f" in _host()[1].split(",")


@cache
def _codegen_fingerprint() -> str:
    """Hash of the sources that decide what a kernel computes: editing them invalidates the cache."""
    here = Path(__file__).parent
    h = hashlib.sha256()
    for path in sorted([*here.glob("codegen/*.py"), here / "rounding.py", here / "jit.py"]):
        h.update(path.read_bytes())
    return h.hexdigest()


def cache_dir() -> Path | None:
    setting = os.environ.get("IMPLC_CACHE_DIR", "")
    if setting.lower() == "off":
        return None
    return Path(setting) if setting else Path.home() / ".cache" / "implc"


def cache_key(source_key: str) -> str:
    cpu, features = _host()
    text = "|".join((source_key, _codegen_fingerprint(), llvmlite.__version__, cpu, features))
    return hashlib.sha256(text.encode()).hexdigest()


class NativeModule:
    """One JIT-compiled LLVM module and the execution engine that keeps its code alive.

    ``llvm_ir`` is a callable producing the module's text; it is only called on a cache miss.
    """

    def __init__(self, llvm_ir, source_key: str, opt_level: int = 2):
        cpu, features = _host()
        target = llvm.Target.from_default_triple()
        self._target_machine = target.create_target_machine(cpu=cpu, features=features, opt=opt_level,
                                                            reloc="pic", codemodel="jitdefault")
        self.opt_level = opt_level
        self.key = cache_key(source_key)
        self.from_cache = False
        obj = self._load_cached()
        if obj is None:
            obj = self._compile(llvm_ir())
            self._store_cached(obj)
        else:
            self.from_cache = True
        empty = llvm.parse_assembly("")
        empty.triple = llvm.get_process_triple()
        self._engine = llvm.create_mcjit_compiler(empty, self._target_machine)
        self._engine.add_object_file(llvm.ObjectFileRef.from_data(obj))
        self._engine.finalize_object()

    def _compile(self, text: str) -> bytes:
        module = llvm.parse_assembly(text)
        module.triple = llvm.get_process_triple()
        module.data_layout = str(self._target_machine.target_data)
        module.verify()
        tuning = llvm.create_pipeline_tuning_options(speed_level=self.opt_level)
        builder = llvm.create_pass_builder(self._target_machine, tuning)
        builder.getModulePassManager().run(module, builder)
        self.optimized_ir = str(module)
        return self._target_machine.emit_object(module)

    def _path(self) -> Path | None:
        directory = cache_dir()
        return None if directory is None else directory / f"{self.key}.o"

    def _load_cached(self) -> bytes | None:
        """The cached object, or None when absent or damaged (LLVM would crash on a bad object file)."""
        path = self._path()
        if path is None:
            return None
        try:
            data = path.read_bytes()
        except OSError:
            return None
        digest, obj = data[:32], data[32:]
        if len(data) <= 32 or hashlib.sha256(obj).digest() != digest:
            return None
        return obj

    def _store_cached(self, obj: bytes) -> None:
        path = self._path()
        if path is None:
            return
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=path.parent, delete=False) as tmp:
                tmp.write(hashlib.sha256(obj).digest() + obj)
            os.replace(tmp.name, path)  # atomic: a concurrent reader sees the old file or the whole new one
        except OSError:
            pass  # a read-only or full disk only costs the next process a compile

    def address(self, name: str) -> int:
        """The address of the exported function ``name`` (valid while this object lives)."""
        address = self._engine.get_function_address(name)
        if not address:
            raise LookupError(f"no function {name} in the compiled module")
        return address

    def function(self, name: str, argtypes: list, restype=None):
        """A ctypes function for the exported symbol ``name``."""
        return ctypes.CFUNCTYPE(restype, *argtypes)(self.address(name))

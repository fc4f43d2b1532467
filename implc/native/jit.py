"""JIT compilation of kernel modules for the host CPU, through the on-disk object cache.

:class:`NativeModule` owns one MCJIT execution engine for its whole life: it optimises LLVM IR with the
new pass manager, emits a host object file (or loads one from :mod:`implc.native.kernel_cache`), and binds the
module's entry points (:mod:`implc.native.abi`) as ctypes functions that stay valid as long as the NativeModule
lives. Calls through them release the GIL.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache

import llvmlite.binding as llvm
from llvmlite import ir

from . import kernel_cache, parallel_compile, split
from .abi import Entry


@cache
def _host() -> tuple[str, str]:
    """(cpu name, cpu features), after initialising LLVM's native target (idempotent)."""
    llvm.initialize_native_target()
    llvm.initialize_native_asmprinter()
    return llvm.get_host_cpu_name(), llvm.get_host_cpu_features().flatten()


def host_has_avx512() -> bool:
    """Whether this CPU has AVX-512F (and with it instructions that round toward ±inf by themselves)."""
    return "+avx512f" in _host()[1].split(",")


LIGHT_PASSES = ("sroa", "instruction_combine", "simplify_cfg", "dead_code_elimination")
"""The optimisation of ``opt_level="light"``: the locals into registers, one round of combining and the
control flow tidied, then the code generator at its level 2. For modules whose IR is written already
vectorised and unrolled (the tape engine's interpreters): LLVM's level-1 pipeline runs instcombine over
them many times for nothing measurable."""


@dataclass(frozen=True)
class Source:
    """What a :class:`NativeModule` compiles: ``build()`` gives its LLVM module (an ``llvmlite.ir.Module``, or
    its IR text; called only on a cache miss, once in each process that compiles a part of it), ``key``
    names it in the disk cache with what decides its code, ``opt_level`` is LLVM's pipeline at that speed
    level (0-3) or ``"light"`` (:data:`LIGHT_PASSES`), ``max_parts`` how many parts it may be compiled in
    at once (:mod:`implc.native.split`; a module given as text is one part), ``weight`` its expected
    compile time against other sources', so that processes compiling several at once share the work
    evenly."""

    build: Callable[[], ir.Module | str]
    key: str
    opt_level: int | str = 2
    max_parts: int = 1
    weight: float = 1.0


def _target_machine(opt_level: int | str):
    cpu, features = _host()
    return llvm.Target.from_default_triple().create_target_machine(
        cpu=cpu, features=features, opt=2 if opt_level == "light" else opt_level, reloc="static",
        codemodel="jitdefault")


def _compile(text: str, opt_level: int | str) -> bytes:
    """The host object file of one module's (or part's) IR text."""
    target_machine = _target_machine(opt_level)
    module = llvm.parse_assembly(text)
    module.triple = llvm.get_process_triple()
    module.data_layout = str(target_machine.target_data)
    module.verify()
    light = opt_level == "light"
    tuning = llvm.create_pipeline_tuning_options(speed_level=2 if light else opt_level)
    builder = llvm.create_pass_builder(target_machine, tuning)
    if light:
        passes = llvm.create_new_module_pass_manager()
        for name in LIGHT_PASSES:
            getattr(passes, f"add_{name}_pass")()
        passes.run(module, builder)
    else:
        builder.getModulePassManager().run(module, builder)
    return target_machine.emit_object(module)


_COUNT = struct.Struct("<Q")


def _bundle(objects: Sequence[bytes]) -> bytes:
    """Objects as one cache entry: their count, then each one's length and bytes."""
    return b"".join([_COUNT.pack(len(objects))] + [_COUNT.pack(len(o)) + o for o in objects])


def _unbundle(data: bytes) -> list[bytes]:
    (count,), at, objects = _COUNT.unpack_from(data, 0), _COUNT.size, []
    for _ in range(count):
        (length,), at = _COUNT.unpack_from(data, at), at + _COUNT.size
        objects.append(data[at:at + length])
        at += length
    return objects


class NativeModule:
    """One JIT-compiled LLVM module (its objects) and the execution engine that keeps its code alive.

    ``build``, ``source_key``, ``opt_level`` and ``max_parts``: the :class:`Source`'s ``build``, ``key``,
    ``opt_level`` and ``max_parts``.
    """

    def __init__(self, build, source_key: str, opt_level: int | str = 2, *, max_parts: int = 1,
                 _compiled: tuple[str, bytes, bool] | None = None):
        source = Source(build, source_key, opt_level, max_parts)
        self.key, bundle, self.from_cache = _compiled or _compile_all([source])[0]
        # from_cache: True when the objects came from the disk cache, no LLVM run
        self.opt_level = opt_level
        self._target_machine = _target_machine(opt_level)
        empty = llvm.parse_assembly("")
        empty.triple = llvm.get_process_triple()
        self._engine = llvm.create_mcjit_compiler(empty, self._target_machine)
        for obj in _unbundle(bundle):
            self._engine.add_object_file(llvm.ObjectFileRef.from_data(obj))
        self._engine.finalize_object()

    @classmethod
    def together(cls, sources: Sequence[Source]) -> list[NativeModule]:
        """A NativeModule for each source; those not in the disk cache compiled at once, their parts
        spread over processes."""
        return [cls(s.build, s.key, s.opt_level, max_parts=s.max_parts, _compiled=c)
                for s, c in zip(sources, _compile_all(sources))]

    def address(self, name: str) -> int:
        """The address of the exported function ``name`` (valid while this object lives)."""
        address = self._engine.get_function_address(name)
        if not address:
            raise LookupError(f"no function {name} in the compiled module")
        return address

    def bind(self, entry: Entry):
        """The exported function ``entry`` as a ctypes function with the ABI's prototype."""
        return entry.ctypes_type()(self.address(entry.name))


def _compile_all(sources: Sequence[Source]) -> list[tuple[str, bytes, bool]]:
    """(cache key, objects bundled, whether from the cache) for each source: the missing ones compiled,
    every part of every one a job of :func:`implc.native.parallel_compile.run`, then stored."""
    cpu, features = _host()
    keys = [kernel_cache.key(s.key, cpu, features, s.opt_level) for s in sources]
    bundles = [kernel_cache.load(k) for k in keys]
    workers = parallel_compile.workers()
    jobs = [(i, part, min(workers, s.max_parts)) for i, s in enumerate(sources) if bundles[i] is None
            for part in range(min(workers, s.max_parts))]
    writers: dict[int, Callable[[int], str]] = {}  # each source's, built once in the process that needs it

    def job(j: int) -> bytes:
        i, part, count = jobs[j]
        if i not in writers:
            module = sources[i].build()
            writers[i] = (lambda part: module) if isinstance(module, str) else split.writer(module, count)
        return _compile(writers[i](part), sources[i].opt_level)

    objects = parallel_compile.run(job, len(jobs), [sources[i].weight / count for i, _, count in jobs])
    out = []
    for i, (key, bundle) in enumerate(zip(keys, bundles)):
        if bundle is None:
            bundle = _bundle([o for (k, _, _), o in zip(jobs, objects) if k == i])
            kernel_cache.store(key, bundle)
            out.append((key, bundle, False))
        else:
            out.append((key, bundle, True))
    return out

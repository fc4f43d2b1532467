"""JIT compilation of kernel modules for the host CPU, through the on-disk object cache.

:class:`NativeModule` owns one MCJIT execution engine for its whole life: it optimises LLVM IR with the
new pass manager, emits a host object file (or loads one from :mod:`implc.kernel_cache`), and binds the
module's entry points (:mod:`implc.abi`) as ctypes functions that stay valid as long as the NativeModule
lives. Calls through them release the GIL.
"""

from __future__ import annotations

from functools import cache

import llvmlite.binding as llvm

from . import kernel_cache
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


class NativeModule:
    """One JIT-compiled LLVM module and the execution engine that keeps its code alive.

    ``llvm_ir`` is a callable producing the module's text; it is only called on a cache miss.
    ``opt_level``: LLVM's pipeline at that speed level (0-3), or ``"light"`` (:data:`LIGHT_PASSES`).
    """

    def __init__(self, llvm_ir, source_key: str, opt_level: int | str = 2):
        cpu, features = _host()
        target = llvm.Target.from_default_triple()
        self._target_machine = target.create_target_machine(cpu=cpu, features=features,
                                                            opt=2 if opt_level == "light" else opt_level,
                                                            reloc="pic", codemodel="jitdefault")
        self.opt_level = opt_level
        self.key = kernel_cache.key(source_key, cpu, features, opt_level)
        obj = kernel_cache.load(self.key)
        self.from_cache = obj is not None  # True: the object came from the disk cache, no LLVM run
        if obj is None:
            obj = self._compile(llvm_ir())
            kernel_cache.store(self.key, obj)
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
        light = self.opt_level == "light"
        tuning = llvm.create_pipeline_tuning_options(speed_level=2 if light else self.opt_level)
        builder = llvm.create_pass_builder(self._target_machine, tuning)
        if light:
            passes = llvm.create_new_module_pass_manager()
            for name in LIGHT_PASSES:
                getattr(passes, f"add_{name}_pass")()
            passes.run(module, builder)
        else:
            builder.getModulePassManager().run(module, builder)
        return self._target_machine.emit_object(module)

    def address(self, name: str) -> int:
        """The address of the exported function ``name`` (valid while this object lives)."""
        address = self._engine.get_function_address(name)
        if not address:
            raise LookupError(f"no function {name} in the compiled module")
        return address

    def bind(self, entry: Entry):
        """The exported function ``entry`` as a ctypes function with the ABI's prototype."""
        return entry.ctypes_type()(self.address(entry.name))

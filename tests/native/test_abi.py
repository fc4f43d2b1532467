"""One ABI: every entry point declared in implc/native/abi.py is exported by its module with exactly the
declared LLVM signature, its ctypes prototype has the same parameters, and nothing else is exported."""

import ctypes
import re

import llvmlite.binding as llvm
import pytest
import sympy

import implc
from implc import x, y, z
from implc.engines.compiled.evaluator_native import build_kernel_walk
from implc.engines.compiled.kernels_native import build_bound_module, build_mean_value_module, build_module
from implc.engines.rows_native import build_rows
from implc.engines.tape.engine_native import build_tape_engine
from implc.meshing.contour_native import build_contouring
from implc.meshing.simplify_native import build_mesh_simplify
from implc.native import abi
from implc.view.splat_native import build_splat
from implc.voxelizer.storage.octree_native import build_octree_index

DEFINE = re.compile(r'^define\s+(.*?)\s*@"?([\w.]+)"?\((.*?)\)', re.M)


def exported(ir_text: str) -> dict[str, str]:
    """name -> "ret (arg types)" of every function the module text defines and exports (typed pointers, as
    written; internal helpers left out)."""
    llvm.parse_assembly(ir_text).verify()
    out = {}
    for ret, name, args in DEFINE.findall(ir_text):
        if ret.startswith("internal "):
            continue
        types = [arg.split()[0] for arg in args.split(", ")] if args else []
        out[name] = f"{ret} ({', '.join(types)})"
    return out


@pytest.fixture(scope="module")
def surface():
    return implc.compile(sympy.Min(x**2 + y**2 - 1, sympy.exp(z) - 2) + sympy.sin(x))


@pytest.mark.parametrize("module_entries", ["surface", "mean_value", "bound", "tape", "rows", "octree",
                                            "splat", "contouring", "walk", "simplify"])
def test_every_entry_is_exported_with_its_declared_signature(module_entries, surface):
    if module_entries == "surface":
        text, entries = str(build_module(surface.tape, surface.gradient_tape)), abi.SURFACE_ENTRIES
    elif module_entries == "mean_value":
        text, entries = str(build_mean_value_module(surface.tape, surface.gradient_tape)), abi.MEAN_VALUE_ENTRIES
    elif module_entries == "bound":
        text, entries = str(build_bound_module(surface.tape, surface.gradient_tape)), abi.BOUND_ENTRIES
    elif module_entries == "tape":
        text, entries = str(build_tape_engine(directed=False)), abi.TAPE_ENTRIES
    elif module_entries == "rows":
        text, entries = str(build_rows()), abi.ROWS_ENTRIES
    elif module_entries == "octree":
        text, entries = str(build_octree_index()), abi.OCTREE_ENTRIES
    elif module_entries == "splat":
        text, entries = str(build_splat()), abi.SPLAT_ENTRIES
    elif module_entries == "contouring":
        text, entries = str(build_contouring()), abi.CONTOURING_ENTRIES
    elif module_entries == "walk":
        text, entries = str(build_kernel_walk()), abi.KERNEL_WALK_ENTRIES
    else:
        text, entries = str(build_mesh_simplify()), abi.MESH_SIMPLIFY_ENTRIES
    defined = exported(text)
    assert set(defined) == {e.name for e in entries}  # no entry missing, none undeclared
    for entry in entries:
        assert defined[entry.name] == str(entry.llvm_type()), entry.name


def test_ctypes_prototypes_follow_the_declarations():
    for entry in (*abi.SURFACE_ENTRIES, *abi.MEAN_VALUE_ENTRIES, *abi.BOUND_ENTRIES, *abi.TAPE_ENTRIES,
                  *abi.ROWS_ENTRIES, *abi.OCTREE_ENTRIES, *abi.SPLAT_ENTRIES,
                  *abi.CONTOURING_ENTRIES, *abi.KERNEL_WALK_ENTRIES, *abi.MESH_SIMPLIFY_ENTRIES):
        proto = entry.ctypes_type()
        assert len(proto._argtypes_) == len(entry.params)
        for (name, kind), ctype in zip(entry.params, proto._argtypes_):
            kinds = {"i64": ctypes.c_int64, "i32": ctypes.c_int32, "f64": ctypes.c_double}
            expected = kinds.get(kind, ctypes.c_void_p)
            assert ctype is expected, (entry.name, name)
        assert proto._restype_ is {None: None, "i32": ctypes.c_int32, "i64": ctypes.c_int64}[entry.returns]


def test_every_surface_entry_binds(surface):
    for entry in (*abi.SURFACE_ENTRIES, *abi.MEAN_VALUE_ENTRIES, *abi.BOUND_ENTRIES):
        assert surface.kernel_address(entry) != 0
        assert isinstance(surface.kernel(entry), ctypes._CFuncPtr)
    with pytest.raises(LookupError, match="implc_subdivide is not a surface kernel"):
        surface.kernel(abi.SUBDIVIDE)


def test_one_runtime_per_process(surface):
    from implc.native.runtime import Runtime
    assert surface.runtime is Runtime.shared() is implc.compile(x - y).runtime

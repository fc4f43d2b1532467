"""The package's layout keeps its promises: imports flow one way, in the order docs/architecture.md lists
the modules; every module is listed; no two modules share a file name; nothing is mounted into the
package from outside it."""

import ast
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "implc"


def documented_order() -> list[str]:
    """The module paths of the table in docs/architecture.md, top to bottom."""
    rows = []
    for line in (ROOT / "docs" / "architecture.md").read_text().splitlines():
        if line.startswith("| `implc/") and line.count("`") >= 2:
            rows.append(line.split("`")[1])
    return rows


def module_name(path: str) -> str:
    parts = path[: -len(".py")].split("/")
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(path: Path) -> set[str]:
    """implc modules ``path`` imports, anywhere in it (functions included), resolved to module names."""
    name = module_name(path.relative_to(ROOT).as_posix())
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names if alias.name.startswith("implc"))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if not target.startswith("implc"):
                continue
            for alias in node.names:  # `from . import abi` imports the module implc.native.abi
                candidate = f"{target}.{alias.name}"
                as_path = ROOT / candidate.replace(".", "/")
                is_module = as_path.with_suffix(".py").is_file() or (as_path / "__init__.py").is_file()
                found.add(candidate if is_module else target)
    found.discard("implc")  # the root package itself: every module's parent
    return found


def test_every_module_is_listed_once():
    listed = documented_order()
    assert len(listed) == len(set(listed)), "a module is listed twice"
    actual = sorted(p.relative_to(ROOT).as_posix() for p in PACKAGE.rglob("*.py") if "scene_files" not in p.parts)
    assert sorted(listed) == actual


def test_imports_flow_one_way():
    order = {module_name(path): k for k, path in enumerate(documented_order())}
    wrong = []
    for path in documented_order():
        me = module_name(path)
        for target in imported_modules(ROOT / path):
            assert target in order, f"{path} imports {target}, which is not a module of the package"
            if order[target] >= order[me]:
                wrong.append(f"{path} imports {target}, listed below it")
    assert not wrong, "\n".join(wrong)


def test_each_package_is_listed_in_one_piece():
    """A package's modules (its subpackages' included) are one run of rows: with one-way imports between rows,
    the packages themselves then import one way, in the order of their first rows."""
    rows = documented_order()
    folders = {row.rsplit("/", 1)[0] for row in rows}
    for folder in sorted(folders - {"implc"}):
        inside = [k for k, row in enumerate(rows) if row.startswith(folder + "/")]
        assert inside == list(range(inside[0], inside[-1] + 1)), f"{folder}/ is listed in more than one piece"


def test_the_checker_sees_a_wrong_import(tmp_path):
    """The walker resolves relative imports, `from . import name` and imports inside functions."""
    module = PACKAGE / "engines" / "compiled" / "kernels_native.py"
    found = imported_modules(module)
    assert {"implc.native.abi", "implc.compiler.ir", "implc.engines.compiled.plan",
            "implc.compiler.llvm.control", "implc.compiler.llvm.elementary"} <= found
    found = imported_modules(PACKAGE / "cli" / "viewing.py")
    assert {"implc.files.voxel_files", "implc.cli.arguments"} <= found


COUNTERPARTS = ("implc/engines/compiled", "implc/engines/tape")
"""The two engines' folders, whose modules carry the same name for the same role."""


def test_no_two_modules_share_a_file_name():
    """Except the engines' counterparts, each in one folder of :data:`COUNTERPARTS`."""
    paths = [p.relative_to(ROOT).as_posix() for p in PACKAGE.rglob("*.py")
             if p.name != "__init__.py" and "scene_files" not in p.parts]
    names = [p.rsplit("/", 1)[1] for p in paths if p.rsplit("/", 1)[0] not in COUNTERPARTS]
    assert len(names) == len(set(names)), sorted(n for n in names if names.count(n) > 1)
    for folder in COUNTERPARTS:  # a counterpart's name is not also a module elsewhere
        mine = {p.rsplit("/", 1)[1] for p in paths if p.rsplit("/", 1)[0] == folder}
        assert not mine & set(names), folder


def test_the_engines_have_counterparts_by_name():
    compiled, tape = ({p.name for p in (ROOT / folder).glob("*.py")} for folder in COUNTERPARTS)
    assert {"evaluator.py", "evaluator_native.py", "tighten_native.py"} <= compiled & tape
    assert "plan.py" in compiled and "plan_native.py" in tape


def test_no_module_shadows_the_standard_library():
    import sys
    names = {p.stem for p in PACKAGE.rglob("*.py")}
    assert not names & set(sys.stdlib_module_names)


def test_every_package_is_built_into_the_wheel():
    """The build's package list (pyproject.toml) names every folder of the package: a folder left out is
    missing from the wheel alone, where a checkout's tests would not notice."""
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    folders = {".".join(p.parent.relative_to(ROOT).parts) for p in PACKAGE.rglob("__init__.py")}
    assert folders == listed, (sorted(folders - listed), sorted(listed - folders))


def test_nothing_is_mounted_into_the_package_from_outside():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    setuptools = config.get("tool", {}).get("setuptools", {})
    assert "package-dir" not in setuptools
    assert all(p == "implc" or p.startswith("implc.") for p in setuptools.get("packages", []))
    for p in setuptools.get("packages", []):
        assert (ROOT / p.replace(".", "/") / "__init__.py").is_file(), p


def temporary_addresses(source: str) -> list[int]:
    """Lines where ``.ctypes.data`` is taken of an array that nothing holds: a call's result, or a property
    of the class read through ``self`` (a fresh array each time). Such an array is freed as soon as the
    address is taken, before the native routine reads it, and the allocator may hand its memory to someone
    else first. A slice, or an element of a list or tuple, of something held is held."""
    lines = []

    def visit(node, properties):
        if isinstance(node, ast.ClassDef):
            properties = {f.name for f in node.body if isinstance(f, ast.FunctionDef)
                          and any(isinstance(d, ast.Name) and d.id == "property" for d in f.decorator_list)}
        if (isinstance(node, ast.Attribute) and node.attr == "data" and isinstance(node.value, ast.Attribute)
                and node.value.attr == "ctypes"):
            held = node.value.value
            while isinstance(held, ast.Subscript) and isinstance(held.slice, (ast.Slice, ast.Constant)):
                held = held.value
            through_self = (isinstance(held, ast.Attribute) and isinstance(held.value, ast.Name)
                            and held.value.id == "self")
            if not (isinstance(held, ast.Name)
                    or (isinstance(held, ast.Attribute) and not (through_self and held.attr in properties))):
                lines.append(node.lineno)
        for child in ast.iter_child_nodes(node):
            visit(child, properties)

    visit(ast.parse(source), set())
    return sorted(lines)


def test_no_native_routine_is_handed_the_address_of_a_temporary_array():
    """Every ``.ctypes.data`` handed to a native routine is of an array something holds for the call: the
    mesher once passed its grid's geometry from a property, and meshes came out wrong at random where
    another thread's allocations took the freed memory first; a test once handed the tape engine scratch
    it had freed, and the heap it overwrote crashed mpmath later. The package, the tests and the
    benchmarks."""
    files = [*PACKAGE.rglob("*.py"), *(ROOT / "tests").rglob("*.py"), *(ROOT / "benchmarks").rglob("*.py")]
    found = {path.relative_to(ROOT).as_posix(): temporary_addresses(path.read_text()) for path in sorted(files)}
    assert not {path: lines for path, lines in found.items() if lines}


def test_the_checker_sees_a_temporary_address():
    source = ("import numpy as np\n"
              "class Grid:\n"
              "    @property\n"
              "    def geometry(self):\n"
              "        return np.zeros(4)\n"
              "    def run(self, native, a, parts):\n"
              "        native(a.ctypes.data, a[1:].ctypes.data, parts[0].ctypes.data, self.table.ctypes.data)\n"
              "        native(self.geometry.ctypes.data)\n"
              "        native(np.ascontiguousarray(a).ctypes.data)\n"
              "        native(a[a > 0].ctypes.data)\n")
    assert temporary_addresses(source) == [8, 9, 10]


def test_neither_engine_imports_the_other():
    """What both engines use lives in engines/ or below it, not in either engine's folder."""
    for mine, other in (COUNTERPARTS, COUNTERPARTS[::-1]):
        for path in sorted((ROOT / mine).glob("*.py")):
            theirs = {m for m in imported_modules(path) if m.startswith(other.replace("/", "."))}
            assert not theirs, f"{path.relative_to(ROOT)} imports {sorted(theirs)}"


def test_old_import_paths_warn_and_work():
    """Every module path of 0.2 still imports for one release, with a DeprecationWarning naming its new home."""
    import importlib
    import sys
    import warnings

    from implc.common.moved import MOVED
    for old, new in sorted(MOVED.items()):
        sys.modules.pop(f"implc.{old}", None)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            module = importlib.import_module(f"implc.{old}")
        assert any(issubclass(w.category, DeprecationWarning) and f"implc.{new[0]}" in str(w.message)
                   for w in caught), old
        target = importlib.import_module(f"implc.{new[0]}")
        public = [n for n in dir(target) if not n.startswith("_") and getattr(target, n).__class__.__name__ != "module"]
        assert all(getattr(module, n) is getattr(target, n) for n in public[:20]), old
    with pytest.warns(DeprecationWarning, match="implc.files.zarr_store"):
        sys.modules.pop("implc.zarr_store", None)
        from implc.zarr_store import write_zarr
    from implc.files.zarr_writer import write_zarr as new
    assert write_zarr is new
    # two 0.2 modules became packages: their names are forwarded by the package
    with pytest.warns(DeprecationWarning, match="implc.cluster.tasks.connect"):
        from implc.cluster import connect
    with pytest.warns(DeprecationWarning, match="implc.cli.commands.main"):
        from implc.cli import main
    from implc.cli.commands import main as new_main
    from implc.cluster.tasks import connect as new_connect
    assert connect is new_connect and main is new_main


def test_tests_follow_the_layout():
    """tests/ mirrors the packages; no test module imports another or the benchmarks: what tests share is in
    tests/support/."""
    tests = ROOT / "tests"
    for folder in (p for p in tests.iterdir() if p.is_dir() and p.name not in ("support", "__pycache__")):
        assert (PACKAGE / folder.name / "__init__.py").is_file(), f"tests/{folder.name}/ mirrors no package"
    for path in tests.rglob("test_*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                names = [node.module or ""] + [f"{node.module or ''}.{a.name}" for a in node.names]
                assert not any(n.split(".")[-1].startswith("test_") or n.startswith("benchmarks") for n in names), \
                    f"{path.relative_to(ROOT)} imports {node.module}"
            elif isinstance(node, ast.Import):
                assert not any(a.name.startswith(("benchmarks", "tests")) for a in node.names), path

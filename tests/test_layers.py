"""The package's layout keeps its promises: imports flow one way, in the order docs/architecture.md lists
the modules; every module is listed; no two modules share a file name; nothing is mounted into the
package from outside it."""

import ast
import tomllib
from pathlib import Path

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
            for alias in node.names:  # `from . import abi` imports the module implc.abi
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


def test_the_checker_sees_a_wrong_import(tmp_path):
    """The walker resolves relative imports, `from . import name` and imports inside functions."""
    module = PACKAGE / "codegen" / "kernels.py"
    found = imported_modules(module)
    assert {"implc.abi", "implc.ir", "implc.regions", "implc.codegen.control"} <= found
    found = imported_modules(PACKAGE / "cli.py")
    assert {"implc.kernel_cache", "implc.voxel_files", "implc.scene"} <= found


def test_no_two_modules_share_a_file_name():
    names = [p.name for p in PACKAGE.rglob("*.py") if p.name != "__init__.py" and "scene_files" not in p.parts]
    assert len(names) == len(set(names)), sorted(n for n in names if names.count(n) > 1)


def test_no_module_shadows_the_standard_library():
    import sys
    names = {p.stem for p in PACKAGE.rglob("*.py")}
    assert not names & set(sys.stdlib_module_names)


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

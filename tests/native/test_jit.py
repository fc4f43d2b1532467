"""The JIT and its disk cache: compiled code is reused across processes, keyed by everything that decides
it (the whole package's source included), bounded in size, and kernels run correctly from several
threads at once."""

import os
import shutil
import subprocess
import sys
import textwrap
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
import sympy

import implc
from implc import x, y, z
from implc.cli.commands import main
from implc.native import kernel_cache, parallel_compile

PROBE = textwrap.dedent("""
    import sympy, implc
    s = implc.compile(sympy.cos(implc.x) * implc.y - implc.z)
    print(implc.__file__, s.from_cache)
""")


def _probe(env_cache, pythonpath=None):
    env = {"IMPLC_CACHE_DIR": str(env_cache), "PATH": os.environ.get("PATH", "/usr/bin:/bin"),
           "PYTHONDONTWRITEBYTECODE": "1"}
    if pythonpath:
        env["PYTHONPATH"] = str(pythonpath)
    run = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True,
                         cwd=env_cache.parent)  # not the checkout: "" on sys.path would import it first
    module, from_cache = run.stdout.split()
    return Path(module), from_cache == "True"


def test_second_compile_loads_from_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("IMPLC_CACHE_DIR", str(tmp_path))
    expr = sympy.sin(x * 3) + y * z
    first = implc.compile(expr)
    assert not first.from_cache
    assert len(list(tmp_path.glob("*.o"))) == 1
    second = implc.compile(expr)
    assert second.from_cache
    pts = np.random.default_rng(0).uniform(-1, 1, (100, 3))
    np.testing.assert_array_equal(first.eval(pts), second.eval(pts))
    assert not implc.compile(expr + 1).from_cache  # a different surface is a different key
    assert not implc.compile(expr, vector_width=4).from_cache  # and so are other compile options
    assert not implc.compile(expr, rounding="widen").from_cache


def test_another_process_reuses_the_cache(tmp_path):
    assert [_probe(tmp_path)[1] for _ in range(2)] == [False, True]


def test_a_first_voxelization_compiles_no_mesher_and_its_parts_compute_what_the_whole_does(tmp_path):
    """A cold start that only voxelizes a tape-engine surface compiles the tape engine, the walk's rows and the
    octree's index, nothing more (the mesher's module, a fifth of a colonnade's first compile, waits for a first
    mesh); a
    surface with compiled kernels adds its kernels, the walk over them and its bound kernel, and its
    box-gradient kernel on its first mesh. Compiled in parts at once (implc.native.parallel_compile: one object
    per part in the cache entry), the modules give the same voxels, normals and meshes, bit for bit, as
    compiled whole."""
    probe = textwrap.dedent("""
        import hashlib, sys, sympy, implc
        from pathlib import Path
        from implc import x, y, z
        from implc.native import jit
        from implc.native import kernel_cache
        from implc.native import parallel_compile
        parallel_compile.MAX_WORKERS = int(sys.argv[2])
        entries = lambda: len(list(Path(sys.argv[1]).glob("*.o")))
        digest = lambda v: hashlib.sha256(v.coords.tobytes() + v.normals.tobytes()).hexdigest()
        s = implc.compile(sympy.Min(x**2 + y**2 + z**2 - 0.5, x + y - 0.25), engine="tape")
        v = implc.voxelize(s, 6)
        print(entries(), len(jit._unbundle(kernel_cache.load(s._engine.native.key))), len(v), digest(v))
        k = implc.compile(sympy.sin(3 * x) * y + z**2 - 0.3, engine="jit")
        w = implc.voxelize(k, 6)
        print(entries(), len(w), digest(w))
        implc.mesh(s, 4)
        print(entries())
        mesh = implc.mesh(k, 5)
        print(entries(), len(mesh.faces), hashlib.sha256(mesh.vertices.tobytes() + mesh.faces.tobytes()).hexdigest())
    """)
    runs = []
    for workers in (1, parallel_compile.MAX_WORKERS):
        cache = tmp_path / f"kernels-{workers}"
        env = {"IMPLC_CACHE_DIR": str(cache), "PATH": os.environ.get("PATH", "/usr/bin:/bin"),
               "PYTHONDONTWRITEBYTECODE": "1"}
        run = subprocess.run([sys.executable, "-c", probe, str(cache), str(workers)], env=env,
                             capture_output=True, text=True, check=True, cwd=tmp_path)
        runs.append([line.split() for line in run.stdout.splitlines()])
    whole, parts = runs
    assert whole[0][0] == parts[0][0] == "3"  # the tape engine, the walk's rows and the octree's index
    assert whole[1][0] == parts[1][0] == "6"  # and the kernels, the walk over them and the bound kernel
    assert whole[2] == parts[2] == ["7"]  # the contouring's, on the first mesh
    assert whole[3][0] == parts[3][0] == "8"  # and the compiled kernels' box gradients, on theirs
    assert whole[0][1] == "1" and parts[0][1] == str(min(parallel_compile.MAX_WORKERS,
                                                         len(os.sched_getaffinity(0))))
    assert int(whole[0][2]) > 1000 and int(whole[1][1]) > 1000
    assert int(whole[3][1]) > 1000
    assert whole[0][2:] == parts[0][2:] and whole[1][1:] == parts[1][1:] and whole[3][1:] == parts[3][1:]


def test_the_cache_key_covers_a_module_in_every_package(tmp_path):
    """An edit to any module, in any package of the layout, gives another fingerprint of the package (a part
    of every cache key), and so does a module moved to another folder."""
    root = Path(implc.__file__).parent
    copy = tmp_path / "implc"
    shutil.copytree(root, copy, ignore=shutil.ignore_patterns("__pycache__"))
    packages = sorted(p.parent for p in copy.rglob("__init__.py"))
    assert {p.relative_to(copy).as_posix() for p in packages} >= {".", "compiler", "compiler/llvm", "native", "engines",
                                                                   "engines/compiled", "engines/tape", "voxelizer",
                                                                   "meshing", "files", "view", "cluster", "cli"}
    seen = {kernel_cache.source_fingerprint(copy)}
    for package in packages:
        module = sorted(package.glob("*.py"))[-1]
        with open(module, "a") as f:
            f.write("\n# edited\n")
        seen.add(kernel_cache.source_fingerprint(copy))
        assert len(seen) == packages.index(package) + 2, module
    (copy / "meshing" / "formats.py").rename(copy / "files" / "formats.py")
    assert kernel_cache.source_fingerprint(copy) not in seen
    assert kernel_cache.source_fingerprint(root) == kernel_cache.package_fingerprint()


@pytest.mark.slow  # twelve fresh processes, 9 s; test_another_process_reuses_the_cache stays in the default run
def test_editing_any_module_of_the_package_invalidates_the_cache(tmp_path):
    """A comment appended to a module that the code generator never reads as code (the region planner,
    the IR, the gradient, the package's __init__) is still a different package: no cached kernel of the
    old source may be served."""
    copy = tmp_path / "src"
    shutil.copytree(Path(implc.__file__).parent, copy / "implc", ignore=shutil.ignore_patterns("__pycache__"))
    cache = tmp_path / "cache"
    module, from_cache = _probe(cache, copy)
    assert module == copy / "implc" / "__init__.py" and not from_cache
    assert _probe(cache, copy)[1]
    for name in ("engines/compiled/plan.py", "compiler/ir.py", "compiler/gradient.py", "__init__.py",
                 "voxelizer/storage/dense.py"):
        with open(copy / "implc" / name, "a") as f:
            f.write("\n# edited\n")
        assert not _probe(cache, copy)[1], name
        assert _probe(cache, copy)[1], name


def test_cache_can_be_disabled(monkeypatch):
    monkeypatch.setenv("IMPLC_CACHE_DIR", "off")
    assert not implc.compile(x + 2 * y).from_cache
    assert not implc.compile(x + 2 * y).from_cache


def test_a_corrupt_cache_entry_is_not_trusted_blindly(tmp_path, monkeypatch):
    monkeypatch.setenv("IMPLC_CACHE_DIR", str(tmp_path))
    implc.compile(x - y * 5)
    (entry,) = tmp_path.glob("*.o")
    entry.write_bytes(b"not an object file")
    s = implc.compile(x - y * 5)
    assert not s.from_cache
    np.testing.assert_array_equal(s.eval(np.array([[1.0, 1.0, 0.0]])), [-4.0])


def test_the_cache_is_bounded_least_recently_used_first(tmp_path, monkeypatch):
    monkeypatch.setenv("IMPLC_CACHE_DIR", str(tmp_path))
    exprs = [x - k * y for k in range(1, 5)]
    for k, expr in enumerate(exprs):
        implc.compile(expr)
        (newest,) = [p for p in tmp_path.glob("*.o") if p.stat().st_mtime_ns == max(
            q.stat().st_mtime_ns for q in tmp_path.glob("*.o"))]
        os.utime(newest, (1000.0 + k, 1000.0 + k))  # a clear order of use: exprs[0] oldest
    sizes = sorted(p.stat().st_size for p in tmp_path.glob("*.o"))
    assert len(sizes) == 4
    assert implc.compile(exprs[0]).from_cache  # a hit is a use: exprs[0] is now the most recent
    limit = sum(sizes[-3:]) + 1  # room for three entries
    monkeypatch.setenv("IMPLC_CACHE_MAX_MB", str(limit / 2**20))
    implc.compile(x - 99 * y)  # a fifth entry: the two least recently used go
    assert sum(p.stat().st_size for p in tmp_path.glob("*.o")) <= limit
    assert implc.compile(exprs[0]).from_cache
    assert not implc.compile(exprs[1]).from_cache


def test_eviction_keeps_the_entry_just_written(tmp_path):
    old, new = tmp_path / "a.o", tmp_path / "b.o"
    old.write_bytes(b"x" * 100)
    new.write_bytes(b"y" * 100)
    os.utime(old, (time.time() - 100,) * 2)
    assert kernel_cache.evict(tmp_path, limit=50, keep="b") == 1
    assert new.exists() and not old.exists()


def test_cache_command_shows_and_clears(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("IMPLC_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("IMPLC_CACHE_MAX_MB", "64")
    implc.compile(x * y - 3)
    implc.compile(x * y - 4)
    assert main(["cache"]) == 0
    out = capsys.readouterr().out
    assert str(tmp_path) in out and "entries       2" in out and "at most 64 MiB" in out
    assert main(["cache", "clear"]) == 0
    assert "removed 2 cached kernel modules" in capsys.readouterr().out
    assert not list(tmp_path.glob("*.o"))
    monkeypatch.setenv("IMPLC_CACHE_MAX_MB", "lots")
    assert main(["cache"]) == 2
    assert "IMPLC_CACHE_MAX_MB must be a number" in capsys.readouterr().err


def test_the_suite_uses_its_own_cache():
    """conftest.py points every compile of the run at a temporary folder, never the user's cache."""
    folder = kernel_cache.directory()
    assert folder is not None and folder != Path.home() / ".cache" / "implc"
    assert not str(folder).startswith(str(Path(__file__).resolve().parents[2]))  # not in the checkout


def test_kernels_run_from_threads():
    s = implc.compile(sympy.exp(x) * sympy.sin(y) - z**2)
    rng = np.random.default_rng(1)
    chunks = [rng.uniform(-1, 1, (5000, 3)) for _ in range(8)]
    expected = [s.eval(c) for c in chunks]
    with ThreadPoolExecutor(4) as pool:
        got = list(pool.map(s.eval, chunks))
    for e, g in zip(expected, got):
        np.testing.assert_array_equal(e, g)


def test_inspection_texts():
    s = implc.compile(x * y - 1)
    assert "mul" in s.ir
    assert "define void @\"implc_interval\"" in s.llvm_ir or "define void @implc_interval" in s.llvm_ir


@pytest.mark.parametrize("engine", ["jit", "tape"])
def test_large_batches_spread_over_threads_give_numpys_values(engine):
    """Surface.eval and .gradient over many chunks (run on several threads at once) against numpy's own
    evaluation of the expression and of SymPy's derivatives, row for row."""
    from implc.common.threads import CHUNK
    expr = sympy.sin(3 * x) * y + sympy.exp(z / 2) - x * z
    surface = implc.compile(expr, engine=engine)
    points = np.random.default_rng(5).uniform(-1, 1, (5 * CHUNK + 13, 3))
    truth = sympy.lambdify((x, y, z), expr, "numpy")(*points.T)
    np.testing.assert_allclose(surface.eval(points), truth, rtol=1e-13, atol=1e-13)
    partials = np.stack([sympy.lambdify((x, y, z), sympy.diff(expr, v), "numpy")(*points.T) for v in (x, y, z)], 1)
    np.testing.assert_allclose(surface.gradient(points), partials, rtol=1e-12, atol=1e-12)


def test_parallel_jobs_raise_the_first_error_and_cancel_the_rest():
    from implc.common.threads import in_parallel
    ran = []

    def fails():
        raise ValueError("this job failed")

    def slow():
        time.sleep(0.001)
        ran.append(1)
    started = time.monotonic()
    with pytest.raises(ValueError, match="this job failed"):
        in_parallel([fails] + [slow] * 5000)
    assert len(ran) < 1000 and time.monotonic() - started < 2  # the jobs not started were cancelled

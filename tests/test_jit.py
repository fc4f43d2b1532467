"""The JIT: compiled code is cached on disk across processes, keyed by what it computes, and kernels
run correctly from several threads at once."""

import subprocess
import sys
import textwrap
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import sympy

import implc
from implc import x, y, z


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
    other = implc.compile(expr + 1)
    assert not other.from_cache  # a different surface is a different key


def test_another_process_reuses_the_cache(tmp_path):
    code = textwrap.dedent("""
        import sympy, implc
        s = implc.compile(sympy.cos(implc.x) * implc.y - implc.z)
        print(s.from_cache)
    """)
    env = {"IMPLC_CACHE_DIR": str(tmp_path), "PATH": "/usr/bin:/bin"}
    runs = [subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
            for _ in range(2)]
    assert [run.stdout.strip() for run in runs] == ["False", "True"]


def test_cache_can_be_disabled(tmp_path, monkeypatch):
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

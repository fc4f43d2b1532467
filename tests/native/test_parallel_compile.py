"""A first compile's parts at once: a module's IR in parts (implc.native.split) computes what the whole
module computes, and jobs spread over forked processes come back whole and in order, even when a worker
dies, fails or the caller is interrupted; a process with other threads never forks."""

import ctypes
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from llvmlite import ir

from implc.native import jit, parallel_compile, split

DOUBLE = ir.DoubleType()
V8 = ir.VectorType(DOUBLE, 8)
STEPS = split.SHARED_MAX  # the big function's multiply-adds: twice SHARED_MAX instructions, so it is placed


def _splat(value):
    return ir.Constant(V8, [value] * 8)


def _module() -> ir.Module:
    """A small helper (copied where called), a big function dispatching through a table of its own blocks
    (placed in one part, with its table) that reads vector constants (each object's own constant pool), and
    two exported entries calling both in the opposite order."""
    module = ir.Module(name="split_test")
    helper = ir.Function(module, ir.FunctionType(V8, [V8]), "split_test.helper")
    helper.linkage = "internal"
    b = ir.IRBuilder(helper.append_basic_block("entry"))
    b.ret(b.fadd(b.fmul(helper.args[0], _splat(1.5)), _splat(0.25)))

    big = ir.Function(module, ir.FunctionType(V8, [V8, ir.IntType(32)]), "split_test.big")
    big.linkage = "internal"
    entry, add_one, double, done = (big.append_basic_block(n) for n in ("entry", "add_one", "double", "done"))
    pointer = ir.IntType(8).as_pointer()
    table = ir.GlobalVariable(module, ir.ArrayType(pointer, 2), "split_test.big.dispatch")
    table.initializer = ir.Constant(ir.ArrayType(pointer, 2), [ir.BlockAddress(big, add_one),
                                                              ir.BlockAddress(big, double)])
    table.global_constant, table.linkage = True, "internal"
    b = ir.IRBuilder(entry)
    value = big.args[0]
    for k in range(STEPS):
        value = b.fadd(b.fmul(value, _splat(1 + k / 1024)), _splat(k / 8 - 3))
    target = b.load(b.gep(table, [ir.Constant(ir.IntType(32), 0), big.args[1]]))
    branch = b.branch_indirect(target)
    branch.add_destination(add_one)
    branch.add_destination(double)
    b = ir.IRBuilder(add_one)
    plus = b.fadd(value, _splat(1.0))
    b.branch(done)
    b = ir.IRBuilder(double)
    twice = b.fmul(value, _splat(2.0))
    b.branch(done)
    b = ir.IRBuilder(done)
    result = b.phi(V8)
    result.add_incoming(plus, add_one)
    result.add_incoming(twice, double)
    b.ret(result)

    for name, order in (("split_test_e1", (helper, big)), ("split_test_e2", (big, helper))):
        fn = ir.Function(module, ir.FunctionType(ir.VoidType(), [DOUBLE.as_pointer()] * 2), name)
        b = ir.IRBuilder(fn.append_basic_block("entry"))
        value = b.load(b.bitcast(fn.args[0], V8.as_pointer()), align=8)
        for callee in order:
            value = b.call(callee, [value] if callee is helper else [value, ir.Constant(ir.IntType(32), 1)])
        b.store(value, b.bitcast(fn.args[1], V8.as_pointer()), align=8)
        b.ret_void()
    return module


def _truth(v: np.ndarray, order: tuple[str, str]) -> np.ndarray:
    for step in order:
        if step == "helper":
            v = v * 1.5 + 0.25
        else:
            for k in range(STEPS):
                v = v * (1 + k / 1024) + (k / 8 - 3)
            v = v * 2.0
    return v


@pytest.mark.parametrize("parts", [1, 2, 3])
def test_a_module_in_parts_computes_what_numpy_does(parts, tmp_path, monkeypatch):
    monkeypatch.setenv("IMPLC_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(parallel_compile, "workers", lambda: parts)  # the parts' count...
    monkeypatch.setattr(os, "fork", lambda: (_ for _ in ()).throw(OSError("no fork")))  # ...all run here
    module = _module()
    texts = [split.writer(module, parts)(k) for k in range(parts)]
    def defines(text, name):
        return any(line.startswith("define") and f'@"{name}"(' in line for line in text.splitlines())

    for name in ("split_test.big", "split_test_e1", "split_test_e2"):  # placed: defined in one part only
        assert sum(defines(t, name) for t in texts) == 1
    assert [defines(t, "split_test.big") for t in texts] == [
        '@"split_test.big.dispatch" =' in t for t in texts]  # the table goes with its blocks
    assert all(defines(t, "split_test.helper") for t in texts if defines(t, "split_test_e1")
               or defines(t, "split_test_e2"))  # copied into each part that calls it
    native = jit.NativeModule(lambda: module, f"split-test-{parts}", max_parts=parts)
    assert len(jit._unbundle(jit.kernel_cache.load(native.key))) == parts
    v = np.random.default_rng(parts).uniform(-1, 1, 8)
    for name, order in (("split_test_e1", ("helper", "big")), ("split_test_e2", ("big", "helper"))):
        out = np.empty(8)
        ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)(native.address(name))(v.ctypes.data,
                                                                                      out.ctypes.data)
        np.testing.assert_array_equal(out, _truth(v.copy(), order))


def _run(code: str, tmp_path) -> str:
    run = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                         timeout=120, cwd=tmp_path, env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1"})
    assert run.returncode == 0, run.stderr
    return run.stdout


def _cpus() -> int:
    return len(os.sched_getaffinity(0))


needs_two = pytest.mark.skipif(sys.platform != "linux" or _cpus() < 2,
                               reason="workers are forked on Linux with two CPUs or more only")


@needs_two
def test_jobs_spread_over_processes_come_back_in_order(tmp_path):
    out = _run("""
        import os
        from implc.native import parallel_compile
        answers = parallel_compile.run(lambda j: f"{j} {os.getpid()}".encode(), 7, [1.0] * 7)
        print(os.getpid(), parallel_compile.workers())
        print("\\n".join(a.decode() for a in answers))
    """, tmp_path).split("\n")
    parent, workers = map(int, out[0].split())
    assert workers == min(parallel_compile.MAX_WORKERS, _cpus())
    rows = [tuple(map(int, line.split())) for line in out[1:8]]
    assert [j for j, _ in rows] == list(range(7))
    pids = {pid for _, pid in rows}
    assert parent in pids and len(pids) == workers


@needs_two
def test_a_worker_that_dies_or_fails_leaves_its_jobs_to_the_caller(tmp_path):
    out = _run("""
        import os, signal
        from implc.native import parallel_compile
        parent = os.getpid()
        def job(j):
            if os.getpid() != parent:
                if j % 2:
                    os.kill(os.getpid(), signal.SIGKILL)
                raise RuntimeError("a worker's failure")
            return f"{j} {os.getpid()}".encode()
        print(parent)
        print("\\n".join(a.decode() for a in parallel_compile.run(job, 6, [1.0] * 6)))
    """, tmp_path).split("\n")
    parent = int(out[0])
    assert [tuple(map(int, line.split())) for line in out[1:7]] == [(j, parent) for j in range(6)]


def test_a_process_with_other_threads_never_forks(tmp_path):
    out = _run("""
        import os, threading
        from implc.native import parallel_compile
        stop = threading.Event()
        threading.Thread(target=stop.wait).start()
        pids = parallel_compile.run(lambda j: str(os.getpid()).encode(), 4, [1.0] * 4)
        print(parallel_compile.workers(), set(pids) == {str(os.getpid()).encode()})
        stop.set()
    """, tmp_path).split()
    assert out == ["1", "True"]


@needs_two
def test_an_interrupted_caller_takes_its_workers_down(tmp_path):
    """The caller's own job raises (as Ctrl-C would) while its workers still run: run returns at once with
    the error, and no worker outlives it."""
    out = _run("""
        import os, time
        from implc.native import parallel_compile
        parent = os.getpid()
        def job(j):
            if os.getpid() == parent:
                time.sleep(0.5)  # the workers are up and writing their pids by now
                raise KeyboardInterrupt
            open(f"worker-{os.getpid()}", "w").close()
            time.sleep(60)
            return b""
        start = time.monotonic()
        try:
            parallel_compile.run(job, 4, [1.0] * 4)
        except KeyboardInterrupt:
            print("interrupted", round(time.monotonic() - start))
    """, tmp_path).split()
    assert out[0] == "interrupted" and int(out[1]) < 30
    pids = [int(p.name.removeprefix("worker-")) for p in tmp_path.glob("worker-*")]
    assert pids
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)

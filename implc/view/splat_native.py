"""``implc_splat``: z-buffered square splats for the point renderer (the nearest point wins each pixel)."""

from __future__ import annotations

from llvmlite import ir

from ..compiler.llvm.control import I64, const, define, for_range, if_, load_at, store_at
from ..native import abi
from ..native.jit import Source
from ..native.runtime import Library


def emit_splat(module: ir.Module):
    fn, b = define(module, abi.SPLAT)
    px, py, sizes, depth, n, size, zbuf, winner = fn.args
    zero = const(I64, 0)
    with for_range(b, n) as i:
        k = load_at(b, sizes, i)
        half = b.sdiv(k, const(I64, 2))
        x0, y0 = b.sub(load_at(b, px, i), half), b.sub(load_at(b, py, i), half)
        z = load_at(b, depth, i)
        with for_range(b, k) as dy:
            y = b.add(y0, dy)
            with if_(b, b.and_(b.icmp_signed(">=", y, zero), b.icmp_signed("<", y, size))):
                with for_range(b, k) as dx:
                    x = b.add(x0, dx)
                    with if_(b, b.and_(b.icmp_signed(">=", x, zero), b.icmp_signed("<", x, size))):
                        pixel = b.add(b.mul(y, size), x)
                        with if_(b, b.fcmp_ordered("<", z, load_at(b, zbuf, pixel))):
                            store_at(b, z, zbuf, pixel)
                            store_at(b, i, winner, pixel)
    b.ret_void()


def build_splat() -> ir.Module:
    """The splatting module."""
    module = ir.Module(name="implc_splat")
    emit_splat(module)
    return module


SPLAT = Library(Source(build_splat, "implc-splat"), abi.SPLAT_ENTRIES)

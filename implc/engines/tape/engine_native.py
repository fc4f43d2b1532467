"""The tape-engine module: one native interpreter for every :class:`~implc.engines.tape.program.TapeProgram`.

Exports (signatures in :mod:`implc.native.abi`): ``implc_tape_interval`` (enclosures over boxes, rows of an
(n, 3) array; an undefined result is the whole line), ``implc_tape_gradient`` (F and its gradient at
points), ``implc_tape_box_gradient`` (enclosures of F and its partials over boxes, as the second look at
the leaves uses them), ``implc_tape_subdivide`` (:mod:`.tape_subdivision`) and ``implc_tape_grouped`` (F at
points grouped by box, each group's program simplified over its box: :mod:`.tape_points`). The same for
every surface, so it is compiled once per rounding mode and cached (:class:`implc.native.runtime.Runtime`); a
surface run by the engine compiles nothing of its own.
"""

from __future__ import annotations

from contextlib import contextmanager

from llvmlite import ir

from ...compiler.llvm.control import I64, define, for_range, load_at, local_array
from ...compiler.llvm.interval_rules import whole_line_if_undefined
from ...compiler.llvm.rows import load_xyz, store_lanes, store_xyz
from ...compiler.llvm.vector import DOUBLE, VectorBuilder
from ...native import abi
from .evaluator_native import emit_tape_normals, emit_tape_subdivide
from .interpreter_native import (
    LANES,
    V8,
    emit_tape_box_gradient,
    emit_tape_dual,
    emit_tape_interval,
    emit_tape_prefill,
)
from .plan_native import emit_tape_simplify
from .points_native import emit_tape_grouped
from .tighten_native import emit_tape_tighten

_P = ir.PointerType


def _soa(b, base, block, target):
    """Rows ``8·block ..`` of an (n, 3) array as three vectors of eight, stored at ``target``."""
    vtarget = b.bitcast(target, _P(V8))
    for a, axis in enumerate(load_xyz(b, base, block, LANES)):
        b.store(axis, b.gep(vtarget, [ir.Constant(I64, a)]), align=8)


def build_tape_engine(directed: bool) -> ir.Module:
    """The tape-engine module (``directed``: see :class:`~implc.compiler.llvm.vector.VectorBuilder`)."""
    module = ir.Module(name="implc_tape_engine")
    prefill = emit_tape_prefill(module)
    interval = emit_tape_interval(module, directed)
    dual = emit_tape_dual(module)
    simplify, substituting = emit_tape_simplify(module), emit_tape_simplify(module, substitute=True)
    normals = emit_tape_normals(module, dual)
    box_gradient = emit_tape_box_gradient(module, directed)
    point = emit_tape_dual(module, partials=False)
    tighten = emit_tape_tighten(module, interval, box_gradient, point, directed)
    emit_tape_subdivide(module, prefill, interval, (simplify, substituting), normals, tighten)
    emit_tape_grouped(module, prefill, interval, (simplify, substituting), point, dual, box_gradient)
    null_remap = ir.Constant(_P(ir.IntType(32)), None)

    @contextmanager
    def over_blocks(entry, inputs, results):
        """Define ``entry``: its prefilled slots, then a loop over blocks of eight rows with ``inputs``
        (scratch doubles per block), ``results`` (scratch doubles) and the whole program; yields the
        builder, the function's arguments, the block, the scratch arrays and the program."""
        fn, b = define(module, entry)
        header, slots = fn.args[:2]
        scratch = local_array(b, DOUBLE, inputs, "in"), local_array(b, DOUBLE, results, "result")
        b.call(prefill, [header, slots, null_remap])
        program = (b.inttoptr(load_at(b, header, abi.PROGRAM_INSTRUCTIONS), _P(ir.IntType(32))),
                   load_at(b, header, abi.PROGRAM_LENGTH), load_at(b, header, abi.PROGRAM_OUTPUT))
        with for_range(b, b.sdiv(fn.args[-1], ir.Constant(I64, LANES))) as block:
            yield b, fn.args, block, scratch, program
        b.ret_void()

    with over_blocks(abi.TAPE_INTERVAL, 6 * LANES, 2 * LANES) as (b, args, block, (box, result), program):
        header, slots, choices, lo, hi, out_lo, out_hi, n = args
        _soa(b, lo, block, box)
        _soa(b, hi, block, b.gep(box, [ir.Constant(I64, 3 * LANES)]))
        b.call(interval, [header, *program, slots, choices, box, result])
        vresult = b.bitcast(result, _P(V8))
        f_lo, f_hi = whole_line_if_undefined(VectorBuilder(b, LANES), b.load(vresult, align=8),
                                             b.load(b.gep(vresult, [ir.Constant(I64, 1)]), align=8))
        store_lanes(b, out_lo, block, f_lo, LANES)
        store_lanes(b, out_hi, block, f_hi, LANES)

    with over_blocks(abi.TAPE_GRADIENT, 3 * LANES, 4 * LANES) as (b, args, block, (points, result), program):
        header, slots, pts, out_value, out_grad, n = args
        _soa(b, pts, block, points)
        b.call(dual, [header, *program, slots, points, result])
        vresult = b.bitcast(result, _P(V8))
        store_lanes(b, out_value, block, b.load(vresult, align=8), LANES)
        store_xyz(b, out_grad, block, [b.load(b.gep(vresult, [ir.Constant(I64, 1 + a)]), align=8) for a in range(3)],
                  LANES)

    with over_blocks(abi.TAPE_POINT, 3 * LANES, LANES) as (b, args, block, (points, result), program):
        header, slots, pts, out_value, n = args
        _soa(b, pts, block, points)
        b.call(point, [header, *program, slots, points, result])
        store_lanes(b, out_value, block, b.load(b.bitcast(result, _P(V8)), align=8), LANES)

    with over_blocks(abi.TAPE_BOX_GRADIENT, 6 * LANES, 8 * LANES) as (b, args, block, (box, result), program):
        header, slots, lo, hi, out, n = args
        _soa(b, lo, block, box)
        _soa(b, hi, block, b.gep(box, [ir.Constant(I64, 3 * LANES)]))
        b.call(box_gradient, [header, *program, slots, box, result, ir.Constant(_P(DOUBLE), None)])
        rows = b.gep(out, [b.mul(block, ir.Constant(I64, 8 * LANES))])
        for k in range(8):  # lane j of result vector k: entry k of box j's row
            for j in range(LANES):
                value = b.load(b.gep(result, [ir.Constant(I64, LANES * k + j)]))
                b.store(value, b.gep(rows, [ir.Constant(I64, 8 * j + k)]))
    return module

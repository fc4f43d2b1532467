"""``implc_tape_grouped``: the tape engine at points grouped by box, each group running the program
simplified over its box.

The points of group g are rows ``starts[g] .. starts[g + 1]`` of ``pts`` (a multiple of eight each: the
caller pads a group with copies of its last point), all inside the box ``lo[g] .. hi[g]``. Eight groups at a
time, ``tape_interval`` encloses F over their boxes recording the Min/Max choices each box decides; each
group's program is then ``tape_simplify``'d by those choices (the full program where none was decided), and
runs at the group's rows, by ``mode``:

- 0: F at the points by ``tape_point`` (the dual numbers' value rules without the partials) into
  ``out_value``;
- 1: F and its gradient by ``tape_dual`` into ``out_value`` and ``out_grad`` (three per row);
- 2: the rows are boxes (``pts`` their lo corners, ``pts_hi`` their hi), and ``tape_box_gradient`` encloses
  F and its partials over each into ``out_grad`` (eight per row: F's lo, hi, then each partial's), or its
  derivatives along the three directions at ``seeds`` where that is not NULL;
- 3: the rows are boxes, and ``tape_interval`` encloses F over each into ``out_grad`` (two per row: lo, hi),
  the group's program also reading a constant for each exponential term negligible over the group's box
  (``tape_simplify_substituting``); ``choices`` has room for twice 8 bytes per instruction here.
 A decided choice holds at every point of its box, so the
simplified program computes what the full one does there (docs/soundness.md): the mesher samples a model of
thousands of instructions with the few that matter near each point.
"""

from __future__ import annotations

from llvmlite import ir

from ...compiler.llvm.control import I32, I64, Local, const, define, for_range, if_, load_at, local_array, store_at
from ...compiler.llvm.rows import load_xyz, store_lanes, store_xyz
from ...compiler.llvm.vector import DOUBLE
from ...native import abi
from .interpreter_native import LANES, V8, interval_findings
from .plan_native import call_simplify

_P = ir.PointerType


def emit_tape_grouped(module: ir.Module, prefill: ir.Function, interval: ir.Function, simplify: tuple,
                      point: ir.Function, dual: ir.Function, box_gradient: ir.Function):
    """Define ``implc_tape_grouped`` (see the module docstring) in ``module``; ``simplify``: ``tape_simplify``
    and its substituting variant."""
    fn, b = define(module, abi.TAPE_GROUPED)
    (header, slots, choices, need, marks, remap, work, lo, hi, starts, groups, pts, pts_hi, out_value, out_grad,
     mode, seeds) = fn.args
    program = b.inttoptr(load_at(b, header, abi.PROGRAM_INSTRUCTIONS), _P(I32))
    length = load_at(b, header, abi.PROGRAM_LENGTH)
    output = load_at(b, header, abi.PROGRAM_OUTPUT)
    box = local_array(b, DOUBLE, 6 * LANES, "box")
    result = local_array(b, DOUBLE, 8 * LANES, "result")
    simplified_output = local_array(b, I64, 1, "simplified_output")
    substituted = local_array(b, I64, 1, "substituted")
    run_program = Local(b, _P(I32), None, "run_program")
    run_length = Local(b, I64, None, "run_length")
    run_output = Local(b, I64, None, "run_output")
    stamp = Local(b, I32, 0, "stamp")
    vbox, vresult = b.bitcast(box, _P(V8)), b.bitcast(result, _P(V8))
    last = b.sub(groups, const(I64, 1))
    b.call(prefill, [header, slots, remap])

    with for_range(b, b.sdiv(b.add(groups, const(I64, LANES - 1)), const(I64, LANES))) as batch:
        first = b.mul(batch, const(I64, LANES))
        for lane in range(LANES):  # lane j: group first + j (the last group again past the end)
            g = b.add(first, const(I64, lane))
            g = b.select(b.icmp_signed(">", g, last), last, g)
            for a in range(3):
                k = b.add(b.mul(g, const(I64, 3)), const(I64, a))
                store_at(b, load_at(b, lo, k), box, const(I64, a * LANES + lane))
                store_at(b, load_at(b, hi, k), box, const(I64, (3 + a) * LANES + lane))
        found = b.call(interval, [header, program, length, output, slots, choices, box, result])
        enclosing = b.icmp_unsigned("==", mode, const(I64, 3))  # the only mode that may substitute a term
        choices_decided, terms_negligible = interval_findings(b, found)
        decided = b.zext(b.select(enclosing, b.or_(choices_decided, terms_negligible), choices_decided), I64)
        with for_range(b, const(I64, LANES)) as lane:
            g = b.add(first, lane)
            with if_(b, b.icmp_signed("<", g, groups)):
                run_program.set(program)
                run_length.set(length)
                run_output.set(output)
                with if_(b, b.trunc(b.lshr(decided, lane), ir.IntType(1))):
                    stamp.set(b.add(stamp.get(), const(I32, 1)))  # the caller's ``need`` starts at zero
                    arguments = [program, length, output, choices, lane, work, need, stamp.get(), marks, remap,
                                 simplified_output, load_at(b, header, abi.PROGRAM_ZERO)]
                    run_length.set(call_simplify(b, simplify, arguments, substituted, enclosing))
                    run_program.set(work)
                    run_output.set(b.load(simplified_output))
                begin = b.sdiv(load_at(b, starts, g), const(I64, LANES))
                end = b.sdiv(load_at(b, starts, b.add(g, const(I64, 1))), const(I64, LANES))
                with for_range(b, end, start=begin) as block:
                    program_now = [run_program.get(), run_length.get(), run_output.get(), slots]
                    xyz = load_xyz(b, pts, block, LANES)
                    for a, axis in enumerate(xyz):
                        b.store(axis, b.gep(vbox, [const(I64, a)]), align=8)
                        b.store(axis, b.gep(vbox, [const(I64, 3 + a)]), align=8)
                    switch = b.switch(b.trunc(mode, I32), b.append_basic_block("mode.value"))
                    done = b.append_basic_block("mode.done")
                    b.position_at_end(switch.default)  # 0: F
                    b.call(point, [header, *program_now, box, result])
                    store_lanes(b, out_value, block, b.load(vresult, align=8), LANES)
                    b.branch(done)
                    gradient = b.append_basic_block("mode.gradient")  # 1: F and its gradient
                    switch.add_case(const(I32, 1), gradient)
                    b.position_at_end(gradient)
                    b.call(dual, [header, *program_now, box, result])
                    store_lanes(b, out_value, block, b.load(vresult, align=8), LANES)
                    store_xyz(b, out_grad, block, [b.load(b.gep(vresult, [const(I64, 1 + a)]), align=8)
                                                   for a in range(3)], LANES)
                    b.branch(done)
                    boxes = b.append_basic_block("mode.box_gradient")  # 2: F and its partials over boxes
                    switch.add_case(const(I32, 2), boxes)
                    b.position_at_end(boxes)
                    for a, axis in enumerate(load_xyz(b, pts_hi, block, LANES)):
                        b.store(axis, b.gep(vbox, [const(I64, 3 + a)]), align=8)
                    b.call(box_gradient, [header, *program_now, box, result, seeds])
                    rows = b.gep(out_grad, [b.mul(block, const(I64, 8 * LANES))])
                    for k in range(8):  # lane j of result vector k: entry k of box j's row
                        for j in range(LANES):
                            value = b.load(b.gep(result, [const(I64, LANES * k + j)]))
                            b.store(value, b.gep(rows, [const(I64, 8 * j + k)]))
                    b.branch(done)
                    intervals = b.append_basic_block("mode.interval")  # 3: F over boxes
                    switch.add_case(const(I32, 3), intervals)
                    b.position_at_end(intervals)
                    for a, axis in enumerate(load_xyz(b, pts_hi, block, LANES)):
                        b.store(axis, b.gep(vbox, [const(I64, 3 + a)]), align=8)
                    row_choices = b.gep(choices, [b.mul(length, const(I64, LANES))])  # not the groups' choices
                    b.call(interval, [header, *program_now, row_choices, box, result])
                    rows = b.gep(out_grad, [b.mul(block, const(I64, 2 * LANES))])
                    for k in range(2):
                        for j in range(LANES):
                            b.store(b.load(b.gep(result, [const(I64, LANES * k + j)])),
                                    b.gep(rows, [const(I64, 2 * j + k)]))
                    b.branch(done)
                    b.position_at_end(done)
    b.ret_void()
    return fn


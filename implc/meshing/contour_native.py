"""The contouring's per-cell work: a hash index of int64 keys (``implc_hash_index``), the cells' corners
numbered in it and their signs (``implc_cell_corners``, ``implc_corner_signs``), marching tetrahedra over
the Kuhn split of each cell with its vertices numbered through that index (``implc_kuhn_triangles``) and
over the fans of feature cells and their neighbours (``implc_fan_triangles``), the cells whose normals
disagree (``implc_bent_cells``) and their points (``implc_qef``), the corners and sampled values at
the ends of grid edges (``implc_edge_ends``), and the dual cells' crossings, vertices and triangles
(``implc_dual_edges``, ``implc_dual_points``, ``implc_dual_triangles``).

The index is open addressing with linear probing over ``2^bits`` slots of two words (key, number); an
empty slot holds key −1. A key's first slot is the Fibonacci hash of its corner (the key without its low
six bits, which name the edge or point at that corner) plus those six bits: the keys of one corner sit
side by side, corners spread over the table. (Folding the key's low bits with the next ones instead kept
neighbouring cells' keys together, faster on flat parts, but made probe chains so long around
colonnade's creases that the index dominated its mesh.) Keys are numbered in the order they are first
seen, so a run over the same cells in the same order numbers them alike, and growing the table
(inserting its keys again, in number order) keeps every number. The loops over many keys or cells prefetch
the slots of the keys a few rows ahead (:func:`_prefetch`): a big index misses the cache on nearly every
lookup, and independent misses overlap.
"""

from __future__ import annotations

from contextlib import contextmanager

from llvmlite import ir

from ..compiler.llvm.control import (
    I64,
    Local,
    at,
    const,
    define,
    define_internal,
    for_range,
    if_,
    intrinsic,
    load_at,
    local_array,
    store_at,
    while_true,
)
from ..native import abi
from ..native.jit import Source
from ..native.runtime import Library
from .tables import DUAL_PACKED, EDGE_ROW, FACE_ROW, FACE_ROW_START, SHAPE_ROW

GOLDEN = 0x9E3779B97F4A7C15
"""2^64/φ: Fibonacci hashing of a key's corner (its bits above the low six)."""


ORIENT_ERROR = 1e-15
"""A filtered orientation's sign is taken only where |det| exceeds this times its permanent (Shewchuk's
bound for the determinant of rounded differences is about 7.8e-16 of it)."""
PREFETCH_AHEAD = 16
"""How many keys ahead the loops over many keys prefetch the index's slots: a big index misses the cache on
nearly every lookup, and the misses of independent keys overlap."""


def _first_slot(b: ir.IRBuilder, bits, key):
    """The slot where ``key``'s probe starts (see the module docstring)."""
    mask = b.sub(b.shl(const(I64, 1), bits), const(I64, 1))
    spread = b.lshr(b.mul(b.ashr(key, const(I64, 6)), const(I64, GOLDEN - (1 << 64))), b.sub(const(I64, 64), bits))
    return b.and_(b.add(spread, b.and_(key, const(I64, 63))), mask)


def _prefetch(b: ir.IRBuilder, table, bits, key):
    """Ask the cache for the slot where ``key``'s probe starts (a hint: nothing is read)."""
    module = b.module
    name = "llvm.prefetch.p0i8"
    fn = module.globals.get(name)
    i8p, i32 = ir.IntType(8).as_pointer(), ir.IntType(32)
    if fn is None:
        fn = ir.Function(module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]), name=name)
    ptr = b.bitcast(at(b, table, b.mul(_first_slot(b, bits, key), const(I64, 2))), i8p)
    b.call(fn, [ptr, ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])  # read, keep, data


def _prefetch_ahead(b: ir.IRBuilder, i, n, keys_of, distance=PREFETCH_AHEAD):
    """Where row ``i + distance`` exists, ``keys_of(row)`` for it (it emits the prefetches)."""
    ahead = b.add(i, const(I64, distance))
    with if_(b, b.icmp_signed("<", ahead, n)):
        keys_of(ahead)


@contextmanager
def _cells_while_room(b: ir.IRBuilder, n, count: Local, limit, prefetch=None, ahead=PREFETCH_AHEAD):
    """A loop over ``n`` cells that stops before a cell once the index holds ``limit`` keys or more (its
    caller grows it and calls again from that cell): yields (the cell, a Local of the cells done: n unless
    it stopped). Where ``prefetch`` is given, ``prefetch(cell)`` runs ``ahead`` cells ahead."""
    done = Local(b, I64, n, "done")
    with for_range(b, n) as c:
        if prefetch is not None:
            _prefetch_ahead(b, c, n, prefetch, ahead)
        with if_(b, b.and_(b.icmp_signed(">=", count.get(), limit), b.icmp_signed("==", done.get(), n))):
            done.set(c)  # the first cell not done; the rest are skipped
        with if_(b, b.icmp_signed("==", done.get(), n)):
            yield c, done


def _number(b: ir.IRBuilder, table, bits, key, insert, count: Local, uniques):
    """The number of ``key`` in the index (inserted with the next number when absent and ``insert`` is
    non-zero; −1 when absent otherwise)."""
    mask = b.sub(b.shl(const(I64, 1), bits), const(I64, 1))
    slot = Local(b, I64, _first_slot(b, bits, key), "slot")
    result = Local(b, I64, -1, "number")
    with while_true(b) as loop:
        s = slot.get()
        at_key = b.mul(s, const(I64, 2))
        k = load_at(b, table, at_key)
        found = b.icmp_signed("==", k, key)
        empty = b.icmp_signed("==", k, const(I64, -1))
        with if_(b, found):
            result.set(load_at(b, table, b.add(at_key, const(I64, 1))))
        with if_(b, b.and_(empty, b.icmp_signed("!=", insert, const(I64, 0)))):
            number = count.get()
            store_at(b, key, table, at_key)
            store_at(b, number, table, b.add(at_key, const(I64, 1)))
            store_at(b, key, uniques, number)
            count.set(b.add(number, const(I64, 1)))
            result.set(number)
        loop.break_if(b.or_(found, empty))
        slot.set(b.and_(b.add(s, const(I64, 1)), mask))
    return result.get()


def emit_hash_index(module: ir.Module):
    """``implc_hash_index(table, bits, keys, n, insert, numbers, uniques, state)``: numbers[i] = the number
    of keys[i] (see :func:`_number`); state[0] counts the keys in the index. Returns state[0]."""
    fn, b = define(module, abi.HASH_INDEX)
    table, bits, keys, n, insert, numbers, uniques, state = fn.args
    count = Local(b, I64, load_at(b, state, 0), "count")
    with for_range(b, n) as i:
        _prefetch_ahead(b, i, n, lambda j: _prefetch(b, table, bits, load_at(b, keys, j)))
        store_at(b, _number(b, table, bits, load_at(b, keys, i), insert, count, uniques), numbers, i)
    store_at(b, count.get(), state, 0)
    b.ret(count.get())


def emit_cell_corners(module: ir.Module):
    """``implc_cell_corners(lowest, n, offsets, table, bits, uniques, limit, state, numbers)``: the numbers
    of the 8 corners of each cell (``lowest``: its lowest corner key, ``offsets``: the corners' key offsets)
    in the index, inserted where absent (:func:`_number`), 8 per cell into ``numbers``; state[0] counts the
    keys in the index. Stops before a cell when the index holds ``limit`` keys or more; returns the cells
    done."""
    fn, b = define(module, abi.CELL_CORNERS)
    lowest, n, offsets, table, bits, uniques, limit, state, numbers = fn.args
    count = Local(b, I64, load_at(b, state, 0), "count")
    eight = const(I64, 8)

    def prefetch(cell):
        base = load_at(b, lowest, cell)
        for corner in (0, 2, 4, 6):  # each with corner + 1 (one step in z) in its block of 64 keys, mostly
            _prefetch(b, table, bits, b.add(base, load_at(b, offsets, const(I64, corner))))

    with _cells_while_room(b, n, count, limit, prefetch) as (c, done):
        base = load_at(b, lowest, c)
        with for_range(b, eight) as corner:
            key = b.add(base, load_at(b, offsets, corner))
            store_at(b, _number(b, table, bits, key, const(I64, 1), count, uniques), numbers,
                     b.add(b.mul(c, eight), corner))
    store_at(b, count.get(), state, 0)
    b.ret(done.get())


def emit_corner_signs(module: ir.Module):
    """``implc_corner_signs(numbers, n, values, signs)``: per cell a byte, bit c set where F < 0 at its
    corner c (``numbers``: 8 per cell, rows of ``values``; NaN counts as outside)."""
    fn, b = define(module, abi.CORNER_SIGNS)
    numbers, n, values, signs = fn.args
    eight = const(I64, 8)
    zero = const(ir.DoubleType(), 0.0)
    with for_range(b, n) as c:
        bits = const(I64, 0)
        for corner in range(8):
            value = load_at(b, values, load_at(b, numbers, b.add(b.mul(c, eight), const(I64, corner))))
            inside = b.zext(b.fcmp_ordered("<", value, zero), I64)  # false for NaN
            bits = b.or_(bits, b.shl(inside, const(I64, corner)))
        store_at(b, b.trunc(bits, ir.IntType(8)), signs, c)
    b.ret_void()


KUHN_CASE = 1 + 12 * 3
"""Words per sign case in :func:`emit_kuhn_triangles`'s tables: the count, then three edges per triangle."""


def emit_kuhn_triangles(module: ir.Module):
    """``implc_kuhn_triangles(lowest, offsets, signs, n, tables, table, bits, uniques, limit, state, faces,
    owner)``: marching tetrahedra over the Kuhn split of cells (``lowest``: each cell's lowest corner key,
    ``offsets``: the 8 corners' key offsets, ``signs``: a byte per cell, bit c set where F < 0 at corner c).

    ``tables``: the cell's 19 edges' lower corners (19) and codes (19), then per sign case of the cell (256)
    its triangles in the order of the six tetrahedra: their count, then each one's three edges as rows of
    the 19 (see :func:`implc.meshing.tables._kuhn_cases`). Each vertex key ((corner key × 8 + code) × 8) is
    numbered through the index once per cell; faces get three numbers per triangle, owner the cell's row.
    state[0]: keys in the index, state[1]: triangles written. Stops before a cell when the index holds
    ``limit`` keys or more; returns the cells done."""
    fn, b = define(module, abi.KUHN_TRIANGLES)
    lowest, offsets, sign_bytes, n, tables, table, bits, uniques, limit, state, faces, owner = fn.args
    count = Local(b, I64, load_at(b, state, 0), "count")
    written = Local(b, I64, load_at(b, state, 1), "written")
    one, three, eight = const(I64, 1), const(I64, 3), const(I64, 8)
    insert = const(I64, 1)
    numbers = local_array(b, I64, 19, "numbers")  # the cell's edges' vertex numbers
    stamp = local_array(b, I64, 19, "stamp")  # the cell whose number each edge holds
    with for_range(b, const(I64, 19)) as e:
        store_at(b, const(I64, -1), stamp, e)

    def edge(e):
        """Edge ``e``'s lower corner and code."""
        return load_at(b, tables, e), load_at(b, tables, b.add(const(I64, 19), e))

    def edge_key(base, corner, code):
        return b.mul(b.add(b.mul(b.add(base, load_at(b, offsets, corner)), eight), code), eight)

    def prefetch(cell):
        """The index's slots of the edges of ``cell`` that change sign (the others hold no vertex), a few
        cells ahead."""
        base = load_at(b, lowest, cell)
        ahead = b.zext(load_at(b, sign_bytes, cell), I64)
        with for_range(b, const(I64, 19)) as e:
            corner, code = edge(e)
            crosses = b.and_(b.xor(b.lshr(ahead, corner), b.lshr(ahead, b.or_(corner, code))), one)
            with if_(b, b.icmp_signed("!=", crosses, const(I64, 0))):
                _prefetch(b, table, bits, edge_key(base, corner, code))

    with _cells_while_room(b, n, count, limit, prefetch, PREFETCH_AHEAD // 4) as (c, done):  # 19 keys a cell
        base = load_at(b, lowest, c)
        row = b.add(const(I64, 38), b.mul(b.zext(load_at(b, sign_bytes, c), I64), const(I64, KUHN_CASE)))
        with for_range(b, load_at(b, tables, row)) as s:
            with for_range(b, three) as v:
                e = load_at(b, tables, b.add(b.add(row, one), b.add(b.mul(s, three), v)))
                with if_(b, b.icmp_signed("!=", load_at(b, stamp, e), c)):
                    store_at(b, _number(b, table, bits, edge_key(base, *edge(e)), insert, count, uniques), numbers, e)
                    store_at(b, c, stamp, e)
                store_at(b, load_at(b, numbers, e), faces, b.add(b.mul(written.get(), three), v))
            store_at(b, c, owner, written.get())
            written.set(b.add(written.get(), one))
    store_at(b, count.get(), state, 0)
    store_at(b, written.get(), state, 1)
    b.ret(done.get())


def emit_fan_triangles(module: ir.Module):
    """``implc_fan_triangles(lowest, cellkey, offsets, signs, cell_in, face_in, split, n, tables, table, bits,
    uniques, limit, state, faces)``: marching tetrahedra over the fans of cells, each from its cell point
    over its six faces' triangles (a face with ``split`` set fanned from its face point, else cut by its
    diagonal). Per cell: ``lowest`` its lowest corner key, ``cellkey`` its cell key, ``signs`` a byte (bit c
    set where F < 0 at corner c), ``cell_in`` one (at the cell point), ``face_in`` and ``split`` six (per face: F < 0 at
    its face point, whether it is fanned from it). ``offsets``: the 8 corners' key offsets. ``tables``: see
    :data:`implc.native.abi.FAN_TABLES` (built by :func:`implc.meshing.tables._fan_face_tables`). A vertex key is
    one of
    (kind, local, code): grid edge ((lowest + offsets[local]) × 8 + code) × 8; face corner (face id × 4 +
    local) × 8 + 1, the face id (lowest + offsets[face's corner]) × 3 + axis; cell corner (cellkey × 8 +
    local) × 8 + 2; face cell (cellkey × 6 + local) × 8 + 3. Each is numbered through the index once per
    cell (as :func:`emit_kuhn_triangles`); faces get three numbers per triangle; state[0]: keys in the index,
    state[1]: triangles written. Stops before a cell when the index holds ``limit`` keys or more; returns
    the cells done."""
    fn, b = define(module, abi.FAN_TRIANGLES)
    (lowest, cellkey, offsets, sign_bytes, cell_in, face_in, split, n, tables, table, bits, uniques, limit, state,
     faces) = fn.args
    count = Local(b, I64, load_at(b, state, 0), "count")
    written = Local(b, I64, load_at(b, state, 1), "written")
    one, six, eight = const(I64, 1), const(I64, 6), const(I64, 8)
    per_triangle = abi.FAN_SHAPE // 4
    numbers = local_array(b, I64, abi.FAN_SLOTS, "numbers")  # the cell's keys' numbers, by slot
    owner = local_array(b, I64, abi.FAN_SLOTS, "owner")  # the cell whose number the slot holds
    with for_range(b, const(I64, abi.FAN_SLOTS)) as i:
        store_at(b, const(I64, -1), owner, i)
    insert = const(I64, 1)

    def table_at(index):
        return load_at(b, tables, index)

    def byte(array, index):
        return b.zext(load_at(b, array, index), I64)

    with _cells_while_room(b, n, count, limit) as (c, done):
        base = load_at(b, lowest, c)
        cell = load_at(b, cellkey, c)
        centre = b.and_(byte(cell_in, c), one)
        corners = byte(sign_bytes, c)
        with for_range(b, six) as f:
            at_face = b.add(b.mul(c, six), f)
            shape = b.add(const(I64, abi.FAN_SHAPES),
                          b.mul(b.add(b.mul(f, const(I64, 2)), b.and_(byte(split, at_face), one)),
                                const(I64, abi.FAN_SHAPE)))
            face_corner = table_at(b.add(const(I64, abi.FAN_FACES + 1), b.mul(f, const(I64, 2))))
            face_axis = table_at(b.add(const(I64, abi.FAN_FACES), b.mul(f, const(I64, 2))))
            face_id = b.add(b.mul(b.add(base, load_at(b, offsets, face_corner)), const(I64, 3)), face_axis)
            point_in = b.and_(byte(face_in, at_face), one)
            with for_range(b, table_at(shape)) as t:
                row = b.add(b.add(shape, one), b.mul(t, const(I64, per_triangle)))
                case = Local(b, I64, centre, "case")
                for v in range(3):
                    local = table_at(b.add(row, const(I64, v)))
                    corner = b.and_(b.lshr(corners, b.and_(local, const(I64, 7))), one)
                    flag = b.select(b.icmp_signed("==", local, eight), point_in, corner)
                    case.set(b.or_(case.get(), b.shl(flag, const(I64, v + 1))))
                with for_range(b, table_at(b.add(const(I64, abi.FAN_COUNTS), case.get()))) as s:
                    with for_range(b, const(I64, 3)) as v:
                        edge = table_at(b.add(const(I64, abi.FAN_EDGES),
                                              b.add(b.mul(case.get(), six), b.add(b.mul(s, const(I64, 3)), v))))
                        key_at = b.add(b.add(row, const(I64, 3)), b.mul(edge, const(I64, 4)))
                        kind, local, code, slot = (table_at(b.add(key_at, const(I64, i))) for i in range(4))
                        with if_(b, b.icmp_signed("!=", load_at(b, owner, slot), c)):
                            grid = b.mul(b.add(b.mul(b.add(base, load_at(b, offsets, local)), eight), code), eight)
                            face = b.add(b.mul(b.add(b.mul(face_id, const(I64, 4)), local), eight), one)
                            cell_corner = b.add(b.mul(b.add(b.mul(cell, eight), local), eight), const(I64, 2))
                            face_cell = b.add(b.mul(b.add(b.mul(cell, six), local), eight), const(I64, 3))
                            key = b.select(b.icmp_signed("==", kind, const(I64, 0)), grid,
                                           b.select(b.icmp_signed("==", kind, one), face,
                                                    b.select(b.icmp_signed("==", kind, const(I64, 2)),
                                                             cell_corner, face_cell)))
                            store_at(b, _number(b, table, bits, key, insert, count, uniques), numbers, slot)
                            store_at(b, c, owner, slot)
                        store_at(b, load_at(b, numbers, slot), faces, b.add(b.mul(written.get(), const(I64, 3)), v))
                    written.set(b.add(written.get(), one))
    store_at(b, count.get(), state, 0)
    store_at(b, written.get(), state, 1)
    b.ret(done.get())


QEF_SWEEPS, QEF_CONVERGED = 8, 1e-32
"""At most QEF_SWEEPS sweeps of Jacobi's rotations over a QEF's 3 × 3 matrix (each zeroes its three
off-diagonal terms in turn; the sum of their squares falls quadratically, to rounding within four or five),
none once that sum is below QEF_CONVERGED times the diagonal's."""


def _jacobi_sweep(b: ir.IRBuilder, entry, v):
    """One sweep of Jacobi's rotations over a symmetric 3 × 3 matrix (``entry(i, j)``: its Locals, the
    upper triangle's), each zeroing one off-diagonal term, accumulated into ``v`` (Locals by (row, column))."""
    double = ir.DoubleType()
    zero, one = const(double, 0.0), const(double, 1.0)
    sqrt = intrinsic(b.module, "llvm.sqrt.f64", 1)
    fabs = intrinsic(b.module, "llvm.fabs.f64", 1)
    for p_, q_ in ((0, 1), (0, 2), (1, 2)):
        apq, app, aqq = entry(p_, q_).get(), entry(p_, p_).get(), entry(q_, q_).get()
        off = b.fcmp_ordered("!=", apq, zero)
        safe = b.select(off, apq, one)
        theta = b.fdiv(b.fsub(aqq, app), b.fmul(const(double, 2.0), safe))
        root = b.call(sqrt, [b.fadd(b.fmul(theta, theta), one)])
        t = b.fdiv(one, b.fadd(b.call(fabs, [theta]), root))
        t = b.select(b.fcmp_ordered("<", theta, zero), b.fneg(t), t)
        t = b.select(off, t, zero)  # nothing to rotate (and theta's square may overflow: t is then 0)
        t = b.select(b.fcmp_ordered("==", t, t), t, zero)
        c = b.fdiv(one, b.call(sqrt, [b.fadd(b.fmul(t, t), one)]))
        s = b.fmul(t, c)
        entry(p_, p_).set(b.fsub(app, b.fmul(t, apq)))
        entry(q_, q_).set(b.fadd(aqq, b.fmul(t, apq)))
        entry(p_, q_).set(zero)
        other = 3 - p_ - q_
        arp, arq = entry(other, p_).get(), entry(other, q_).get()
        entry(other, p_).set(b.fsub(b.fmul(c, arp), b.fmul(s, arq)))
        entry(other, q_).set(b.fadd(b.fmul(s, arp), b.fmul(c, arq)))
        for i in range(3):
            vip, viq = v[i, p_].get(), v[i, q_].get()
            v[i, p_].set(b.fsub(b.fmul(c, vip), b.fmul(s, viq)))
            v[i, q_].set(b.fadd(b.fmul(s, vip), b.fmul(c, viq)))


def _qef_point(b: ir.IRBuilder, k, present, point, normal, cutoff, project=None):
    """Dual contouring's point over ``k`` candidates (``present(j)``: an i1, ``point(j, i)``, ``normal(j, i)``:
    doubles; ``project``: an axis whose normal component is dropped, or None): the least-squares meeting
    point of the tangent planes, solved around their mean (see :func:`emit_qef`). Returns (x, y, z, how
    many were present, as a double)."""
    double = ir.DoubleType()
    zero, one = const(double, 0.0), const(double, 1.0)
    count = Local(b, double, 0.0, "count")
    mean = [Local(b, double, 0.0, f"mean{i}") for i in range(3)]
    with for_range(b, k) as j:
        with if_(b, present(j)):
            count.set(b.fadd(count.get(), one))
            for i in range(3):
                mean[i].set(b.fadd(mean[i].get(), point(j, i)))
    n_points = b.select(b.fcmp_ordered(">", count.get(), zero), count.get(), one)
    centre = [b.fdiv(mean[i].get(), n_points) for i in range(3)]
    a = {(i, j): Local(b, double, 0.0, f"a{i}{j}") for i in range(3) for j in range(i, 3)}
    rhs = [Local(b, double, 0.0, f"rhs{i}") for i in range(3)]
    along = [Local(b, double, 0.0, f"along{i}") for i in range(3)]  # Σ n, each turned to agree with the first
    with for_range(b, k) as j:
        with if_(b, present(j)):
            n = [normal(j, i) if project is None
                 else b.select(b.icmp_signed("==", project, const(I64, i)), zero, normal(j, i)) for i in range(3)]
            d = zero
            for i in range(3):
                d = b.fadd(d, b.fmul(n[i], b.fsub(point(j, i), centre[i])))
            for (i, jj), cell in a.items():
                cell.set(b.fadd(cell.get(), b.fmul(n[i], n[jj])))
            for i in range(3):
                rhs[i].set(b.fadd(rhs[i].get(), b.fmul(n[i], d)))
            agree = zero
            for i in range(3):
                agree = b.fadd(agree, b.fmul(n[i], along[i].get()))
            sign = b.select(b.fcmp_ordered("<", agree, zero), const(double, -1.0), one)
            for i in range(3):
                along[i].set(b.fadd(along[i].get(), b.fmul(sign, n[i])))
    result = [Local(b, double, 0.0, f"point{i}") for i in range(3)]
    # where the normals agree so closely that A's two smaller eigenvalues are surely under the cutoff (for
    # u = Σ n / |Σ n|: trace − uᵀAu bounds their sum, and uᵀAu the largest from below), the point moves
    # along u alone: mean + u (u · b) / uᵀAu, without Jacobi's rotations (a smooth surface's cells)
    u_length = zero
    for i in range(3):
        u_length = b.fadd(u_length, b.fmul(along[i].get(), along[i].get()))
    u_length = b.select(b.fcmp_ordered(">", u_length, zero), u_length, one)
    entries = {key: cell.get() for key, cell in a.items()}
    u_a_u = zero
    for (i, jj), value in entries.items():
        term = b.fmul(value, b.fmul(along[i].get(), along[jj].get()))
        u_a_u = b.fadd(u_a_u, term if i == jj else b.fadd(term, term))
    u_a_u = b.fdiv(u_a_u, u_length)
    trace = b.fadd(b.fadd(entries[0, 0], entries[1, 1]), entries[2, 2])
    rest = b.fsub(trace, u_a_u)
    simple = b.and_(b.fcmp_ordered(">", u_a_u, zero), b.fcmp_ordered("<=", rest, b.fmul(cutoff, u_a_u)))
    with b.if_else(simple) as (then, otherwise):
        with then:
            u_b = zero
            for i in range(3):
                u_b = b.fadd(u_b, b.fmul(along[i].get(), rhs[i].get()))
            scale = b.fdiv(u_b, b.fmul(u_a_u, u_length))
            for i in range(3):
                result[i].set(b.fadd(centre[i], b.fmul(along[i].get(), scale)))
        with otherwise:
            for i, value in enumerate(_jacobi_point(b, a, rhs, centre, cutoff)):
                result[i].set(value)
    return (*[value.get() for value in result], count.get())


def _jacobi_point(b: ir.IRBuilder, a, rhs, centre, cutoff):
    """The QEF's point mean + A⁺b by Jacobi's rotations, A's eigenvalues below ``cutoff`` times the largest
    dropped (``a``: A's upper triangle as Locals, rotated in place)."""
    double = ir.DoubleType()
    zero, one = const(double, 0.0), const(double, 1.0)
    # Jacobi: A = V diag(e) Vᵀ, A's entries rotated in place, V's columns the eigenvectors
    v = {(i, j): Local(b, double, 1.0 if i == j else 0.0, f"v{i}{j}") for i in range(3) for j in range(3)}

    def entry(i, j):
        return a[min(i, j), max(i, j)]

    def squares(pairs):
        total = zero
        for i, j in pairs:
            value = entry(i, j).get()
            total = b.fadd(total, b.fmul(value, value))
        return total

    with for_range(b, const(I64, QEF_SWEEPS)):
        off = squares(((0, 1), (0, 2), (1, 2)))
        diagonal = squares(((0, 0), (1, 1), (2, 2)))
        # rotations smaller than rounding change nothing: done (the loop runs on, empty)
        with if_(b, b.fcmp_ordered(">", off, b.fmul(const(double, QEF_CONVERGED), diagonal))):
            _jacobi_sweep(b, entry, v)
    e = [entry(i, i).get() for i in range(3)]
    largest = b.select(b.fcmp_ordered(">", e[0], e[1]), e[0], e[1])
    largest = b.select(b.fcmp_ordered(">", largest, e[2]), largest, e[2])
    step = [centre[i] for i in range(3)]
    for col in range(3):
        keep = b.fcmp_ordered(">", e[col], b.fmul(cutoff, largest))
        along = zero
        for i in range(3):
            along = b.fadd(along, b.fmul(v[i, col].get(), rhs[i].get()))
        scale = b.select(keep, b.fdiv(along, b.select(keep, e[col], one)), zero)
        step = [b.fadd(step[i], b.fmul(v[i, col].get(), scale)) for i in range(3)]
    return step


def emit_qef(module: ir.Module):
    """``implc_qef(points, normals, mask, m, k, project, cutoff, out)``: dual contouring's point per row of
    ``m``: the least-squares meeting point of the tangent planes through ``points`` (k points of three
    doubles per row) with unit ``normals`` where ``mask`` (k bytes per row) is set, solved around their
    mean: A = Σ n nᵀ, b = Σ n (n · (p − mean)), the point mean + A⁺b with A's eigenvalues below ``cutoff``
    times the largest dropped (the point stays near the mean along those directions). ``project`` ≥ 0: that
    axis's normal component is set to 0 first (a face's 2D QEF). A's eigenvectors by cyclic Jacobi
    rotations (:data:`QEF_SWEEPS`), or, where the normals agree so closely that both smaller eigenvalues are
    surely dropped, the step along their mean direction alone (:func:`_qef_point`); three doubles per row
    into ``out``."""
    fn, b = define(module, abi.QEF)
    points, normals, mask, m, k, project, cutoff, out = fn.args
    three = const(I64, 3)
    with for_range(b, m) as r:
        def at_(j):
            return b.add(b.mul(r, k), j)

        point = _qef_point(b, k, lambda j: b.icmp_signed("!=", b.zext(load_at(b, mask, at_(j)), I64), const(I64, 0)),
                           lambda j, i: load_at(b, points, b.add(b.mul(at_(j), three), const(I64, i))),
                           lambda j, i: load_at(b, normals, b.add(b.mul(at_(j), three), const(I64, i))),
                           cutoff, project)
        for i in range(3):
            store_at(b, point[i], out, b.add(b.mul(r, three), const(I64, i)))
    b.ret_void()


def emit_dual_points(module: ir.Module):
    """``implc_dual_points(edges, m, positions, normals, cells, geometry, cutoff, margin, sharp, out)``: each
    of m dual cells' vertex (three doubles into ``out``): the QEF point (:func:`_qef_point`) of the vertices
    ``edges`` names (12 per cell, −1: none; ``positions``, ``normals``: three doubles per vertex, a normal
    not a number where it is not usable), or with ``sharp`` 0 their mean; kept ``margin`` of the cell inside
    each face of the cell (``cells``: three indices each; ``geometry``: see :func:`emit_edge_ends`); the
    cell's centre where no vertex has a usable normal."""
    fn, b = define(module, abi.DUAL_POINTS)
    edges, m, positions, normals, cells, geometry, cutoff, margin, sharp, out = fn.args
    double = ir.DoubleType()
    three, twelve = const(I64, 3), const(I64, 12)
    lo = [load_at(b, geometry, 2 + i) for i in range(3)]
    step = [load_at(b, geometry, 5 + i) for i in range(3)]
    sharp_ = b.icmp_signed("!=", sharp, const(I64, 0))
    with for_range(b, m) as r:
        def vertex(j):
            return load_at(b, edges, b.add(b.mul(r, twelve), j))

        def safe(j):
            number = vertex(j)
            return b.select(b.icmp_signed(">=", number, const(I64, 0)), number, const(I64, 0))

        def at_vertex(array, j, i):
            return load_at(b, array, b.add(b.mul(safe(j), three), const(I64, i)))

        def usable(j):  # present, and with a usable normal where the point is the QEF's
            present = b.icmp_signed(">=", vertex(j), const(I64, 0))
            normal = at_vertex(normals, j, 0)
            return b.and_(present, b.or_(b.not_(sharp_), b.fcmp_ordered("ord", normal, normal)))

        x, y, z, count = _qef_point(b, twelve, usable, lambda j, i: at_vertex(positions, j, i),
                                    lambda j, i: b.select(sharp_, at_vertex(normals, j, i), const(double, 0.0)),
                                    cutoff)
        for i, value in enumerate((x, y, z)):
            corner = b.sitofp(load_at(b, cells, b.add(b.mul(r, three), const(I64, i))), double)
            low = b.fadd(lo[i], b.fmul(corner, step[i]))
            high = b.fadd(lo[i], b.fmul(b.fadd(corner, const(double, 1.0)), step[i]))
            inset = b.fmul(b.fsub(high, low), margin)
            centre = b.fmul(b.fadd(low, high), const(double, 0.5))
            value = b.select(b.fcmp_ordered(">", count, const(double, 0.0)), value, centre)
            value = b.select(b.fcmp_ordered("<", value, b.fadd(low, inset)), b.fadd(low, inset), value)
            value = b.select(b.fcmp_ordered(">", value, b.fsub(high, inset)), b.fsub(high, inset), value)
            store_at(b, value, out, b.add(b.mul(r, three), const(I64, i)))
    b.ret_void()


def emit_bent_cells(module: ir.Module):
    """``implc_bent_cells(faces, owner, n, normals, cells, mean, cosine, bent)``: for n triangles (three
    vertex numbers each, ``owner`` the cell row of each), sum the vertices' unit ``normals`` (three doubles
    each) per cell into ``mean`` (cells × 3, zeroed by the caller), then set bent[cell] = 1 where a
    vertex's normal meets the cell's mean direction at a cosine below ``cosine`` (or is not a number)."""
    fn, b = define(module, abi.BENT_CELLS)
    faces, owner, n, normals, cells, mean, cosine, bent = fn.args
    three = const(I64, 3)

    def normal(vertex, axis):
        return load_at(b, normals, b.add(b.mul(vertex, three), const(I64, axis)))

    with for_range(b, n) as t:
        cell = load_at(b, owner, t)
        with for_range(b, three) as v:
            vertex = load_at(b, faces, b.add(b.mul(t, three), v))
            values = [normal(vertex, axis) for axis in range(3)]
            finite = b.fcmp_ordered("ord", values[0], values[1])
            finite = b.and_(finite, b.fcmp_ordered("ord", values[2], values[2]))
            with if_(b, finite):
                for axis in range(3):
                    slot = at(b, mean, b.add(b.mul(cell, three), const(I64, axis)))
                    b.store(b.fadd(b.load(slot), values[axis]), slot)
    with for_range(b, n) as t:
        cell = load_at(b, owner, t)
        m = [load_at(b, mean, b.add(b.mul(cell, three), const(I64, axis))) for axis in range(3)]
        length = b.call(intrinsic(module, "llvm.sqrt.f64", 1), [b.fadd(b.fadd(b.fmul(m[0], m[0]), b.fmul(m[1], m[1])),
                                                                          b.fmul(m[2], m[2]))])
        with for_range(b, three) as v:
            vertex = load_at(b, faces, b.add(b.mul(t, three), v))
            dot = b.fadd(b.fadd(b.fmul(normal(vertex, 0), m[0]), b.fmul(normal(vertex, 1), m[1])),
                         b.fmul(normal(vertex, 2), m[2]))
            straight = b.fcmp_ordered(">=", dot, b.fmul(cosine, length))  # false for NaN
            with if_(b, b.not_(straight)):
                store_at(b, const(ir.IntType(8), 1), bent, cell)
    b.ret_void()


def _corner_point(b: ir.IRBuilder, geometry, k, cells, key, out, index):
    """Writes the world coordinates of corner ``key`` to out[3 index ...] (see :func:`emit_edge_ends` for
    ``geometry``)."""
    ijk = [b.sdiv(key, b.mul(k, k)), b.srem(b.sdiv(key, k), k), b.srem(key, k)]
    for axis, i in enumerate(ijk):
        lo = load_at(b, geometry, 2 + axis)
        step = load_at(b, geometry, 5 + axis)
        hi = load_at(b, geometry, 8 + axis)
        inner = b.fadd(lo, b.fmul(b.sitofp(i, ir.DoubleType()), step))
        store_at(b, b.select(b.icmp_signed("==", i, cells), hi, inner), out, b.add(b.mul(index, const(I64, 3)),
                                                                                  const(I64, axis)))


def emit_corner_points(module: ir.Module):
    """``implc_corner_points(keys, n, geometry, points)``: the world coordinates of n corner keys (three
    doubles each; ``geometry`` as for :func:`emit_edge_ends`)."""
    fn, b = define(module, abi.CORNER_POINTS)
    keys, n, geometry, points = fn.args
    k = b.fptosi(load_at(b, geometry, 0), I64)
    cells = b.fptosi(load_at(b, geometry, 1), I64)
    with for_range(b, n) as i:
        _corner_point(b, geometry, k, cells, load_at(b, keys, i), points, i)
    b.ret_void()


def emit_edge_ends(module: ir.Module):
    """``implc_edge_ends(keys, n, geometry, table, bits, values, a, b, fa, fb)``: for n vertex keys of grid
    edges ((corner key × 8 + code) × 8; code 0 names the corner itself, both ends), the edge's two corners
    in world coordinates (three doubles each into ``a`` and ``b``) and F there (``fa``, ``fb``), looked up
    in the corner index (``table``, ``bits``) and its ``values``. ``geometry``: corners per axis, cells per
    axis (as doubles), then lo, step and hi per axis; a corner at index ``cells`` sits at hi exactly, any
    other at lo + i·step.
    Returns how many corners were not in the index (their values left NaN)."""
    fn, b = define(module, abi.EDGE_ENDS)
    keys, n, geometry, table, bits, values, out_a, out_b, out_fa, out_fb = fn.args
    k = b.fptosi(load_at(b, geometry, 0), I64)
    cells = b.fptosi(load_at(b, geometry, 1), I64)
    missing = Local(b, I64, 0, "missing")
    count = Local(b, I64, 0, "unused")  # the lookups never insert
    nan = const(ir.DoubleType(), float("nan"))
    seven, one, three = const(I64, 7), const(I64, 1), const(I64, 3)

    def corner(index, key, out_xyz, out_f):
        _corner_point(b, geometry, k, cells, key, out_xyz, index)
        number = _number(b, table, bits, key, const(I64, 0), count, table)  # never inserts: no uniques written
        found = b.icmp_signed(">=", number, const(I64, 0))
        with if_(b, b.not_(found)):
            missing.set(b.add(missing.get(), one))
        safe = b.select(found, number, const(I64, 0))
        store_at(b, b.select(found, load_at(b, values, safe), nan), out_f, index)

    def ends(index):
        """The corner keys at the two ends of vertex key ``index``'s edge (the code's bit a: one step
        along axis a)."""
        payload = b.ashr(load_at(b, keys, index), three)
        start, code = b.ashr(payload, three), b.and_(payload, seven)
        step = b.add(b.add(b.mul(b.and_(code, one), b.mul(k, k)), b.mul(b.and_(b.lshr(code, one), one), k)),
                     b.and_(b.lshr(code, const(I64, 2)), one))
        return start, b.add(start, step)

    def prefetch(index):
        for key in ends(index):
            _prefetch(b, table, bits, key)

    with for_range(b, n) as i:
        _prefetch_ahead(b, i, n, prefetch)
        start, end = ends(i)
        corner(i, start, out_a, out_fa)
        corner(i, end, out_b, out_fb)
    b.ret(missing.get())


def _store_unit(b: ir.IRBuilder, vector, targets):
    """Stores ``vector`` (three doubles) divided by its length into ``targets``, or NaN in all three where
    that is not finite (a zero or undefined gradient)."""
    double = ir.DoubleType()
    length = b.call(intrinsic(b.module, "llvm.sqrt.f64", 1),
                    [b.fadd(b.fadd(b.fmul(vector[0], vector[0]), b.fmul(vector[1], vector[1])),
                            b.fmul(vector[2], vector[2]))])
    unit = [b.fdiv(v, length) for v in vector]
    infinity = const(double, float("inf"))
    finite = [b.fcmp_ordered("<", b.call(intrinsic(b.module, "llvm.fabs.f64", 1), [u]), infinity) for u in unit]
    ok = b.and_(b.and_(finite[0], finite[1]), finite[2])
    for u, target in zip(unit, targets):
        b.store(b.select(ok, u, const(double, float("nan"))), target)


def emit_edge_roots(module: ir.Module):
    """``implc_edge_roots(phase, n, rows, keys, a, b, fa, fb, state, f, g, guesses, vertices, normals, margin,
    nudge, tolerance)``: the root of F on edges from a to b (three doubles per end) by Newton's method along
    the edge, kept inside a bracket (regula falsi, Illinois, where a Newton step would leave it), one phase
    per call, F and its gradient sampled by the caller between calls. ``state``: five doubles
    per edge (the bracket's t and F at its inside and outside ends, the last guess). Every guess t is kept
    in [margin, 1 − margin] and moved by up to ``nudge`` by the Fibonacci hash of the edge's key (a guess
    outside its bracket, or not finite, is the bracket's middle).

    - phase 0 (``n``: all the edges): puts each edge's inside end (F < 0) first, swapping a with b and fa
      with fb in place, opens the bracket [0, 1], writes the first guesses (the secant through the ends)
      to ``vertices`` and the edges' numbers 0 … n − 1 to ``rows``; returns how many edges do not change sign
      (F < 0 at neither end or at both, NaN counting as outside);
    - phase 1 (``n``: the edges still open, row j of ``rows``, ``f`` and ``g`` for edge ``rows[j]``):
      narrows each bracket by the sign of F at its guess. An edge is done where F is 0 there or its next
      guess (Newton's: F over its derivative ∇F·(b − a)) lies in the bracket within ``tolerance`` (a
      fraction of the edge) of the guess: its vertex is that Newton point (the guess where F is 0), its
      normal the gradient at the guess made a unit vector (NaN where that is not finite) (``vertices`` and
      ``normals``, rows by edge number). The others'
      numbers and next guesses are packed to the front of ``rows`` and ``guesses``; returns how many;
    - phase 2 (``n``: the edges still open): each one's vertex is the secant through its bracket, written
      to ``vertices`` and, packed, to ``guesses`` (for the caller's gradients); returns 0."""
    fn, b = define(module, abi.EDGE_ROOTS)
    phase, n, rows, keys, a, bb, fa, fb, state, f, g, guesses, vertices, normals, margin, nudge, tolerance = fn.args
    double = ir.DoubleType()
    zero, one_d, half = const(double, 0.0), const(double, 1.0), const(double, 0.5)
    three, five = const(I64, 3), const(I64, 5)
    counted = Local(b, I64, 0, "counted")  # phase 0: edges without a sign change; phase 1: edges still open
    top = b.fsub(one_d, margin)
    no_newton = const(double, float("nan"))  # a guess with no Newton point: the secant, else the middle

    def field(i, k):
        return at(b, state, b.add(b.mul(i, five), const(I64, k)))

    def secant(t_in, t_out, f_in, f_out):
        return b.fsub(t_in, b.fdiv(b.fmul(f_in, b.fsub(t_out, t_in)), b.fsub(f_out, f_in)))

    def within(t, lo, hi):
        """lo <= t <= hi (false for NaN): an end is a fine guess, kept off it by the margin."""
        return b.and_(b.fcmp_ordered(">=", t, lo), b.fcmp_ordered("<=", t, hi))

    def clip(t, lo, hi):
        t = b.select(b.fcmp_ordered(">", t, lo), t, lo)
        return b.select(b.fcmp_ordered("<", t, hi), t, hi)

    def placed(i, t):
        """t kept in [margin, 1 − margin] and nudged by edge i's hash."""
        hashed = b.lshr(b.mul(load_at(b, keys, i), const(I64, GOLDEN - (1 << 64))), const(I64, 11))
        unit = b.fsub(b.fmul(b.uitofp(hashed, double), const(double, 2.0 ** -52)), one_d)
        return clip(b.fadd(clip(t, margin, top), b.fmul(nudge, unit)), margin, top)

    def slot(ptr, j, axis):
        return at(b, ptr, b.add(b.mul(j, three), const(I64, axis)))

    def write_point(i, t, targets):
        """Edge i's point at t into each (array, row) of ``targets``."""
        for axis in range(3):
            p, q = b.load(slot(a, i, axis)), b.load(slot(bb, i, axis))
            value = b.fadd(p, b.fmul(t, b.fsub(q, p)))
            for target, j in targets:
                b.store(value, slot(target, j, axis))

    def guess(i, t_in, t_out, f_in, f_out, newton):
        """The next guess: ``newton`` where it lies in the bracket, else the secant, else the middle; placed."""
        s = secant(t_in, t_out, f_in, f_out)
        s = b.select(within(s, t_in, t_out), s, b.fmul(b.fadd(t_in, t_out), half))
        return placed(i, b.select(within(newton, t_in, t_out), newton, s))

    with b.if_else(b.icmp_signed("==", phase, const(I64, 0))) as (first, later):
        with first:
            with for_range(b, n) as i:
                store_at(b, i, rows, i)
                with if_(b, b.not_(b.fcmp_ordered("<", load_at(b, fa, i), zero))):
                    for axis in range(3):
                        p, q = slot(a, i, axis), slot(bb, i, axis)
                        vp, vq = b.load(p), b.load(q)
                        b.store(vq, p)
                        b.store(vp, q)
                    vp, vq = load_at(b, fa, i), load_at(b, fb, i)
                    store_at(b, vq, fa, i)
                    store_at(b, vp, fb, i)
                f_in, f_out = load_at(b, fa, i), load_at(b, fb, i)
                crosses = b.and_(b.fcmp_ordered("<", f_in, zero), b.not_(b.fcmp_ordered("<", f_out, zero)))
                with if_(b, b.not_(crosses)):
                    counted.set(b.add(counted.get(), const(I64, 1)))
                for k, value in enumerate((zero, one_d, f_in, f_out)):
                    b.store(value, field(i, k))
                t = guess(i, zero, one_d, f_in, f_out, no_newton)
                b.store(t, field(i, 4))
                write_point(i, t, [(vertices, i)])
        with later:
            with for_range(b, n) as j:
                i = load_at(b, rows, j)
                t_in, t_out, f_in, f_out, t = (b.load(field(i, k)) for k in range(5))
                with b.if_else(b.icmp_signed("==", phase, const(I64, 1))) as (step, last):
                    with step:
                        value = load_at(b, f, j)
                        neg = b.fcmp_ordered("<", value, zero)  # false for NaN: outside
                        bracket = (b.select(neg, t, t_in), b.select(neg, t_out, t),
                                   b.select(neg, value, b.fmul(f_in, half)),  # Illinois: halve the end that stays
                                   b.select(neg, b.fmul(f_out, half), value))
                        for k, v in enumerate(bracket):
                            b.store(v, field(i, k))
                        slope = zero
                        for axis in range(3):
                            d = b.fsub(b.load(slot(bb, i, axis)), b.load(slot(a, i, axis)))
                            slope = b.fadd(slope, b.fmul(b.load(slot(g, j, axis)), d))
                        newton = b.fsub(t, b.fdiv(value, slope))
                        following = guess(i, *bracket, newton)
                        distance = b.fsub(following, t)
                        close = b.and_(b.fcmp_ordered("<=", distance, tolerance),
                                       b.fcmp_ordered(">=", distance, b.fneg(tolerance)))
                        done = b.or_(b.fcmp_ordered("==", value, zero),
                                     b.and_(within(newton, bracket[0], bracket[1]), close))
                        with b.if_else(done) as (finished, open_):
                            with finished:  # at the Newton point (the guess itself where F is 0 there)
                                write_point(i, b.select(b.fcmp_ordered("==", value, zero), t, following),
                                            [(vertices, i)])
                                _store_unit(b, [b.load(slot(g, j, axis)) for axis in range(3)],
                                            [slot(normals, i, axis) for axis in range(3)])
                            with open_:  # packed: row w <= j, whose entry was read already
                                w = counted.get()
                                store_at(b, i, rows, w)
                                b.store(following, field(i, 4))
                                write_point(i, following, [(guesses, w)])
                                counted.set(b.add(w, const(I64, 1)))
                    with last:  # the secant through the bracket (no Newton point: NaN)
                        write_point(i, guess(i, t_in, t_out, f_in, f_out, no_newton), [(vertices, i), (guesses, j)])
    b.ret(counted.get())


def _filtered_orientation(b: ir.IRBuilder, a, p, q, r):
    """The sign of ((p − a) × (q − a)) · (r − a) where the doubles certify it (+1 or −1), else 0: |det| must
    exceed :data:`ORIENT_ERROR` times its permanent (Shewchuk's bound for rounded
    differences)."""
    double = ir.DoubleType()
    fabs = intrinsic(b.module, "llvm.fabs.f64", 1)
    u = [b.fsub(p[i], a[i]) for i in range(3)]
    v = [b.fsub(q[i], a[i]) for i in range(3)]
    w = [b.fsub(r[i], a[i]) for i in range(3)]
    det = const(double, 0.0)
    perm = const(double, 0.0)
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        first, second = b.fmul(u[j], v[k]), b.fmul(u[k], v[j])
        det = b.fadd(det, b.fmul(w[i], b.fsub(first, second)))
        perm = b.fadd(perm, b.fmul(b.call(fabs, [w[i]]), b.fadd(b.call(fabs, [first]), b.call(fabs, [second]))))
    sure = b.fcmp_ordered(">", b.call(fabs, [det]), b.fmul(const(double, ORIENT_ERROR), perm))
    positive = b.select(b.fcmp_ordered(">", det, const(double, 0.0)), const(I64, 1), const(I64, -1))
    return b.select(sure, positive, const(I64, 0))


def _emit_ju_split(module: ir.Module):
    """``implc_ju_split(quad, ends)`` (internal): bit 0 set where the quad (four points, counter-clockwise
    about the edge from ``ends[0:3]`` to ``ends[3:6]``) may be split along its diagonal 0-2, bit 1 along 1-3:
    both triangles have the edge's upper end certainly above and its lower end certainly below (Ju and
    Udeshi's test), on the doubles and again on their float32 roundings."""
    double = ir.DoubleType()
    pointer = double.as_pointer()
    fn, b = define_internal(module, "implc_ju_split", I64, [pointer, pointer])
    quad, ends = fn.args
    result = const(I64, 0)
    for narrow in (False, True):
        def value(ptr, i):
            x = load_at(b, ptr, i)
            return b.fpext(b.fptrunc(x, ir.FloatType()), double) if narrow else x
        q = [[value(quad, 3 * k + i) for i in range(3)] for k in range(4)]
        low = [value(ends, i) for i in range(3)]
        high = [value(ends, 3 + i) for i in range(3)]
        bits = const(I64, 0)
        for bit, (i, j, k, m) in enumerate(((0, 1, 2, 3), (1, 2, 3, 0))):
            ok = ir.Constant(ir.IntType(1), 1)
            for t in ((i, j, k), (i, k, m)):
                a, p, r = (q[c] for c in t)
                ok = b.and_(ok, b.icmp_signed("==", _filtered_orientation(b, a, p, r, high), const(I64, 1)))
                ok = b.and_(ok, b.icmp_signed("==", _filtered_orientation(b, a, p, r, low), const(I64, -1)))
            bits = b.or_(bits, b.shl(b.zext(ok, I64), const(I64, bit)))
        result = bits if not narrow else b.and_(result, bits)
    b.ret(result)
    return fn


def emit_dual_edges(module: ir.Module):
    """``implc_dual_edges(lowest, offsets, signs, n, tables, table, bits, uniques, limit, state, numbers)``: the
    number of the vertex on each of a cell's 12 edges that change sign (``tables``: the edges' lower
    corners, then their codes, in :data:`implc.meshing.dual.CELL_EDGES` order), inserted in the index where
    absent, −1 where the edge keeps its sign; 12 per cell into ``numbers``. state[0]: keys in the index.
    Stops before a cell when the index holds ``limit`` keys or more; returns the cells done."""
    fn, b = define(module, abi.DUAL_EDGES)
    lowest, offsets, sign_bytes, n, tables, table, bits, uniques, limit, state, numbers = fn.args
    count = Local(b, I64, load_at(b, state, 0), "count")
    one, eight, twelve = const(I64, 1), const(I64, 8), const(I64, 12)
    with _cells_while_room(b, n, count, limit) as (c, done):
        base = load_at(b, lowest, c)
        signs = b.zext(load_at(b, sign_bytes, c), I64)
        with for_range(b, twelve) as e:
            corner, code = load_at(b, tables, e), load_at(b, tables, b.add(e, twelve))
            crosses = b.and_(b.xor(b.lshr(signs, corner), b.lshr(signs, b.or_(corner, code))), one)
            key = b.mul(b.add(b.mul(b.add(base, load_at(b, offsets, corner)), eight), code), eight)
            number = Local(b, I64, -1, "edge_number")
            with if_(b, b.icmp_signed("!=", crosses, const(I64, 0))):
                number.set(_number(b, table, bits, key, const(I64, 1), count, uniques))
            store_at(b, number.get(), numbers, b.add(b.mul(c, twelve), e))
    store_at(b, count.get(), state, 0)
    b.ret(done.get())


def emit_dual_triangles(module: ir.Module):
    """``implc_dual_triangles(cells, signs, edges, first, points, start, m, tables, geometry, cell_table,
    cell_bits, dual_of_row, table, bits, faces, counts)``: the triangles of m dual cells
    (:mod:`implc.meshing.dual`): ``cells`` their indices (three each), ``signs`` a byte each (bit c: F < 0
    at corner c), ``edges`` the vertex numbers of their 12 edges (:func:`emit_dual_edges`); the dual cell of
    dual row d has vertex number ``first`` + d, at ``points``[d] (these m are rows ``start`` on);
    ``cell_table``/``cell_bits``: the contoured cells' index (cell key → row), ``dual_of_row`` each row's
    dual row (−1: not dual); ``table``/``bits``: the vertex index (the face diagonals' crossings looked up
    there, never inserted); ``geometry``: the grid's (see :func:`emit_edge_ends`); ``tables``:
    :data:`implc.meshing.tables.DUAL_PACKED`.

    Each sign-changing edge is made by the first dual cell around it (counter-clockwise about its axis from
    the cell beyond its lower corner), each face toward a cell that is not dual by its dual cell. Three
    vertex numbers per triangle into ``faces``; counts[0..4] += quads, edges fanned, edges stitched,
    cones, lookups that found nothing (0 unless the cells are not closed). Returns the triangles written."""
    fn, b = define(module, abi.DUAL_TRIANGLES)
    (cells, sign_bytes, edges, first, points, start, m, tables, geometry, cell_table, cell_bits, dual_of_row, table,
     bits, faces, counts) = fn.args
    double = ir.DoubleType()
    split = _emit_ju_split(module)
    n = b.fptosi(load_at(b, geometry, 1), I64)
    k = b.fptosi(load_at(b, geometry, 0), I64)
    lo = [load_at(b, geometry, 2 + i) for i in range(3)]
    step = [load_at(b, geometry, 5 + i) for i in range(3)]
    zero, one, three, twelve = const(I64, 0), const(I64, 1), const(I64, 3), const(I64, 12)
    written = Local(b, I64, 0, "written")
    tally = [Local(b, I64, 0, f"tally{i}") for i in range(5)]
    unused = Local(b, I64, 0, "unused")  # the lookups insert nothing: the index's count stays
    quad = local_array(b, double, 12, "quad")
    ends = local_array(b, double, 6, "ends")
    ring = local_array(b, I64, 4, "ring")

    def emit(p, q, r, flip=None):
        if flip is not None:
            p, r = b.select(flip, r, p), b.select(flip, p, r)
        at_ = b.mul(written.get(), three)
        for i, value in enumerate((p, q, r)):
            store_at(b, value, faces, b.add(at_, const(I64, i)))
        written.set(b.add(written.get(), one))

    def count(i, condition=None):
        tally[i].set(b.add(tally[i].get(), one if condition is None else b.zext(condition, I64)))

    def dual_at(cell):
        """The dual row of the contoured cell at ``cell`` (three i64), −1 where it is not dual; counts a cell
        that is not contoured."""
        key = b.add(b.mul(b.add(b.mul(cell[0], n), cell[1]), n), cell[2])
        row = _number(b, cell_table, cell_bits, key, zero, unused, cell_table)
        found = b.icmp_signed(">=", row, zero)
        count(4, b.not_(found))
        return b.select(found, load_at(b, dual_of_row, b.select(found, row, zero)), const(I64, -1))

    with for_range(b, m) as r:
        cell = [load_at(b, cells, b.add(b.mul(r, three), const(I64, i))) for i in range(3)]
        signs = b.zext(load_at(b, sign_bytes, r), I64)
        apex = b.add(first, b.add(start, r))
        own = b.add(start, r)
        for e in range(12):  # unrolled: each edge's corner, axis and ring are constants
            at_row = e * EDGE_ROW
            u, axis, mine = (int(value) for value in DUAL_PACKED[at_row:at_row + 3])
            steps = DUAL_PACKED[at_row + 3:at_row + EDGE_ROW].reshape(4, 3).tolist()
            crosses = b.and_(b.xor(b.lshr(signs, const(I64, u)), b.lshr(signs, const(I64, u | 1 << axis))), one)
            with if_(b, b.icmp_signed("!=", crosses, zero)):
                # the first dual cell around the edge makes it: look at those before this one, up to one dual
                earlier = Local(b, ir.IntType(1), ir.Constant(ir.IntType(1), 0), "earlier")
                for kk in range(mine):
                    with if_(b, b.not_(earlier.get())):
                        dual = dual_at([b.add(cell[i], const(I64, steps[kk][i])) for i in range(3)])
                        store_at(b, dual, ring, kk)
                        earlier.set(b.icmp_signed(">=", dual, zero))
                with if_(b, b.not_(earlier.get())):
                    store_at(b, own, ring, mine)
                    for kk in range(mine + 1, 4):
                        store_at(b, dual_at([b.add(cell[i], const(I64, steps[kk][i])) for i in range(3)]), ring, kk)
                    root = load_at(b, edges, b.add(b.mul(r, twelve), const(I64, e)))
                    flip = b.icmp_signed("==", b.and_(b.lshr(signs, const(I64, u)), one), zero)  # lower end outside
                    rows = [load_at(b, ring, kk) for kk in range(4)]
                    lean = ir.Constant(ir.IntType(1), 1)
                    for kk in range(4):
                        lean = b.and_(lean, b.icmp_signed(">=", rows[kk], zero))
                    safe = [b.select(b.icmp_signed(">=", rows[kk], zero), rows[kk], zero) for kk in range(4)]
                    v = [b.add(first, safe[kk]) for kk in range(4)]
                    fan = Local(b, ir.IntType(1), ir.Constant(ir.IntType(1), 1), "fan")
                    with if_(b, lean):
                        for kk in range(4):
                            for i in range(3):
                                store_at(b, load_at(b, points, b.add(b.mul(safe[kk], three), const(I64, i))), quad,
                                         3 * kk + i)
                        for i in range(3):
                            corner = b.add(cell[i], const(I64, u >> i & 1))
                            up = b.add(corner, const(I64, int(axis == i)))
                            store_at(b, b.fadd(lo[i], b.fmul(b.sitofp(corner, double), step[i])), ends, i)
                            store_at(b, b.fadd(lo[i], b.fmul(b.sitofp(up, double), step[i])), ends, 3 + i)
                        ok = b.call(split, [quad, ends])
                        diagonals = []
                        for p_, q_ in ((0, 2), (1, 3)):
                            total = const(double, 0.0)
                            for i in range(3):
                                d = b.fsub(load_at(b, quad, 3 * p_ + i), load_at(b, quad, 3 * q_ + i))
                                total = b.fadd(total, b.fmul(d, d))
                            diagonals.append(total)
                        first_ok = b.icmp_signed("!=", b.and_(ok, one), zero)
                        second_ok = b.icmp_signed("!=", b.and_(ok, const(I64, 2)), zero)
                        use_first = b.and_(first_ok, b.or_(b.fcmp_ordered("<=", diagonals[0], diagonals[1]),
                                                           b.not_(second_ok)))
                        use_second = b.and_(second_ok, b.not_(use_first))
                        with if_(b, use_first):
                            emit(v[0], v[1], v[2], flip)
                            emit(v[0], v[2], v[3], flip)
                        with if_(b, use_second):
                            emit(v[1], v[2], v[3], flip)
                            emit(v[1], v[3], v[0], flip)
                        split_ = b.or_(use_first, use_second)
                        count(0, split_)
                        count(1, b.not_(split_))
                        fan.set(b.not_(split_))
                    count(2, b.not_(lean))
                    with if_(b, fan.get()):
                        for kk in range(4):
                            pair = b.and_(b.icmp_signed(">=", rows[kk], zero), b.icmp_signed(">=", rows[(kk + 1) % 4],
                                                                                              zero))
                            with if_(b, pair):
                                emit(root, v[kk], v[(kk + 1) % 4], flip)
        # the cones over the faces toward cells that are not dual
        for face in range(6):
            base = FACE_ROW_START + face * FACE_ROW
            face_axis, side, *local = DUAL_PACKED[base:base + 6].tolist()
            inside_count = const(I64, 0)
            for corner in local:
                inside_count = b.add(inside_count, b.and_(b.lshr(signs, const(I64, corner)), one))
            crossed = b.and_(b.icmp_signed(">", inside_count, zero), b.icmp_signed("<", inside_count, const(I64, 4)))
            with if_(b, crossed):
                beyond = [b.add(cell[i], const(I64, (1 if side else -1) if i == face_axis else 0)) for i in range(3)]
                with if_(b, b.icmp_signed("<", dual_at(beyond), zero)):
                    for shape in range(2):
                        at_ = base + 6 + shape * SHAPE_ROW
                        corners = DUAL_PACKED[at_:at_ + 3].tolist()
                        inside = [b.icmp_signed("!=", b.and_(b.lshr(signs, const(I64, c)), one), zero) for c in corners]
                        mixed = b.xor(b.or_(b.or_(inside[0], inside[1]), inside[2]),
                                      b.and_(b.and_(inside[0], inside[1]), inside[2]))
                        with if_(b, mixed):
                            numbers = []
                            for j in range(3):
                                edge, lower, code = DUAL_PACKED[at_ + 3 + 3 * j:at_ + 6 + 3 * j].tolist()
                                if edge >= 0:
                                    numbers.append(load_at(b, edges, b.add(b.mul(r, twelve), const(I64, edge))))
                                    continue
                                corner = [b.add(cell[i], const(I64, lower >> i & 1)) for i in range(3)]
                                corner_key = b.add(b.mul(b.add(b.mul(corner[0], k), corner[1]), k), corner[2])
                                key = b.mul(b.add(b.mul(corner_key, const(I64, 8)), const(I64, code)), const(I64, 8))
                                number = _number(b, table, bits, key, zero, unused, table)
                                used = b.xor(inside[j], inside[(j + 1) % 3])  # a crossing on the diagonal
                                count(4, b.and_(used, b.icmp_signed("<", number, zero)))
                                numbers.append(number)
                            entry, leave = const(I64, -1), const(I64, -1)
                            for j in range(3):
                                now, after = inside[j], inside[(j + 1) % 3]
                                entry = b.select(b.and_(b.not_(now), after), numbers[j], entry)
                                leave = b.select(b.and_(now, b.not_(after)), numbers[j], leave)
                            emit(apex, entry, leave)
                            count(3)
    for i in range(5):
        slot = at(b, counts, i)
        b.store(b.add(b.load(slot), tally[i].get()), slot)
    b.ret(written.get())


def build_contouring() -> ir.Module:
    """The contouring module."""
    module = ir.Module(name="implc_contouring")
    for emit in (emit_hash_index, emit_cell_corners, emit_corner_signs, emit_kuhn_triangles, emit_fan_triangles,
                 emit_qef, emit_bent_cells, emit_edge_ends, emit_edge_roots, emit_corner_points, emit_dual_edges,
                 emit_dual_points, emit_dual_triangles):
        emit(module)
    return module


CONTOURING = Library(Source(build_contouring, "implc-contouring", max_parts=4, weight=2.0), abi.CONTOURING_ENTRIES)
"""The mesher's module, built on a first mesh (a first voxelization does not compile it)."""

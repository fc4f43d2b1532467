"""``implc_flat_collapse``: the interior vertices of a mesh's flat regions collapsed away, one at a time.

The mesh is closed and oriented: ``faces`` (three int64 vertex numbers each, counter-clockwise seen from
outside), each face's corners linked per vertex (``head[v]``: v's first corner, ``next[c]``: the next
corner of the same vertex, −1 at the end; a corner c is face c / 3, place c % 3). First, each vertex
of ``order`` (those in a region, ``region[v]``) is marked ``inner`` (and ``movable``, both zeroed by the
caller) where its fan is interior to its region as below, with every neighbour in the region. Then each
pass visits the vertices still ``movable`` and, for each:

- gathers its fan (the far edges (a, b) of its live faces, at most :data:`MAX_FAN`; more: left for now);
- checks it interior to its region r: every neighbour ``inner`` (in r, with every face around it in r,
  turning one way, once around it: so the faces around the vertex's neighbours, which the new faces may
  come near, are r's too), every face turning one way on r's plane (``planes``: its unit normal n, then a
  unit tangent t, per region) with sin(angle) > ``min_sine``, and the fan once around it (exactly one
  face's angle at the vertex holds the ray along t, half-open). A vertex that fails is no longer movable
  (valid collapses elsewhere keep a non-interior vertex so);
- tries its neighbours u in turn as the target, until one is valid: every face not through u, with u in
  the vertex's place, turns one way with sin > ``min_sine`` (the new fan tiles the same polygon), and no
  neighbour of the vertex but u's two in the fan is a neighbour of u already (the link condition);
- collapses into it: faces through u die (``dead``), the others take u and join u's corner list.

Passes repeat until one removes nothing or ``passes`` ran. Returns the vertices removed; ``stats[0]``: the
passes run.
"""

from __future__ import annotations

from llvmlite import ir

from ..compiler.llvm.control import (
    DOUBLE,
    I64,
    Local,
    const,
    define,
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

I1 = ir.IntType(1)
I8 = ir.IntType(8)
MAX_FAN = 64
"""The most faces around a vertex the collapse looks at (a vertex with more keeps them)."""
MAX_AROUND = 512
"""The most neighbour entries (two per face) of a target gathered for the link condition."""


def emit_flat_collapse(module: ir.Module):
    fn, b = define(module, abi.FLAT_COLLAPSE)
    faces, vertices, region, planes, inner, movable, head, next_, dead, order, count, passes, min_sine, stats = fn.args
    sqrt = intrinsic(module, "llvm.sqrt.f64", 1)
    fan_a = local_array(b, I64, MAX_FAN, "fan_a")
    fan_b = local_array(b, I64, MAX_FAN, "fan_b")
    around = local_array(b, I64, MAX_AROUND, "around")
    three = const(I64, 3)
    zero = const(DOUBLE, 0.0)

    def point(v):
        return [load_at(b, vertices, b.add(b.mul(v, three), const(I64, k))) for k in range(3)]

    def minus(p, q):
        return [b.fsub(p[k], q[k]) for k in range(3)]

    def dot(p, q):
        return b.fadd(b.fadd(b.fmul(p[0], q[0]), b.fmul(p[1], q[1])), b.fmul(p[2], q[2]))

    def turn(p, q, n):
        """(p × q) · n: exactly the negation of turn(q, p, n) in floating point."""
        cross = [b.fsub(b.fmul(p[1], q[2]), b.fmul(p[2], q[1])),
                 b.fsub(b.fmul(p[2], q[0]), b.fmul(p[0], q[2])),
                 b.fsub(b.fmul(p[0], q[1]), b.fmul(p[1], q[0]))]
        return dot(cross, n)

    def length(p):
        return b.call(sqrt, [dot(p, p)])

    def for_live_corners(v, body, unlink_dead=True):
        """body(corner, face) for each corner in v's list whose face is alive (the next corner read first,
        so that the body may move the corner to another list); ``unlink_dead``: drop the dead faces' corners
        from the list on the way (a vertex that absorbs many keeps a short list)."""
        corner = Local(b, I64, load_at(b, head, v), "corner")
        previous = Local(b, I64, -1, "previous")
        with while_true(b) as walk:
            c = corner.get()
            walk.break_if(b.icmp_signed("<", c, const(I64, 0)))
            following = load_at(b, next_, c)
            face = b.sdiv(c, three)
            alive = b.icmp_unsigned("==", load_at(b, dead, face), const(I8, 0))
            with b.if_else(alive) as (live, gone):
                with live:
                    body(c, face)
                    previous.set(c)
                with gone:
                    if unlink_dead:
                        before = previous.get()
                        with b.if_else(b.icmp_signed("<", before, const(I64, 0))) as (first, later):
                            with first:
                                store_at(b, following, head, v)
                            with later:
                                store_at(b, following, next_, before)
            corner.set(following)

    def far_edge(c, face):
        k = b.sub(c, b.mul(face, three))
        base = b.mul(face, three)
        k1 = b.select(b.icmp_signed("==", k, const(I64, 2)), const(I64, 0), b.add(k, const(I64, 1)))
        k2 = b.select(b.icmp_signed("==", k, const(I64, 0)), const(I64, 2), b.sub(k, const(I64, 1)))
        return load_at(b, faces, b.add(base, k1)), load_at(b, faces, b.add(base, k2))

    def gather_fan(v):
        """v's fan into fan_a, fan_b; returns its size (more than MAX_FAN: only the first kept)."""
        fan = Local(b, I64, 0, "fan")

        def gather(c, face):
            n = fan.get()
            with if_(b, b.icmp_signed("<", n, const(I64, MAX_FAN))):
                a, far = far_edge(c, face)
                store_at(b, a, fan_a, n)
                store_at(b, far, fan_b, n)
            fan.set(b.add(n, const(I64, 1)))

        for_live_corners(v, gather)
        return fan.get()

    def plane_of(v):
        r = load_at(b, region, v)
        return ([load_at(b, planes, b.add(b.mul(r, const(I64, 6)), const(I64, k))) for k in range(3)],
                [load_at(b, planes, b.add(b.mul(r, const(I64, 6)), const(I64, 3 + k))) for k in range(3)])

    def fan_interior(v, n, plane, neighbour_ok):
        """Whether v's gathered fan (n faces) turns one way on its region's ``plane`` (:func:`plane_of`),
        once around v, with ``neighbour_ok(a)`` (an i1) for every neighbour a."""
        normal, tangent = plane
        pv = point(v)
        interior = Local(b, I1, const(I1, 1), "interior")
        crossings = Local(b, I64, 0, "crossings")
        with for_range(b, n) as i:
            a, far = load_at(b, fan_a, i), load_at(b, fan_b, i)
            da, db = minus(point(a), pv), minus(point(far), pv)
            one_way = b.fcmp_ordered(">", turn(da, db, normal), b.fmul(min_sine, b.fmul(length(da), length(db))))
            interior.set(b.and_(interior.get(), b.and_(b.and_(neighbour_ok(a), neighbour_ok(far)), one_way)))
            hit = b.and_(b.fcmp_ordered(">=", turn(da, tangent, normal), zero),
                         b.fcmp_ordered(">", turn(tangent, db, normal), zero))
            crossings.set(b.add(crossings.get(), b.zext(hit, I64)))
        return b.and_(interior.get(), b.icmp_signed("==", crossings.get(), const(I64, 1)))

    def try_target(j, n, normal, best):
        """best = j where collapsing the gathered fan's vertex into its neighbour fan_a[j] is valid."""
        u, x = load_at(b, fan_a, j), load_at(b, fan_b, j)
        y = Local(b, I64, -1, "y")  # the fan's faces through u: (v, u, x) and (v, y, u)
        valid = Local(b, I1, const(I1, 1), "valid")
        pu = point(u)
        with for_range(b, n) as i:
            a, far = load_at(b, fan_a, i), load_at(b, fan_b, i)
            with if_(b, b.icmp_signed("==", far, u)):
                y.set(a)
            through = b.or_(b.icmp_signed("==", a, u), b.icmp_signed("==", far, u))
            with if_(b, b.not_(through)):
                da, db = minus(point(a), pu), minus(point(far), pu)
                one_way = b.fcmp_ordered(">", turn(da, db, normal), b.fmul(min_sine, b.fmul(length(da), length(db))))
                valid.set(b.and_(valid.get(), one_way))
        with if_(b, valid.get()):  # the link condition: u's neighbours gathered
            seen = Local(b, I64, 0, "seen")

            def neighbours(c, face):
                m = seen.get()
                with if_(b, b.icmp_signed("<", m, const(I64, MAX_AROUND - 1))):
                    a, far = far_edge(c, face)
                    store_at(b, a, around, m)
                    store_at(b, far, around, b.add(m, const(I64, 1)))
                seen.set(b.add(m, const(I64, 2)))

            for_live_corners(u, neighbours)
            m = seen.get()
            valid.set(b.icmp_signed("<=", m, const(I64, MAX_AROUND)))
            with if_(b, valid.get()):
                with for_range(b, n) as i:
                    a = load_at(b, fan_a, i)
                    other = b.and_(b.icmp_signed("!=", a, u),
                                   b.and_(b.icmp_signed("!=", a, x), b.icmp_signed("!=", a, y.get())))
                    with if_(b, other):
                        with for_range(b, m) as t:
                            with if_(b, b.icmp_signed("==", load_at(b, around, t), a)):
                                valid.set(const(I1, 0))
        with if_(b, valid.get()):
            best.set(j)

    # first, which vertices are inner: their fan interior to their region, every neighbour in it
    with for_range(b, count) as index:
        v = load_at(b, order, index)
        n = gather_fan(v)
        with if_(b, b.and_(b.icmp_signed(">=", n, const(I64, 3)), b.icmp_signed("<=", n, const(I64, MAX_FAN)))):
            r = load_at(b, region, v)
            inside = fan_interior(v, n, plane_of(v), lambda a: b.icmp_signed("==", load_at(b, region, a), r))
            store_at(b, b.zext(inside, I8), inner, v)
            store_at(b, b.zext(inside, I8), movable, v)

    removed_total = Local(b, I64, 0, "removed_total")
    done_passes = Local(b, I64, 0, "passes")
    with while_true(b) as pass_loop:
        pass_loop.break_if(b.icmp_signed(">=", done_passes.get(), passes))
        removed = Local(b, I64, 0, "removed")
        with for_range(b, count) as index:
            v = load_at(b, order, index)
            with if_(b, b.icmp_unsigned("!=", load_at(b, movable, v), const(I8, 0))):
                n = gather_fan(v)
                with if_(b, b.and_(b.icmp_signed(">=", n, const(I64, 4)), b.icmp_signed("<=", n, const(I64, MAX_FAN)))):
                    plane = plane_of(v)
                    is_interior = fan_interior(v, n, plane, lambda a: b.icmp_unsigned("!=", load_at(b, inner, a),
                                                                                      const(I8, 0)))
                    with b.if_else(is_interior) as (yes, no):
                        with no:
                            store_at(b, const(I8, 0), movable, v)
                        with yes:
                            best = Local(b, I64, -1, "best")
                            with for_range(b, n) as j:
                                with if_(b, b.icmp_signed("<", best.get(), const(I64, 0))):  # the first valid
                                    try_target(j, n, plane[0], best)
                            with if_(b, b.icmp_signed(">=", best.get(), const(I64, 0))):
                                u = load_at(b, fan_a, best.get())

                                def collapse(c, face):
                                    base = b.mul(face, three)
                                    corners = [load_at(b, faces, b.add(base, const(I64, k))) for k in range(3)]
                                    through = b.or_(b.icmp_signed("==", corners[0], u),
                                                    b.or_(b.icmp_signed("==", corners[1], u),
                                                          b.icmp_signed("==", corners[2], u)))
                                    with b.if_else(through) as (gone, moved):
                                        with gone:
                                            store_at(b, const(I8, 1), dead, face)
                                        with moved:
                                            store_at(b, u, faces, c)
                                            store_at(b, load_at(b, head, u), next_, c)
                                            store_at(b, c, head, u)

                                for_live_corners(v, collapse, unlink_dead=False)
                                store_at(b, const(I8, 0), movable, v)
                                removed.set(b.add(removed.get(), const(I64, 1)))
        done_passes.set(b.add(done_passes.get(), const(I64, 1)))
        removed_total.set(b.add(removed_total.get(), removed.get()))
        pass_loop.break_if(b.icmp_signed("==", removed.get(), const(I64, 0)))
    store_at(b, done_passes.get(), stats, 0)
    b.ret(removed_total.get())


def build_mesh_simplify() -> ir.Module:
    """The mesh-simplification module."""
    module = ir.Module(name="implc_mesh_simplify")
    emit_flat_collapse(module)
    return module


MESH_SIMPLIFY = Library(Source(build_mesh_simplify, "implc-mesh-simplify"), abi.MESH_SIMPLIFY_ENTRIES)

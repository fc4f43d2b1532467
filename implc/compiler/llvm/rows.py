"""Vectors loaded from and stored to rows of arrays: the batched kernels' and the tape engine's ends."""

from __future__ import annotations

from llvmlite import ir

from .vector import DOUBLE, I64


def vector_ptr(builder, base, offset, lanes):
    """A pointer to ``lanes`` doubles from entry ``offset`` of the array at ``base``, as one vector."""
    ptr = builder.gep(base, [offset])
    return builder.bitcast(ptr, ir.PointerType(ir.VectorType(DOUBLE, lanes)))


def load_xyz(builder, base, block, width):
    """Three vectors (x, y, z) of ``width`` lanes from as many consecutive rows of an (n, 3) array."""
    offset = builder.mul(block, ir.Constant(I64, 3 * width))
    rows = builder.load(vector_ptr(builder, base, offset, 3 * width), align=8)
    return [builder.shuffle_vector(rows, ir.Constant(rows.type, ir.Undefined),
                                   ir.Constant(ir.VectorType(ir.IntType(32), width),
                                               [3 * lane + axis for lane in range(width)]))
            for axis in range(3)]


def store_xyz(builder, base, block, vectors, width):
    """Interleave three vectors of ``width`` lanes back into as many rows of an (n, 3) array."""
    i32 = ir.IntType(32)
    pair = builder.shuffle_vector(vectors[0], vectors[1], ir.Constant(ir.VectorType(i32, 2 * width),
                                                                      list(range(2 * width))))
    third = builder.shuffle_vector(vectors[2], ir.Constant(vectors[2].type, ir.Undefined),
                                   ir.Constant(ir.VectorType(i32, 2 * width),
                                               list(range(width)) + [0] * width))
    order = [axis * width + lane if axis < 2 else 2 * width + lane
             for lane in range(width) for axis in range(3)]
    rows = builder.shuffle_vector(pair, third, ir.Constant(ir.VectorType(i32, 3 * width), order))
    offset = builder.mul(block, ir.Constant(I64, 3 * width))
    builder.store(rows, vector_ptr(builder, base, offset, 3 * width), align=8)


def store_lanes(builder, base, block, vector, width):
    """Store a vector of ``width`` lanes as entries ``width·block ..`` of a flat array."""
    offset = builder.mul(block, ir.Constant(I64, width))
    builder.store(vector, vector_ptr(builder, base, offset, width), align=8)

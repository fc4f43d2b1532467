"""The independent check of the peer models: their .vm text run by numpy (never by implc's compiler) at
every corner of a grid, and the cells where F changes sign, touches 0 or is undefined there.

Built for the large tapes: values are freed after their last use, and the grid is evaluated in chunks,
so that prospero's 7,866 instructions at 129³ corners fit in a few hundred MB.
"""

from __future__ import annotations

import numpy as np

OPS = {
    "add": np.add, "sub": np.subtract, "mul": np.multiply, "div": np.divide, "min": np.minimum,
    "max": np.maximum, "neg": np.negative, "square": np.square, "sqrt": np.sqrt, "exp": np.exp, "ln": np.log,
    "sin": np.sin, "cos": np.cos, "abs": np.abs, "atan2": np.arctan2,
}


def parse(text: str) -> list[tuple[str, str, list[str]]]:
    rows = []
    for line in text.splitlines():
        words = line.split("#")[0].split()
        if words:
            rows.append((words[0], words[1], words[2:]))
    return rows


def evaluate(rows, x, y, z):
    """F at arrays x, y, z (the last instruction), each value dropped after its last use."""
    last_use = {}
    for i, (_, _, args) in enumerate(rows):
        for a in args:
            last_use[a] = i
    values: dict[str, np.ndarray] = {}
    with np.errstate(all="ignore"):
        for i, (name, op, args) in enumerate(rows):
            if op.startswith("var-"):
                v = {"x": x, "y": y, "z": z}[op[4:]]
            elif op == "const":
                v = np.full_like(x, float(args[0]))
            else:
                v = OPS[op](*[values[a] for a in args])
            for a in args:
                if last_use[a] == i:
                    values.pop(a, None)
            values[name] = v
    return values[rows[-1][0]]


def uses_z(rows) -> bool:
    return any(op == "var-z" for _, op, _ in rows)


def corner_values(rows, bounds, depth, extrude: float | None = None, chunk: int = 1 << 18) -> np.ndarray:
    """F at the (2^depth + 1)³ grid corners; ``extrude``: max(F, |z| − extrude) (a 2-D model made solid)."""
    n = (1 << depth) + 1
    axes = [np.linspace(lo, hi, n) for lo, hi in bounds]
    gx, gy, gz = (a.ravel() for a in np.meshgrid(*axes, indexing="ij"))
    out = np.empty(n ** 3)
    for start in range(0, n ** 3, chunk):
        part = slice(start, start + chunk)
        f = evaluate(rows, gx[part], gy[part], gz[part])
        if extrude is not None:
            f = np.maximum(f, np.abs(gz[part]) - extrude)
        out[part] = f
    return out.reshape(n, n, n)


def sign_change_cells(corners: np.ndarray) -> np.ndarray:
    """Cells whose eight corner values change sign, touch 0 or include NaN."""
    n = corners.shape[0] - 1
    lo, hi = np.full((n,) * 3, np.inf), np.full((n,) * 3, -np.inf)
    undefined = np.zeros((n,) * 3, bool)
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                c = corners[dx:dx + n, dy:dy + n, dz:dz + n]
                lo, hi = np.minimum(lo, c), np.maximum(hi, c)
                undefined |= np.isnan(c)
    return ((lo <= 0) & (hi >= 0)) | undefined

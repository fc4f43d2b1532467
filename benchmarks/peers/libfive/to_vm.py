"""Convert an implc scene (SymPy expression) to fidget's .vm SSA text, as read by lfmesh.

    python to_vm.py SCENE [OUT.vm]        (prints the bounds to stderr)

Library use: ``scene_to_vm(name) -> (text, bounds)``, ``expr_to_vm(expr) -> text``.

Ops emitted: var-x var-y var-z const add sub mul div neg square sqrt min max exp ln sin cos tan asin acos atan
atan2 abs (fidget's set), plus lfmesh's extensions where needed: compare (Piecewise), pow / nth-root (rational
powers other than +-1/2). Identical subexpressions are emitted once (hash-consed on the SymPy node).

Lowerings:
  x**n (integer n): square / mul by repeated squaring; n < 0: div 1 (x**|n|)
  x**(1/2) -> sqrt, x**(-1/2) -> div 1 sqrt, x**(p/q) -> nth-root(pow(x, p), q), x**e (irrational) -> exp(e ln x)
  Piecewise((K*Q**n, Q <= 0 ... ), (0, True)) -> K*min(Q, 0)**n   (exact rewrite; n >= 1; the blobs' form)
  other Piecewise -> r_k + m_k*(e_k - r_k) folded from the last branch, mask m from compare:
      A <= B: 1 - max(compare(A, B), 0);  A < B: max(-compare(A, B), 0);  And/Or: min/max of masks
"""

from __future__ import annotations

import sys

import sympy

FIDGET_EXTRA = {"compare", "pow", "nth-root"}


class _Emitter:
    def __init__(self):
        self.lines: list[str] = []
        self.memo: dict = {}
        self.n = 0

    def emit(self, op: str, *args) -> str:
        key = (op, *args)
        if key in self.memo:
            return self.memo[key]
        name = f"_{self.n:x}"
        self.n += 1
        self.lines.append(" ".join((name, op, *args)))
        self.memo[key] = name
        return name

    def const(self, v) -> str:
        return self.emit("const", repr(float(v)))

    # ---------------------------------------------------------------- expressions
    def expr(self, e) -> str:
        key = ("expr", e)
        if key in self.memo:
            return self.memo[key]
        out = self._expr(e)
        self.memo[key] = out
        return out

    def _expr(self, e) -> str:
        if e.is_Number or e in (sympy.pi, sympy.E) or (e.is_number and e.is_real):
            return self.const(sympy.N(e, 17))
        if e.is_Symbol:
            if e.name in ("x", "y", "z"):
                return self.emit(f"var-{e.name}")
            raise ValueError(f"unexpected symbol {e} (convert to cartesian form first)")
        if isinstance(e, sympy.Add):
            return self._add(e.args)
        if isinstance(e, sympy.Mul):
            return self._mul(e)
        if isinstance(e, sympy.Pow):
            return self._pow(e.base, e.exp)
        if isinstance(e, (sympy.Min, sympy.Max)):
            op = "min" if isinstance(e, sympy.Min) else "max"
            return self._balanced(op, [self.expr(a) for a in e.args])
        if isinstance(e, sympy.Piecewise):
            return self._piecewise(e)
        unary = {sympy.Abs: "abs", sympy.sin: "sin", sympy.cos: "cos", sympy.tan: "tan", sympy.exp: "exp",
                 sympy.log: "ln", sympy.asin: "asin", sympy.acos: "acos", sympy.atan: "atan"}
        for cls, op in unary.items():
            if isinstance(e, cls):
                if cls is sympy.log and len(e.args) != 1:
                    raise ValueError(f"log with base: {e}")
                return self.emit(op, self.expr(e.args[0]))
        if isinstance(e, sympy.atan2):
            return self.emit("atan2", self.expr(e.args[0]), self.expr(e.args[1]))
        if isinstance(e, sympy.sign):
            a = self.expr(e.args[0])
            return self.emit("compare", a, self.const(0))
        raise ValueError(f"unsupported SymPy node {type(e).__name__}: {e}")

    def _balanced(self, op, names):
        while len(names) > 1:
            nxt = [self.emit(op, names[i], names[i + 1]) for i in range(0, len(names) - 1, 2)]
            if len(names) % 2:
                nxt.append(names[-1])
            names = nxt
        return names[0]

    def _add(self, terms) -> str:
        pos, neg = [], []
        for t in terms:
            c, rest = t.as_coeff_Mul()
            if c.is_Number and c < 0 and not (rest == 1):
                neg.append(self.expr(-c * rest))
            else:
                pos.append(self.expr(t))
        if not pos:
            return self.emit("neg", self._chain("add", neg))
        out = self._chain("add", pos)
        for n in neg:
            out = self.emit("sub", out, n)
        return out

    def _chain(self, op, names):
        out = names[0]
        for n in names[1:]:
            out = self.emit(op, out, n)
        return out

    def _mul(self, e) -> str:
        c, rest = e.as_coeff_Mul()
        if c == -1:
            return self.emit("neg", self.expr(rest))
        num, den = [], []
        for f in sympy.Mul.make_args(e):
            if isinstance(f, sympy.Pow) and f.exp.is_Integer and f.exp < 0:
                den.append(self._pow(f.base, -f.exp))
            elif f.is_Rational and not f.is_Integer and f.p == 1:
                den.append(self.const(f.q))
            else:
                num.append(self.expr(f))
        out = self._chain("mul", num) if num else self.const(1)
        if den:
            out = self.emit("div", out, self._chain("mul", den))
        return out

    def _ipow(self, a: str, n: int) -> str:
        if n == 1:
            return a
        if n % 2 == 0:
            return self.emit("square", self._ipow(a, n // 2))
        return self.emit("mul", self._ipow(a, n - 1), a)

    def _pow(self, base, exp) -> str:
        if exp.is_Integer:
            n = int(exp)
            if n == 0:
                return self.const(1)
            b = self.expr(base)
            p = self._ipow(b, abs(n))
            return p if n > 0 else self.emit("div", self.const(1), p)
        if exp.is_Rational:
            b = self.expr(base)
            if exp == sympy.Rational(1, 2):
                return self.emit("sqrt", b)
            if exp == sympy.Rational(-1, 2):
                return self.emit("div", self.const(1), self.emit("sqrt", b))
            p, q = int(exp.p), int(exp.q)
            inner = b if p == 1 else self.emit("pow", b, self.const(p))
            return self.emit("nth-root", inner, self.const(q))
        # general real exponent
        return self.emit("exp", self.emit("mul", self.expr(exp), self.emit("ln", self.expr(base))))

    # ---------------------------------------------------------------- Piecewise
    def _mask(self, cond) -> str:
        if cond is sympy.true:
            return self.const(1)
        if cond is sympy.false:
            return self.const(0)
        if isinstance(cond, sympy.And):
            return self._balanced("min", [self._mask(c) for c in cond.args])
        if isinstance(cond, sympy.Or):
            return self._balanced("max", [self._mask(c) for c in cond.args])
        if isinstance(cond, sympy.Not):
            return self.emit("sub", self.const(1), self._mask(cond.args[0]))
        if isinstance(cond, (sympy.LessThan, sympy.StrictLessThan, sympy.GreaterThan, sympy.StrictGreaterThan)):
            a, b = cond.lhs, cond.rhs
            if isinstance(cond, (sympy.GreaterThan, sympy.StrictGreaterThan)):
                a, b = b, a
            cmp = self.emit("compare", self.expr(a), self.expr(b))
            zero = self.const(0)
            if isinstance(cond, (sympy.LessThan, sympy.GreaterThan)):       # a <= b
                return self.emit("sub", self.const(1), self.emit("max", cmp, zero))
            return self.emit("max", self.emit("neg", cmp), zero)             # a < b
        raise ValueError(f"unsupported Piecewise condition {cond}")

    def _piecewise_min_form(self, e):
        """Piecewise((K*Q**n, Q' <= c), (0, True)) with Q == Q' - c, n >= 1 integer -> K*min(Q, 0)**n."""
        if len(e.args) != 2 or e.args[1].cond is not sympy.true or e.args[1].expr != 0:
            return None
        f, cond = e.args[0].expr, e.args[0].cond
        if not isinstance(cond, (sympy.LessThan, sympy.StrictLessThan)):
            return None
        q = cond.lhs - cond.rhs                           # inside where q <= 0
        k, rest = f.as_coeff_Mul()
        if not (isinstance(rest, sympy.Pow) and rest.exp.is_Integer and rest.exp >= 1):
            return None
        if sympy.expand(rest.base - q) != 0:
            return None
        m = self.emit("min", self.expr(rest.base), self.const(0))
        out = self._ipow(m, int(rest.exp))
        return out if k == 1 else self.emit("mul", self.const(k), out)

    def _piecewise(self, e) -> str:
        special = self._piecewise_min_form(e)
        if special is not None:
            return special
        pieces = list(e.args)
        if pieces[-1].cond is not sympy.true:
            raise ValueError(f"Piecewise without a True default: {e}")
        r = self.expr(pieces[-1].expr)
        for p in reversed(pieces[:-1]):
            m = self._mask(p.cond)
            v = self.expr(p.expr)
            r = self.emit("add", r, self.emit("mul", m, self.emit("sub", v, r)))
        return r


def expr_to_vm(expr, header: str = "") -> str:
    em = _Emitter()
    out = em.expr(expr)
    if em.lines[-1].split()[0] != out:      # the output was emitted earlier (hash-consing): make it last
        zero = em.const(0)
        em.lines.append(f"_out add {out} {zero}")
    lines = [f"# {line}" for line in header.splitlines()] + em.lines
    return "\n".join(lines) + "\n"


def scene_to_vm(name: str):
    """(.vm text, bounds) of the implc scene ``name`` in Cartesian form."""
    from implc.compiler.symbols import cartesian_form
    from implc.files.scene import load

    sc = load(name)
    expr = cartesian_form(sc.surface)
    bounds = tuple(tuple(float(v) for v in b) for b in sc.bounds)
    return expr_to_vm(expr, header=f"implc scene {name}, bounds {bounds}"), bounds


if __name__ == "__main__":
    text, bounds = scene_to_vm(sys.argv[1])
    print(f"bounds {bounds}", file=sys.stderr)
    if len(sys.argv) > 2:
        open(sys.argv[2], "w").write(text)
    else:
        sys.stdout.write(text)

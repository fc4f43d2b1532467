"""What a surface was built from, as data that can travel to another process (a cluster's worker) and be
compiled there: a SymPy expression's ``srepr`` text or a ``.vm`` model's text, with the bounds and the
compile options as they were resolved here (the rounding too, so that every worker computes the same
enclosures). Never native code: each process compiles once (through its kernel cache or the tape
engine) and :func:`build` keeps the result for every later task.
"""

from __future__ import annotations

import functools
import hashlib
import threading
from dataclasses import dataclass
from typing import Any

from ..compiler.vm import VmModel, parse_vm
from ..engines.surface import Surface
from ..engines.surface import compile as compile_surface
from ..errors import TravelError
from ..native.kernel_cache import package_fingerprint


@dataclass(frozen=True)
class SurfaceRecipe:
    """A surface as text and options: ``kind`` "sympy" (``source`` is ``sympy.srepr`` of F) or "vm"
    (``source`` is the model's ``.vm`` text, ``name`` its name)."""

    kind: str
    source: str
    name: str
    bounds: tuple
    vector_width: int
    rounding: str
    engine: str
    software: str = ""
    """implc's source fingerprint and llvmlite's version where the recipe was made: a worker running
    other software refuses it (its enclosures could differ)."""

    @property
    def key(self) -> str:
        """A digest of everything the surface is built from: equal keys build equal surfaces."""
        text = repr((self.kind, self.source, self.name, self.bounds, self.vector_width, self.rounding, self.engine))
        return hashlib.sha256(text.encode()).hexdigest()[:32]


def recipe_of(surface: Surface) -> SurfaceRecipe:
    """The recipe that rebuilds ``surface`` elsewhere; :class:`TravelError` (one line, why) where it
    cannot travel: a ``.vm`` model inlined into a SymPy expression, a model read without its text, an
    expression whose printed form does not read back as itself."""
    if not isinstance(surface, Surface):
        raise TravelError(f"only an implc.Surface can travel to a cluster's workers, not a {type(surface).__name__}")
    options: dict[str, Any] = dict(bounds=tuple(tuple(map(float, b)) for b in surface.bounds),
                                   vector_width=surface.width, engine=surface.engine,
                                   rounding="directed" if surface.directed else "widen")
    expr = surface.expr
    if isinstance(expr, VmModel):
        if not expr.source:
            raise TravelError(f"the model {expr.name} was built without its .vm text, which is what travels to "
                              "a cluster's workers: read it with implc.load_vm or implc.compiler.vm.parse_vm")
        return SurfaceRecipe("vm", expr.source, expr.name, **options, software=software())
    import sympy  # only for an expression's recipe: a .vm model's never imports SymPy

    inlined = sorted({str(f.func) for f in expr.atoms(sympy.Function) if getattr(f.func, "implc_tape", None)})
    if inlined:
        raise TravelError(f"this expression applies the .vm model(s) {', '.join(inlined)}, which cannot travel to a "
                          "cluster's workers inside a SymPy expression; voxelize the model itself there, or run here")
    source = sympy.srepr(expr, order="none")  # the operands of sums and products in their stored order
    try:
        back = _read_srepr(source)
    except Exception as exc:  # noqa: BLE001 - any failure to read it back means it cannot travel
        raise TravelError(f"this expression cannot travel to a cluster's workers: its printed form does not read "
                          f"back ({type(exc).__name__}: {exc})") from None
    if back != expr:
        raise TravelError("this expression cannot travel to a cluster's workers: its printed form reads back as "
                          "another expression (a custom SymPy class or function?)")
    return SurfaceRecipe("sympy", source, "", **options, software=software())


@functools.lru_cache(maxsize=1)
def software() -> str:
    """This process's implc (the fingerprint of its source) and llvmlite version."""
    import llvmlite
    return f"implc {package_fingerprint()[:16]}, llvmlite {llvmlite.__version__}"


def _read_srepr(source: str) -> Any:
    """The expression ``sympy.srepr(expr, order="none")`` printed (SymPy's own classes only: the names are
    SymPy's namespace), rebuilt node for node: nothing evaluated again, Min and Max with their operands as
    printed (SymPy's evaluation would prune and sort a part's operands, slowly, into another expression)."""
    import sympy
    from sympy.functions.elementary.piecewise import ExprCondPair

    from ..compiler.symbols import min_max_as_given
    namespace: dict[str, Any] = {name: getattr(sympy, name) for name in dir(sympy) if not name.startswith("_")}
    namespace["ExprCondPair"] = ExprCondPair  # printed by srepr inside Piecewise, not exported by sympy
    namespace["Min"] = lambda *args: min_max_as_given(sympy.Min, *args)
    namespace["Max"] = lambda *args: min_max_as_given(sympy.Max, *args)
    with sympy.evaluate(False):  # every node as printed, in its stored order: the same expression, and fast
        return eval(source, {"__builtins__": {}}, namespace)  # noqa: S307 - text implc printed itself


_BUILT: dict[str, Surface] = {}
_LOCK = threading.Lock()
_KEEP = 8  # surfaces a process keeps compiled (a parameter sweep sends many, one after another)


def build(recipe: SurfaceRecipe) -> Surface:
    """The surface ``recipe`` describes, compiled once per process and kept for the next tasks."""
    if recipe.software and recipe.software != software():
        raise TravelError(f"this worker runs {software()}, the run was started with {recipe.software}: install the "
                          "same implc and llvmlite on every worker")
    with _LOCK:
        surface = _BUILT.get(recipe.key)
        if surface is None:
            if recipe.kind == "vm":
                expr: Any = parse_vm(recipe.source, name=recipe.name, where=f"{recipe.name}.vm")
            elif recipe.kind == "sympy":
                expr = _read_srepr(recipe.source)
            else:
                raise TravelError(f"unknown recipe kind {recipe.kind!r}")
            surface = compile_surface(expr, recipe.bounds, vector_width=recipe.vector_width,
                                      rounding=recipe.rounding, engine=recipe.engine)
            if len(_BUILT) >= _KEEP:
                _BUILT.pop(next(iter(_BUILT)))
            _BUILT[recipe.key] = surface
        return surface

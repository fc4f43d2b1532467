"""A module's IR text in parts, so that its parts compile at once in separate processes (:mod:`implc.native.jit`).

Each function of :data:`SHARED_MAX` instructions or more (and every exported one) is defined in exactly one
part and declared in the others, which call it across objects (the execution engine links the parts'
objects); the parts are balanced by instructions, the largest functions placed first. A smaller internal
function (an elementary function's helper, a prefill) is copied into every part that calls it, where it
stays internal. A global whose initializer takes block addresses of a function goes with that function.
One part is the whole module, as written.
"""

from __future__ import annotations

from collections.abc import Callable

from llvmlite import ir

SHARED_MAX = 200
"""Internal functions shorter than this many instructions are copied into each part that calls them."""


def _instructions(fn: ir.Function) -> int:
    return sum(len(block.instructions) for block in fn.blocks)


def _callees(fn: ir.Function) -> set[str]:
    return {instr.callee.name for block in fn.blocks for instr in block.instructions
            if isinstance(instr, ir.CallInstr) and isinstance(instr.callee, ir.Function)}


def _block_owner(value: ir.GlobalVariable) -> str | None:
    """The function whose block addresses ``value``'s initializer takes (a dispatch table), if any."""
    init = value.initializer
    for element in getattr(init, "constant", None) or ():
        if isinstance(element, ir.BlockAddress):
            return element.function.name
    return None


def _placed(module: ir.Module) -> set[str]:
    """The functions defined in one part only: every exported one, and internal ones of
    :data:`SHARED_MAX` instructions or more."""
    return {fn.name for fn in module.functions
            if fn.blocks and (fn.linkage != "internal" or _instructions(fn) >= SHARED_MAX)}


def _helpers(functions: dict[str, ir.Function], name: str, placed: set[str]) -> set[str]:
    """The internal functions ``name`` calls, transitively, that are copied rather than placed."""
    found: set[str] = set()
    pending = [name]
    while pending:
        for callee in _callees(functions[pending.pop()]):
            if callee in functions and callee not in placed and callee not in found:
                found.add(callee)
                pending.append(callee)
    return found


def plan(module: ir.Module, parts: int) -> list[set[str]]:
    """The functions each of ``parts`` parts defines: its own (placed) ones and the helpers they call,
    balanced by instructions (each placed function, the largest first, goes where the part's total with it
    and the helpers it would add is least)."""
    functions = {fn.name: fn for fn in module.functions if fn.blocks}
    placed = _placed(module)
    defined: list[set[str]] = [set() for _ in range(parts)]
    for name in sorted(placed, key=lambda n: (-_instructions(functions[n]), n)):
        added = [{name} | (_helpers(functions, name, placed) - defined[k]) for k in range(parts)]
        load = [sum(_instructions(functions[n]) for n in defined[k] | added[k]) for k in range(parts)]
        k = load.index(min(load))
        defined[k] |= added[k]
    return defined


def writer(module: ir.Module, parts: int) -> Callable[[int], str]:
    """``writer(part)``: the IR text of part ``part`` of ``parts`` (see the module); one part is
    ``str(module)``."""
    if parts == 1:
        return lambda part: str(module)
    defined, placed = plan(module, parts), _placed(module)

    def part_text(part: int) -> str:
        lines = [f'; ModuleID = "{module.name}" part {part} of {parts}', f'target triple = "{module.triple}"',
                 f'target datalayout = "{module.data_layout}"', ""]
        lines += [it.get_declaration() for it in module.get_identified_types().values()]
        for value in module.globals.values():
            if isinstance(value, ir.Function) and value.name in placed:
                blocks, linkage = value.blocks, value.linkage
                value.linkage = ""  # placed: called across parts
                if value.name not in defined[part]:
                    value.blocks = []  # declared here
                try:
                    lines.append(str(value))
                finally:
                    value.blocks, value.linkage = blocks, linkage
            elif isinstance(value, ir.Function) and value.blocks and value.name not in defined[part]:
                continue  # a helper this part does not call
            elif isinstance(value, ir.GlobalVariable) and _block_owner(value) not in (None, *defined[part]):
                continue  # a table of another part's blocks
            else:
                lines.append(str(value))
        lines += [f"!{name} = !{{ {', '.join(op.get_reference() for op in md.operands)} }}"
                  for name, md in module.namedmetadata.items()]
        return "\n".join(lines + [str(md) for md in module.metadata])

    return part_text

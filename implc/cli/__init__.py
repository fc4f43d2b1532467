"""The implc command."""

from ..common.moved import forward


def __getattr__(name: str):  # the 0.2 module implc.cli's names, for one release
    return forward(__name__, ("commands", "outputs", "viewing", "upkeep", "parser", "arguments", "signals"), name)

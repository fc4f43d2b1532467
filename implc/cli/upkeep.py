"""The commands that look after implc: implc bench (the suite of a checkout) and implc cache."""

from __future__ import annotations

import importlib.util
from pathlib import Path

from .arguments import (
    UsageError,
)


def cmd_bench(argv) -> int:
    """Run the benchmark suite of the source checkout this package was imported from: benchmarks/ is a
    client of implc, not part of the package."""
    suite = Path(__file__).resolve().parents[2] / "benchmarks" / "suite.py"
    if not suite.is_file():
        raise UsageError("'implc bench' runs the benchmark suite of a source checkout (benchmarks/suite.py), which an "
                         "installed package does not carry: in a clone of implc, 'pip install -e .[bench]' then "
                         "'implc bench'")
    spec = importlib.util.spec_from_file_location("implc_benchmark_suite", suite)
    if spec is None or spec.loader is None:
        raise UsageError(f"cannot load the benchmark suite at {suite}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main(argv)


def cmd_cache(args) -> int:
    from ..native import kernel_cache
    if args.action == "clear":
        removed = kernel_cache.clear()
        folder = kernel_cache.directory()
        print(f"removed {removed} cached kernel modules from {folder}" if folder else "the kernel cache is off")
        return 0
    cache = kernel_cache.info()
    if cache.directory is None:
        print("kernel cache  off (IMPLC_CACHE_DIR=off)")
        return 0
    print(f"kernel cache  {cache.directory}")
    print(f"entries       {cache.entries}")
    print(f"size          {cache.bytes / 2**20:.2f} MiB of at most {cache.limit / 2**20:.0f} MiB "
          "(IMPLC_CACHE_MAX_MB; least recently used entries go first)")
    return 0

"""Shared set-up: the suite's own kernel cache, no files outside temporary folders, and the over-inclusion
report of the sampling tests.

The suite never touches the user's kernel cache: every compile (in this process, its xdist workers and
the subprocesses they start) goes to one temporary cache folder for the whole run, removed at the end.
``IMPLC_TEST_CACHE_DIR`` names a folder to use instead (kept: a warm cache across runs). Hypothesis keeps
its files in the run's temporary folder too, not in ``.hypothesis/`` of the checkout.
"""

import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest
from hypothesis import settings
from hypothesis.configuration import set_hypothesis_home_dir

from .support.browser import browser  # noqa: F401 - the fixture, for every test that drives the page

sys.dont_write_bytecode = True  # nothing written into the checkout
settings.register_profile("implc", database=None)  # no .hypothesis/ folder in the checkout
settings.load_profile("implc")

_RATIOS = {}


def pytest_configure(config):
    if not hasattr(config, "workerinput"):  # the controller (or a run without xdist) sets the run's folder up
        run = tempfile.mkdtemp(prefix="implc-test-")
        config._implc_run = run
        os.environ["IMPLC_TEST_RUN_DIR"] = run  # inherited by xdist workers and subprocesses
        os.environ["IMPLC_CACHE_DIR"] = os.environ.get("IMPLC_TEST_CACHE_DIR") or os.path.join(run, "kernels")
    set_hypothesis_home_dir(Path(os.environ["IMPLC_TEST_RUN_DIR"]) / "hypothesis")


def pytest_unconfigure(config):
    run = getattr(config, "_implc_run", None)
    if run:
        shutil.rmtree(run, ignore_errors=True)


class _Recorder:
    """``recorder[(surface, depth)] = ratio``: kept in the test's report, so that it reaches the process
    that prints the summary (the xdist controller, or this one)."""

    def __init__(self, node):
        self.node = node

    def __setitem__(self, key, ratio):
        self.node.user_properties.append(("over_inclusion", (*key, float(ratio))))


@pytest.fixture
def over_inclusion(request):
    """Tests record voxels / sign-change cells here; the ratios are printed at the end of the run."""
    return _Recorder(request.node)


def pytest_runtest_logreport(report):
    if report.when == "call":
        for key, value in report.user_properties:
            if key == "over_inclusion":
                name, depth, ratio = value
                _RATIOS[(name, depth)] = ratio


def pytest_terminal_summary(terminalreporter):
    if not _RATIOS:
        return
    terminalreporter.section("over-inclusion: voxels / sign-change cells (1.00 is exact)")
    names = sorted({name for name, _ in _RATIOS})
    depths = sorted({d for _, d in _RATIOS})
    terminalreporter.write_line(f"{'surface':<20}" + "".join(f"{'depth ' + str(d):>10}" for d in depths))
    for name in names:
        cells = "".join(f"{_RATIOS[(name, d)]:>10.3f}" if (name, d) in _RATIOS else f"{'':>10}" for d in depths)
        terminalreporter.write_line(f"{name:<20}{cells}")

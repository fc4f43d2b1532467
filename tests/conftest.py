"""Shared fixtures: the over-inclusion report of the sampling tests."""

import pytest

_RATIOS = {}


@pytest.fixture
def over_inclusion():
    """Tests record voxels / sign-change cells here; the ratios are printed at the end of the run."""
    return _RATIOS


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

"""Live editing: from saving a scene file to the new picture in the browser, under ``implc view --watch``.

Starts ``implc view PART --watch --no-browser`` as a user does, opens its page in headless Chromium, then
saves the part again and again (each time a different parameter, so each save is a new model) and times,
from the moment the file is written:

- *first frame*: the page has drawn the new model (its coarse levels at least);
- *settled*: the page has drawn it to the finest level the camera needs, nothing left to fetch.

The part is a heat sink built from ``implc.shapes`` (a rounded plate, a smooth union with a polar array of
fins and a grid of bosses, drilled holes); ``--fins`` sets its size: the table names its operation count
(SymPy's ``count_ops``) and its tape's length. The medians are of ``--saves`` saves. Example::

    python benchmarks/live_editing.py --depth 8 --saves 9
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PART = '''"""A heat sink: a rounded plate, {fins} polar fins and a 4 x 4 grid of bosses joined smoothly, 12 holes."""
import sympy
from implc import shapes as s
plate = s.rounded_box((0.8, 0.8, 0.1), 0.03)
fins = s.array_polar(s.translate(s.box(({length}, 0.02, 0.3)), (0.45, 0, 0.3)), {fins})
bosses = s.array_grid(s.translate(s.capped_cylinder(0.05, 0.15), (-0.3, -0.3, 0.15)), (4, 4, 1), (0.2, 0.2, 0))
holes = [s.translate(s.capped_cylinder(0.03, 0.5), (0.6 * sympy.cos(2 * sympy.pi * k / 12),
                                                   0.6 * sympy.sin(2 * sympy.pi * k / 12), 0)) for k in range(12)]
surface = s.difference(s.smooth_union(0.02, plate, s.union(fins, bosses)), *holes)
bounds = ((-1, 1), (-1, 1), (-1, 1))
view = (35, 40)
'''


def part_text(fins: int, save: int) -> str:
    return PART.format(fins=fins, length=f"{0.20 + 0.005 * (save % 10):.3f}")


def until(page, condition: str, timeout: float = 120.0, every: float = 0.005):
    """Poll ``condition`` in the page (the server's CSP forbids the string evaluation of Playwright's
    wait_for_function)."""
    deadline = time.monotonic() + timeout
    while not page.evaluate(condition):
        if time.monotonic() > deadline:
            sys.exit(f"timed out waiting for {condition}")
        time.sleep(every)


def measure(args) -> list[tuple[float, float]]:
    from playwright.sync_api import sync_playwright
    from suite import CHROMIUM_ARGS  # this folder's: the viewer's benchmarks launch Chromium alike
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        sys.exit("no Chromium here (Debian: apt-get install chromium)")
    folder = Path(tempfile.mkdtemp(prefix="implc-live-"))
    part = folder / "heat_sink.py"
    part.write_text(part_text(args.fins, 0))
    server = subprocess.Popen([sys.executable, "-m", "implc", "view", str(part), "--watch", "--no-browser",
                               "--port", "0", "--depth", str(args.depth)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = None
        for line in server.stdout:
            if line.startswith("http://"):
                url = line.strip()
                break
        if url is None:
            sys.exit(f"implc view did not start: {server.stderr.read()}")
        times = []
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 800, "height": 600})
            page.goto(url)
            until(page, "window.implcViewer.drawnGeneration >= 0")
            time.sleep(2.0)  # the next build process warms up, as while a user reads the picture
            for save in range(1, args.saves + 1):
                text = part_text(args.fins, save)
                saved = page.evaluate("performance.now()")  # the page's clock: its frames are timed on it
                part.write_text(text)
                until(page, f"window.implcViewer.drawnGeneration >= {save}")
                until(page, "window.implcViewer.stats().settled")
                now = page.evaluate("performance.now()")
                first = page.evaluate(f"window.implcViewer.timings.drawn[{save}]")
                times.append(((first - saved) / 1000, (now - saved) / 1000))
                time.sleep(args.pause)
            browser.close()
        return times
    finally:
        server.terminate()
        server.wait(10)
        if args.verbose:
            print(server.stderr.read(), file=sys.stderr)
        shutil.rmtree(folder, ignore_errors=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--depth", type=int, default=8)
    parser.add_argument("--fins", type=int, default=24)
    parser.add_argument("--saves", type=int, default=7)
    parser.add_argument("--verbose", action="store_true", help="print the server's log (each build's time)")
    parser.add_argument("--pause", type=float, default=2.0, help="seconds between saves (the user reading)")
    args = parser.parse_args()
    import sympy

    import implc
    namespace: dict = {}
    exec(part_text(args.fins, 0), namespace)  # noqa: S102 - our own part, to count it
    ops = sympy.count_ops(namespace["surface"])
    tape = len(implc.compile(namespace["surface"]).tape)
    times = measure(args)
    firsts, settled = [t[0] for t in times], [t[1] for t in times]
    print(f"live editing at {1 << args.depth}³: heat sink of {ops} operations ({tape} tape nodes), "
          f"{len(times)} saves")
    print(f"| {'from save to':<14} | {'median s':>8} | {'min s':>6} | {'max s':>6} |")
    print(f"|{'-' * 16}|{'-' * 10}|{'-' * 8}|{'-' * 8}|")
    for name, values in (("first frame", firsts), ("settled", settled)):
        print(f"| {name:<14} | {statistics.median(values):8.3f} | {min(values):6.3f} | {max(values):6.3f} |")


if __name__ == "__main__":
    main()

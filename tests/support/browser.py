"""Headless Chromium (Debian's, driven by Playwright) for the tests that look at the viewer's page."""

import shutil
import time

import pytest

CHROMIUM_ARGS = ["--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run"]


@pytest.fixture(scope="module")
def browser():
    executable = shutil.which("chromium") or shutil.which("chromium-browser")
    if executable is None:
        pytest.skip("no Chromium here (Debian: apt-get install chromium); the page cannot be tested in a browser")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("Playwright for Python is not installed (pip install playwright); the page cannot be driven")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=executable, args=CHROMIUM_ARGS)
        yield b
        b.close()


def until(page, condition: str, timeout: float = 60.0):
    """Poll ``condition`` (a JavaScript expression) in the page until it holds (the server's CSP forbids the
    string evaluation Playwright's wait_for_function uses); fails the test with the page's stats after
    ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not page.evaluate(condition):
        assert time.monotonic() < deadline, f"{condition} never held: {page.evaluate('window.implcViewer.stats()')}"
        time.sleep(0.05)

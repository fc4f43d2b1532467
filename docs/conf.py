"""Sphinx configuration of implc's documentation site: ``python -m sphinx -W -b html docs docs/_build/html``.

Pages are Markdown (MyST); the API reference is generated from the docstrings (autodoc); the gallery runs
every script in ``examples/`` when the site is built and shows the pictures it writes (sphinx-gallery, with
a scraper of our own that picks up the PNG files an example saves).
"""

import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("IMPLC_EXAMPLE_DEPTH", "7")  # the gallery's pictures at 128³: a build in seconds

import implc  # noqa: E402

project = "implc"
author = "the implc developers"
copyright = "2026, the implc developers"
release = version = implc.__version__

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.autosummary", "sphinx.ext.viewcode",
              "sphinx_gallery.gen_gallery"]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "gallery/*.ipynb", "gallery/*.py", "gallery/*.md5", "gallery/*.json",
                    "gallery/*.zip"]
myst_heading_anchors = 3
html_theme = "furo"
html_title = f"implc {release}"
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "undoc-members": False}


def _png_scraper(block, block_vars, gallery_conf):
    """The PNG files an example wrote in its folder since the last block, moved to the gallery's images."""
    from sphinx_gallery.scrapers import figure_rst
    folder = Path(block_vars["src_file"]).parent
    since = block_vars.setdefault("implc_since", block_vars.get("implc_started", 0.0))
    written = sorted(p for p in set(folder.glob("*.png")) | set(Path.cwd().glob("*.png")) if p.stat().st_mtime >= since)
    paths = []
    for png, target in zip(written, block_vars["image_path_iterator"]):
        os.replace(png, target)
        paths.append(target)
    block_vars["implc_since"] = time.time()
    return figure_rst(paths, gallery_conf["src_dir"])


EXAMPLES = ROOT / "examples"
_KEPT = {p.name for p in EXAMPLES.iterdir()}  # what the examples' folder held before the build


def _clean_examples(gallery_conf, fname, when):
    """After each example: remove what it wrote into examples/ (its pictures were moved already), so a
    build leaves the checkout as it found it."""
    if when == "after":
        for path in EXAMPLES.iterdir():
            if path.name not in _KEPT and path.is_file():
                path.unlink()


sphinx_gallery_conf = {
    "reset_modules": (_clean_examples,),
    "reset_modules_order": "both",
    "examples_dirs": str(EXAMPLES),
    "gallery_dirs": "gallery",
    "filename_pattern": r".*\.py",
    "image_scrapers": (_png_scraper,),
    "download_all_examples": False,
    "remove_config_comments": True,
    "abort_on_example_error": True,
}
suppress_warnings = ["config.cache"]  # the gallery configuration holds our scraper (a function): not cached

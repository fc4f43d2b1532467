"""Helpers the tests share: independent truths (exact and high-precision values, numpy runs of .vm text),
small models, mesh checks, the command run in a process. No test module imports another."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
"""The checkout the tests run from."""

"""Tests of implc.engines."""

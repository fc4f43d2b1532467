"""Tests of implc.cli."""

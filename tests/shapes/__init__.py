"""Tests of implc.shapes."""

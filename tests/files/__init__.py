"""Tests of implc.files."""

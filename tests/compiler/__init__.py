"""Tests of implc.compiler."""

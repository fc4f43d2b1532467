"""Tests of implc.view."""

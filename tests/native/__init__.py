"""Tests of implc.native."""

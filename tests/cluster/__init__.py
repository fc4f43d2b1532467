"""Tests of implc.cluster."""

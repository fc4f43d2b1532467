"""Tests of implc.meshing."""

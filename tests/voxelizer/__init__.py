"""Tests of implc.voxelizer."""

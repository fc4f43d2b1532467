"""Helpers every package shares: what implc reads from outside, outputs written under a temporary name, worker
threads and bounds."""

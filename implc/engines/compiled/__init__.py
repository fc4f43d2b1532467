"""The compiled kernels: one LLVM module per surface, pruned per region by live-term masks."""

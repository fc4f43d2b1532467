"""The LLVM code generators: the IR of every kernel and of the generic runtime module."""

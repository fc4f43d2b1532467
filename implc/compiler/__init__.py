"""From an expression to a tape and its meanings: symbols, the SymPy and .vm front ends, the IR, the gradient, the
numpy reference, rounding; llvm/ holds the LLVM building blocks every kernel shares."""

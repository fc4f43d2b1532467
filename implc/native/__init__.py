"""Running LLVM IR: the native ABI, the JIT, the kernel cache, compiling in parts, the process's runtime of shared
modules, big buffers."""

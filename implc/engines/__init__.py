"""Evaluators of a surface over boxes and points and the one walk over them: the compiled kernels (compiled/), the
tape engine (tape/), the walk, normals and second look they share, and Surface."""

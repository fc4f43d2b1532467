"""implc's benchmark suite (installed as implc.benchmarks; run it with `implc bench`)."""

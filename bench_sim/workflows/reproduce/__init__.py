"""bench-sim reproduce: the paper's experiment (run), its figures and its report."""

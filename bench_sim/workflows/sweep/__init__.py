"""bench-sim sweep: spec (points), run (on the execution layer) and report (tables, plots)."""

"""bench-sim dataset: spec, run, card, and the reader of a dataset folder."""

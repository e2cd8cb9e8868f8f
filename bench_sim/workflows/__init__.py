"""The commands' workflows: render, simulate, fuse, and the packages reproduce/, sweep/ and
dataset/ (each its spec, run and report or card). Workflows only orchestrate."""

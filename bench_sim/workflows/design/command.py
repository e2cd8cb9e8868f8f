"""``bench-sim design SPEC.toml --out DIR``: the command's arguments (registered by
:mod:`bench_sim.cli`, which gives it the error contract of every command)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from bench_sim.workflows.design import run as design_run

__all__ = ["design_command"]


def design_command(
    spec: Annotated[Path, typer.Argument(help="design spec (TOML): base bench, [stages], rules, beta_bits, "
                                         "objectives, [[constraints]], rank, [[parameters]]")],
    out: Annotated[Path, typer.Option("--out", help="output folder")],
    workers: Annotated[int | None, typer.Option(
        "--workers", help="worker processes of a local Dask cluster (default: this process for a design of "
        "one point, else the cores; 0: this process)")] = None,
    scheduler: Annotated[
        str | None, typer.Option("--scheduler", help="address of a running Dask scheduler, tcp://HOST:PORT")
    ] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="finish a stopped design: keep its finished points")
    ] = False,
    plots: Annotated[bool, typer.Option("--plots/--no-plots", help="draw DIR/plots/")] = True,
) -> None:
    """Which stages to fuse, and which rule, word, line period and light, for a camera and a scene:
    every candidate scored on the exact truth; DIR/candidates.csv, design.nc, plots/, report.md."""
    design_run.run_design(spec, out, workers=workers, scheduler=scheduler, resume=resume, plots=plots,
                          progress=sys.stderr.isatty())

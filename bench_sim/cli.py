"""The ``bench-sim`` command.

Every sub-command validates its inputs first and prints a bad config, file or argument as one
line on stderr (exit status 2), without writing any output. Heavy modules are imported inside
the commands so ``bench-sim --help`` stays instant.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer

from bench_sim.config import DEFAULT_CONFIG_PATH, TRA_METHODS
from bench_sim.errors import BenchSimError

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="bench_sim: optical test-bench simulator for HDR push-broom imaging with digital TDI.",
)

ConfigArg = Annotated[
    Path, typer.Argument(help="bench config (TOML)", show_default="scenes/paper_rig.toml")
]
SeedOpt = Annotated[int, typer.Option("--seed", help="seed of the run's one random generator")]


def _user_errors(func: Callable[..., Any]) -> Callable[..., Any]:
    """Turn a :class:`BenchSimError` into one line on stderr and exit status 2."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except BenchSimError as exc:
            msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            print(f"bench-sim: error: {msg}", file=sys.stderr)
            raise typer.Exit(2) from None

    return wrapper


def parse_stages(text: str, max_stage: int | None = None) -> list[int]:
    """Parse ``"1,10,80"`` or ``"5:100:5"`` (start:stop:step, inclusive) into sorted stages."""
    stages: set[int] = set()
    try:
        for part in text.split(","):
            part = part.strip()
            if not part:
                continue
            if ":" in part:
                bits = [int(b) for b in part.split(":")]
                start, stop = bits[0], bits[1]
                step = bits[2] if len(bits) > 2 else 1
                if step < 1:
                    raise ValueError
                stages.update(range(start, stop + 1, step))
            else:
                stages.add(int(part))
    except ValueError:
        raise BenchSimError(
            f"--stages = {text!r}: expected integers like '1,10,80' or ranges like '5:100:5'"
        ) from None
    if not stages or min(stages) < 1 or (max_stage is not None and max(stages) > max_stage):
        top = max_stage if max_stage is not None else "rows"
        raise BenchSimError(f"--stages = {text!r}: stages must lie in 1..{top}")
    return sorted(stages)


@app.command()
@_user_errors
def doctor() -> None:
    """Print the chosen Mitsuba variant, the LLVM library and why, and versions."""
    from bench_sim.backend import choose_backend, versions

    choice = choose_backend()
    print(f"variant     : {choice.variant} ({choice.kind})")
    print(f"libLLVM     : {choice.llvm_path or '-'}")
    print(f"why         : {choice.reason}")
    for what, detail in choice.probes.items():
        print(f"  probe {what}: {detail}")
    for pkg, ver in versions().items():
        print(f"{pkg:<12}: {ver}")


@app.command()
@_user_errors
def render(
    config: ConfigArg = DEFAULT_CONFIG_PATH,
    frames: Annotated[int, typer.Option("--frames", help="line periods to render")] = 8,
    engine: Annotated[
        str | None, typer.Option("--engine", help="fast | reference (default: the config's)")
    ] = None,
    seed: SeedOpt = 0,
    out: Annotated[Path, typer.Option("--out", help="output folder")] = Path("out/render"),
) -> None:
    """Render per-row exposures (photons per pixel per frame) to DIR/exposures.exr + meta.json."""
    from bench_sim.config import load_config
    from bench_sim.experiments.render_job import run_render

    cfg = load_config(config)
    if engine is not None and engine not in ("fast", "reference"):
        raise BenchSimError(f"--engine = {engine!r}: allowed 'fast' or 'reference'")
    run_render(cfg, frames=frames, engine=engine, seed=seed, out=out)


@app.command()
@_user_errors
def ptc(
    config: ConfigArg = DEFAULT_CONFIG_PATH,
    stages: Annotated[str, typer.Option("--stages", help="e.g. 1,10,80")] = "1,10,80",
    seed: SeedOpt = 0,
    out: Annotated[Path, typer.Option("--out", help="output folder")] = Path("out/ptc"),
) -> None:
    """Photon-transfer series through the sensor and DTDI: EMVA 1288 files and results."""
    from bench_sim.config import load_config
    from bench_sim.experiments.ptc import run_ptc

    cfg = load_config(config)
    run_ptc(cfg, stages=parse_stages(stages, cfg.sensor.rows), seed=seed, out=out)


@app.command()
@_user_errors
def fuse(
    low: Annotated[Path, typer.Argument(help="stage-mu1 image (TIFF/PNG 16-bit, EXR or NPY)")],
    high: Annotated[Path, typer.Argument(help="stage-mu2 image, same shape")],
    mu1: Annotated[int, typer.Option("--mu1")] = 10,
    mu2: Annotated[int, typer.Option("--mu2")] = 80,
    beta: Annotated[int, typer.Option("--beta", help="output word bits: Phi_FS = 2**beta")] = 12,
    out: Annotated[Path, typer.Option("--out", help="HDR output (.exr)")] = Path("hdr.exr"),
    tra: Annotated[Path | None, typer.Option("--tra", help="also write Gamma_TRA (.png)")] = None,
    tra_method: Annotated[
        str, typer.Option("--tra-method", help=" | ".join(TRA_METHODS))
    ] = "log",
    pedestal: Annotated[
        float,
        typer.Option(
            "--pedestal",
            help="offset [DN] the stage words carry (dtdi.pedestal_dn: 64 for bench_sim's images; "
            "0 for a plain word), subtracted before eq. 11",
        ),
    ] = 0.0,
) -> None:
    """Fuse two stage images with the paper's rule (eq. 11)."""
    from bench_sim.experiments.fuse_files import fuse_files

    fuse_files(
        low, high, mu1=mu1, mu2=mu2, beta=beta, out=out, tra=tra, tra_method=tra_method,
        pedestal_dn=pedestal,
    )


@app.command()
@_user_errors
def reproduce(
    config: ConfigArg = DEFAULT_CONFIG_PATH,
    seed: SeedOpt = 0,
    out: Annotated[Path, typer.Option("--out", help="output folder")] = Path("results/paper"),
    quick: Annotated[bool, typer.Option("--quick", help="small preset for CI and first runs")] = False,
) -> None:
    """Reproduce the paper end to end: Fig. 3, Fig. 4, Table 1, DR analysis, report."""
    from bench_sim.config import load_config
    from bench_sim.experiments.reproduce import run_reproduce

    cfg = load_config(config)
    run_reproduce(cfg, seed=seed, out=out, quick=quick)


@app.command()
@_user_errors
def simulate(
    config: ConfigArg = DEFAULT_CONFIG_PATH,
    stages: Annotated[str, typer.Option("--stages", help="'all' or stages like 10,80")] = "10,80",
    seed: SeedOpt = 0,
    out: Annotated[Path, typer.Option("--out", help="output folder")] = Path("out/simulate"),
    fmt: Annotated[str, typer.Option("--format", help="zarr | netcdf | tiff")] = "zarr",
) -> None:
    """Any bench to its DTDI stage images with exact ground truth (dn, mean_dn, photons,
    reflectance, clipped, hdr): DIR/simulation.zarr, simulation.nc, or TIFFs + meta.json."""
    from bench_sim.experiments.simulate import run_simulate

    run_simulate(config, stages=stages, seed=seed, out=out, fmt=fmt)


@app.command()
@_user_errors
def dataset(
    spec: Annotated[Path, typer.Argument(help="dataset spec (TOML), e.g. scenes/datasets/example.toml")],
    out: Annotated[Path, typer.Option("--out", help="dataset folder")],
    workers: Annotated[
        int | None,
        typer.Option("--workers", help="worker processes of a local Dask cluster (default: the cores; "
                     "0: this process)"),
    ] = None,
    scheduler: Annotated[
        str | None, typer.Option("--scheduler", help="address of a running Dask scheduler (tcp://HOST:PORT)")
    ] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="complete a stopped run: skip complete samples, redo the rest")
    ] = False,
    only: Annotated[
        list[int] | None, typer.Option("--only", help="make just sample I (repeatable), identically")
    ] = None,
) -> None:
    """Synthetic validation dataset: many samples with exact ground truth, sharded per sample in
    DIR/data.zarr, a manifest, a dataset card; resumable, on Dask."""
    from bench_sim.experiments.dataset import main_summary, run_dataset

    command = f"bench-sim dataset {spec} --out {out}"  # what remakes it (workers change nothing)
    run = run_dataset(
        spec, out, workers=workers, scheduler=scheduler, resume=resume, only=only,
        progress=sys.stderr.isatty(), command=command,
    )
    print(main_summary(run))
    if run.failed:
        raise typer.Exit(1)


@app.command()
@_user_errors
def sweep(
    spec: Annotated[Path, typer.Argument(help="sweep spec (TOML): base config, [[parameters]], mode, seed")],
    out: Annotated[Path, typer.Option("--out", help="output folder")],
    workers: Annotated[
        int | None,
        typer.Option("--workers", help="worker processes of a local Dask cluster (default: the cores; 0: "
                     "run in this process)"),
    ] = None,
    scheduler: Annotated[
        str | None, typer.Option("--scheduler", help="address of a running Dask scheduler, tcp://HOST:PORT")
    ] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="finish a killed sweep: skip its finished points")
    ] = False,
    plots: Annotated[bool, typer.Option("--plots/--no-plots", help="draw DIR/plots/")] = True,
) -> None:
    """Scenario study: one simulation pass per point of a parameter sweep, on Dask:
    DIR/points.csv, sweep.nc, plots/, sweep.json, report.md."""
    from bench_sim.experiments.sweep import run_sweep

    run_sweep(spec, out, workers=workers, scheduler=scheduler, resume=resume, plots=plots)


def main() -> None:  # pragma: no cover
    app()


if __name__ == "__main__":  # pragma: no cover
    main()

"""The ``bench-sim`` command.

Every sub-command validates its inputs first (config, arguments, input files, output folder,
the memory and disk the run needs) and only then computes. The group class :class:`_BenchSimGroup`
gives every command, including those added later, the same behaviour towards the user:

* a bad config, file, argument or environment (:class:`~bench_sim.errors.BenchSimError`) and a
  usage error (unknown option, bad value) are one line on stderr, exit status 2;
* Ctrl-C (or ``SIGTERM``) is one line, exit status 130 (143), and leaves no partial output (the
  output sets of :mod:`bench_sim.io` remove their temporaries);
* a warning (:class:`~bench_sim.errors.ConfigWarning` and others) is one line, the run goes on;
* anything else is a bug: one line naming it, exit status 1.

No traceback reaches the user unless ``BENCH_SIM_DEBUG=1`` (then it is printed before the line).
bench_sim's workflows are imported at the top (as modules: a command calls ``module.function``
when it runs, so a test can patch it); the heavy libraries they use (Mitsuba, Dask, matplotlib,
xarray, zarr) are imported inside the functions that use them, so ``bench-sim --help`` stays
fast (``tests/test_layout.py`` checks it).
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
import traceback
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
from typer.core import TyperGroup

from bench_sim.config import DEFAULT_CONFIG_PATH, load_config
from bench_sim.errors import BenchSimError, kept_note
from bench_sim.fusion.methods import FUSE_METHODS
from bench_sim.fusion.tonemap import TONEMAP_METHODS
from bench_sim.io import format_bytes
from bench_sim.io.interrupts import Terminated, command_signals, signal_raised
from bench_sim.render import kernel_store, record_store, texture_store
from bench_sim.runtime.backend import choose_backend, versions
from bench_sim.runtime.resources import available_memory_bytes
from bench_sim.workflows import area_ptc_job, config_cmd, mtf_cmd, ptc_job, render_job, simulate_summary
from bench_sim.workflows import calibrate as calibrate_workflow
from bench_sim.workflows import fuse as fuse_workflow
from bench_sim.workflows import simulate as simulate_workflow
from bench_sim.workflows.dataset import run as dataset_run
from bench_sim.workflows.design.command import design_command
from bench_sim.workflows.reproduce import run as reproduce_run
from bench_sim.workflows.sweep import camera_store
from bench_sim.workflows.sweep import export as sweep_export
from bench_sim.workflows.sweep import run as sweep_run

try:  # typer >= 0.22 carries its own copy of click
    from typer._click import exceptions as _click_exc
except ImportError:  # pragma: no cover - older typer on click
    from click import exceptions as _click_exc  # type: ignore[no-redef]

__all__ = ["app", "main", "guarded"]

PROG = "bench-sim"
#: exit status of a user error, of Ctrl-C (128 + SIGINT) and of SIGTERM (128 + SIGTERM)
EXIT_USER, EXIT_INTERRUPT, EXIT_TERM, EXIT_BUG = 2, 130, 143, 1

T = TypeVar("T")


def _debug() -> bool:
    return os.environ.get("BENCH_SIM_DEBUG") == "1"


def _say(kind: str, text: str) -> None:
    """One line on stderr: ``bench-sim: KIND: TEXT`` (whitespace and newlines collapsed)."""
    line = " ".join(str(text).split()) or "(no message)"
    print(f"{PROG}: {kind}: {line}", file=sys.stderr, flush=True)


@contextlib.contextmanager
def _one_line_warnings() -> Iterator[None]:
    """Show each warning as one line (``bench-sim: warning: ...``), once per message."""
    if _debug():
        yield
        return
    seen: set[str] = set()

    def show(message: Any, category: type[Warning], *args: Any, **kwargs: Any) -> None:
        if issubclass(category, ResourceWarning) and signal_raised():
            return  # a socket or file the interrupted step left open: collected while it unwinds
        text = str(message).removeprefix("bench_sim: ")
        if text not in seen:
            seen.add(text)
            prefix = "" if issubclass(category, UserWarning) else f"{category.__name__}: "
            _say("warning", prefix + text)

    with warnings.catch_warnings():  # restores the filters and showwarning on the way out
        warnings.simplefilter("default")
        warnings.showwarning = show
        yield


def guarded(func: Callable[[], T]) -> T:
    """Run a command body with the CLI's contract (see the module docstring): exceptions become
    one line and an exit status (:class:`typer.Exit`); usage errors pass through to the group."""
    try:
        with command_signals(), _one_line_warnings():
            return func()
    except (typer.Exit, typer.Abort, _click_exc.ClickException):
        raise
    except BenchSimError as exc:
        if _debug():
            traceback.print_exc()
        kept = kept_note(exc)
        _say("error", (str(exc) or type(exc).__name__) + (f"; {kept}" if kept else ""))
        # a lost cluster (ClusterError) has its own status, 3
        raise typer.Exit(int(getattr(exc, "exit_status", EXIT_USER))) from None
    except KeyboardInterrupt as exc:
        if _debug():
            traceback.print_exc()
        _say("interrupted", f"stopped by Ctrl-C; {kept_note(exc) or _NOTHING_LEFT}")
        raise typer.Exit(EXIT_INTERRUPT) from None
    except Terminated as exc:
        _say("terminated", f"stopped by SIGTERM; {kept_note(exc) or _NOTHING_LEFT}")
        raise typer.Exit(EXIT_TERM) from None
    except MemoryError as exc:
        if _debug():
            traceback.print_exc()
        _say("error", f"out of memory ({exc or 'MemoryError'}); lower lines, sensor.columns or --frames")
        raise typer.Exit(EXIT_USER) from None
    except BrokenPipeError:  # the reader went away (``| head``): nothing to say to it
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        raise typer.Exit(EXIT_BUG) from None
    except OSError as exc:  # the environment: a file that cannot be read or written
        if _debug():
            traceback.print_exc()
        where = f"{exc.filename}: " if exc.filename else ""
        _say("error", f"{where}{exc.strerror or exc}")
        raise typer.Exit(EXIT_USER) from None
    except Exception as exc:
        cause = _interruption(exc)
        if cause is not None:  # Ctrl-C inside a C extension (an import), re-raised wrapped
            _say(*cause)
            raise typer.Exit(EXIT_INTERRUPT if cause[0] == "interrupted" else EXIT_TERM) from None
        if _debug():
            raise
        first = " ".join(str(exc).split())[:300]
        _say(
            "internal error",
            f"{type(exc).__name__}: {first} (a bug in bench_sim; BENCH_SIM_DEBUG=1 shows the traceback)",
        )
        raise typer.Exit(EXIT_BUG) from None


_NOTHING_LEFT = "no partial output was left (an earlier complete output is kept)"


def _interruption(exc: BaseException) -> tuple[str, str] | None:
    """The interruption (Ctrl-C, SIGTERM) an exception was raised from, if any, as the line to
    print: a signal that arrives while C code runs (an import) can come back wrapped, e.g. as
    ``SystemError: ... returned a result with an exception set``."""
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        seen.add(id(cur))
        if isinstance(cur, KeyboardInterrupt):
            return "interrupted", f"stopped by Ctrl-C; {_NOTHING_LEFT}"
        if isinstance(cur, Terminated):
            return "terminated", f"stopped by SIGTERM; {_NOTHING_LEFT}"
        cur = cur.__cause__ or cur.__context__
    return None


def _given(exc: Exception, args: Any) -> str:
    """`` (got 'VALUE')`` for a bad option value, found in the command line (click's message
    names the option but not the value)."""
    param = getattr(exc, "param", None)
    opts = list(getattr(param, "opts", ()) or ())
    argv = list(args) if args is not None else sys.argv[1:]
    for i, tok in enumerate(argv):
        for opt in opts:
            if tok == opt and i + 1 < len(argv):
                return f" (got {argv[i + 1]!r})"
            if tok.startswith(opt + "="):
                return f" (got {tok[len(opt) + 1:]!r})"
    return ""


class _BenchSimGroup(TyperGroup):
    """The command group: every sub-command runs :func:`guarded`; usage errors are one line."""

    def invoke(self, ctx: Any) -> None:
        # a command's return value is not an exit status (as in click's standalone mode)
        guarded(lambda: super(_BenchSimGroup, self).invoke(ctx))

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        windows_expand_args: bool = True,
        **extra: Any,
    ) -> Any:
        if not standalone_mode:
            return super().main(
                args, prog_name, complete_var, standalone_mode=False,
                windows_expand_args=windows_expand_args, **extra,
            )
        try:
            rv = super().main(
                args, PROG, complete_var, standalone_mode=False,
                windows_expand_args=windows_expand_args, **extra,
            )
        except _click_exc.NoArgsIsHelpError as exc:
            exc.show()
            sys.exit(exc.exit_code)
        except _click_exc.ClickException as exc:
            ctx = getattr(exc, "ctx", None)
            path = ctx.command_path if ctx is not None else PROG
            sub = path.split(" ", 1)[1] + ": " if " " in path else ""
            hint = f" (see '{path} --help')" if isinstance(exc, _click_exc.UsageError) else ""
            _say("error", f"{sub}{exc.format_message()}{_given(exc, args)}{hint}")
            sys.exit(exc.exit_code)
        except (typer.Abort, EOFError):
            _say("interrupted", "aborted")
            sys.exit(EXIT_INTERRUPT)
        except KeyboardInterrupt:  # Ctrl-C while parsing, before a command runs
            _say("interrupted", "stopped by Ctrl-C; nothing was written")
            sys.exit(EXIT_INTERRUPT)
        except Terminated:  # SIGTERM while parsing
            _say("terminated", "stopped by SIGTERM; nothing was written")
            sys.exit(EXIT_TERM)
        sys.exit(rv if isinstance(rv, int) else 0)  # an int here is typer.Exit's status


app = typer.Typer(
    cls=_BenchSimGroup,
    # help texts are plain text: "[[parameters]]" and "5:100:5" are not console markup or emoji
    rich_markup_mode=None,
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="bench_sim: optical test-bench simulator for HDR push-broom imaging with digital TDI.",
)

ConfigArg = Annotated[
    Path, typer.Argument(help="bench config (TOML)", show_default="scenes/paper_rig.toml")
]
SeedOpt = Annotated[int, typer.Option("--seed", help="seed of the run's one random generator (0..2**63-1)")]


def _user_errors(func: Callable[..., Any]) -> Callable[..., Any]:
    """Kept for commands written against the former per-command wrapper: the group
    (:class:`_BenchSimGroup`) now gives every command the error contract, so this returns
    ``func`` unchanged."""
    return func


@app.command()
def doctor() -> None:
    """Print the chosen Mitsuba variant, the LLVM library and why, memory, the disk stores'
    folders and sizes (light records; texture blocks, row kernels and a sweep's camera DR beside
    them), and versions.

    A variant forced by ``BENCH_SIM_VARIANT`` that cannot run here is one line, exit status 2."""
    choice = choose_backend()
    print(f"variant     : {choice.variant} ({choice.kind})")
    print(f"libLLVM     : {choice.llvm_path or '-'}")
    print(f"why         : {choice.reason}")
    for what, detail in choice.probes.items():
        print(f"  probe {what}: {detail}")
    mem = available_memory_bytes()
    print(f"memory      : {format_bytes(mem[0]) + ' available (' + mem[1] + ')' if mem else 'unknown'}")
    folder, (size, files) = record_store.store_dir(), record_store.usage()
    print(f"record cache: {folder} ({size / 2**20:.1f} MiB, {files} sets)" if folder else "record cache: off")
    for name, store in (("textures", texture_store), ("kernels", kernel_store), ("camera DR", camera_store)):
        if (here := store.store_dir()) is not None:  # off with the record store
            size, files = record_store.usage(here)
            print(f"  {name:<10}: {here} ({size / 2**20:.1f} MiB, {files} files)")
    for pkg, ver in versions().items():
        print(f"{pkg:<12}: {ver}")


@app.command()
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
    render_job.run_render(load_config(config), frames=frames, engine=engine, seed=seed, out=out)


@app.command()
def ptc(
    config: ConfigArg = DEFAULT_CONFIG_PATH,
    stages: Annotated[str, typer.Option("--stages", help="e.g. 1,10,80, 5:100:5 or all")] = "1,10,80",
    seed: SeedOpt = 0,
    out: Annotated[Path, typer.Option("--out", help="output folder")] = Path("out/ptc"),
    area: Annotated[bool, typer.Option("--area", help=area_ptc_job.AREA_HELP)] = False,
) -> None:
    """Photon-transfer series through the sensor and DTDI: EMVA 1288 files and results."""
    ptc_job.run_ptc_command(load_config(config), stages, seed, out, area=area)


@app.command()
def fuse(
    low: Annotated[Path, typer.Argument(help="stage-mu1 image (TIFF/PNG 16-bit, EXR or NPY)")],
    high: Annotated[Path, typer.Argument(help="stage-mu2 image, same shape")],
    mu1: Annotated[int, typer.Option("--mu1")] = 10,
    mu2: Annotated[int, typer.Option("--mu2")] = 80,
    beta: Annotated[int, typer.Option("--beta", help="output word bits: Phi_FS = 2**beta")] = 12,
    out: Annotated[Path, typer.Option("--out", help="HDR output (.exr)")] = Path("hdr.exr"),
    tra: Annotated[Path | None, typer.Option("--tra", help="also write Gamma_TRA (.png)")] = None,
    tra_method: Annotated[
        str, typer.Option("--tra-method", help=" | ".join(TONEMAP_METHODS))
    ] = "log",
    pedestal: Annotated[
        float | None,
        typer.Option(
            "--pedestal",
            help="offset [DN] the stage words carry, subtracted before fusing (default: the "
            "dtdi.pedestal_dn of bench_sim's own images, from their metadata; else 0, a plain word)",
            show_default=False,
        ),
    ] = None,
    method: Annotated[
        str, typer.Option("--method", help=" | ".join(FUSE_METHODS) + ": eq11 = the paper's rule; "
                          "clip = the highest stage whose word is below its clip")
    ] = "eq11",
) -> None:
    """Fuse two stage images: the paper's rule (eq. 11) or the clip-aware rule (--method)."""
    meta = fuse_workflow.fuse_files(
        low, high, mu1=mu1, mu2=mu2, beta=beta, out=out, tra=tra, tra_method=tra_method,
        pedestal_dn=pedestal, method=method,
    )
    print(f"method {meta['method']}; pedestal subtracted: {meta['pedestal_source']}; "
          f"{meta['pixels_from_clipped_high']} pixels from a clipped Gamma2; wrote {out}"
          + (f" and {tra}" if tra else ""))


@app.command()
def reproduce(
    config: ConfigArg = DEFAULT_CONFIG_PATH,
    seed: SeedOpt = 0,
    out: Annotated[Path, typer.Option("--out", help="output folder")] = Path("results/paper"),
    quick: Annotated[bool, typer.Option("--quick", help="small preset for CI and first runs")] = False,
    seeds: Annotated[int, typer.Option("--seeds", min=1, help="noise seeds (seed, seed+1, ...): headline "
                                       "numbers as mean +- sd; the files are the first seed's")] = 1,
) -> None:
    """Reproduce the paper end to end: Fig. 3, Fig. 4, Table 1, DR analysis, report."""
    cfg = load_config(config)
    reproduce_run.run_reproduce(cfg, seed=seed, out=out, quick=quick, seeds=seeds)


@app.command()
def simulate(
    config: ConfigArg = DEFAULT_CONFIG_PATH,
    stages: Annotated[str, typer.Option("--stages", help="'all' or stages like 10,80")] = "10,80",
    seed: SeedOpt = 0,
    out: Annotated[Path, typer.Option("--out", help="output folder")] = Path("out/simulate"),
    fmt: Annotated[str, typer.Option("--format", help="zarr | netcdf | tiff")] = "zarr",
) -> None:
    """Any bench to its DTDI stage images with exact ground truth (dn, mean_dn, photons,
    reflectance, clipped, hdr): DIR/simulation.zarr, simulation.nc, or TIFFs + meta.json."""
    start = time.perf_counter()
    simulate_workflow.run_simulate(config, stages=stages, seed=seed, out=out, fmt=fmt)
    print(simulate_summary.simulate_summary(out, fmt, time.perf_counter() - start))


#: the execution layer of ``dataset`` and ``sweep`` (bench_sim.runtime.execution.open_client)
WorkersOption = Annotated[
    int | None,
    typer.Option("--workers", help="worker processes of a local Dask cluster (default: the cores; "
                 "0: run in this process)"),
]
SchedulerOption = Annotated[
    str | None, typer.Option("--scheduler", help="address of a running Dask scheduler, tcp://HOST:PORT")
]


@app.command()
@_user_errors
def dataset(
    spec: Annotated[Path, typer.Argument(help="dataset spec (TOML), e.g. scenes/datasets/example.toml")],
    out: Annotated[Path, typer.Option("--out", help="dataset folder")],
    workers: WorkersOption = None,
    scheduler: SchedulerOption = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="complete a stopped run: skip complete samples, redo the rest")
    ] = False,
    only: Annotated[
        list[int] | None, typer.Option("--only", help="make just sample I (repeatable), identically")
    ] = None,
) -> None:
    """Synthetic validation dataset: many samples with exact ground truth, sharded per sample in
    DIR/data.zarr, a manifest, a dataset card; resumable, on Dask."""
    command = f"bench-sim dataset {spec} --out {out}"  # what remakes it (workers change nothing)
    run = dataset_run.run_dataset(
        spec, out, workers=workers, scheduler=scheduler, resume=resume, only=only,
        progress=sys.stderr.isatty(), command=command,
    )
    print(dataset_run.main_summary(run))
    if run.failed:
        raise typer.Exit(1)


@app.command()
@_user_errors
def sweep(
    spec: Annotated[Path, typer.Argument(help="sweep spec (TOML): base config, [[parameters]], mode, seed")],
    out: Annotated[Path | None, typer.Option("--out", help="output folder")] = None,
    workers: WorkersOption = None,
    scheduler: SchedulerOption = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="finish a killed sweep: skip its finished points")
    ] = False,
    plots: Annotated[bool, typer.Option("--plots/--no-plots", help="draw DIR/plots/")] = True,
    export_point: Annotated[
        tuple[int, Path] | None,
        typer.Option("--export-point", metavar="I DIR", help="write point I's resolved config.toml (ready "
                     "for simulate) and point.json into DIR; runs nothing"),
    ] = None,
) -> None:
    """Scenario study: one simulation pass per point of a parameter sweep, on Dask:
    DIR/points.csv, points_images.csv, sweep.nc, plots/, sweep.json, report.md."""
    if export_point is not None:
        if out is not None:
            raise BenchSimError("--export-point and --out: give one (--export-point runs nothing)")
        print(sweep_export.export_point(spec, export_point[0], export_point[1]))
        return
    if out is None:
        raise BenchSimError("--out: missing (the sweep's output folder)")
    sweep_run.run_sweep(spec, out, workers=workers, scheduler=scheduler, resume=resume, plots=plots)


@app.command()
def calibrate(
    input_path: Annotated[Path, typer.Argument(metavar="INPUT", help=calibrate_workflow.INPUT_HELP)],
    out: Annotated[Path, typer.Option("--out", help="output folder")],
    stages: Annotated[str | None, typer.Option("--stages", help="mu1,mu2 (default: the config's)")] = None,
    config: Annotated[Path | None, typer.Option("--config", help="base config (default: paper rig)")] = None,
    seed: SeedOpt = 0,
) -> None:
    """Digital twin of a camera: EMVA 1288 fit with standard errors, DIR/sensor.toml, and the
    predicted DTDI dynamic range of mu1, mu2 and Gamma_HDR (report.md)."""
    calibrate_workflow.calibrate(input_path, out, stages=stages, config=config, seed=seed)


# ``bench-sim config keys|show`` and ``bench-sim init`` (their arguments live with the workflow)
app.add_typer(config_cmd.config_app, name="config")
app.command("init")(config_cmd.init_command)
app.command("mtf")(mtf_cmd.mtf_command)
app.command("design")(design_command)  # bench-sim design SPEC.toml --out DIR (its arguments live with it)


def main() -> None:  # pragma: no cover
    """Run the command line (the ``bench-sim`` script is :func:`bench_sim.__main__.main`)."""
    app()


if __name__ == "__main__":  # pragma: no cover
    main()

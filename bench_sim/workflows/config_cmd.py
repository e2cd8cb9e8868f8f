"""``bench-sim config keys [SECTION]``, ``bench-sim config show CONFIG`` and ``bench-sim init DIR``:
finding the settings and starting one's own bench from the shipped examples.

``config keys`` lists every key of the schema (:func:`bench_sim.config.catalogue.config_keys`:
type, unit, default, allowed range, typical range, description), as text or as the Markdown
table of ``docs/config-reference.md``. ``config show`` prints a config resolved through its
``base`` chain, as the TOML every output carries. ``init`` copies the shipped scenes, scenario
presets, sweep, dataset and design specs and example targets (``bench_sim/scenes/``) into a new folder,
keeping their layout so the relative paths inside them (``base = "../paper_rig.toml"``, the
dataset's image glob) still work.
"""

from __future__ import annotations

import difflib
import functools
import os
import shutil
import tempfile
from pathlib import Path
from typing import Annotated

import typer

from bench_sim.config import DEFAULT_CONFIG_PATH, SCENES_DIR, config_to_toml_text, load_config
from bench_sim.config.catalogue import KeyInfo, config_keys, config_sections, model_keys
from bench_sim.config.plausible import Typical
from bench_sim.errors import BenchSimError
from bench_sim.sensor.effects.base import Effect
from bench_sim.sensor.effects.chain import effect_kinds, sensor_chain

__all__ = [
    "keys_text", "keys_markdown", "show_text", "init_folder", "INIT_IGNORED", "config_app", "init_command",
]

#: What ``init`` does not copy out of ``bench_sim/scenes/``.
INIT_IGNORED = ("__pycache__", "*.pyc", ".*")


def _typical_of(cls: type[Effect], key: str) -> Typical | None:
    """The typical range of an effect's key (its ``TYPICAL``, by the key's last part)."""
    return cls.TYPICAL.get(key.rsplit(".", 1)[-1])


def effect_keys() -> list[KeyInfo]:
    """The keys of every sensor effect, ``sensor.effects.<name>[kind=KIND].KEY``, from each
    effect's own parameters (:mod:`bench_sim.sensor.effects`), after its ``kind`` line."""
    out = []
    for kind, cls in effect_kinds().items():
        prefix = f"sensor.effects.<name>[kind={kind}]."
        out.append(KeyInfo(prefix + "kind", "str", "", f'"{kind}"', "", "", cls.summary))
        out.extend(model_keys(cls.Params, prefix, functools.partial(_typical_of, cls)))
    return out


def _chosen(section: str | None) -> list[KeyInfo]:
    keys = config_keys(section)
    head = (section or "").rstrip(".").split("<")[0]
    if "sensor.effects".startswith(head) or head.startswith("sensor.effects"):
        keys += [k for k in effect_keys() if k.key.startswith(head)]
    if not keys:
        names = config_sections()
        close = difflib.get_close_matches(section or "", names, n=1, cutoff=0.5)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        raise BenchSimError(
            f"config keys: section {section!r} is not a table of the config (tables: "
            f"{', '.join(n for n in names if '<' not in n)}, lights.<name>){hint}"
        )
    return keys


def keys_text(section: str | None = None) -> str:
    """Every key (of ``section``), two lines each: ``key  type [unit] = default`` and the
    allowed range, typical range and description, indented."""
    out = []
    for k in _chosen(section):
        unit = f" [{k.unit}]" if k.unit else ""
        out.append(f"{k.key}  {k.type}{unit} = {k.default}")
        notes = [
            f"allowed {k.allowed}" if k.allowed else "",
            f"typical {k.typical} (refused far outside)" if k.typical else "",
            k.description,
        ]
        out.append("    " + "; ".join(n for n in notes if n) if any(notes) else "    -")
    return "\n".join(out)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("<", "&lt;").replace(">", "&gt;") or " "


def keys_markdown(section: str | None = None) -> str:
    """Every key (of ``section``) as a Markdown table (the body of ``docs/config-reference.md``)."""
    rows = [
        "| key | type | unit | default | allowed | typical | description |",
        "|---|---|---|---|---|---|---|",
    ]
    for k in _chosen(section):
        cells = (f"`{k.key}`", k.type, k.unit, f"`{k.default}`", k.allowed, k.typical, k.description)
        rows.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return "\n".join(rows)


def show_text(config: Path) -> str:
    """The config ``config`` resolved through its ``base`` chain, as TOML (with a comment naming
    the file); a bad config is the one-line error of :func:`bench_sim.config.load_config`."""
    cfg = load_config(config)
    sensor_chain(cfg.sensor)  # its effects checked as every command checks them
    return f"# {Path(config).resolve()}, resolved (base chain applied, defaults filled in)\n" + (
        config_to_toml_text(cfg)
    )


def init_folder(folder: Path) -> list[Path]:
    """Copy the shipped examples (``bench_sim/scenes/``) into the new folder ``folder``.

    Returns
    -------
    list of Path
        The files written, relative to ``folder``.

    Raises
    ------
    BenchSimError
        ``folder`` is a file, or a folder that is not empty (nothing is overwritten), or cannot be
        written.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise BenchSimError(f"init: {folder}: is a file; give a new or empty folder")
    if folder.is_dir() and any(folder.iterdir()):
        raise BenchSimError(
            f"init: {folder}: is not empty; give a new or empty folder (nothing is overwritten)"
        )
    parent = folder.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BenchSimError(f"init: {parent}: cannot make the folder ({exc.strerror or exc})") from None
    if not os.access(parent, os.W_OK):
        raise BenchSimError(f"init: {parent}: cannot be written (no permission)")
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.partial-", dir=parent))
    try:
        shutil.copytree(SCENES_DIR, tmp / "x", ignore=shutil.ignore_patterns(*INIT_IGNORED))
        written = sorted(p.relative_to(tmp / "x") for p in (tmp / "x").rglob("*") if p.is_file())
        if folder.is_dir():
            folder.rmdir()  # empty (checked above)
        (tmp / "x").rename(folder)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return written


# ---------------------------------------------------------------- the command line
# (registered by bench_sim.cli, whose command group gives them its one-line errors)

config_app = typer.Typer(
    no_args_is_help=True, add_completion=False,
    help="Find the settings: every key of the schema, and a config resolved through its base chain.",
)


@config_app.command("keys")
def config_keys_command(
    section: Annotated[
        str | None, typer.Argument(help="only this table or key, e.g. sensor, timing, lights.strong")
    ] = None,
    markdown: Annotated[bool, typer.Option("--markdown", help="as a Markdown table")] = False,
) -> None:
    """Every config key: type, unit, default, allowed range, typical range, description."""
    print(keys_markdown(section) if markdown else keys_text(section))


@config_app.command("show")
def config_show_command(
    config: Annotated[
        Path, typer.Argument(help="bench config (TOML)", show_default="scenes/paper_rig.toml")
    ] = DEFAULT_CONFIG_PATH,
) -> None:
    """The config resolved through its base chain (defaults filled in), as TOML."""
    print(show_text(config), end="")


def init_command(
    folder: Annotated[Path, typer.Argument(help="new (or empty) folder for the example configs")],
) -> None:
    """Copy the example scenes, scenario presets, sweep, dataset and design specs and targets."""
    written = init_folder(folder)
    configs = ", ".join(str(p) for p in written if p.suffix == ".toml")
    print(f"wrote {len(written)} files to {folder}/: {configs}")
    print(f"next: bench-sim config show {folder}/paper_rig.toml; "
          f"bench-sim simulate {folder}/paper_rig.toml --out out/simulate")

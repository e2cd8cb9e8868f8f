"""Compare the data files of this checkout with those of another git revision, byte for byte.

Runs the same commands with the same configs and seeds on both trees -- ``reproduce --quick``,
``simulate`` (Zarr and TIFF), ``ptc``, a two-point ``sweep`` and a two-sample ``dataset`` -- and
reports, per command, which files are byte-identical, which differ, and which exist on one side
only. The other revision is exported with ``git archive`` into a temporary folder and run from
there with this checkout's virtual environment (``PYTHONPATH`` puts its package first), so both
use the same libraries.

Files that hold wall-clock times or the process's state (``metrics.json``'s ``wall_s``,
``timings_s``, ``report.md``'s timing table, ``meta.json``'s ``wall_s``, a sweep's and a
dataset's run records) are compared after dropping those fields; everything else is compared
as bytes. ``--rename OLD=NEW`` maps a file or variable name of the old tree to the new one
(a renamed Zarr array, a renamed CSV column) and is applied to paths and to text files.

Usage::

    .venv/bin/python scripts/compare_outputs.py --baseline origin/main [--keep DIR]

Exit status 0 when every data file matches, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: keys of JSON files that carry times or counts of the process, not data
VOLATILE_KEYS = {"wall_s", "timings_s", "mitsuba_renders", "mitsuba_renders_process", "worker",
                 "started", "finished", "elapsed_s", "host", "pid", "probes"}

SWEEP_SPEC = """name = "compare"
base = "{base}"
quick = true
seed = 5
mode = "product"
[[parameters]]
key = "lights.strong.irradiance_w_m2"
values = [64.0, 256.0]
"""

DATASET_SPEC = """name = "compare"
base = "{base}"
samples = 2
seed = 11
stages = [10, 80]
lines = 64
columns = 64
[config.target]
panel_lines = 64
panel_columns = 64
[randomize]
"lights.strong.irradiance_w_m2" = {{ dist = "loguniform", low = 32.0, high = 512.0 }}
"""


def commands(work: Path) -> dict[str, list[str]]:
    """The commands to compare, each writing into ``OUT`` (substituted per tree)."""
    rig = str(ROOT / "bench_sim" / "scenes" / "paper_rig.toml")
    (work / "sweep.toml").write_text(SWEEP_SPEC.format(base=rig))
    (work / "dataset.toml").write_text(DATASET_SPEC.format(base=rig))
    return {
        "reproduce": ["reproduce", "--quick", "--seed", "3", "--out", "OUT"],
        "simulate": ["simulate", rig, "--stages", "1,10,80", "--seed", "4", "--out", "OUT"],
        "simulate_tiff": ["simulate", rig, "--stages", "10,80", "--seed", "4", "--format", "tiff",
                          "--out", "OUT"],
        "ptc": ["ptc", rig, "--stages", "1,10", "--seed", "2", "--out", "OUT"],
        "sweep": ["sweep", str(work / "sweep.toml"), "--workers", "0", "--no-plots", "--out", "OUT"],
        "dataset": ["dataset", str(work / "dataset.toml"), "--workers", "0", "--out", "OUT"],
    }


def run_tree(tree: Path, out: Path, cmds: dict[str, list[str]]) -> None:
    env = dict(os.environ, PYTHONPATH=str(tree), BENCH_SIM_THREADS="2")
    for name, args in cmds.items():
        target = out / name
        argv = [sys.executable, "-m", "bench_sim", *[str(target) if a == "OUT" else a for a in args]]
        proc = subprocess.run(argv, env=env, cwd=tree, capture_output=True, text=True)
        if proc.returncode != 0:
            raise SystemExit(f"{tree}: {args[0]} failed ({proc.returncode}): {proc.stderr[-2000:]}")
        print(f"  {name}: done ({tree.name})", flush=True)


def _strip(obj: object) -> object:
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items() if k not in VOLATILE_KEYS}
    if isinstance(obj, list):
        return [_strip(v) for v in obj]
    return obj


def _renamed(data: bytes, renames: list[tuple[str, str]]) -> bytes:
    for a, b in renames:
        data = re.sub(rb"\b" + re.escape(a.encode()) + rb"\b", b.encode(), data)
    return data


def _json_bytes(text: str, renames: Sequence[tuple[str, str]] = ()) -> bytes:
    try:
        data = json.dumps(_strip(json.loads(text)), sort_keys=True).encode()
    except ValueError:
        data = text.encode()
    return _renamed(data, list(renames))


def _image_bytes(path: Path, renames: list[tuple[str, str]]) -> bytes:
    """Pixels and metadata (less its process fields) of a TIFF, PNG or EXR file."""
    import numpy as np

    if path.suffix == ".tiff":
        import tifffile

        with tifffile.TiffFile(path) as tif:
            desc = tif.pages[0].description
            return tif.asarray().tobytes() + _json_bytes(desc, renames)
    if path.suffix == ".png":
        from PIL import Image

        with Image.open(path) as im:
            text = {k: _json_bytes(v, renames) for k, v in sorted(im.text.items())}
            return np.asarray(im).tobytes() + repr(text).encode()
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        parts = [np.ascontiguousarray(c.pixels).tobytes() for _, c in sorted(f.channels().items())]
        head = {k: str(v) for k, v in f.header().items() if k != "bench_sim"}
        meta = f.header().get("bench_sim")
        return b"".join(parts) + repr(sorted(head.items())).encode() + _json_bytes(str(meta), renames)


def _table_bytes(path: Path) -> bytes:
    """A CSV or Parquet table less its time and worker columns (and ``#`` provenance lines)."""
    import pandas as pd

    if path.suffix == ".csv":
        lines = path.read_text().splitlines()
        comments = [_json_bytes(line.split(": ", 1)[1]) if ": {" in line else line.encode()
                    for line in lines if line.startswith("#")]
        frame = pd.read_csv(path, comment="#")
    else:
        comments, frame = [], pd.read_parquet(path)
    frame = frame.drop(columns=[c for c in frame.columns if c in VOLATILE_KEYS])
    return b"".join(comments) + frame.to_csv(index=False).encode()


def _netcdf_bytes(path: Path) -> bytes:
    import xarray as xr

    with xr.open_dataset(path) as ds:
        ds = ds.drop_vars([v for v in ds.variables if v in VOLATILE_KEYS])
        attrs = {k: (_json_bytes(v) if isinstance(v, str) else repr(v)) for k, v in sorted(ds.attrs.items())}
        body = b"".join(ds[v].values.tobytes() + repr(sorted(ds[v].attrs.items())).encode()
                        for v in sorted(ds.variables))
        return body + repr(attrs).encode()


def _normalise(path: Path, data: bytes, renames: list[tuple[str, str]], old: bool) -> bytes:
    if path.suffix in (".tiff", ".png", ".exr"):
        data = _image_bytes(path, renames if old else [])
    elif path.suffix in (".csv", ".parquet"):
        data = _table_bytes(path)
    elif path.suffix == ".nc":
        data = _netcdf_bytes(path)
    elif path.suffix == ".json" and data[:1] in (b"{", b"["):
        try:
            text = json.dumps(_strip(json.loads(data)), sort_keys=True)
        except ValueError:
            return data
        data = text.encode()
    if path.suffix == ".md":
        data = re.sub(rb"--out \S+", b"--out DIR", data)
        data = re.sub(rb"/tmp/\S+", b"PATH", data)
        # the timing table of reproduce's report: rows of seconds
        data = re.sub(rb"\| [0-9.]+ s? ?\|", b"| t |", data)
        data = re.sub(rb"[0-9]+\.[0-9]+ s\b", b"t s", data)
    if old and path.suffix in (".json", ".csv", ".md", ".toml"):
        data = _renamed(data, renames)
    return data


def compare(old: Path, new: Path, renames: list[tuple[str, str]]) -> tuple[int, int, list[str]]:
    def files(root: Path, old_side: bool) -> dict[str, Path]:
        out = {}
        for p in sorted(root.rglob("*")):
            if p.is_file():
                rel = str(p.relative_to(root))
                if old_side:
                    for a, b in renames:
                        rel = re.sub(r"(^|/)" + re.escape(a) + r"(/|$|\.)", r"\1" + b + r"\2", rel)
                out[rel] = p
        return out

    a, b = files(old, True), files(new, False)
    problems = []
    same = raw = 0
    for rel in sorted(set(a) | set(b)):
        if rel not in a:
            problems.append(f"only in the new tree: {rel}")
        elif rel not in b:
            problems.append(f"only in the old tree: {rel}")
        else:
            da = _normalise(a[rel], a[rel].read_bytes(), renames, True)
            db = _normalise(b[rel], b[rel].read_bytes(), renames, False)
            if da == db:
                same += 1
                raw += a[rel].read_bytes() == b[rel].read_bytes()
            else:
                problems.append(f"differs: {rel}")
    return same, raw, problems


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", required=True, help="git revision to compare against")
    ap.add_argument("--keep", type=Path, help="keep both trees' outputs in this folder")
    ap.add_argument("--rename", action="append", default=[], metavar="OLD=NEW",
                    help="a name of the old tree that the new tree calls otherwise")
    ap.add_argument("--only", action="append", help="compare only these commands")
    ap.add_argument("--no-run", action="store_true", help="compare the outputs already in --keep")
    args = ap.parse_args()
    renames = [tuple(r.split("=", 1)) for r in args.rename]
    work = Path(tempfile.mkdtemp(prefix="bench_sim_compare_"))
    try:
        base_tree = work / "baseline"
        base_tree.mkdir()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.baseline], check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(base_tree)], input=archive, check=True)
        cmds = commands(work)
        if args.only:
            cmds = {k: v for k, v in cmds.items() if k in args.only}
        out_old, out_new = (args.keep or work) / "old", (args.keep or work) / "new"
        if not (args.no_run and args.keep):
            for d in (out_old, out_new):
                shutil.rmtree(d, ignore_errors=True)
                d.mkdir(parents=True)
            print(f"baseline {args.baseline}: running {len(cmds)} commands", flush=True)
            run_tree(base_tree, out_old, cmds)
            print("this checkout: running the same commands", flush=True)
            run_tree(ROOT, out_new, cmds)
        failed = 0
        for name in cmds:
            same, raw, problems = compare(out_old / name, out_new / name, renames)
            verdict = "all identical" if not problems else f"{len(problems)} mismatches"
            print(f"{name}: {same} files identical ({raw} as raw bytes, {same - raw} in their data: "
                  f"pixels, table cells, JSON less times), {verdict}")
            for line in problems:
                print(f"    {line}")
            failed += bool(problems)
        return 1 if failed else 0
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())

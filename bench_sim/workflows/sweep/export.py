"""``bench-sim sweep SPEC --export-point I DIR``: one point of a sweep as a config to look at.

Writes, into ``DIR`` (new or empty):

- ``config.toml``: point ``I``'s fully resolved bench config (the spec's base, its overrides and
  the point's values), ready for ``bench-sim simulate DIR/config.toml --stages ...``;
- ``point.json``: the point's index, swept values, the stages a sweep pass of it accumulates, its
  random stream (``SeedSequence(seed).spawn(n)[stream]``, :mod:`bench_sim.workflows.sweep.spec`)
  and the ``simulate`` command line.

Nothing runs: the spec and the point's config are checked as for a sweep (one-line errors).
``simulate --seed S`` draws from ``SeedSequence(S)``, not from the point's child stream, so its
noise is another realisation of the same bench.
"""

from __future__ import annotations

from pathlib import Path

from bench_sim.config import config_sha256, config_to_toml_text
from bench_sim.errors import BenchSimError
from bench_sim.io import check_output_dir, output_set, write_json, write_text
from bench_sim.version import __version__
from bench_sim.workflows.sweep.spec import load_spec

__all__ = ["export_point"]


def export_point(spec_path: str | Path, index: int, out: str | Path) -> Path:
    """Write point ``index`` of the sweep ``spec_path`` into ``out`` (module docstring); returns
    the path of its ``config.toml``."""
    spec = load_spec(spec_path)
    n = len(spec.points)
    if isinstance(index, bool) or not 0 <= int(index) < n:
        raise BenchSimError(f"--export-point = {index}: outside 0..{n - 1} (the sweep has {n} points)")
    check_output_dir(out, "--export-point DIR")  # before anything is computed
    point = spec.points[int(index)]
    cfg = point.cfg
    stages = sorted({cfg.fusion.mu1, cfg.fusion.mu2, *spec.stages})
    header = (f"# point {point.index} of sweep {spec.name!r} ({spec.path.name}), bench_sim {__version__}\n"
              f"# values: {', '.join(f'{k} = {v!r}' for k, v in point.values.items())}\n")
    folder = Path(out).expanduser().resolve()
    record = {"command": "sweep --export-point", "point": point.index, "version": __version__}
    with output_set(folder, record, "--export-point DIR") as tmp:  # both files or neither
        write_text(tmp / "config.toml", header + config_to_toml_text(cfg))
        write_json(tmp / "point.json", {
            "sweep": spec.name, "spec": str(spec.path), "point": point.index, "values": point.values,
            "varied": point.varied, "config_sha256": config_sha256(cfg), "seed": spec.seed,
            "stream": 0 if spec.noise == "common" else point.index, "stages": stages, "version": __version__,
            "simulate": f"bench-sim simulate {folder / 'config.toml'} --stages "
                        f"{','.join(str(m) for m in stages)} --out OUT",
        })
    return folder / "config.toml"

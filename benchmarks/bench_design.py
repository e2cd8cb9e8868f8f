"""Cost of ``bench-sim design`` scoring every stage pair of a 100-row sensor against one all-stage
``bench-sim simulate`` of the same bench (issue 36: at most 3x).

Both at ``--quick`` size (the paper rig, 256 lines x 512 columns, 100 rows), as whole commands
(start-up included), paired and interleaved (:func:`baseline.paired`) in one run so that the
machine's load weighs on both alike:

- ``simulate --stages all`` of the quick bench (streamed to its Zarr store, truth included);
- ``design`` of the same bench: all 4,950 pairs, the rules ``--rules`` (default: eq11, clip and
  clip_margin: 14,850 candidates), one word, the sharpness per stage (a noise-free companion pass),
  no chain DR (``chain_dr = "none"``: what the issue times is the scoring of the pairs; the
  chain DR of the front is measured separately with ``--chain``, and printed apart).

Prints the medians of wall and CPU seconds and the ratios design / simulate (target <= 3).

Usage: python benchmarks/bench_design.py [--repeat 1] [--rules eq11,clip,clip_margin] [--chain]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from baseline import ROOT, Side, load_line, median

RATIO_TARGET = 3.0


def _files(folder: Path, rules: list[str], chain: str) -> tuple[Path, Path]:
    """The quick bench config and the design spec on it."""
    base = ROOT / "bench_sim" / "scenes" / "paper_rig.toml"
    cfg = folder / "quick.toml"
    cfg.write_text(f'base = "{base}"\nlines = 256\n[sensor]\ncolumns = 512\n'
                   "[target]\npanel_lines = 256\npanel_columns = 512\n[render]\nspp = 8\n")
    spec = folder / "design.toml"
    spec.write_text(f'base = "quick.toml"\nseed = 0\nrules = {json.dumps(rules)}\nchain_dr = "{chain}"\n'
                    '[stages]\nmu1 = "all"\nmu2 = "all"\n')
    return cfg, spec


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--rules", default="eq11,clip,clip_margin")
    ap.add_argument("--chain", action="store_true", help="also time a design with the chain DR of its front")
    args = ap.parse_args()
    rules = args.rules.split(",")
    side = Side.current()
    print(load_line())
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        cfg, spec = _files(tmp, rules, "none")

        def run(s: Side, i: int, which: str) -> tuple[float, float]:
            out = tmp / f"{which}_{i}"
            if which == "simulate":
                return s.bench_sim("simulate", str(cfg), "--stages", "all", "--seed", "0", "--out", str(out),
                                   cwd=tmp)
            return s.bench_sim("design", str(spec), "--out", str(out), cwd=tmp)

        got: dict[str, list[tuple[float, float]]] = {"simulate": [], "design": []}
        for i in range(args.repeat):  # interleaved: simulate, design, simulate, design, ...
            for which in ("simulate", "design"):
                got[which].append(run(side, i, which))
        wall = {k: median([w for w, _ in v]) for k, v in got.items()}
        cpu = {k: median([c for _, c in v]) for k, v in got.items()}
        n = 4950 * len(rules)
        print(f"simulate --stages all (quick, 100 stages): wall {wall['simulate']:.1f} s, "
              f"CPU {cpu['simulate']:.1f} s")
        print(f"design, 4950 pairs x {len(rules)} rules = {n} candidates: wall {wall['design']:.1f} s, "
              f"CPU {cpu['design']:.1f} s")
        for what, d in (("wall", wall), ("CPU", cpu)):
            r = d["design"] / d["simulate"]
            print(f"ratio design / simulate ({what}): {r:.2f} (target <= {RATIO_TARGET:g}: "
                  f"{'ok' if r <= RATIO_TARGET else 'NOT MET'})")
        if args.chain:
            _, spec_chain = _files(tmp, rules, "front")
            w, c = side.bench_sim("design", str(spec_chain), "--out", str(tmp / "chain"), cwd=tmp)
            print(f"design with the chain DR of its front: wall {w:.1f} s, CPU {c:.1f} s "
                  f"(the front's DR: {w - wall['design']:.1f} s more)")


if __name__ == "__main__":
    main()

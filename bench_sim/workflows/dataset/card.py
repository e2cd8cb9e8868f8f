"""The dataset card (``DIR/README.md``) and its thumbnail sheet (``DIR/thumbnails.png``).

The card says what is in a dataset (samples, stages, size, variables with units and types),
whether it is complete, how it was made (command, spec, seed, version, the streams), the
randomised values drawn and the summary metrics, and how to load it. The sheet shows the first
complete samples: the image the camera gives (``Gamma_TRA`` of ``gamma_hdr`` when two stages are
fused, else the highest stage on one display scale) beside the reflectance truth behind it.
Nothing in either depends on the wall clock, so the same dataset gives the same card.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bench_sim.fusion.tonemap import tone_map
from bench_sim.io import format_bytes, markdown_table, write_png, write_text
from bench_sim.workflows.dataset.reader import (
    CARD,
    COMPLETION_RECORD,
    DATA_STORE,
    DATASET_JSON,
    MANIFEST_CSV,
    MANIFEST_META,
    MANIFEST_PARQUET,
    RECORDS_DIR,
    THUMBNAILS,
    iter_samples,
    read_info,
)
from bench_sim.workflows.reproduce.figures import stage_display

if TYPE_CHECKING:
    import pandas as pd

    from bench_sim.workflows.dataset.spec import DatasetSpec

__all__ = ["write_card", "write_thumbnails", "THUMBNAIL_SAMPLES"]

#: Samples shown on the thumbnail sheet (the first complete ones)
THUMBNAIL_SAMPLES = 16
#: Samples listed one by one on the card (larger datasets: see the manifest)
LISTED_SAMPLES = 64


def _fmt(v: Any) -> str:
    if isinstance(v, bool) or v is None:
        return str(v)
    if isinstance(v, int | np.integer):
        return str(int(v))
    if isinstance(v, float | np.floating):
        x = float(v)
        if math.isnan(x):
            return "-"
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        return f"{x:.4g}"
    return str(v)


def write_thumbnails(
    out: Path, spec: DatasetSpec, indices: list[int], provenance: dict[str, Any] | None = None
) -> Path | None:
    """Thumbnail sheet of the samples ``indices``: per sample the camera image and the
    reflectance truth (``provenance`` in the PNG's ``bench_sim`` text chunk). Returns the path,
    or ``None`` when there is nothing to show."""
    if not indices:
        (out / THUMBNAILS).unlink(missing_ok=True)
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    variables = ["dn", "reflectance"] + (["gamma_hdr"] if spec.fused else [])
    per_row = 4
    rows = -(-len(indices) // per_row)
    lines, cols = spec.base.lines, spec.base.sensor.columns
    tile = 1.7
    fig, axes = plt.subplots(
        rows, 2 * per_row, figsize=(2 * per_row * tile, rows * tile * lines / cols + 0.35 * rows + 0.5),
        dpi=100, squeeze=False,
    )
    for ax in axes.ravel():
        ax.set_axis_off()
    beta = spec.base.dtdi.beta_bits
    layout_key = "target.layout" if "target.layout" in spec.randomize else None
    for k, sample in enumerate(iter_samples(out, variables=variables, only=indices, incomplete=True)):
        ax_img, ax_truth = axes[k // per_row, 2 * (k % per_row)], axes[k // per_row, 2 * (k % per_row) + 1]
        if spec.fused:
            img = tone_map(sample.arrays["gamma_hdr"], spec.base.fusion.tra)
            what = f"HDR ({spec.base.fusion.tra})"
        else:
            img = stage_display(sample.arrays["dn"][-1], beta)
            what = f"m = {sample.stages[-1]}"
        ax_img.imshow(img, cmap="gray", vmin=0, vmax=1, interpolation="antialiased")
        ax_truth.imshow(
            sample.arrays["reflectance"][0], cmap="gray", vmin=0, vmax=1, interpolation="antialiased"
        )
        label = f"#{sample.index}"
        if layout_key:
            label += f" {sample.values.get(layout_key)}"
        ax_img.set_title(f"{label}: {what}", fontsize=7)
        ax_truth.set_title("reflectance truth", fontsize=7)
    fig.suptitle(
        f"{spec.name}: camera image and reflectance truth of samples {indices[0]}..{indices[-1]}", fontsize=9
    )
    fig.tight_layout()
    meta = {**(provenance or {}), "dataset": spec.name, "seed": spec.seed, "samples": indices}
    canvas: Any = fig.canvas  # Agg: has buffer_rgba
    canvas.draw()
    grey = np.asarray(canvas.buffer_rgba())[..., 0].copy()  # a grey figure: R = G = B
    plt.close(fig)
    return write_png(out / THUMBNAILS, grey, meta)  # 8-bit grey: a third of the RGBA file


def _uses(spec: DatasetSpec, key: str, row: dict[str, Any]) -> bool:
    """Whether a sample's bench reads the randomised ``key`` (``target.image``: only with the
    ``image`` layout; the value is drawn, and in the config, either way)."""
    if key != "target.image":
        return True
    return row.get("target.layout", spec.base.target.layout) == "image"


def _randomized_rows(spec: DatasetSpec, df: pd.DataFrame) -> list[list[Any]]:
    from pandas.api.types import is_bool_dtype, is_numeric_dtype

    done = df[df.status == "complete"]
    rows = []
    for key, dist in spec.randomize.items():
        if key == "target.image":
            done_key = done[[_uses(spec, key, r) for r in done.to_dict("records")]] if len(done) else done
        else:
            done_key = done
        params = {k: v for k, v in dist.model_dump().items() if k not in ("dist", "files")}
        if dist.dist == "glob":
            params["files"] = len(dist.files)
        described = f"{dist.dist}(" + ", ".join(f"{k}={_fmt(v)}" for k, v in params.items()) + ")"
        col = done_key[key] if len(done_key) else df[key].iloc[:0]
        if len(col) and is_numeric_dtype(col) and not is_bool_dtype(col):
            drawn = f"{_fmt(col.min())} .. {_fmt(col.median())} .. {_fmt(col.max())} (min .. median .. max)"
        else:
            counts = col.astype(str).value_counts().sort_index()
            drawn = ", ".join(f"{k} x {v}" for k, v in counts.items()) or "-"
            if key == "target.image":
                drawn += " (samples with layout image)"
        rows.append([f"`{key}`", described.replace("|", "/"), drawn.replace("|", "/")])
    for key, sv in spec.scene.items():  # where the windows sit, the light levels (dataset.sample_scene)
        col = done[f"scene.{key}"] if len(done) else df[f"scene.{key}"].iloc[:0]
        drawn = (f"{_fmt(col.min())} .. {_fmt(col.median())} .. {_fmt(col.max())} (min .. median .. max)"
                 if len(col) else "-")
        rows.append([f"`scene.{key}`", sv.describe(), drawn])
    return rows


def _intro(
    spec: DatasetSpec, info: dict[str, Any], complete: list[int], failed: int, shown: list[int],
    store_bytes: int, cmd: str,
) -> list[str]:
    """Title, whether the dataset is complete, what it holds and its size, the thumbnails."""
    lines, cols = spec.base.lines, spec.base.sensor.columns
    per_sample = store_bytes / max(len(complete), 1)
    md: list[str] = [f"# Dataset card: {spec.name}", ""]
    if spec.description:
        md += [spec.description.strip(), ""]
    state = (
        f"**Complete**: all {spec.samples} samples (the completion record `{COMPLETION_RECORD}` is written "
        "last)." if len(complete) == spec.samples else
        f"**Incomplete**: {len(complete)} of {spec.samples} samples complete"
        + (f", {failed} failed" if failed else "")
        + f". `{cmd} --resume` completes it; only samples whose record in `{RECORDS_DIR}/` says "
        "`complete` are valid."
    )
    md += [
        state, "",
        f"Synthetic DTDI push-broom images made by bench_sim {info['base']['version']} with the exact "
        "ground truth behind every pixel: "
        f"{spec.samples} samples of {lines} lines x {cols} columns at stages "
        f"{', '.join(str(m) for m in spec.stages)}"
        + (f", fused by the paper's eq. 11 (mu1 = {spec.base.fusion.mu1}, mu2 = {spec.base.fusion.mu2})"
           if spec.fused else "")
        + f". On disk: {format_bytes(store_bytes)} of arrays ({format_bytes(per_sample)} per sample, "
        "Zarr v3 with Zstandard).", "",
        f"![thumbnails]({THUMBNAILS})" if shown else "", "",
        "## Contents", "",
    ]
    return md


def _contents(schema: dict[str, Any]) -> list[str]:
    """The variables, the files and what the truth and the summary metrics are."""
    var_rows = [
        [f"`{n}`", ", ".join(v["dims"]), v["dtype"], v["units"], v["long_name"]] for n, v in schema.items()
    ]
    md = markdown_table(["variable", "dimensions", "type", "units", "meaning"], var_rows, fmt=_fmt) + [""]
    md += markdown_table(["file", "what"], [
        [f"`{DATA_STORE}`", "the arrays (Zarr v3, `simulate`'s schema with a `sample` dimension): one chunk "
         "per sample and stage, `units` on every array, each sample's physical coordinates"],
        [f"`{MANIFEST_PARQUET}`, `{MANIFEST_CSV}`", "one row per sample: `sample`, `seed`, `split`, the "
         "randomised and scene values, `config_sha256`, summary metrics, `status`, `error`, `wall_s`, "
         "`worker`; the CSV is plain (`pandas.read_csv` reads it as it is), its provenance in "
         f"`{MANIFEST_META}`"],
        [f"`{DATASET_JSON}`", "the spec, provenance (version, resolved base bench and its SHA-256), streams, "
         "schema"],
        [f"`{RECORDS_DIR}/NNNNNNNN.json`",
         "per-sample record, written after the sample's arrays are on disk"],
        [f"`{CARD}`, `{THUMBNAILS}`", "this card and its thumbnail sheet"],
        [f"`{COMPLETION_RECORD}`", "written last, when every sample is complete"],
    ], fmt=_fmt) + [""]
    md += [
        "Truth: `mean_dn` is the exact expectation of `dn` with every clip (full well, ADC, word) and the "
        "fixed patterns in, `linear_dn` the same without any clip, `noise_std_dn` the temporal standard "
        "deviation of `dn`, `photons` the mean photons the stage pixel collected, `reflectance` the "
        "target reflectance its footprints integrated (exact under the sample's sync error), `clipped` "
        "marks reads or words that clipped in this draw. The training target of an HDR fusion is "
        "`true_hdr_dn`, the noise-free stage-mu2 signal without any clip (`linear_dn` of stage mu2 less "
        "its offsets); `eq11_expected_dn` is eq. 11 of the expected words (what eq. 11 gives without "
        "noise, not the truth); `hdr_recoverable` marks the pixels some stage can give. "
        "Summary metrics per sample: `scene_dr_db` = 20 lg of the 99.9th over "
        "the 0.1th percentile of `photons`; per stage m, `saturated_fraction_m{m}` and "
        "`snr_dark_m{m}` / `snr_bright_m{m}` = mean signal above the dark level over the rms of "
        "`dn - mean_dn` in the darkest / brightest tenth of the scene (clipped pixels left out).",
        "",
    ]
    return md


def _how_made(spec: DatasetSpec, info: dict[str, Any], df: pd.DataFrame, cmd: str) -> list[str]:
    """The command, seed and streams, the hashes, the spec and the randomised values drawn."""
    md = [
        "## How it was made", "",
        f"```sh\n{cmd}\n```", "",
        f"Root seed {spec.seed}. {info['streams']}. A sample's content depends only on (spec, seed, i): "
        "any number of workers, `--resume` and `--only i` give it bit for bit.", "",
        "Splits (samples): " + ", ".join(f"{k} {v}" for k, v in info["split_samples"].items())
        + f" ({info['split_rule']}).", "",
        f"Base bench SHA-256 `{info['base']['config_sha256']}`; spec SHA-256 `{info['spec_sha256']}`"
        + (f"; image files: {', '.join(f'`{k}`' for k in spec.images)}" if spec.images else "") + ".", "",
        f"The spec (`{info['spec_file']}`):", "",
        "```toml", spec.path.read_text().rstrip(), "```", "",
        "### Randomised values", "",
    ]
    md += markdown_table(
        ["key", "distribution", "drawn (complete samples)"], _randomized_rows(spec, df), fmt=_fmt
    ) + [""]
    return md


def _metrics(spec: DatasetSpec, df: pd.DataFrame) -> list[str]:
    """The summary metrics over the complete samples and, for small datasets, each sample."""
    md: list[str] = []
    metric_cols = [c for c in df.columns if c in ("scene_dr_db", "light_scale", "recoverable_fraction")
                   or c.startswith(("saturated_", "snr_", "light_ratio_"))]
    done = df[df.status == "complete"]
    if len(done):
        md += ["### Summary metrics", ""]
        md += markdown_table(["metric", "samples with a value", "min", "median", "max"], [
            [f"`{c}`", int(done[c].notna().sum()), done[c].min(), done[c].median(), done[c].max()]
            for c in metric_cols
        ], fmt=_fmt)
        md += ["", "A metric has no value (`nan`) where its region clipped entirely at that stage. "
               "`light_ratio_*`: the TDI window's light ratio r (`tdi_light_ratio`; eq. 11 assumes r = 1): "
               "its 1st and 99th percentiles, largest |r - 1| and the fraction of pixels with |r - 1| > 5 %.",
               ""]
    if len(done) and spec.samples <= LISTED_SAMPLES:
        keys = list(spec.randomize)
        head = ["sample", *[f"`{k}`" for k in keys], "scene_dr_db",
                *[f"sat. m={m}" for m in spec.stages]]
        rows = []
        for d in done.to_dict("records"):
            vals = [
                (Path(d[k]).name if _uses(spec, k, d) else "-") if k == "target.image" else d[k] for k in keys
            ]
            rows.append([d["sample"], *vals, d["scene_dr_db"],
                         *[d[f"saturated_fraction_m{m}"] for m in spec.stages]])
        md += ["### Samples", ""] + markdown_table(head, rows, fmt=_fmt) + [""]
    return md


#: How to load a dataset (the card's last section)
HOW_TO_LOAD = [
    "## How to load it", "",
    "```python",
    "import bench_sim",
    "ds = bench_sim.dataset.open(DIR)      # xarray.Dataset, lazy; manifest columns as coordinates",
    'ds.dn.sel(stage=80).isel(sample=0)     # one stage image; ds["lights.strong.irradiance_w_m2"] ...',
    "from bench_sim.dataset import iter_batches, score_fusion",
    'for batch in iter_batches(DIR, split="train", fields=["dn", "true_hdr_dn"], batch_size=8):',
    "    ...                                 # numpy arrays; the target: true_hdr_dn",
    'score_fusion(DIR, "gamma_hdr", split="test").regions   # any fusion against the true target',
    "for s in bench_sim.dataset.iter_samples(DIR):   # numpy only, one sample at a time",
    '    s.arrays["dn"], s.arrays["mean_dn"], s.values, s.metrics',
    "```", "",
    "Or with the libraries themselves: `xarray.open_zarr(DIR + '/data.zarr')` (keep the samples "
    "whose record is complete), `pandas.read_parquet(DIR + '/manifest.parquet')`, "
    "`pandas.read_csv(DIR + '/manifest.csv')`.", "",
]


def write_card(
    out: Path,
    spec: DatasetSpec,
    df: pd.DataFrame,
    command: str | None = None,
    provenance: dict[str, Any] | None = None,
) -> Path:
    """Write ``DIR/README.md`` and ``DIR/thumbnails.png`` for the dataset in ``out`` with
    manifest ``df`` (:func:`bench_sim.workflows.dataset.store.manifest_frame`); ``provenance``
    (version, seed, hashes) goes into the PNG."""
    info = read_info(out)
    complete = [int(i) for i in df["sample"][df.status == "complete"]]
    failed = int((df.status == "failed").sum())
    shown = complete[:THUMBNAIL_SAMPLES]
    write_thumbnails(out, spec, shown, provenance)
    store_bytes = sum(f.stat().st_size for f in (out / DATA_STORE).rglob("*") if f.is_file())
    cmd = command or f"bench-sim dataset {info['spec_file']} --out DIR"
    md = _intro(spec, info, complete, failed, shown, store_bytes, cmd)
    md += _contents(info["schema"]["variables"])
    md += _how_made(spec, info, df, cmd)
    md += _metrics(spec, df)
    md += HOW_TO_LOAD
    return write_text(out / CARD, "\n".join(md).replace("\n\n\n", "\n\n"))

"""``bench-sim mtf``'s command line (registered by :mod:`bench_sim.cli`, whose command group gives
it the one-line errors): the options of :class:`bench_sim.workflows.mtf.MtfRequest`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from bench_sim.workflows import mtf as mtf_workflow

__all__ = ["mtf_command"]


def mtf_command(
    image: Annotated[Path, typer.Argument(
        help="image with slanted edges (PNG, TIFF, BMP, JPEG, EXR, NPY; linear) or a simulate output "
        "(its folder, simulation.zarr, simulation.nc or meta.json)")],
    roi: Annotated[list[str] | None, typer.Option(
        "--roi", help="x0,y0,x1,y1: an edge's region [px, ends exclusive]; repeat for more; default: "
        "every slanted edge found")] = None,
    channel: Annotated[str | None, typer.Option(
        "--channel", help="of a colour image: R, G, B or Y (ISO 12233 luminance)")] = None,
    mask: Annotated[Path | None, typer.Option(
        "--mask", help="image of the same size: pixels where it is 0 are left out")] = None,
    saturation: Annotated[float | None, typer.Option(
        "--saturation", help="value at which the camera clips, in the file's units (default: a full "
        "8..16-bit word when the image reaches one); clipped pixels are left out")] = None,
    encoding: Annotated[str, typer.Option(
        "--encoding", help="auto | linear | srgb: how the values encode the light (auto: srgb for "
        "JPEG, linear otherwise)")] = "auto",
    frequency_axis: Annotated[str, typer.Option(
        "--frequency-axis", help="normal (along the edge normal, ISO 12233:2017) | pixel (along the "
        "pixel rows or columns: f cos(angle))")] = "normal",
    pixel_pitch_um: Annotated[float | None, typer.Option(
        "--pixel-pitch-um", help="pixel pitch [um], for cycles/mm")] = None,
    out: Annotated[Path, typer.Option("--out", help="output folder")] = Path("out/mtf"),
) -> None:
    """ISO 12233 slanted-edge SFR of every edge of an image (or of every stage of a simulate output):
    edges.csv, sfr.csv, sfr.png, rois.png and summary.json in DIR."""
    req = mtf_workflow.MtfRequest(
        image=image, out=out, rois=tuple(roi or ()), channel=channel, mask=mask, saturation=saturation,
        encoding=encoding, frequency_axis=frequency_axis, pixel_pitch_um=pixel_pitch_um,
    )
    summary = mtf_workflow.run_mtf(req)
    print(mtf_workflow.summary_line(summary, out))

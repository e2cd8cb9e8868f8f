"""The report's sharpness section: the lens, the companion pass's e-SFR against the closed form
and the warning when the system is sharper than Nyquist (:class:`~bench_sim.workflows.reproduce.
result.SharpnessResult`)."""

from __future__ import annotations

from bench_sim.workflows.reproduce.result import SharpnessResult

__all__ = ["sharpness_section", "SHARPNESS_HEADING"]

#: the section's heading
SHARPNESS_HEADING = "## Sharpness (ISO 12233 e-SFR)"


def _f(v: float | None, digits: int = 3) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def sharpness_section(s: SharpnessResult) -> list[str]:
    """The Markdown lines of the section."""
    stages = ", ".join(str(m) for m in s.sharpness_stages)
    measured, closed = s.mtf_nyquist_across, s.closed_nyquist_across_binned
    if measured is None:
        verdict = "which the companion pass could not measure"
    else:
        dev = measured / closed - 1
        words = "which the measurement matches" if abs(dev) <= 0.03 else "from which the measurement differs"
        verdict = f"{words} ({dev * 100:+.1f} %)"
    lines = [
        SHARPNESS_HEADING,
        "",
        f"Lens: {s.lens}. Measured on the companion pass (slanted edges at 5 +- 1 deg on the same bench, "
        f"`mtf50_vs_stage.csv`), medians over its stages {stages}:",
        "",
        "| | across the track | along the track |",
        "|---|---:|---:|",
        f"| MTF50 [cycles/px] | {_f(s.mtf50_across_cyc_px)} | {_f(s.mtf50_along_cyc_px)} |",
        f"| SFR at Nyquist (0.5 cycles/px) | {_f(measured)} | {_f(s.mtf_nyquist_along)} |",
        "",
        f"Closed form across the track (lens x pixel aperture at the edges' 5 deg): SFR at Nyquist "
        f"{_f(s.closed_nyquist_across)}, {_f(closed)} with the e-SFR's 1/4-px bins, {verdict}; "
        f"MTF50 {_f(s.closed_mtf50_across_cyc_px)} cycles/px. Along the "
        "track the integration smear (a box of one line) and DTDI's stage sums add their own.",
        "",
    ]
    if s.nyquist_warning:
        lines += [f"**Warning:** {s.nyquist_warning}.", ""]
    return lines

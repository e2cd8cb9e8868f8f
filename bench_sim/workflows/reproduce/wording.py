"""Numbers in the report's sentences, worded so that the text never claims more than the number:
a fraction reads "0%" only when it is exactly 0 and "100%" only when it is exactly 1, and an SNR
always says whether it is temporal or spatial."""

from __future__ import annotations

import math

__all__ = ["pct", "SPATIAL", "TEMPORAL", "read_noise_limit_note"]

#: Label of an SNR measured as mean / standard deviation over a patch of one image.
SPATIAL = "spatial SNR"
#: Label of an SNR measured from the temporal noise (photon-transfer series, repeats or truth).
TEMPORAL = "temporal SNR"


def pct(x: float | None, decimals: int = 1, sign: bool = False) -> str:
    """``x`` (a fraction) as a percentage with ``decimals`` decimals, more where needed so that a
    non-zero fraction never reads 0 and one below 1 never reads 100 (up to 6 decimals; beyond:
    ``<0.000001%`` / ``>99.999999%``). ``None`` or NaN: ``n/a``.

    Parameters
    ----------
    x
        Fraction (1 = 100 %).
    decimals
        Decimals of the percentage where they suffice.
    sign
        Print the sign (``+``/``-``) as well.
    """
    if x is None or not math.isfinite(x):
        return "n/a"
    if x in (0, 1):
        return f"{100 * x:.0f}%"
    plus = "+" if sign else ""
    for d in range(decimals, 7):
        text = f"{100 * x:{plus}.{d}f}"
        if float(text) != 0 and abs(float(text)) != 100:
            return f"{text}%"
    return "<0.000001%" if abs(x) < 0.5 else ">99.999999%"


def read_noise_limit_note(mu1: int, mu2: int) -> str:
    """The read-noise limit of the temporal SNR gain of stage ``mu2`` over ``mu1``, labelled as
    such: ``sqrt(mu2/mu1)`` bounds a temporal SNR ratio, not a spatial one."""
    return (
        f"read-noise limit of the {TEMPORAL} gain sqrt({mu2}/{mu1}) = {math.sqrt(mu2 / mu1):.2f}, "
        "for reference: it bounds a temporal ratio, not this spatial one"
    )

"""Numbers in the report's sentences, worded so that the text never claims more than the number:
a fraction reads "0%" only when it is exactly 0 and "100%" only when it is exactly 1, an SNR
always says whether it is temporal or spatial, and ``sqrt(mu2/mu1)`` is called what it is, the
ratio of the two stages' read-noise floors, never a bound of a measured gain."""

from __future__ import annotations

import math

__all__ = ["pct", "SPATIAL", "TEMPORAL", "READ_NOISE_RATIO", "read_noise_ratio", "read_noise_ratio_note"]

#: Label of an SNR measured as mean / standard deviation over a patch of one image.
SPATIAL = "spatial SNR"
#: Label of an SNR measured from the temporal noise (photon-transfer series, repeats or truth).
TEMPORAL = "temporal SNR"
#: What ``sqrt(mu2/mu1)`` is: the noise at zero signal of the sum of ``mu2`` reads over that of
#: ``mu1`` reads, each read adding its own read noise (DTDI sums digitally)
READ_NOISE_RATIO = "ratio of the two stages' read-noise floors"


def pct(x: float | None, decimals: int = 1, sign: bool = False) -> str:
    """``x`` (a fraction) as a percentage with ``decimals`` decimals, more where needed so that a
    non-zero fraction never reads 0 and one below 1 never reads 100 (up to 6 decimals, or
    ``decimals`` where more are asked; beyond: ``<0.000001%`` / ``>99.999999%``). ``None`` or NaN:
    ``n/a``.

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
    for d in range(decimals, max(decimals + 1, 7)):
        text = f"{100 * x:{plus}.{d}f}"
        if float(text) != 0 and abs(float(text)) != 100:
            return f"{text}%"
    return "<0.000001%" if abs(x) < 0.5 else ">99.999999%"


def read_noise_ratio(mu1: int, mu2: int, verb: str = "") -> str:
    """``sqrt(mu2/mu1) = x.xx``, named: the ratio of the two stages' read-noise floors (``verb``
    between the name and the value, e.g. ``"is"``)."""
    return f"{READ_NOISE_RATIO} {verb + ' ' if verb else ''}sqrt({mu2}/{mu1}) = {math.sqrt(mu2 / mu1):.2f}"


def read_noise_ratio_note(mu1: int, mu2: int) -> str:
    """``sqrt(mu2/mu1)`` beside a measured gain, for reference: the ratio of the read-noise floors,
    which bounds no measured gain (a temporal gain at the noise floor exceeds it by the signal's own
    shot noise; a spatial one is another quantity)."""
    return f"{read_noise_ratio(mu1, mu2)}, for reference: not a bound of this gain"

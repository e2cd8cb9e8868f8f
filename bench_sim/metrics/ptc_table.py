"""The photon-transfer table of EMVA 1288: per level the exposure time, the irradiation (when
known), the temporal mean and variance of the images, and the matching dark level; built and
checked by :func:`make_table`, fitted by :func:`bench_sim.metrics.emva_fit.fit_camera`.

Forms a lab publishes, all accepted:

* raw means and variances (``mean_dn``, ``var_dn2``), the dark levels as rows of their own
  (``photons_per_pixel = 0``, or ``dark = True``) or as ``dark_mean_dn``/``dark_var_dn2`` of
  every lit row;
* dark-subtracted (``signal_dn = mu_y - mu_y.dark`` and/or ``signal_var_dn2 = sigma_y^2 -
  sigma_y.dark^2``, the form most authors plot), with the dark level of every row
  (``dark_var_dn2``; ``dark_mean_dn`` if known, else the dark offset is unknown): the table then
  holds the same numbers as the raw one and every fit gives the same results;
* without a photon calibration: no ``photons_per_pixel`` (the irradiation is then the
  ``relative_irradiance`` given, or the exposure time of an exposure-time series at constant
  irradiance): K, the dark noise and the saturation come out in DN and e-, the quantum
  efficiency and the responsivity are unknown.

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), sections 3 and 6 (photon-transfer method, image
pairs, dark images at every exposure time).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from bench_sim.config.plausible import Typical, judge
from bench_sim.errors import BenchSimError

__all__ = ["EXPOSURE_TYPICAL", "BELOW_DARK_SE", "PtcTable", "make_table"]

#: Typical exposure time of an EMVA 1288 measurement: a value more than 10 times outside is
#: refused as a unit slip (milliseconds written as seconds), as a config's keys are
#: (:func:`bench_sim.config.plausible.judge`).
EXPOSURE_TYPICAL = Typical(1e-6, 1.0, "s")
#: A lit mean this many standard errors below its dark level is refused (a table that gives its
#: pixel count; without one, any lit mean below its dark level is refused).
BELOW_DARK_SE = 5.0


@dataclass(frozen=True)
class PtcTable:
    """A checked photon-transfer table: the lit levels, each with its matching dark level.

    Arrays (one value per lit level, in increasing irradiation): ``exposure_s`` [s], ``photons``
    (mean photons per pixel during the exposure; None: no photon calibration), ``irradiance``
    (the abscissa of the response: photons, a relative irradiance or the exposure time; None:
    none known), ``mean_dn`` [DN], ``var_dn2`` [DN^2], ``dark_mean_dn`` [DN], ``dark_var_dn2``
    [DN^2]. ``dark_exposure_s``, ``dark_means_dn``, ``dark_vars_dn2``: the distinct dark levels.
    ``pixels``: pixels per image (None: unknown); ``images``, ``dark_images``: images per level
    behind each mean and variance (2: an EMVA 1288 pair); ``bits``: ADC bits (None: unknown);
    ``wavelength_nm`` (None: unknown); ``dark_mean_known``: False when the table gave the signal
    only (its ``dark_mean_dn`` are then 0); ``irradiance_kind``: ``photons``,
    ``relative_irradiance``, ``exposure`` or ``none``; ``row_noise_var_dn2`` and ``columns``: a
    temporal row noise the ``columns`` pixels of a row share (its errors widen those of the means
    and variances, :meth:`var_rel_se`).
    """

    exposure_s: np.ndarray
    photons: np.ndarray | None
    irradiance: np.ndarray | None
    mean_dn: np.ndarray
    var_dn2: np.ndarray
    dark_mean_dn: np.ndarray
    dark_var_dn2: np.ndarray
    dark_exposure_s: np.ndarray
    dark_means_dn: np.ndarray
    dark_vars_dn2: np.ndarray
    pixels: int | None = None
    bits: int | None = None
    wavelength_nm: float | None = None
    source: str = "table"
    images: int = 2
    dark_images: int = 2
    dark_mean_known: bool = True
    irradiance_kind: str = "photons"
    row_noise_var_dn2: float = 0.0
    columns: int = 1

    @property
    def signal_dn(self) -> np.ndarray:
        """``mu_y - mu_y.dark`` [DN] of every lit level."""
        return self.mean_dn - self.dark_mean_dn

    def _shared(self, var: np.ndarray) -> np.ndarray:
        """``1 + (N_c - 1) (b / var)^2``: how much a row noise ``b`` shared by the ``N_c`` pixels of a
        row widens the error of a variance over the pixels (1 without row noise)."""
        b = self.row_noise_var_dn2
        return 1.0 + (self.columns - 1) * (b / np.maximum(var, 1e-300)) ** 2

    def var_rel_se(self, var: np.ndarray, images: int) -> np.ndarray:
        """Relative standard error of a temporal variance ``var`` from ``images`` images of the
        ``pixels``: ``sqrt(2 / (N (L - 1)))`` for independent pixels, widened by the row noise
        they share (:attr:`row_noise_var_dn2`, :attr:`columns`)."""
        n = float(self.pixels or 1)
        return np.sqrt(2.0 / (n * max(images - 1, 1)) * self._shared(np.asarray(var, dtype=np.float64)))

    def dark_groups(self) -> np.ndarray:
        """Index of the dark level every lit level subtracts (levels sharing one get one index)."""
        keys = np.column_stack([self.exposure_s, self.dark_var_dn2, self.dark_mean_dn])
        _, inverse = np.unique(keys, axis=0, return_inverse=True)
        return np.asarray(inverse).ravel()

    def signal_cov_dn2(self) -> np.ndarray:
        """Covariance [DN^2] of the signals ``mu_y - mu_y.dark``: each lit mean's temporal noise
        on the diagonal (relative units when ``pixels`` is unknown; a row noise adds ``b / M`` per
        image), each dark mean's shared by the levels that subtract it."""
        n = float(self.pixels or 1)
        shared = (self.columns - 1) * self.row_noise_var_dn2
        own = (np.maximum(self.var_dn2, 1e-12) + shared) / (n * self.images)
        dark = (np.maximum(self.dark_var_dn2, 0.0) + shared) / (n * self.dark_images)
        grp = self.dark_groups()
        return np.diag(own) + np.where(grp[:, None] == grp[None, :], np.sqrt(np.outer(dark, dark)), 0.0)

    def signal_se_dn(self) -> np.ndarray:
        """Standard error of every signal [DN] (the diagonal of :meth:`signal_cov_dn2`)."""
        return np.sqrt(np.diag(self.signal_cov_dn2()))


def _col(name: str, values: Any, n: int, source: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=np.float64).ravel()
    except (TypeError, ValueError) as exc:
        raise BenchSimError(f"{source}: column {name!r} holds values that are not numbers") from exc
    if arr.size != n:
        raise BenchSimError(f"{source}: column {name!r} has {arr.size} values, expected {n}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        i = int(bad[0])
        raise BenchSimError(f"{source}: row {i + 1}: {name} = {float(arr[i])} is not a finite number")
    return arr


def _dark_for(
    t: float, dark_t: np.ndarray, dark_m: np.ndarray, dark_v: np.ndarray, source: str
) -> tuple[float, float]:
    same = np.isclose(dark_t, t, rtol=1e-6, atol=0.0)
    if not same.any():
        raise BenchSimError(
            f"{source}: no dark level (a dark row, or dark_mean_dn/dark_var_dn2 columns) at "
            f"exposure_s = {t:.6g}; EMVA 1288 needs the dark pair of every exposure time"
        )
    return float(dark_m[same].mean()), float(dark_v[same].mean())


def _check_rows(cols: dict[str, np.ndarray], lit: np.ndarray, order: np.ndarray | None, source: str) -> None:
    """Refuse negative values, too few lit rows, a decreasing exposure, a non-increasing order."""
    for name in ("var_dn2", "dark_var_dn2", "photons_per_pixel", "relative_irradiance", "exposure_s"):
        if name in cols and (cols[name] < 0).any():
            i = int(np.flatnonzero(cols[name] < 0)[0])
            what = "a variance" if "var" in name else "it"
            raise BenchSimError(
                f"{source}: row {i + 1}: {name} = {cols[name][i]:g} < 0: {what} cannot be negative"
            )
    _check_exposures(cols["exposure_s"], source)
    if lit.size < 3:
        raise BenchSimError(f"{source}: {lit.size} lit rows: need at least 3")
    tl = cols["exposure_s"][lit]
    if (np.diff(tl) < 0).any():
        i = int(lit[np.flatnonzero(np.diff(tl) < 0)[0] + 1])
        raise BenchSimError(
            f"{source}: row {i + 1}: exposure_s = {cols['exposure_s'][i]:g} below the row before: "
            "non-monotonic exposure (list the lit levels in the order of the series, exposure never "
            "decreasing)"
        )
    if order is not None and (np.diff(order[lit]) <= 0).any():
        i = int(lit[np.flatnonzero(np.diff(order[lit]) <= 0)[0] + 1])
        raise BenchSimError(
            f"{source}: row {i + 1}: the irradiation does not increase over the row before "
            "(lit levels must be listed in increasing irradiation)"
        )


def _check_exposures(t: np.ndarray, source: str) -> None:
    """Refuse an exposure time of 0 (dark rows too) or one in the wrong unit (a unit slip)."""
    if (t == 0).any():
        i = int(np.flatnonzero(t == 0)[0])
        raise BenchSimError(
            f"{source}: row {i + 1}: exposure_s = 0: every level (dark rows too) is measured over an "
            "exposure time > 0 s"
        )
    for i, value in enumerate(t):
        slip = judge("exposure_s", float(value), EXPOSURE_TYPICAL)
        if slip:
            raise BenchSimError(f"{source}: row {i + 1}: {slip}")


def _check_above_dark(table: PtcTable, lit: np.ndarray) -> None:
    """Refuse a lit level whose mean lies below its dark level (swapped columns, or the dark pair
    of another exposure time): its signal ``mu_y - mu_y.dark`` would be negative. With a pixel
    count, a lit mean within :data:`BELOW_DARK_SE` standard errors of its dark level is noise."""
    tol = BELOW_DARK_SE * table.signal_se_dn() if table.pixels else np.zeros(lit.size)
    below = np.flatnonzero(table.mean_dn < table.dark_mean_dn - tol)
    if below.size and table.dark_mean_known:
        j = int(below[0])
        raise BenchSimError(
            f"{table.source}: row {int(lit[j]) + 1}: mean_dn = {table.mean_dn[j]:g} below its dark level "
            f"{table.dark_mean_dn[j]:g} DN: a lit level cannot be darker than the dark (mean_dn and "
            "dark_mean_dn swapped, or the dark rows of another exposure time?)"
        )


def _irradiance(cols: dict[str, np.ndarray], dark: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, str]:
    """The dark-row mask, the abscissa of every row and its kind (see :class:`PtcTable`)."""
    t = cols["exposure_s"]
    for name, kind in (("photons_per_pixel", "photons"), ("relative_irradiance", "relative_irradiance")):
        if name in cols:
            x = cols[name]
            return (x == 0) if dark is None else dark, x, kind
    is_dark = np.zeros(t.size, dtype=bool) if dark is None else dark
    lit_t = t[~is_dark]
    if lit_t.size and float(lit_t.min()) > 0 and float(lit_t.max()) > 2.0 * float(lit_t.min()):
        return is_dark, t, "exposure"
    return is_dark, np.arange(t.size, dtype=np.float64), "none"


def _means(cols: dict[str, np.ndarray], source: str) -> tuple[np.ndarray, np.ndarray, bool]:
    """Raw means and variances of every row from the raw or the dark-subtracted columns."""
    has_dark_mean = "dark_mean_dn" in cols
    if "mean_dn" in cols:
        mean = cols["mean_dn"]
    elif "signal_dn" in cols:
        mean = cols["signal_dn"] + (cols["dark_mean_dn"] if has_dark_mean else 0.0)
    else:
        raise BenchSimError(f"{source}: missing column mean_dn (or signal_dn, the dark-subtracted mean)")
    if "var_dn2" in cols:
        var = cols["var_dn2"]
    elif "signal_var_dn2" in cols:
        if "dark_var_dn2" not in cols:
            raise BenchSimError(
                f"{source}: signal_var_dn2 (dark-subtracted variance) needs dark_var_dn2, the dark "
                "variance of every row (the dark noise)"
            )
        var = cols["signal_var_dn2"] + cols["dark_var_dn2"]
    else:
        raise BenchSimError(
            f"{source}: missing column var_dn2 (or signal_var_dn2, the dark-subtracted variance)"
        )
    return mean, var, "mean_dn" in cols or has_dark_mean


def _dark_levels(
    cols: dict[str, np.ndarray], mean: np.ndarray, var: np.ndarray, lit: np.ndarray, drk: np.ndarray,
    source: str,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every lit row's dark (mean, variance), the distinct dark exposures and their levels: from
    the dark columns of each row (and the dark rows), or from the dark rows of the same exposure."""
    t = cols["exposure_s"]
    if "dark_mean_dn" in cols or "dark_var_dn2" in cols:
        dm = cols.get("dark_mean_dn", np.zeros(t.size))
        if "dark_var_dn2" not in cols:
            raise BenchSimError(f"{source}: dark_mean_dn without dark_var_dn2: give both dark columns")
        dt, dmm, dv = t[lit], dm[lit], cols["dark_var_dn2"][lit]
        if drk.size:  # the dark rows count as well
            dt, dmm, dv = (np.concatenate([a[drk], b]) for a, b in ((t, dt), (mean, dmm), (var, dv)))
        pairs = np.column_stack([dmm[-lit.size :], dv[-lit.size :]])
    else:
        dt, dmm, dv = t[drk], mean[drk], var[drk]
        pairs = np.array([_dark_for(float(v), dt, dmm, dv, source) for v in t[lit]]).reshape(-1, 2)
    ut = np.unique(dt)
    levels = np.array([_dark_for(float(v), dt, dmm, dv, source) for v in ut]).reshape(-1, 2)
    return pairs, ut, levels


def make_table(
    exposure_s: Any,
    *,
    photons_per_pixel: Any = None,
    relative_irradiance: Any = None,
    mean_dn: Any = None,
    var_dn2: Any = None,
    signal_dn: Any = None,
    signal_var_dn2: Any = None,
    dark_mean_dn: Any = None,
    dark_var_dn2: Any = None,
    dark: Any = None,
    pixels: int | None = None,
    bits: int | None = None,
    wavelength_nm: float | None = None,
    images: int = 2,
    dark_images: int = 2,
    row_noise_var_dn2: float = 0.0,
    columns: int = 1,
    source: str = "table",
) -> PtcTable:
    """Check a photon-transfer table and pair every lit level with its dark level (module doc).

    Dark rows are those with ``dark`` set, else ``photons_per_pixel = 0`` (or
    ``relative_irradiance = 0``); each lit row takes the ``dark_mean_dn``/``dark_var_dn2`` of its
    row where given, else the dark rows of the same exposure time.

    Raises
    ------
    BenchSimError
        One line naming the row and value: a value not finite; a negative variance, irradiation
        or exposure time; an exposure time of 0 or in the wrong unit (milliseconds written as
        seconds); the lit levels' exposure time decreasing (non-monotonic exposure) or their
        irradiation not increasing; a lit level without a dark level or below it; a missing
        column.
    """
    n = np.asarray(exposure_s, dtype=object).ravel().size
    given = {"exposure_s": exposure_s, "photons_per_pixel": photons_per_pixel,
             "relative_irradiance": relative_irradiance, "mean_dn": mean_dn, "var_dn2": var_dn2,
             "signal_dn": signal_dn, "signal_var_dn2": signal_var_dn2, "dark_mean_dn": dark_mean_dn,
             "dark_var_dn2": dark_var_dn2}
    cols = {k: _col(k, v, n, source) for k, v in given.items() if v is not None}
    flag = None if dark is None else _col("dark", dark, n, source) != 0
    is_dark, x, kind = _irradiance(cols, flag)
    mean, var, mean_known = _means(cols, source)
    cols["var_dn2"] = var
    lit, drk = np.flatnonzero(~is_dark), np.flatnonzero(is_dark)
    t = cols["exposure_s"]
    _check_rows(cols, lit, x if kind != "none" else None, source)
    pairs, ut, levels = _dark_levels(cols, mean, var, lit, drk, source)
    table = PtcTable(
        exposure_s=t[lit],
        photons=x[lit] if kind == "photons" else None,
        irradiance=x[lit] if kind != "none" else None,
        mean_dn=mean[lit],
        var_dn2=var[lit],
        dark_mean_dn=pairs[:, 0],
        dark_var_dn2=pairs[:, 1],
        dark_exposure_s=ut,
        dark_means_dn=levels[:, 0],
        dark_vars_dn2=levels[:, 1],
        pixels=None if pixels is None else int(pixels),
        bits=None if bits is None else int(bits),
        wavelength_nm=wavelength_nm,
        source=source,
        images=int(images),
        dark_images=int(dark_images),
        dark_mean_known=mean_known,
        irradiance_kind=kind,
        row_noise_var_dn2=float(max(row_noise_var_dn2, 0.0)),
        columns=int(columns),
    )
    _check_above_dark(table, lit)
    return table

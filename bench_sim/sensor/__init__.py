"""sensor stage: EMVA 1288 pixel model (:mod:`.emva`), DTDI accumulation (:mod:`.dtdi`) and the
streaming sensor + DTDI pass (:mod:`.pipeline`).

Data flow: mean photons per pixel per frame ``(K, M, N)`` -> :func:`expose` -> raw pixel DN ->
:class:`DTDIAccumulator` -> stage images ``{m: (lines, N)}`` in ``beta``-bit words.
"""

from bench_sim.sensor.dtdi import (
    DTDIAccumulator,
    complete_lines,
    dtdi_direct,
    frames_needed,
    full_scale_dn,
    run_dtdi,
    stage_mean_var_dn,
)
from bench_sim.sensor.emva import FixedPattern, draw_fixed_pattern, expose, pixel_mean_var_dn
from bench_sim.sensor.stream import iter_sensor_dtdi, sensor_dtdi_pass

__all__ = [
    "FixedPattern",
    "draw_fixed_pattern",
    "expose",
    "pixel_mean_var_dn",
    "DTDIAccumulator",
    "dtdi_direct",
    "run_dtdi",
    "complete_lines",
    "frames_needed",
    "full_scale_dn",
    "stage_mean_var_dn",
    "sensor_dtdi_pass",
    "iter_sensor_dtdi",
]

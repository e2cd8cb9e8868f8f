"""The fast engine's Mitsuba records, one set per light, rendered once per process and reused.

The fast engine (:class:`bench_sim.render.engines.FastEngine`) needs, for every record (one of
``subpixels x subpixels`` film samples per sensor pixel), the mean hit position on the drum and,
for every light ``l`` alone, the radiance ``S0_l`` the record sees from everything that is not
the drum's print and the radiance per unit albedo ``D_l`` the print sends it. Mitsuba renders:

1. per light, the scene under that light alone (:func:`bench_sim.rig.scene.scene_dict` with
   ``lights=[name]``) on a drum of albedo 1 -- and, for the trimesh drum, of albedo 0 (``S0``);
   on the analytic cylinder a record either hit the drum or saw the light directly, so ``S0``
   is the radiance of the records that missed it. A fill light on the analytic drum (mono)
   needs no render: its records are the fill's radiance in closed form
   (:func:`_fill_in_closed_form`);
2. the hit positions: an ``aov`` render (no light needed).

All renders use the same film, samples per pixel and sampler seed (:data:`RECORD_SEED`), so they
trace the same camera rays: positions and radiances belong to the same samples.

Reuse
    Radiance is linear in each light's power, so every light is rendered at the reference
    irradiance :data:`REFERENCE_IRRADIANCE_W_M2` and scaled by ``irradiance_w_m2 /
    REFERENCE_IRRADIANCE_W_M2`` when frames are formed; the records are per unit albedo, so the
    target pattern does not enter them either. A process-level cache keyed by everything that
    does change them (:func:`records_key`: drum, lens, sensor size and wavelength, timing,
    render settings, the lights' kinds, positions, aims and spectra, the print's finish, the
    Mitsuba variant) -- but not by a light's power, its flicker (``flicker_*``), the target
    pattern, the sensor's noise model, DTDI, fusion or the run's seed -- makes a sweep of any
    of those inside one process cost one set of Mitsuba renders. :func:`mitsuba_render_count`
    counts every ``mi.render`` call made in the process.

    Across processes (the workers of a sweep or a data set), the records of one key are made
    once by one worker and handed to the others: :func:`bench_sim.render.exposures.fast_records`
    makes them (a task of its own), :func:`install_records` puts them in the receiving process's
    cache, where the fast engine finds them as if it had rendered them. They are the same arrays
    either way (the renders use :data:`RECORD_SEED`, not the run's seed), so results do not
    depend on which process rendered them.

    Across runs, the records are also kept on disk (:mod:`bench_sim.render.record_store`:
    by default ``~/.cache/bench_sim/records``, at most 2 GiB, least recently used dropped first;
    ``BENCH_SIM_RECORD_CACHE=off`` turns it off): :func:`cached_records` looks in the process's
    cache, then on disk (a set found there joins the process's cache), and :func:`light_records`
    stores what it renders. A set from disk holds the rendered arrays byte for byte and counts
    no renders (``renders`` 0: none was made in this process), so a new process of a scene
    rendered before imports no Mitsuba for it and gives the same bytes.

The records are rendered with a fixed sampler seed, not the run's: they are the engine's
estimate of the scene's (deterministic) radiance, whose Monte Carlo error (about 1 % per pixel at
16 spp x 4 x 4 records) is a fixed error of the renderer, the same for every run of the scene.
"""

from __future__ import annotations

import json
import threading
from collections import OrderedDict
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig, config_to_toml_dict, with_overrides
from bench_sim.render import record_store
from bench_sim.rig import spectra
from bench_sim.rig.geometry import RigGeometry
from bench_sim.rig.scene import fill_radiance_w_m2_sr, light_names, scene_dict

__all__ = [
    "LightRecords",
    "REFERENCE_IRRADIANCE_W_M2",
    "RECORD_SEED",
    "render_array",
    "mitsuba_render_count",
    "light_power_w_m2",
    "reference_config",
    "records_key",
    "light_records",
    "cached_records",
    "install_records",
    "clear_record_cache",
]

#: Irradiance [W/m^2] every light is rendered at; frames scale by ``irradiance_w_m2`` / this.
REFERENCE_IRRADIANCE_W_M2 = 1.0
#: Mitsuba sampler seed of every record render (the records do not depend on the run's seed).
RECORD_SEED = 0
#: Record sets kept by the process-level cache (least recently used dropped first).
CACHE_ENTRIES = 2

#: Sensor settings that only the pixel model reads (not the renderer): not part of the key.
_SENSOR_NOISE_MODEL = frozenset({
    "full_well_e", "read_noise_e", "dark_current_e_s", "dsnu_e_s", "prnu", "column_offset_dn",
    "conversion_gain_dn_per_e", "black_offset_dn", "adc_bits", "shot_noise", "dark_noise",
    "read_noise", "prnu_enabled", "dsnu_enabled", "column_fpn", "quantization",
    "shot_noise_sampler",
})
#: Target settings the records depend on (the print's surface and spectrum, not its pattern).
_TARGET_SURFACE = frozenset({"finish", "gloss_roughness", "reflectance_spectrum"})

_lock = threading.Lock()
_renders = 0
_cache: OrderedDict[str, LightRecords] = OrderedDict()


def render_array(mi: Any, scene: Any, spp: int, seed: int) -> np.ndarray:
    """``mi.render`` as a float32 array (height, width, channels), counted by
    :func:`mitsuba_render_count`."""
    global _renders
    img = mi.render(scene, spp=spp, seed=int(seed) & 0x7FFFFFFF)
    with _lock:
        _renders += 1
    return np.array(img, dtype=np.float32)


def mitsuba_render_count() -> int:
    """Number of Mitsuba renders (``mi.render`` calls) made in this process so far."""
    return _renders


def _lights_table(cfg: BenchConfig) -> dict[str, dict[str, Any]]:
    lights = config_to_toml_dict(cfg).get("lights", {})
    return {k: v for k, v in lights.items() if isinstance(v, dict) and "irradiance_w_m2" in v}


def light_power_w_m2(cfg: BenchConfig, name: str) -> float:
    """The configured irradiance ``lights.<name>.irradiance_w_m2`` [W/m^2] of light ``name``."""
    table = _lights_table(cfg)
    if name not in table:
        raise ValueError(f"light {name!r}: not a light of this bench ({sorted(table)})")
    return float(table[name]["irradiance_w_m2"])


def reference_config(cfg: BenchConfig) -> BenchConfig:
    """``cfg`` with every light at :data:`REFERENCE_IRRADIANCE_W_M2` (enabled lights of zero
    power included, so they have records too)."""
    over = {name: {"irradiance_w_m2": REFERENCE_IRRADIANCE_W_M2} for name in _lights_table(cfg)}
    return with_overrides(cfg, {"lights": over}, source="fast engine reference lights")


def records_key(cfg: BenchConfig, variant: str) -> str:
    """Cache key of the records of ``cfg`` rendered with Mitsuba ``variant``: the resolved
    config without what the records do not depend on (see the module docstring), as JSON."""
    d = config_to_toml_dict(cfg)
    for k in ("name", "lines", "dtdi", "fusion"):
        d.pop(k, None)
    d["target"] = {k: v for k, v in d.get("target", {}).items() if k in _TARGET_SURFACE}
    d["sensor"] = {k: v for k, v in d.get("sensor", {}).items() if k not in _SENSOR_NOISE_MODEL}
    d.get("timing", {}).pop("sync_error", None)  # the drum's speed: records are at frame 0
    d.get("render", {}).pop("engine", None)
    lights = {}
    for name, light in d.get("lights", {}).items():
        if isinstance(light, dict):
            light = {
                k: v for k, v in light.items() if k != "irradiance_w_m2" and not k.startswith("flicker_")
            }
        lights[name] = light
    d["lights"] = lights
    d["variant"] = variant
    d["record_seed"] = RECORD_SEED
    sources = spectra.check_spectra(cfg)  # a measured spectrum's table (a file's SHA-256 too)
    if sources:
        d["spectrum_sources"] = sources
    return json.dumps(d, sort_keys=True)


@dataclass
class LightRecords:
    """Per-light records of one scene (see the module docstring), at the reference power.

    Attributes
    ----------
    lights
        Light names, in the order of the arrays' first axis.
    d_rec
        (L, M s, N s) float32: radiance per unit albedo [W m^-2 sr^-1] of every record under
        each light alone (``D_l``).
    static
        (L, M, N) float32: pixel-mean radiance not from the print (``S0_l``) under each light.
    position
        (M s, N s, 3) float32: mean hit position [m] of every record (0 where all samples missed).
    hit
        (M s, N s) bool: the record hit the drum.
    key
        :func:`records_key` of the scene.
    renders
        Mitsuba renders that made these records.
    derived
        Quantities derived from the records and cached with them (the engine's kernels).
    """

    lights: tuple[str, ...]
    d_rec: np.ndarray
    static: np.ndarray
    position: np.ndarray
    hit: np.ndarray
    key: str
    renders: int
    derived: dict[Any, Any] = field(default_factory=dict)

    def page_out(self) -> None:
        """Let the pages of the arrays that only the kernels read (``d_rec``, ``position``,
        ``hit``) leave this process's resident memory when they are mapped from the disk store
        (:func:`bench_sim.render.record_store.page_out`): once the kernels are made; a later set of
        kernels reads them again from the file, the same values."""
        record_store.page_out([self.d_rec, self.position, self.hit])

    def shareable(self) -> LightRecords:
        """These records without their derived quantities: the arrays (not copied) to hand to
        another process, apart from this process's cached object (whose ``derived`` changes)."""
        return replace(self, derived={})


def _fill_in_closed_form(cfg: BenchConfig, name: str) -> bool:
    """A fill light (uniform environment of radiance ``L``) on the analytic drum, rendered mono:
    the drum is convex and the only shape, so every point of it sees the whole sky above its
    tangent plane and sends ``rho L`` to the camera (a record per unit albedo: ``L``), and a
    record that misses it sees ``L``: the records are ``L`` everywhere, exactly what Mitsuba's
    cosine-weighted BSDF sampling gives sample by sample, without a render."""
    return (
        cfg.drum.geometry == "analytic" and not cfg.render.spectral and cfg.lights.get(name).kind == "fill"
    )


def _render_records(mi: Any, cfg: BenchConfig, geom: RigGeometry, key: str) -> LightRecords:
    ref = reference_config(cfg)
    M, N, ss = cfg.sensor.rows, cfg.sensor.columns, cfg.render.subpixels
    spp, spectral = cfg.render.spp, cfg.render.spectral
    count0 = mitsuba_render_count()

    printed = spectra.reflectance_dict(cfg)  # the print's spectrum (spectral mode), else grey

    def scene(albedo: float, lights: list[str], aov: bool) -> dict[str, Any]:
        refl = printed if albedo == 1.0 and printed is not None else {"type": "uniform", "value": albedo}
        return scene_dict(
            mi, ref, geom, refl, width=N * ss, height=M * ss,
            spp=spp, aov_position=aov, spectral=spectral, lights=lights,
        )

    names = light_names(ref)
    # hit positions alone: the aov integrator without an inner one traces the camera rays only
    # (cheaper than an aov output of a light's render: measured 0.8 + 1.0 s against 2.6 s)
    d = scene(1.0, [], True)
    d["integrator"] = {"type": "aov", "aovs": "pos:position"}
    position = render_array(mi, mi.load_dict(d), spp, RECORD_SEED)[..., -3:]
    hit = ~np.all(position == 0.0, axis=-1)
    d_rec = np.empty((len(names), M * ss, N * ss), dtype=np.float32)
    static = np.empty((len(names), M, N), dtype=np.float32)
    for li, name in enumerate(names):
        if _fill_in_closed_form(ref, name):
            lit = np.full((M * ss, N * ss), fill_radiance_w_m2_sr(ref, name), dtype=np.float32)
        else:
            lit = render_array(mi, mi.load_dict(scene(1.0, [name], False)), spp, RECORD_SEED)[..., 0]
        if cfg.drum.geometry == "analytic":
            # the drum is the only shape: a record either hit it (no light without its albedo)
            # or missed everything (sees the light directly, independent of the albedo)
            s0 = np.where(hit, 0.0, lit).astype(np.float32)
        else:
            s0 = render_array(mi, mi.load_dict(scene(0.0, [name], False)), spp, RECORD_SEED)[..., 0]
        d_rec[li] = lit - s0
        static[li] = s0.reshape(M, ss, N, ss).mean(axis=(1, 3))
    import drjit as dr

    dr.flush_malloc_cache()  # the renders' buffers: give them back, the pass needs none of them
    return LightRecords(
        tuple(names), d_rec, static, position, hit, key, mitsuba_render_count() - count0
    )


def light_records(mi: Any, cfg: BenchConfig, geom: RigGeometry, variant: str) -> tuple[LightRecords, bool]:
    """The records of ``cfg``'s scene: from the process-level cache or the disk store
    (:func:`cached_records`), or rendered now (and then put in both).

    Returns ``(records, rendered)``; ``rendered`` is False on a cache hit.
    """
    cached = cached_records(cfg, variant)
    if cached is not None:
        return cached, False
    rec = _render_records(mi, cfg, geom, records_key(cfg, variant))
    with _lock:
        _store(rec)
    record_store.save(rec.key, rec.lights, {name: getattr(rec, name) for name in record_store.ARRAYS})
    return rec, True


def _store(rec: LightRecords) -> None:
    """Put ``rec`` in the cache under its key, dropping the least recently used beyond
    :data:`CACHE_ENTRIES` (the caller holds ``_lock``)."""
    _cache[rec.key] = rec
    while len(_cache) > CACHE_ENTRIES:
        _cache.popitem(last=False)


def cached_records(cfg: BenchConfig, variant: str) -> LightRecords | None:
    """The records of ``cfg``'s scene for Mitsuba ``variant`` if this process's cache holds them
    (rendered here or installed) or the disk store does (:mod:`bench_sim.render.record_store`;
    such a set, of 0 renders, joins the process's cache), else ``None``; Mitsuba is not needed
    to ask."""
    key = records_key(cfg, variant)
    with _lock:
        rec = _cache.get(key)
        if rec is not None:
            _cache.move_to_end(key)
            return rec
    stored = record_store.load(key)
    if stored is None:
        return None
    with _lock:
        rec = _cache.get(key)  # another thread may have put them there meanwhile
        if rec is None:
            lights, arrays = stored
            d_rec, static, position, hit = (arrays[name] for name in record_store.ARRAYS)
            rec = LightRecords(lights, d_rec, static, position, hit, key, renders=0)
            _store(rec)
        _cache.move_to_end(key)
        return rec


def install_records(rec: LightRecords) -> bool:
    """Put records made in another process (:meth:`LightRecords.shareable`) into this process's
    cache under their key; the fast engine then finds them there. Returns False (and keeps the
    cached set) when records of that key are there already."""
    with _lock:
        if rec.key in _cache:
            _cache.move_to_end(rec.key)
            return False
        _store(rec.shareable())
    return True


def forget_records(key: str) -> None:
    """Drop the records of ``key`` (and the kernels derived from them) from this process's cache:
    the next pass of the scene reads them from the disk store, or renders them again."""
    with _lock:
        _cache.pop(key, None)


def clear_record_cache() -> None:
    """Forget every record set this process holds (the next fast-engine set-up reads them from
    the disk store, if it has them, or renders again); the disk store is left as it is."""
    with _lock:
        _cache.clear()

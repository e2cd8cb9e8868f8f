"""Configuration: pydantic models for every section of a bench, loaded from TOML.

Units are SI and carried in the field names (``_m``, ``_s``, ``_w_m2``, ``_e``, ``_dn``).
The defaults are the paper rig (``scenes/paper_rig.toml`` restates them explicitly).
Unknown keys are rejected. A TOML file may name a ``base`` file (relative to itself) whose
values it overrides, which is how the lighting presets in ``scenes/`` are built.

Errors are raised as :class:`ConfigError` with one line naming the file, the key, the value and
what is allowed. Every float of every section must be finite (``inf``/``nan`` are refused by the
base section model, so sections added later are covered too); combinations the physics cannot
mean are refused (:meth:`BenchConfig._cross`), and odd-but-legal ones are reported by
:func:`config_warnings` (issued as :class:`~bench_sim.errors.ConfigWarning` when a user's config
is loaded: :func:`load_config`, :func:`warn_config`), with the numbers.

Modules
-------
:mod:`~bench_sim.config.schema`
    The section models (rig, sensor, timing, DTDI, rendering, fusion) and their closed forms.
:mod:`~bench_sim.config.lighting`
    The lights.
:mod:`~bench_sim.config.bench`
    :class:`BenchConfig`, its physics cross-checks and :func:`config_warnings`.
:mod:`~bench_sim.config.variants`
    The Mitsuba variant names ``render.variant`` may take.
:mod:`~bench_sim.config.loading`
    The one TOML reader, ``base`` chains, overrides and the one pydantic error formatter
    (shared with the sweep and dataset specs).
:mod:`~bench_sim.config.serialise`
    A config as a dict, as TOML text and its SHA-256.
:mod:`~bench_sim.config.presets`
    The ``--quick`` preset.
"""

from __future__ import annotations

from bench_sim.config.bench import BenchConfig, config_warnings
from bench_sim.config.lighting import (
    BUILTIN_LIGHT_SPECTRA,
    FLICKER_WAVEFORMS,
    LIGHT_KINDS,
    AreaLightConfig,
    DirectionalLightConfig,
    FillLightConfig,
    LightConfig,
    LightsConfig,
    PointLightConfig,
    SpotLightConfig,
)
from bench_sim.config.loading import (
    DEFAULT_CONFIG_PATH,
    SCENES_DIR,
    ConfigError,
    config_from_dict,
    load_config,
    read_toml,
    validate_model,
    validation_line,
    warn_config,
    with_overrides,
)
from bench_sim.config.presets import QUICK_OVERRIDES, quick_config
from bench_sim.config.schema import (
    BETA_BITS_MAX,
    BETA_BITS_MIN,
    DrumConfig,
    DTDIConfig,
    EffectEntry,
    FusionConfig,
    LensConfig,
    RenderConfig,
    SensorConfig,
    TargetConfig,
    TimingConfig,
    word_full_scale_dn,
    word_top_dn,
)
from bench_sim.config.serialise import config_sha256, config_to_toml_dict, config_to_toml_text
from bench_sim.config.variants import check_variant_name

__all__ = [
    "ConfigError",
    "DrumConfig",
    "LensConfig",
    "TargetConfig",
    "SpotLightConfig",
    "FillLightConfig",
    "DirectionalLightConfig",
    "PointLightConfig",
    "AreaLightConfig",
    "LightConfig",
    "LightsConfig",
    "LIGHT_KINDS",
    "BUILTIN_LIGHT_SPECTRA",
    "FLICKER_WAVEFORMS",
    "EffectEntry",
    "SensorConfig",
    "TimingConfig",
    "DTDIConfig",
    "RenderConfig",
    "FusionConfig",
    "BenchConfig",
    "DEFAULT_CONFIG_PATH",
    "SCENES_DIR",
    "BETA_BITS_MIN",
    "BETA_BITS_MAX",
    "load_config",
    "config_from_dict",
    "with_overrides",
    "config_to_toml_dict",
    "config_sha256",
    "config_to_toml_text",
    "config_warnings",
    "warn_config",
    "read_toml",
    "validation_line",
    "validate_model",
    "QUICK_OVERRIDES",
    "quick_config",
    "word_full_scale_dn",
    "word_top_dn",
    "check_variant_name",
]

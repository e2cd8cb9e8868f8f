"""Reading configs and specs: the one TOML reader, ``base`` chains, overrides, and the one
formatter of pydantic errors.

Every TOML file the project reads (bench configs, sweep specs, dataset specs) goes through
:func:`read_toml`: a folder, a missing file, an unreadable file, text that is not UTF-8, NUL
bytes or invalid TOML is one line naming the file. A config file may name a ``base`` file
(relative to itself) whose values it overrides, which is how the lighting presets in
``scenes/`` are built. Every model (the config and both specs) is validated by
:func:`validate_model`, whose errors are one line naming the key path, the value and what is
allowed (:func:`validation_line`).

A user's config is checked for odd-but-legal settings when it is loaded (:func:`load_config`,
:func:`warn_config`: each line of :func:`~bench_sim.config.bench.config_warnings` issued as a
:class:`~bench_sim.errors.ConfigWarning`).
"""

from __future__ import annotations

import difflib
import tomllib
import typing
import warnings
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from bench_sim.config.bench import BenchConfig, config_warnings
from bench_sim.config.lighting import LIGHT_KINDS, LightConfig
from bench_sim.config.plausible import plausibility_error
from bench_sim.config.serialise import config_to_toml_dict
from bench_sim.errors import BenchSimError, ConfigWarning
from bench_sim.io.input_files import input_file_problem

__all__ = [
    "SCENES_DIR",
    "DEFAULT_CONFIG_PATH",
    "ConfigError",
    "read_toml",
    "validation_line",
    "validate_model",
    "config_from_dict",
    "warn_config",
    "load_config",
    "with_overrides",
]

#: The scenes shipped inside the package (``scenes/`` in a source checkout links here).
SCENES_DIR = Path(__file__).resolve().parents[1] / "scenes"
DEFAULT_CONFIG_PATH = SCENES_DIR / "paper_rig.toml"

#: What an unknown key of a config section is told.
UNKNOWN_CONFIG_KEY = "not a setting of this section"

M = TypeVar("M", bound=BaseModel)


class ConfigError(BenchSimError):
    """A bad configuration: the message is one line naming file, key, value and what is allowed."""


def read_toml(path: Path, label: str, what: str = "a config") -> dict[str, Any]:
    """Parse the TOML file ``path`` (UTF-8 text).

    Parameters
    ----------
    path
        The file.
    label
        Start of every error message, naming the file (``config error: PATH``,
        ``sweep spec PATH``, ...); the message is ``label: problem``.
    what
        What the file is, for the messages about its encoding (``a config``, ``a sweep spec``).

    Raises
    ------
    ConfigError
        One line: no such file, a folder or a special file (a FIFO, a device), unreadable, not
        UTF-8, NUL bytes or not valid TOML.
    """
    problem = input_file_problem(path)  # missing, a folder, a FIFO or device (never opened)
    if problem is not None:
        raise ConfigError(f"{label}: {problem}")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{label}: cannot read it ({exc.strerror})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{label}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start}); "
            f"{what} is a TOML text file in UTF-8"
        ) from None
    if "\x00" in text:
        raise ConfigError(f"{label}: holds NUL bytes (a binary file?); {what} is TOML text")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{label}: not valid TOML ({' '.join(str(exc).split())})") from None


def _format_loc(loc: tuple[int | str, ...]) -> str:
    """``('lights', 'strong', 'spot', 'position_m', 0)`` -> ``lights.strong.position_m[0]``."""
    parts = [p for p in loc if not (isinstance(p, str) and p.startswith("function-"))]
    if len(parts) > 2 and parts[0] == "lights" and parts[2] in LIGHT_KINDS:
        del parts[2]  # the union's tag (the light's kind) is not a key of the file
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else p)
    return out


def _lookup(data: Any, loc: tuple[int | str, ...]) -> Any:
    cur = data
    for part in loc:
        if isinstance(cur, dict) and part in cur:
            cur = cur[part]
        elif isinstance(cur, list | tuple) and isinstance(part, int) and part < len(cur):
            cur = cur[part]
        else:
            return None
    return cur


def _model_in(annotation: Any) -> type[BaseModel] | None:
    """The pydantic model an annotation names (``X``, ``X | None``), else ``None``."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        if isinstance(arg, type) and issubclass(arg, BaseModel):
            return arg
    return None


#: the model of each light kind (the tag pydantic puts in the location of a light's error)
_LIGHT_MODELS: dict[str, type[BaseModel]] = {
    m.model_fields["kind"].default: m for m in typing.get_args(LightConfig)
}


def _did_you_mean(model: type[BaseModel] | None, loc: tuple[int | str, ...]) -> str:
    """``; did you mean 'pixel_pitch_m'?`` for the unknown key at ``loc`` of ``model`` (the
    closest field name of its table, :func:`difflib.get_close_matches`), else empty."""
    cur: type[BaseModel] | None = model
    for part in loc[:-1]:
        if cur is None or not isinstance(part, str):
            return ""
        if part in cur.model_fields:
            cur = _model_in(cur.model_fields[part].annotation)
        elif part in _LIGHT_MODELS:
            cur = _LIGHT_MODELS[part]
        elif cur.model_config.get("extra") != "allow":
            return ""
    if cur is None or not loc or not isinstance(loc[-1], str):
        return ""
    close = difflib.get_close_matches(loc[-1], list(cur.model_fields), n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


def validation_line(
    exc: ValidationError,
    data: Any,
    prefix: str = "",
    unknown: str = UNKNOWN_CONFIG_KEY,
    model: type[BaseModel] | None = None,
) -> str:
    """The first error of ``exc`` as one line: ``key = value: message``.

    Parameters
    ----------
    exc
        The error of validating ``data``.
    data
        What was validated (to show a value pydantic does not report).
    prefix
        Dotted key of ``data`` in its file (``randomize.lens.f_number``), put before the key.
    unknown
        What an unknown key is told (``allowed: a, b, c``).
    model
        The model validated: an unknown key is then told the closest key of its table
        (``did you mean 'pixel_pitch_m'?``).

    Returns
    -------
    str
        ``unknown key 'KEY' (unknown)``, ``KEY: missing (required)``, ``KEY = VALUE: message``,
        or ``KEY: message`` for a check of a whole table (its own message names the fields).
    """
    err = exc.errors(include_url=False)[0]
    loc = tuple(err.get("loc", ()))
    where = _format_loc(loc)
    key = f"{prefix}{where}" if where.startswith("[") else ".".join(p for p in (prefix, where) if p)
    kind = err.get("type")
    if kind == "extra_forbidden":
        return f"unknown key '{key}' ({unknown}{_did_you_mean(model, loc)})"
    if kind == "missing":
        return f"{key}: missing (required)"
    msg = " ".join(str(err.get("msg", "invalid")).removeprefix("Value error, ").split())
    value = err.get("input") if loc else None
    if loc and value is None:
        value = _lookup(data, loc)
    if isinstance(value, dict) or not loc:
        return f"{key or '(top level)'}: {msg}" if loc or prefix else msg
    shown = repr(value)
    if len(shown) > 60:
        shown = shown[:40] + "..." + shown[-12:]
    return f"{key} = {shown}: {msg}"


def validate_model(
    model: type[M], data: Any, label: str, prefix: str = "", unknown: str = UNKNOWN_CONFIG_KEY
) -> M:
    """``model.model_validate(data)``, its error as one :class:`ConfigError` line
    ``label: key = value: message`` (:func:`validation_line`)."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(f"{label}: {validation_line(exc, data, prefix, unknown, model)}") from None


def _deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _deep_merge(out[k], v)
        else:
            out[k] = v
    return out


#: ``(section, key)`` of the keys that name a file, resolved against the config file naming them
FILE_KEYS = (("target", "image"), ("lens", "mtf_file"), ("lens", "psf_file"))
#: ``(section, key)`` of the keys that may name a spectrum's file as ``csv:FILE`` (``lights``: every
#: light's ``spectrum``)
SPECTRUM_FILE_KEYS = (("target", "reflectance_spectrum"), ("sensor", "qe_spectrum"), ("lights", "spectrum"))


def _resolve_files(data: dict[str, Any], folder: Path) -> None:
    """The file names of ``data`` (:data:`FILE_KEYS`, :data:`SPECTRUM_FILE_KEYS`) made absolute
    against ``folder``, the config file's, in place."""
    tables: list[tuple[dict[str, Any], str, bool]] = []
    for section, key in (*((s, k) for s, k in FILE_KEYS), *SPECTRUM_FILE_KEYS):
        table = data.get(section)
        if not isinstance(table, dict):
            continue
        csv = (section, key) in SPECTRUM_FILE_KEYS
        if section == "lights":
            tables += [(t, key, True) for t in table.values() if isinstance(t, dict)]
        else:
            tables.append((table, key, csv))
    for table, key, csv in tables:
        name = table.get(key)
        if not isinstance(name, str) or not name:
            continue
        prefix = "csv:" if csv else ""
        if csv and not name.startswith(prefix):
            continue
        file = name[len(prefix):].strip()
        if file and not Path(file).is_absolute():
            table[key] = prefix + str((folder / file).resolve())
#: keys of a sensor effect that name a file (relative to the config that writes them)
EFFECT_FILE_KEYS = ("table", "map_file")


def _resolve_effect_files(data: dict[str, Any], folder: Path) -> None:
    """The files a config's sensor effects name (a response table, a defect map, a plug-in's
    ``file.py:function``), made absolute against ``folder`` (the config's own)."""
    effects = data.get("sensor", {}).get("effects") if isinstance(data.get("sensor"), dict) else None
    for entry in (effects or {}).values() if isinstance(effects, dict) else ():
        if not isinstance(entry, dict):
            continue
        for key in EFFECT_FILE_KEYS:
            if isinstance(entry.get(key), str) and entry[key] and not Path(entry[key]).is_absolute():
                entry[key] = str((folder / entry[key]).resolve())
        fn = entry.get("function")
        if isinstance(fn, str) and ".py:" in fn:
            file, _, name = fn.rpartition(":")
            if not Path(file).is_absolute():
                entry["function"] = f"{(folder / file).resolve()}:{name}"


def _read_config_file(path: Path, chain: tuple[Path, ...] = ()) -> dict[str, Any]:
    """A config file's settings, merged over its ``base`` chain; the file keys (:data:`FILE_KEYS`)
    resolved against the file that names them."""
    if path in chain:
        raise ConfigError(f"config error: {path}: 'base' chain loops back to itself")
    data = read_toml(path, f"config error: {path}")
    _resolve_files(data, path.parent)
    _resolve_effect_files(data, path.parent)
    base = data.pop("base", None)
    if base is None:
        return data
    if not isinstance(base, str):
        raise ConfigError(f"config error: {path}: base = {base!r}: must be a file name string")
    base_data = _read_config_file((path.parent / base).resolve(), (*chain, path))
    return _deep_merge(base_data, data)


def config_from_dict(data: dict[str, Any], source: str = "<dict>", *, warn: bool = False) -> BenchConfig:
    """Validate a plain dict (as parsed from TOML) into a :class:`BenchConfig`.

    With ``warn``, each line of :func:`config_warnings` is issued as a
    :class:`~bench_sim.errors.ConfigWarning` (a user's config; not the configs the code derives).
    """
    if not isinstance(data, dict):
        raise ConfigError(f"config error: {source}: expected a table of settings, got {type(data).__name__}")
    slip = plausibility_error(data)  # before the cross-checks, so a slip is named as itself
    if slip:
        raise ConfigError(f"config error: {source}: {slip}")
    cfg = validate_model(BenchConfig, data, f"config error: {source}")
    if warn:
        warn_config(cfg, source)
    return cfg


def warn_config(cfg: BenchConfig, source: str) -> None:
    """Issue each line of :func:`config_warnings` as a :class:`~bench_sim.errors.ConfigWarning`
    (``source``: the file or argument the config came from)."""
    for line in config_warnings(cfg):
        warnings.warn(f"{source}: {line}", ConfigWarning, stacklevel=3)


def load_config(path: str | Path | None = None) -> BenchConfig:
    """Load and validate a bench config from TOML (default: ``scenes/paper_rig.toml``); its odd
    but legal settings are warned about (:func:`config_warnings`), and so is a file with no
    settings at all (it runs the defaults, the paper rig)."""
    p = Path(path) if path is not None else DEFAULT_CONFIG_PATH
    p = p.resolve()
    data = _read_config_file(p)
    if not data:  # an empty file (or comments only): legal, but say what it runs
        warnings.warn(
            f"{p}: no settings (an empty file): it runs the defaults, the paper rig "
            f"({DEFAULT_CONFIG_PATH.name})", ConfigWarning, stacklevel=2,
        )
    return config_from_dict(data, source=str(p), warn=True)


def with_overrides(cfg: BenchConfig, overrides: dict[str, Any], source: str = "<overrides>") -> BenchConfig:
    """A copy of ``cfg`` with the (nested) keys of ``overrides`` replaced, validated again."""
    return config_from_dict(_deep_merge(config_to_toml_dict(cfg), overrides), source=source)

"""``bench-sim config keys`` lists every key of the schema, with its default and bounds.

The listing is compared with the config's JSON schema (pydantic's own export, a path
independent of the model walk that makes the listing), and each listed default is put back into
a config to check it is the default.
"""

from __future__ import annotations

import tomllib
from typing import Any

import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import BenchConfig, config_from_dict, config_to_toml_dict
from bench_sim.config.catalogue import config_keys, unit_of
from bench_sim.workflows.config_cmd import effect_keys

runner = CliRunner()


def _schema_leaves() -> dict[str, dict[str, Any]]:
    """Every leaf key of BenchConfig's JSON schema (lights of another name once per kind)."""
    schema = BenchConfig.model_json_schema()
    defs = schema["$defs"]

    def resolve(node: dict[str, Any]) -> dict[str, Any]:
        return defs[node["$ref"].split("/")[-1]] if "$ref" in node else node

    out: dict[str, dict[str, Any]] = {}

    def walk(node: dict[str, Any], prefix: str) -> None:
        for name, prop in node.get("properties", {}).items():
            sub = resolve(prop)
            if "properties" in sub:
                walk(sub, f"{prefix}{name}.")
                extra = sub.get("additionalProperties")
                if isinstance(extra, dict) and "discriminator" in extra:
                    for kind, ref in extra["discriminator"]["mapping"].items():
                        walk(defs[ref.split("/")[-1]], f"{prefix}{name}.<name>[kind={kind}].")
            else:
                out[f"{prefix}{name}"] = prop

    walk(schema, "")
    return out


def test_config_keys_lists_every_key_of_the_schema() -> None:
    listed = {k.key for k in config_keys()}
    schema = set(_schema_leaves())
    assert listed == schema, (sorted(schema - listed), sorted(listed - schema))


def test_cli_listing_holds_every_key_and_unit() -> None:
    r = runner.invoke(app, ["config", "keys"])
    assert r.exit_code == 0, r.stderr
    heads = [ln.split("  ")[0] for ln in r.stdout.splitlines() if not ln.startswith(" ")]
    assert heads == [k.key for k in config_keys()] + [k.key for k in effect_keys()]
    assert "timing.line_period_s  float [s] = 0.0001" in r.stdout
    assert "sensor.full_well_e  float [e-] = 13500" in r.stdout


def test_bounds_match_the_schema() -> None:
    leaves = _schema_leaves()
    names = {"minimum": ">=", "exclusiveMinimum": ">", "maximum": "<=", "exclusiveMaximum": "<"}
    for k in config_keys():
        prop = leaves[k.key]
        options = [prop, *prop.get("anyOf", [])]
        for node in options:
            for word, op in names.items():
                if word in node:
                    assert f"{op} {node[word]:g}" in k.allowed, (k.key, k.allowed, node)


@pytest.mark.parametrize("section", ["drum", "lens", "target", "sensor", "timing", "dtdi", "render", "fusion",
                                     "lights.strong", "lights.weak"])
def test_listed_defaults_are_the_defaults(section: str) -> None:
    """Writing each listed default back (parsed as TOML) gives the default config."""
    default = config_to_toml_dict(BenchConfig())
    for k in config_keys(section):
        if k.default in ("(unset)", "(required)"):
            assert k.key.split(".")[-1] not in _dig(default, k.key), k.key
            continue
        value = tomllib.loads(f"v = {k.default}")["v"]
        data: dict[str, Any] = {}
        node = data
        *parents, leaf = k.key.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
        got = config_to_toml_dict(config_from_dict(data))
        assert got == default, k.key


def _dig(d: dict[str, Any], key: str) -> dict[str, Any]:
    for p in key.split(".")[:-1]:
        d = d[p]
    return d


def test_units_come_from_the_names() -> None:
    assert [unit_of(n) for n in ("line_period_s", "irradiance_w_m2", "dark_current_e_s", "full_well_e",
                                 "conversion_gain_dn_per_e", "flicker_hz", "rows", "mesh_segments")] == [
        "s", "W/m^2", "e-/s", "e-", "DN/e-", "Hz", "", ""]


def test_section_filter_and_unknown_section() -> None:
    assert all(k.key.startswith("timing.") for k in config_keys("timing"))
    r = runner.invoke(app, ["config", "keys", "sensr"])
    assert r.exit_code == 2 and "did you mean 'sensor'?" in r.stderr

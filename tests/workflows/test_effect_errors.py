"""A bad sensor effect fails early (issue 33): an import error, a wrong signature, shape or dtype,
NaN, negative electrons, a response declared monotone that is not (or draws random numbers), a
truth declared at the wrong point, an unknown kind or key, a unit slip -- each is ONE line
``bench-sim: error:`` naming ``sensor.effects.<name>`` and what is wrong, exit status 2, before
any rendering (the renderer's entry point and Dask's cluster are replaced by ones that fail the
test) and with nothing written, from every command that reads a config."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

import bench_sim.pipeline.one_pass
import bench_sim.render.exposures
from bench_sim.cli import app
from bench_sim.config import DEFAULT_CONFIG_PATH

runner = CliRunner()

BASE = (
    f"base = '{DEFAULT_CONFIG_PATH}'\nlines = 600\n"
    "[sensor]\nrows = 12\ncolumns = 48\n[target]\npanel_lines = 256\npanel_columns = 48\n"
    "[render]\nspp = 4\n[fusion]\nmu1 = 2\nmu2 = 8\n"
)

#: the user's functions: each breaks the contract in one way
USER = '''
import numpy as np

def gamma(e, *, rng, gamma=0.9):
    return 13500.0 * (e / 13500.0) ** gamma

def two_arrays(e, other):
    return e

def no_rng(e):
    return e

def first_column(e, *, rng):
    return e[..., :1]

def complex_out(e, *, rng):
    return e.astype(complex)

def object_out(e, *, rng):
    return e.astype(object)

def a_list(e, *, rng):
    return e.tolist()

def nan_out(e, *, rng):
    e = e.copy()
    e.flat[5] = np.nan
    return e

def negative(e, *, rng):
    return e - 500.0

def falls(e, *, rng):
    return np.where(e < 8000.0, e, 16000.0 - e)

def random_response(e, *, rng):
    return e + rng.uniform(0.0, 1.0, e.shape)

def raises(e, *, rng):
    raise ValueError("the lookup table is empty")
'''


def _plugin(function: str, point: str = "charge", truth: str = "monotone", args: str = "") -> str:
    return (f'[sensor.effects.mine]\nkind = "plugin"\nfunction = "{function}"\npoint = "{point}"\n'
            f'truth = "{truth}"\n' + (f"args = {{ {args} }}\n" if args else ""))


#: (id, the effect's TOML, what the one line says)
CASES = [
    ("missing file", _plugin("nowhere.py:gamma"), "sensor.effects.mine.function", "no such file"),
    ("syntax error", _plugin("broken.py:gamma"), "sensor.effects.mine.function", "SyntaxError"),
    ("module raises", _plugin("raising.py:gamma"), "sensor.effects.mine.function",
     "RuntimeError: no licence"),
    ("no such function", _plugin("user.py:gama"), "sensor.effects.mine.function", "has no function 'gama'"),
    ("no such module", _plugin("no_such_package.effects:gamma"), "sensor.effects.mine.function",
     "ModuleNotFoundError"),
    ("not a path", _plugin("user.py"), "sensor.effects.mine.function", "expected 'path/to/file.py:function'"),
    ("two arrays", _plugin("user.py:two_arrays"), "sensor.effects.mine.function", "wrong signature"),
    ("no rng", _plugin("user.py:no_rng"), "sensor.effects.mine.function", "wrong signature"),
    ("unknown arg", _plugin("user.py:gamma", args="gama = 0.8"), "sensor.effects.mine.function",
     "unexpected keyword argument 'gama'"),
    ("wrong shape", _plugin("user.py:first_column", truth="none"), "sensor.effects.mine",
     "it must keep the shape"),
    ("complex", _plugin("user.py:complex_out", truth="none"), "sensor.effects.mine", "dtype complex128"),
    ("object", _plugin("user.py:object_out", truth="none"), "sensor.effects.mine", "dtype object"),
    ("a list", _plugin("user.py:a_list", point="digital", truth="none"), "sensor.effects.mine",
     "returned list, expected a numpy array"),
    ("nan", _plugin("user.py:nan_out", point="analog", truth="none"), "sensor.effects.mine", "NaN"),
    ("negative electrons", _plugin("user.py:negative", truth="none"), "sensor.effects.mine",
     "negative electrons"),
    ("raises", _plugin("user.py:raises", truth="none"), "sensor.effects.mine",
     "ValueError: the lookup table is empty"),
    ("falls", _plugin("user.py:falls"), "sensor.effects.mine", "the response falls after"),
    ("random but monotone", _plugin("user.py:random_response"), "sensor.effects.mine",
     "two calls on the same charge differ"),
    ("monotone at analog", _plugin("user.py:gamma", point="analog"), "sensor.effects.mine.truth",
     "only a response of the charge"),
    ("unknown kind", '[sensor.effects.mine]\nkind = "nonlinearty"\n', "sensor.effects.mine.kind",
     "did you mean 'nonlinearity'?"),
    ("unknown key", '[sensor.effects.mine]\nkind = "nonlinearity"\ncompresion = 0.1\n',
     "sensor.effects.mine.compresion", "did you mean 'compression'?"),
    ("unit slip", '[sensor.effects.mine]\nkind = "nonlinearity"\nknee_e = 9e9\n',
     "sensor.effects.mine.knee_e", "a unit slip?"),
    ("falling polynomial", '[sensor.effects.mine]\nkind = "nonlinearity"\nform = "polynomial"\n'
     "coefficients = [-0.8]\n", "sensor.effects.mine.coefficients", "must be monotone"),
    ("bad name", '[sensor.effects.Mine]\nkind = "row_noise"\n', "sensor.effects.Mine",
     "lower-case identifier"),
]


@pytest.fixture
def folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The user's files and the tiny bench; rendering or starting a cluster fails the test."""
    (tmp_path / "base.toml").write_text(BASE)
    (tmp_path / "user.py").write_text(USER)
    (tmp_path / "broken.py").write_text("def gamma(e, *, rng:\n    return e\n")
    (tmp_path / "raising.py").write_text("raise RuntimeError('no licence for this sensor')\n")

    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError("rendering or a cluster started before the effect was checked")

    monkeypatch.setattr(bench_sim.render.exposures, "prepare", never)
    monkeypatch.setattr(bench_sim.pipeline.one_pass, "prepare", never)
    import distributed

    monkeypatch.setattr(distributed.LocalCluster, "__init__", never)
    return tmp_path


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*") if "__pycache__" not in p.parts}


def _write(folder: Path, effect: str) -> dict[str, Path]:
    """The bench with ``effect``, and a sweep and a data set over it."""
    cfg = folder / "bench.toml"
    cfg.write_text("base = 'base.toml'\n" + effect)
    sweep = folder / "sweep.toml"
    sweep.write_text('base = "bench.toml"\n[[parameters]]\nkey = "lights.weak.irradiance_w_m2"\n'
                     "values = [3.0, 6.0]\n")
    data = folder / "data.toml"
    data.write_text('base = "bench.toml"\nsamples = 2\nseed = 1\nstages = [2, 8]\nlines = 8\ncolumns = 48\n'
                    '[randomize]\n"lights.weak.irradiance_w_m2" = '
                    '{ dist = "uniform", low = 2.0, high = 12.0 }\n')
    return {"config": cfg, "sweep": sweep, "dataset": data}


def _commands(paths: dict[str, Path], out: Path) -> dict[str, list[str]]:
    cfg = str(paths["config"])
    return {
        "simulate": ["simulate", cfg, "--out", str(out), "--stages", "2,8"],
        "sweep": ["sweep", str(paths["sweep"]), "--out", str(out), "--workers", "2"],
        "dataset": ["dataset", str(paths["dataset"]), "--out", str(out), "--workers", "2"],
        "reproduce": ["reproduce", cfg, "--out", str(out), "--quick"],
        "ptc": ["ptc", cfg, "--out", str(out), "--stages", "1,2"],
        "config show": ["config", "show", cfg],
    }


def assert_one_line(result: object, *needles: str) -> None:
    err = result.stderr  # type: ignore[attr-defined]
    assert result.exit_code == 2, (result.exit_code, err[-2000:])  # type: ignore[attr-defined]
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("bench-sim: error: "), err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


@pytest.mark.parametrize(("where", "message"), [c[2:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_bad_effect_is_one_line_from_simulate(folder, where, message):
    effect = next(c[1] for c in CASES if c[2:] == (where, message))
    paths = _write(folder, effect)
    before = _files(folder)
    result = runner.invoke(app, _commands(paths, folder / "out")["simulate"])
    assert_one_line(result, where, message)
    assert _files(folder) == before, "files were left behind"


@pytest.mark.parametrize("command", ["sweep", "dataset", "reproduce", "ptc", "config show"])
@pytest.mark.parametrize("case", ["missing file", "falls", "unit slip"])
def test_every_command_refuses_a_bad_effect_before_it_starts(folder, command, case):
    """The same line from every command that reads a config; the sweep and the data set with
    ``--workers 2`` start no cluster."""
    _, effect, where, message = next(c for c in CASES if c[0] == case)
    paths = _write(folder, effect)
    before = _files(folder)
    result = runner.invoke(app, _commands(paths, folder / "out")[command])
    assert_one_line(result, where, message)
    assert _files(folder) == before, "files were left behind"


def test_a_good_effect_passes_the_same_checks(folder):
    """The user's gamma curve passes ``config show`` (the checks are not over-eager)."""
    paths = _write(folder, _plugin("user.py:gamma", args="gamma = 0.8"))
    result = runner.invoke(app, ["config", "show", str(paths["config"])])
    assert result.exit_code == 0, result.stderr
    assert "user.py:gamma" in result.stdout


KNEE = '[sensor.effects.knee]\nkind = "nonlinearity"\ncompression = 0.05\n'


@pytest.mark.parametrize(("key", "values", "needles"), [
    ("sensor.effects.knee.knee_e", "[4000.0, 9e9]", ("point 1", "sensor.effects.knee.knee_e = 9000000000.0",
                                                      "a unit slip?")),
    ("sensor.effects.knee.compresion", "[0.1, 0.2]",
     ("key 'sensor.effects.knee.compresion': not a setting",)),
    ("sensor.effects.other.compression", "[0.1, 0.2]", ("key 'sensor.effects.other.compression'",)),
    ("sensor.effects.knee.compression", "[0.1, 1.5]", ("point 1", "sensor.effects.knee.compression")),
])
def test_a_sweep_of_a_bad_effect_value_is_one_line(folder, key, values, needles):
    """A point that sets an effect's parameter out of range (or a key no effect has) is refused
    with the spec, before any point runs."""
    paths = _write(folder, KNEE)
    paths["sweep"].write_text(f'base = "bench.toml"\n[[parameters]]\nkey = "{key}"\nvalues = {values}\n')
    before = _files(folder)
    assert_one_line(runner.invoke(app, _commands(paths, folder / "out")["sweep"]), *needles)
    assert _files(folder) == before


@pytest.mark.parametrize(("entry", "needles"), [
    ('"sensor.effects.knee.compresion" = { dist = "uniform", low = 0.01, high = 0.1 }',
     ("sensor.effects.knee.compresion", "did you mean 'compression'?")),
    ('"sensor.effects.knee.knee_e" = { dist = "loguniform", low = 1000.0, high = 5e9 }',
     ("sensor.effects.knee.knee_e", "a unit slip?")),
])
def test_a_data_set_randomising_a_bad_effect_value_is_one_line(folder, entry, needles):
    paths = _write(folder, KNEE)
    head = paths["dataset"].read_text().split("[randomize]")[0].replace("samples = 2", "samples = 8")
    paths["dataset"].write_text(head + "[randomize]\n" + entry + "\n")
    before = _files(folder)
    assert_one_line(runner.invoke(app, _commands(paths, folder / "out")["dataset"]), *needles)
    assert _files(folder) == before


def test_a_sweep_spec_reaches_every_parameter_of_an_effect(folder):
    """Dotted keys into ``sensor.effects``: a parameter the base leaves at its default, a plug-in's
    ``args`` entry and ``enabled``; each point's config holds its value (checked, not run)."""
    from bench_sim.sensor.effects.chain import sensor_chain
    from bench_sim.workflows.sweep.spec import load_spec

    paths = _write(folder, KNEE + _plugin("user.py:gamma", args="gamma = 0.8").replace("mine", "g"))
    paths["sweep"].write_text(
        'base = "bench.toml"\nmode = "sequential"\n'
        '[[parameters]]\nkey = "sensor.effects.knee.knee_e"\nvalues = [3000.0, 5000.0]\n'
        '[[parameters]]\nkey = "sensor.effects.g.args.gamma"\nvalues = [0.7, 0.95]\n'
        '[[parameters]]\nkey = "sensor.effects.knee.enabled"\nvalues = [false]\n')
    spec = load_spec(paths["sweep"])
    effects = [p.cfg.sensor.effects for p in spec.points]
    assert [e["knee"].model_extra.get("knee_e") for e in effects[:2]] == [3000.0, 5000.0]
    assert [e["g"].model_extra["args"]["gamma"] for e in effects[2:4]] == [0.7, 0.95]
    assert effects[4]["knee"].enabled is False
    assert [len(sensor_chain(p.cfg.sensor).effects) for p in spec.points] == [2, 2, 2, 2, 1]

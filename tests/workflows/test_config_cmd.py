"""``bench-sim config show`` and ``bench-sim init``."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import SCENES_DIR, config_sha256, load_config
from bench_sim.workflows.dataset import spec as dataset_spec
from bench_sim.workflows.design import spec as design_spec
from bench_sim.workflows.sweep import spec as sweep_spec

runner = CliRunner()


def test_show_resolves_the_base_chain_and_loads_back(tmp_path: Path) -> None:
    r = runner.invoke(app, ["config", "show", str(SCENES_DIR / "scenarios" / "dusk.toml")])
    assert r.exit_code == 0, r.stderr
    assert "base" not in r.stdout.split("\n", 1)[1]  # resolved: no chain left
    resolved = tmp_path / "resolved.toml"
    resolved.write_text(r.stdout)
    dusk = load_config(SCENES_DIR / "scenarios" / "dusk.toml")
    assert config_sha256(load_config(resolved)) == config_sha256(dusk)


def test_show_refuses_a_bad_config_in_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[fusion]\nmu1 = 80\nmu2 = 10\n")
    r = runner.invoke(app, ["config", "show", str(bad)])
    assert r.exit_code == 2 and r.stdout == "" and len(r.stderr.splitlines()) == 1


def test_init_copies_the_examples_and_their_relative_paths_work(tmp_path: Path) -> None:
    start = tmp_path / "a" / "start"
    r = runner.invoke(app, ["init", str(start)])
    assert r.exit_code == 0, r.stderr
    shipped = sorted(p.relative_to(SCENES_DIR) for p in SCENES_DIR.rglob("*")
                     if p.is_file() and "__pycache__" not in p.parts)
    copied = sorted(p.relative_to(start) for p in start.rglob("*") if p.is_file())
    assert copied == shipped
    assert (start / "paper_rig.toml").read_bytes() == (SCENES_DIR / "paper_rig.toml").read_bytes()
    # the copies resolve their bases and images inside the new folder, not the package
    for path in [start / "weak.toml", start / "camera.toml", *sorted((start / "scenarios").glob("*.toml"))]:
        assert load_config(path).name
    assert str(start) in str(load_config(start / "camera.toml").target.image)
    sweep_spec.load_spec(start / "sweeps" / "light_ratio_beta.toml")
    ds = dataset_spec.load_spec(start / "datasets" / "example.toml")
    assert ds is not None
    design = design_spec.load_design_spec(start / "designs" / "example.toml")
    assert design.base.name == "paper_rig" and design.reference == (10, 80)
    assert not [p for p in start.parent.iterdir() if p.name.startswith(".")]  # no temporaries left


def test_init_refuses_a_folder_that_is_not_empty(tmp_path: Path) -> None:
    (tmp_path / "mine.toml").write_text("# mine\n")
    r = runner.invoke(app, ["init", str(tmp_path)])
    assert r.exit_code == 2 and "not empty" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.toml"]
    f = tmp_path / "file"
    f.write_text("x")
    r = runner.invoke(app, ["init", str(f)])
    assert r.exit_code == 2 and "is a file" in r.stderr

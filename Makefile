# The two commands of the README: `make reproduce` (main job) and `make test` (test suite).
# Both set up what is missing first (libllvm19, .venv, the package), see scripts/setup.sh.
VENV := .venv
PY := $(VENV)/bin/python

.PHONY: setup reproduce sweep-example test install-check lint bench clean

.setup-stamp: pyproject.toml scripts/setup.sh
	bash scripts/setup.sh
	@touch .setup-stamp

setup: .setup-stamp

reproduce: setup
	$(VENV)/bin/bench-sim reproduce

# The committed example sweep (README): spot/fill ratio x output word, results/sweeps/light_ratio_beta
sweep-example: setup
	rm -rf results/sweeps/light_ratio_beta
	$(VENV)/bin/bench-sim sweep scenes/sweeps/light_ratio_beta.toml --out results/sweeps/light_ratio_beta

test: setup
	$(VENV)/bin/ruff check bench_sim tests benchmarks
	$(PY) -m pytest
	bash scripts/check_install.sh

# `pip install .` into a fresh venv, then `bench-sim reproduce --quick` from another folder
install-check:
	bash scripts/check_install.sh

bench: setup
	$(PY) benchmarks/bench_render.py
	$(PY) benchmarks/bench_sensor.py
	$(PY) benchmarks/bench_fusion.py
	$(PY) benchmarks/bench_reproduce.py
	$(PY) benchmarks/bench_sweep.py
	$(PY) benchmarks/bench_resources.py

clean:
	rm -rf $(VENV) .setup-stamp

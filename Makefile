# The newcomer's two commands: `make demo` and `make test`. Both create .venv when it is missing.
# `make demo` passes --force: it may replace the results of its own earlier runs in $(OUT) (only the
# files optlight wrote there; see optlight/export.py).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
OUT    ?= results/default

.PHONY: demo test lint bench docs clean

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,mitsuba,sim]'
	@touch $(STAMP)

demo: $(STAMP)
	$(BIN)/optlight solve default --out $(OUT) --force

test: $(STAMP) lint
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check optlight tests benchmarks examples
	$(BIN)/mypy optlight

bench: $(STAMP)
	$(BIN)/optlight bench

docs: $(STAMP)
	$(BIN)/python -c "from optlight.spec import reference_markdown as r; print(r(), end='')" > docs/problems.md

clean:
	rm -rf $(VENV) results build *.egg-info

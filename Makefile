# Two entry points for a fresh machine with Python 3.11:
#   make run   - install into .venv and run the main job (jmse-jax reproduce, built-in defaults)
#   make test  - install into .venv (with test extras) and run the test suite
# (make test-slow runs the heavier checks that make test leaves out)
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
OUT ?= jmse_output

.PHONY: run test test-slow test-oldest install lint bench clean

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[test,dev]"
	touch $@

install: $(BIN)/.installed

run: $(BIN)/.installed
	$(BIN)/jmse-jax reproduce --out $(OUT)

# Two or more worker processes (one per core, whole test files each): compilation, which
# dominates the suite, is single-threaded in XLA, so the workers overlap it.
test: $(BIN)/.installed
	$(BIN)/python -m pytest -q -n auto --dist loadfile

# The heavier checks the default run leaves out (second derivatives, the GPU's vectorised
# batching, float32 twins of float64 checks, the CLI's compile cache): tests marked slow.
# Many of them run finer grids for long, so they run the optimised code users get (the
# default run compiles with LLVM's optimisations off: tests/conftest.py).
test-slow: $(BIN)/.installed
	XLA_FLAGS="$$XLA_FLAGS --xla_backend_optimization_level=2" \
		$(BIN)/python -m pytest -q -n auto --dist loadfile -m slow

# The test suite on the oldest dependency versions the package supports (constraints-oldest.txt,
# the floors of pyproject.toml), in a virtual environment of its own.
OLDEST ?= .venv-oldest
test-oldest:
	$(PYTHON) -m venv $(OLDEST)
	$(OLDEST)/bin/pip install --quiet --upgrade pip
	$(OLDEST)/bin/pip install --quiet -c constraints-oldest.txt -e ".[test]"
	$(OLDEST)/bin/python -m pytest -q -n auto --dist loadfile

lint: $(BIN)/.installed
	$(BIN)/ruff check jmse_jax tests benchmarks notebooks docs

bench: $(BIN)/.installed
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) $(OLDEST) $(OUT) .pytest_cache

"""Shared test configuration: float64 everywhere, the bank on the path, shared compiled merits.

The library never turns on float64 itself (STYLE.md); the tests do, before any array exists.
Compiled closures are module-level singletons so each distinct option set and input
structure is compiled once per test session (compilation dominates the suite's runtime).

Compilation is also shared *between* processes: the xdist workers, and the subprocesses the
CLI, notebook and multi-host tests start, all use one JAX persistent compilation cache, a
temporary folder made by the first process (it sets ``JAX_COMPILATION_CACHE_DIR``, which the
others inherit) and removed at the end. A user's own ``JAX_COMPILATION_CACHE_DIR`` is used as
it is and kept.
"""

from __future__ import annotations

import os
import pathlib
import shutil
import sys
import tempfile

if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    os.environ["JAX_COMPILATION_CACHE_DIR"] = tempfile.mkdtemp(prefix="jmse_jax_test_jit_")
    os.environ["JMSE_JAX_TEST_CACHE_OWNER"] = str(os.getpid())
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.3")
# The suite compiles its programs with LLVM's optimisations off (XLA's backend level 0):
# compilation is most of its time, and this takes 25-45 % off the compile-bound tests, while
# code that runs long gets 2-4 times slower (so the finer grids' references of the default
# run's heaviest accuracy checks are stored: ``test_merit.STORED_REFERENCES``). It changes
# how the arithmetic is scheduled, not what it computes (XLA's CPU code is not fast-math):
# results agree to rounding. ``test_readme.py`` runs the README example with the optimised
# code users get, in a process without this flag, and checks its value, gradient, baseline
# and OTF against this process's to 1e-11. A level the caller set in ``XLA_FLAGS`` is kept
# (``XLA_FLAGS=--xla_backend_optimization_level=2 make test`` runs the suite on the users'
# code; ``make test-slow`` sets it, since its checks run long).
if "--xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = " ".join(
        (os.environ.get("XLA_FLAGS", ""), "--xla_backend_optimization_level=0")).strip()

# The suite's programs carry no run-time design checks (``jmse_jax.run_time_checks``): a
# program with their host callback is not stored in the persistent cache above, so each
# process would compile every traced default program again (tests/test_tiers.py alone,
# serially: 435 s with them, 369 s without). The checks add an exact zero: the values and
# gradients are the same bit for bit (``test_merit.py::
# test_run_time_checks_off_gives_the_same_numbers_without_a_callback``); the tests of the
# checks themselves turn them on (the ``with_run_time_checks`` fixture), and the README's
# example runs in a process with them on, as users get it (``test_readme.py``).
os.environ.setdefault("JMSE_JAX_RUN_TIME_CHECKS", "0")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
jax.config.update("jax_persistent_cache_min_compile_time_secs",
                  float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]))


def pytest_unconfigure(config):
    """The process that made the shared cache folder removes it."""
    if os.environ.get("JMSE_JAX_TEST_CACHE_OWNER") == str(os.getpid()):
        shutil.rmtree(os.environ["JAX_COMPILATION_CACHE_DIR"], ignore_errors=True)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import pytest  # noqa: E402

import jmse_jax as jj  # noqa: E402

FIG1_COEFFICIENTS = dict(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
FIG1_JMSE = 2.6539432e-3  # SPEC §5
FIG1_BASELINE_B64 = 2.440918e-3  # SPEC §5 gives 2.4409e-3 (-8 %)


@pytest.fixture(scope="session")
def fig1():
    """The paper's Fig. 1 point: (aberrations, field, u, signal, noise)."""
    return (jj.Seidel(**FIG1_COEFFICIENTS), 0.95, 0.2, jj.MarkovSignal(1.0, 5.0),
            jj.WhiteNoise(1e-3))


@pytest.fixture
def with_run_time_checks(monkeypatch):
    """``jmse``'s run-time checks on (as users get them; off elsewhere in the suite, above),
    for the tests of the warnings traced calls give when their programs run."""
    monkeypatch.setenv(jj.RUN_TIME_CHECKS_VARIABLE, "1")


@pytest.fixture
def vectorised_vmap(monkeypatch):
    """``vmap`` of ``jmse`` vectorised over the batch, as on a GPU, instead of design by
    design as on CPU (``jmse_jax._merit.SEQUENTIAL_VMAP_BACKENDS``): for the tests of the
    batching rules (tiers' dispatch, peaks) that only the vectorised form consults. Read
    when ``jmse`` is traced, so the function under test must be traced inside the test."""
    import jmse_jax._merit as merit

    monkeypatch.setattr(merit, "SEQUENTIAL_VMAP_BACKENDS", ())

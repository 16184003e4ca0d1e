"""Shared test configuration: float64 everywhere, the bank on the path, shared compiled merits.

The library never turns on float64 itself (STYLE.md); the tests do, before any array exists.
Compiled closures are module-level singletons so each distinct option set and input
structure is compiled once per test session (compilation dominates the suite's runtime).
"""

from __future__ import annotations

import pathlib
import sys

import jax

jax.config.update("jax_enable_x64", True)

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

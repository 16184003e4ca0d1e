"""Small tiers for the default preset in tests: the same structure as ``DEFAULT_TIERS`` (a
switch, a shortcut in the tier the Fig. 1 point selects, a balanced grid), in programs that
compile in seconds instead of the default's tens of seconds."""

from __future__ import annotations

import math

import jmse_jax as jj

# Small tiers with the same structure as the default's (a switch, and a shortcut in the tier
# the Fig. 1 point selects), cheap to compile.
SMALL = dict(nodes=(12, 6), se_nodes=(60, 24), overlap_nodes=(10, 10))
SMALL_TIERS = (
    (1.0, math.inf, dict(nodes=(8, 4), se_nodes=(40, 16), overlap_nodes=(8, 8)), None),
    (math.inf, math.inf, SMALL,
     jj.TierShortcut(trial=dict(nodes=(8, 4), se_nodes=(40, 16), overlap_nodes=(8, 8)),
                     check=dict(nodes=(6, 4), se_nodes=(30, 12), overlap_nodes=(6, 6)),
                     rtol=1e-5)),
)


# A balanced grid of the same structure as ``BALANCED_GRID`` (closed-form peaks, its own
# overlap floor), cheap to compile.
SMALL_BALANCED = dict(nodes=(12, 6), se_nodes=(60, 24), overlap_nodes=(10, 10), overlap_floor=10,
                      peaks=True)


def tiers_without_one_ray(monkeypatch, tiers, balanced=None):
    """The default with ``tiers``, no one-ray plans and the balanced grid ``balanced`` (none
    unless given), through ``monkeypatch``; the presets are read when ``jmse`` is traced, so
    the function under test must be traced after this call. For the off-axis designs of the
    shortcut and derivative-rule tests (tests/test_tiers.py) and the lens merit's field mean
    (tests/test_optimise.py): a traced design might be symmetric, or its terms might cancel,
    so the default's programs also hold the one-ray plans and their symmetry-breaking
    derivative rule (tests/test_radial.py), a third of their compile time, and the balanced
    tier, whose closed-form peaks are most of the rest: at the Fig. 1 point with
    ``SMALL_TIERS`` the jitted value compiles in 2.7 s without it and 6.7 s with
    ``BALANCED_GRID``, and ``value_and_grad`` in 3.5 and 11.5 s."""
    monkeypatch.setitem(jj.PRESETS["default"], "tiers", tiers)
    monkeypatch.setitem(jj.PRESETS["default"], "radial", False)
    monkeypatch.setitem(jj.PRESETS["default"], "balanced", balanced)

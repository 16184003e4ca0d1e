"""The adaptive default preset: aberration strength, tier choice, and its derivative rule."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from compiled import assert_vmap_matches_singles, jmse_fn, jmse_value_and_grad_fn
from oracles import richardson_difference
from problems import REFERENCES
from small_tiers import (
    SMALL as _SMALL,
    SMALL_BALANCED,
    SMALL_TIERS,
    tiers_without_one_ray as _tiers_without_one_ray,
)

import jmse_jax as jj
from jmse_jax._merit import _route, _strength, _tier_index

SIGNAL, NOISE = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)

# One design per tier: nearly diffraction limited (strength 0.2), the paper's Fig. 1 (3.1),
# every term at 3 waves at field 0.8 (8.8), and every term at 5 waves at full field
# (strength 17.4, but a wavefront slope of 62 waves per pupil radius, past STEEP_SLOPE: the
# steep tier).
DESIGNS = [
    (jj.Seidel(w020=0.3, w222=0.2), 0.5, 0.2, 0),
    (jj.Seidel(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198), 0.95, 0.2, 1),
    (jj.Seidel(w020=3.0, w040=3.0, w131=3.0, w222=3.0, w220=3.0), 0.8, 0.2, 2),
    (jj.Seidel(w020=5.0, w040=5.0, w131=5.0, w222=5.0, w220=5.0), 1.0, 0.2, 4),
]
# Strength 14.7 (tier 2's range) but a wavefront slope of 52: the steep tier.
ALL_5 = (jj.Seidel(w020=5.0, w040=5.0, w131=5.0, w222=5.0, w220=5.0), 0.8, 0.2, 4)
# The tier-2 design above (slope 31) on a wider band, u = 0.5: strength 22, not steep, so
# tier 3.
STRONG = (jj.Seidel(w020=3.0, w040=3.0, w131=3.0, w222=3.0, w220=3.0), 0.8, 0.5, 3)
# A second middle-tier design (strength 2.0) that keeps the shortcut's first grid (the
# check agrees with it to 1.8e-6, its error estimate is 1.7e-6).
FIRST_KEPT = (jj.Seidel(w020=1.52, w040=0.23, w131=-1.02, w222=1.73, w220=-1.18), 0.9, 0.2, 1)
# A second middle-tier design (strength 3.4) whose shortcut is refused: 6 waves of defocus
# has S_e ridges along its OTF's zero rings that the first tier's grid misses by 4e-4. A
# trace of astigmatism keeps it off the one-ray path of rotationally symmetric designs
# (tests/test_radial.py), so that it runs the polar grids of the tier.
DEFOCUS_M6 = (jj.Seidel(w020=-6.0, w222=0.02), 1.0, 0.2, 1)
# A middle-tier design (strength 3.6, u = 0.6) whose OTF varies across angle more than 8
# angular nodes resolve: the shortcut's first grid is 1.15e-5 off while its estimate reads
# 1.0e-5 (within ``first_tol``), and a check grid with the same 8 angular nodes agreed with it
# to 2e-6; the check's 10 angular nodes (since session 80) see the error and refuse it.
ANGULAR_MISSED = (jj.Seidel(w020=-0.4, w131=0.5, w222=1.5611), 1.0, 0.6, 1)
# Astigmatism at the medial focus (w020 = -w222 h^2 / 2): cancellation 3, strength 2.8 (by
# strength alone tier 1 of SMALL_TIERS), so it takes the balanced tier.
MEDIAL_FOCUS = (jj.Seidel(w020=-5.0, w222=10.0), 1.0, 0.2, 1)


@pytest.mark.parametrize("a, u", [(1.0, 0.5), (-3.0, 0.2), (2.0, 1.2)])
def test_strength_of_defocus_is_analytic(a, u):
    # W = a rho^2: |grad W| = 2 |a| rho, largest on the rim (sampled exactly).
    value = float(jj.aberration_strength(jj.Seidel(w020=a), 0.0, u))
    assert value == pytest.approx(2 * abs(a) * min(math.sqrt(2) * u, 1.0), rel=1e-12)


def test_strength_of_coma_is_analytic_and_ignores_tilt():
    # Coma less its hidden tilt: W = c (rho^2 y - 2 y / 3), grad = c (2xy, x^2 + 3y^2 - 2/3),
    # largest at (0, +-1): |c| 7/3. Distortion and tilt add nothing.
    c = 0.8 * 1.5
    value = float(jj.aberration_strength(jj.Seidel(w131=1.5, w311=4.0, w111=-2.0), 0.8, 0.3))
    assert value == pytest.approx(abs(c) * 7 / 3 * math.sqrt(2) * 0.3, rel=1e-12)


def test_strength_has_zero_gradient_and_validates():
    grad = jax.grad(lambda w: _strength(jj.Seidel(w020=w), 0.0, 0.2))(1.0)
    assert float(grad) == 0.0
    with pytest.raises(ValueError, match="field"):
        jj.aberration_strength(jj.Seidel(), 1.5, 0.2)
    with pytest.raises(ValueError, match="u"):
        jj.aberration_strength(jj.Seidel(), 0.5, -0.1)


def test_tier_index_honours_both_bounds():
    tiers = jj.DEFAULT_TIERS
    assert int(_tier_index(0.5, 0.2, tiers)) == 0
    assert int(_tier_index(0.5, 0.8, tiers)) == 1  # a band reaching the cutoff skips tier 0
    assert int(_tier_index(3.0, 0.2, tiers)) == 1
    assert int(_tier_index(9.0, 0.2, tiers)) == 2
    # A design steeper than STEEP_SLOPE (max |grad W| = strength / min(sqrt(2) u, 1), here
    # 35.4 and 42.4 waves per pupil radius) takes the last tier (the steep one) whatever its
    # strength.
    assert int(_tier_index(10.0, 0.2, tiers)) == 4
    assert int(_tier_index(3.0, 0.05, tiers)) == 4
    assert int(_tier_index(9.8, 0.2, tiers)) == 2  # slope 34.6
    assert int(_tier_index(50.0, 0.2, tiers)) == 4
    # Strong designs that are not steep take the fourth tier (slope 28.3 and 34.6 here).
    assert int(_tier_index(20.0, 0.5, tiers)) == 3
    assert int(_tier_index(24.5, 0.5, tiers)) == 3
    assert int(_tier_index(25.0, 0.5, tiers)) == 4  # slope 35.4
    # Rays reaching the cutoff (u > 1/sqrt(2)) need the fourth tier's radial nodes from
    # strength 5 on; weaker designs keep the second tier's grid.
    assert int(_tier_index(10.0, 0.72, tiers)) == 3
    assert int(_tier_index(3.0, 0.72, tiers)) == 1
    assert int(_tier_index(10.0, 0.7, tiers)) == 2
    assert [t[0] for t in tiers] == sorted(t[0] for t in tiers) and tiers[-1][0] == math.inf


def test_tier_index_skips_the_weak_tiers_at_high_ring_snr():
    """Above ``WEAK_TIER_SNR`` a design skips tier 0, then tier 1 (tier 2 keeps its own u
    bound); a caller's own tiers ignore the SNR."""
    tiers = jj.DEFAULT_TIERS
    low, high = jj.WEAK_TIER_SNR
    assert int(_tier_index(0.5, 0.2, tiers, 0.5 * low)) == 0
    assert int(_tier_index(0.5, 0.2, tiers, 2.0 * low)) == 1
    assert int(_tier_index(0.5, 0.2, tiers, 2.0 * high)) == 2
    assert int(_tier_index(3.0, 0.2, tiers, 0.5 * high)) == 1
    assert int(_tier_index(3.0, 0.2, tiers, 2.0 * high)) == 2
    assert int(_tier_index(3.0, 0.8, tiers, 2.0 * high)) == 3  # tier 2 stops at 1/sqrt(2)
    assert int(_tier_index(10.0, 0.2, tiers, 2.0 * high)) == 4  # the steep tier, as before
    own = tuple((b, ub, dict(g), s) for b, ub, g, s in tiers[:3]) + (
        (math.inf, math.inf, dict(tiers[3][2]), None),)
    assert int(_tier_index(0.5, 0.2, own, 2.0 * high)) == 0


def test_ring_snr_is_the_spectra_at_the_innermost_ring():
    """``_ring_snr``: S_x / S_n at 0.3 u / strength (at most sqrt(2) u), from the closed
    forms of ``MarkovSignal`` and ``WhiteNoise``."""
    from jmse_jax._merit import _ring_snr

    signal, noise = jj.MarkovSignal(2.0, 1.5), jj.WhiteNoise(1e-4)

    def expected(nu):
        return 2.0 * 2 * math.pi * 1.5 ** 2 / (1 + (2 * math.pi * 1.5 * nu) ** 2) ** 1.5 / 1e-4

    assert float(_ring_snr(2.0, 0.2, signal, noise)) == pytest.approx(expected(0.03), rel=1e-12)
    assert float(_ring_snr(0.01, 0.2, signal, noise)) == pytest.approx(
        expected(math.sqrt(2) * 0.2), rel=1e-12)


# Near the axis (field 0.07) 2.5 waves of defocus at u = 0.096 (strength 0.78, tier 0 by
# strength) put a zero ring of the OTF inside the band; with a flat signal spectrum
# (correlation length 1.35) at a peak SNR of 1.9e6, inside CHECKED_SNR, tier 0's grid was
# 1.3e-2 off and tier 1's 1.4e-4 (session 80's adversarial climb, default_climb.py).
RING_DESIGN = (jj.Seidel(w020=-2.51, w040=-0.1131, w131=1.8707, w222=-0.0014, w220=0.47),
               0.06676, 0.09612, jj.MarkovSignal(1.0, 1.3455), jj.WhiteNoise(6.0293e-6))


def test_a_ring_at_high_snr_near_the_axis_skips_the_weak_tiers():
    """The default takes tier 2 there and is within 1e-7 of tier 2's grid with closed-form
    peaks (2e-8 from a converged grid); tier 0's own grid, which it took before, is more
    than 1e-3 off that oracle."""
    ab, field, u, signal, noise = RING_DESIGN
    oracle = float(jj.jmse(*RING_DESIGN, **{**jj.DEFAULT_TIERS[2][2], "peaks": True}))
    assert float(jj.aberration_strength(ab, field, u)) < jj.DEFAULT_TIERS[0][0]
    assert _route(*RING_DESIGN)["tier"] == 4
    assert float(jj.jmse(*RING_DESIGN)) == pytest.approx(oracle, rel=1e-7)
    assert abs(float(jj.jmse(*RING_DESIGN, **jj.DEFAULT_TIERS[0][2])) / oracle - 1) > 1e-3


def test_tier_index_skips_tiers_1_to_3_at_high_snr_at_the_band_edge():
    """Above ``EDGE_TIER_SNR`` at the band's edge a design of tiers 1 to 3 takes the steep
    tier; below it, or for a caller's own tiers, the tier by strength stands."""
    tiers, bound = jj.DEFAULT_TIERS, jj.EDGE_TIER_SNR
    assert int(_tier_index(3.0, 0.8, tiers, 0.0, 0.5 * bound)) == 1
    assert int(_tier_index(3.0, 0.8, tiers, 0.0, 2.0 * bound)) == 4
    assert int(_tier_index(3.0, 0.3, tiers, 0.0, 2.0 * bound)) == 4
    assert int(_tier_index(10.0, 0.7, tiers, 0.0, 0.5 * bound)) == 2
    assert int(_tier_index(10.0, 0.7, tiers, 0.0, 2.0 * bound)) == 4
    assert int(_tier_index(20.0, 0.5, tiers, 0.0, 0.5 * bound)) == 3
    assert int(_tier_index(20.0, 0.5, tiers, 0.0, 2.0 * bound)) == 4
    # Tier 0 has no edge bound (the ring SNR, WEAK_TIER_SNR, holds its designs).
    assert int(_tier_index(0.5, 0.3, tiers, 0.0, 2.0 * bound)) == 0
    own = tuple((b, ub, dict(g), s) for b, ub, g, s in tiers[:3]) + (
        (math.inf, math.inf, dict(tiers[3][2]), None),)
    assert int(_tier_index(3.0, 0.8, own, 0.0, 2.0 * bound)) == 1


def test_edge_snr_is_the_spectra_at_the_band_edge():
    """``_edge_snr``: S_x / S_n from ``PowerLawSignal``'s closed form at the band's corner
    ``sqrt(2) u``, or at the cutoff for a band that reaches it."""
    from jmse_jax._merit import _edge_snr

    signal, noise = jj.PowerLawSignal(2.0, 2.5, 0.5), jj.WhiteNoise(1e-5)

    def expected(nu):
        return 2.0 / (0.5 ** 2 + nu ** 2) ** 1.25 / 1e-5

    assert float(_edge_snr(0.8, signal, noise)) == pytest.approx(expected(1.0), rel=1e-12)
    assert float(_edge_snr(1.2, signal, noise)) == pytest.approx(expected(1.0), rel=1e-12)
    for u in (0.7, 0.3, 0.05):
        assert float(_edge_snr(u, signal, noise)) == pytest.approx(
            expected(u * math.sqrt(2)), rel=1e-12)


# A weak design (strength 1.2, tier 1 by strength) on a band reaching the cutoff, u = 0.905,
# under a flat power-law spectrum at SNR 3.8e5 at the cutoff (peak 9e5, inside CHECKED_SNR):
# tier 1's 40 radial OTF nodes were 2.6e-4 off (session 81's climb under power-law spectra,
# default_climb.py --signal powerlaw).
EDGE_DESIGN = (jj.Seidel(w020=-0.1518, w040=0.1118, w131=0.4855, w222=0.3675, w220=0.1166),
               0.624, 0.905, jj.PowerLawSignal(2.11, 2.499, 1.0), jj.WhiteNoise(2.34e-6))


# u just below 1/sqrt(2): the band's corner (0.994) lies just inside the cutoff, at an SNR of
# 2.9e5 there (peak 1.4e6) under a flat power-law spectrum; strength 3.3, tier 1 by strength
# (5.5e-4 off), tier 2's grid 1.2e-3 off (session 81's climb from a corner design).
CORNER_DESIGN = (jj.Seidel(w020=1.4338, w040=-0.2546, w131=-0.7411, w222=-1.5247, w220=-1.19),
                 0.827, 0.703, jj.PowerLawSignal(0.88, 2.638, 0.643), jj.WhiteNoise(1.97e-6))


def test_a_band_whose_corner_is_near_the_cutoff_at_high_snr_takes_the_steep_tier():
    """The default takes the steep tier there (512 angular fine nodes) and is within 2e-6
    of tier 3's grid with 960 (6e-7 from a converged grid); tiers 1 and 2 are more than
    1e-4 off that oracle, and tier 3 with its own 256 more than 2e-5."""
    oracle = _stored_oracle("corner")
    assert _route(*CORNER_DESIGN)["tier"] == 4
    assert float(jj.jmse(*CORNER_DESIGN)) == pytest.approx(oracle, rel=2e-6)
    for grid in (jj.DEFAULT_TIERS[1][2], jj.DEFAULT_TIERS[2][2]):
        assert abs(float(jj.jmse(*CORNER_DESIGN, **grid)) / oracle - 1) > 1e-4
    assert abs(float(jj.jmse(*CORNER_DESIGN, **jj.DEFAULT_TIERS[3][2])) / oracle - 1) > 2e-5


# Terms that cancel (the balanced tier) at u = 0.195 under a flat power-law spectrum at SNR
# 1.5e5 at the band's corner: BALANCED_GRID with its former 256 angular fine nodes was
# 2.4e-4 off (session 81's climb under power-law spectra), with 512 5.6e-6.
BALANCED_FLAT_DESIGN = (jj.Seidel(w020=-4.9762, w040=4.2658, w131=0.5119, w222=-5.9652,
                                  w220=1.7956), 0.809, 0.195,
                        jj.PowerLawSignal(0.646, 2.779, 0.182), jj.WhiteNoise(9.36e-5))


def test_the_balanced_tier_under_a_flat_spectrum_at_high_snr():
    """The default takes the balanced tier there and is within 2e-5 of its grid with 960
    angular fine nodes (the former 256 were 2.4e-4 off it)."""
    oracle = _stored_oracle("balanced_flat")
    assert _route(*BALANCED_FLAT_DESIGN)["balanced"]
    assert float(jj.jmse(*BALANCED_FLAT_DESIGN)) == pytest.approx(oracle, rel=2e-5)


# A band reaching the cutoff (u = 0.905, strength 13.7) under a flat power-law spectrum at
# SNR 6.2e4 there: "high"'s own grid (80 radial OTF nodes) was 3.9e-5 off
# (benchmarks/edge_snr_tiers.py); past EDGE_TIER_SNR it takes HIGH_STEEP_GRID (128).
HIGH_EDGE_DESIGN = (jj.Seidel(w020=3.7096, w040=-0.49412, w131=0.78185, w222=3.70915,
                              w220=1.76912), 0.78934, 0.90480,
                    jj.PowerLawSignal(1.0, 1.58362, 0.60722), jj.WhiteNoise(1.25561e-5))


#: The oracles of the four tests on these designs: each design's value on a finer grid,
#: stored (3.0-5.4 s each to compile and run alone at LLVM's level 0, more beside the
#: suite's other worker; session 108). ``test_stored_oracles_are_their_finer_grids``
#: (slow) recomputes them, so an edited design or grid fails there.
STORED_ORACLES = {
    "edge": (EDGE_DESIGN, {**jj.DEFAULT_TIERS[3][2], "nodes": (160, 64)}, 0.05091132737529298),
    "corner": (CORNER_DESIGN, {**jj.DEFAULT_TIERS[3][2], "se_nodes": (4800, 960)},
               0.0029524510876106787),
    "balanced_flat": (BALANCED_FLAT_DESIGN, {**jj.BALANCED_GRID, "se_nodes": (4800, 960)},
                      0.006126549671099563),
    "high_edge": (HIGH_EDGE_DESIGN, dict(nodes=(160, 64), se_nodes=(4800, 960),
                                         overlap_nodes=(96, 96), overlap_floor=96, peaks=True),
                  0.4295886499899544),
}


def _stored_oracle(name):
    return STORED_ORACLES[name][2]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(STORED_ORACLES))
def test_stored_oracles_are_their_finer_grids(name):
    """Each stored oracle is its finer grid's value on its design (to rounding, which may
    differ between jax versions and XLA's optimisation levels)."""
    design, grid, value = STORED_ORACLES[name]
    assert float(jj.jmse(*design, **grid)) == pytest.approx(value, rel=1e-11)


def test_high_takes_its_steep_grid_at_high_snr_at_the_cutoff():
    """``"high"`` takes ``HIGH_STEEP_GRID`` there and is within 1e-6 of an independent finer
    grid; its own grid is more than 1e-5 off that oracle."""
    oracle = _stored_oracle("high_edge")
    assert _route(*HIGH_EDGE_DESIGN, preset="high")["steep"]
    assert float(jj.jmse(*HIGH_EDGE_DESIGN, preset="high")) == pytest.approx(oracle, rel=1e-6)
    own = {k: jj.PRESETS["high"][k] for k in ("nodes", "se_nodes", "overlap_nodes",
                                              "overlap_floor", "peaks")}
    assert abs(float(jj.jmse(*HIGH_EDGE_DESIGN, **own)) / oracle - 1) > 1e-5


def test_a_band_at_high_snr_at_the_cutoff_skips_tier_1():
    """The default takes the steep tier there and is within 1e-7 of a grid with 160 radial
    OTF nodes (tier 3's other counts); tier 1's own grid, which it took before, is more
    than 1e-4 off that oracle."""
    oracle = _stored_oracle("edge")
    assert float(jj.aberration_strength(*EDGE_DESIGN[:3])) < jj.DEFAULT_TIERS[1][0]
    assert _route(*EDGE_DESIGN)["tier"] == 4
    assert float(jj.jmse(*EDGE_DESIGN)) == pytest.approx(oracle, rel=1e-7)
    assert abs(float(jj.jmse(*EDGE_DESIGN, **jj.DEFAULT_TIERS[1][2])) / oracle - 1) > 1e-4


def _fixed(ab, field, u, grid):
    """The fixed ``grid``'s value, from one compiled program per grid (field and ``u`` are
    arguments, so the designs of every test share it)."""
    return float(jmse_fn(**grid)(ab, field, u, SIGNAL, NOISE))


def _first_estimate(ab, field, u, grid):
    """A shortcut's first-grid error estimate (checked against an independent restatement in
    ``test_first_grid_estimate_is_the_change_under_lowered_interpolants``)."""
    from jmse_jax._merit import _estimated_merit_value

    options = {**jj.jmse_options(), **grid}
    operands = (ab.without_tilt(), field, u, SIGNAL, NOISE)
    return float(jax.jit(lambda ops: _estimated_merit_value(options, jnp.dtype(jnp.float64),
                                                            *ops)[1])(operands))


def _to_float32(tree):
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float32), tree)


def _fixed32(ab, field, u, grid):
    """``_fixed`` with every input in float32 (the whole computation in float32)."""
    return float(jmse_fn(**grid)(*_to_float32((ab, field, u, SIGNAL, NOISE))))


@pytest.mark.parametrize("ab, field, u, tier, path", [
    (*DESIGNS[0], "first"), (*DESIGNS[1], "first"), (*FIRST_KEPT, "first"),
    (*DEFOCUS_M6, "grid"), (*DESIGNS[2], "grid"), (*STRONG, "grid"), (*DESIGNS[3], "grid"),
    (*ANGULAR_MISSED, "grid"),
])
def test_default_equals_the_grid_its_tier_selects(ab, field, u, tier, path):
    """Eager, jit and value_and_grad all run the tier the strength selects,
    and within a tier with a shortcut the grid that the shortcut's rule picks."""
    strength = float(jj.aberration_strength(ab, field, u))
    assert int(_tier_index(strength, u, jj.DEFAULT_TIERS)) == tier
    _, _, grid, shortcut = jj.DEFAULT_TIERS[tier]
    taken = "grid"
    if shortcut is not None and u <= shortcut.u_max:
        # The rule, restated: keep the first grid when the check agrees with it and its
        # error estimate is within tolerance, else the trial when the check agrees with it.
        check = _fixed32(ab, field, u, shortcut.check)  # the check runs in float32
        check64 = _fixed(ab, field, u, shortcut.check)
        first = _fixed(ab, field, u, shortcut.first)
        estimate = _first_estimate(ab, field, u, shortcut.first)
        agrees = abs(first - check) <= shortcut.rtol * abs(first)
        # ... and the float32 check decides as the float64 one would.
        assert agrees == (abs(first - check64) <= shortcut.rtol * abs(first))
        if agrees and estimate <= shortcut.first_tol:
            taken, grid = "first", shortcut.first
        elif shortcut.trial is not None:
            trial = _fixed(ab, field, u, shortcut.trial)
            accepted = abs(trial - check) <= shortcut.rtol * abs(trial)
            assert accepted == (abs(trial - check64) <= shortcut.rtol * abs(trial))
            if accepted:
                taken, grid = "trial", shortcut.trial
    assert path == taken
    # The benchmarks' report of the plan taken (``_route``) names the same tier and grid.
    route = _route(ab, field, u, SIGNAL, NOISE)
    assert (route["tier"], route["path"], route["one_ray"]) == (tier, taken, False)
    expected, expected_grad = jmse_value_and_grad_fn(**grid)(ab, field, u, SIGNAL, NOISE)
    eager = jj.jmse(ab, field, u, SIGNAL, NOISE)
    jitted = jmse_fn()(ab, field, u, SIGNAL, NOISE)
    value, gradient = _default_value_and_grad(ab, field, u, SIGNAL, NOISE)
    np.testing.assert_allclose([eager, jitted, value], float(expected), rtol=1e-13)
    for name in ("w020", "w040", "w131", "w222", "w220"):
        np.testing.assert_allclose(getattr(gradient, name), getattr(expected_grad, name),
                                   rtol=1e-10, atol=1e-16)


def test_shortcut_check_sees_the_first_grids_angular_error():
    """At ``ANGULAR_MISSED`` the first grid's error is angular (its 8 angular OTF nodes; the
    oracle is the same grid with 32) and more than 1e-5, its own estimate stays within
    ``first_tol``, so only a check that does not share its angular nodes refuses it; the
    default then returns its tier's own grid, within 1e-6 of the oracle."""
    ab, field, u, _ = ANGULAR_MISSED
    shortcut = jj.DEFAULT_TIERS[1][3]
    first_grid = shortcut.first
    oracle = _fixed(ab, field, u, {**first_grid, "nodes": (first_grid["nodes"][0], 32)})
    first = _fixed(ab, field, u, first_grid)
    assert abs(first / oracle - 1.0) > 1.1e-5
    assert _first_estimate(ab, field, u, first_grid) <= shortcut.first_tol
    assert shortcut.check["nodes"][1] != first_grid["nodes"][1]
    assert _route(ab, field, u, SIGNAL, NOISE)["path"] == "grid"
    assert float(jj.jmse(ab, field, u, SIGNAL, NOISE)) == pytest.approx(oracle, rel=1e-6)


# Slow: forward mode through the default's whole tier switch is a program of its own (about
# 40 s to compile on the CI machine). Reverse mode, checked above on the same designs, runs
# the same derivative rule (JAX linearises the rule and transposes its linear part).
@pytest.mark.slow
@pytest.mark.parametrize("ab, field, u, tier", [
    DESIGNS[0], DESIGNS[1], FIRST_KEPT, DEFOCUS_M6, DESIGNS[2], STRONG, DESIGNS[3]])
def test_forward_mode_of_the_default_equals_reverse_mode(ab, field, u, tier):
    """d/dt jmse(w020 + t) equals the reverse-mode gradient, in every tier and path."""
    _, gradient = _default_value_and_grad(ab, field, u, SIGNAL, NOISE)
    _, tangent = _default_jvp_w020(ab, field, u)
    np.testing.assert_allclose(tangent, gradient.w020, rtol=1e-10)


# Middle-tier designs without coma: the float32 computation starts from the same float32
# coefficients whether the tilt is removed before or after the cast (coma's hidden tilt,
# -2/3 w131, would round differently).
@pytest.mark.parametrize("ab, field, u", [
    (jj.Seidel(w020=-2.75, w040=1.5578, w222=1.4089, w220=2.7198), 0.95, 0.2), DEFOCUS_M6[:3],
])
def test_shortcut_check_runs_in_float32(ab, field, u):
    """The shortcut's check is computed in float32 whatever the merit's dtype and returned
    in that dtype: bit for bit the float32 computation, and within 2e-6 of the float64 one
    (inside the acceptance tolerance, 1e-5; 1.2e-6 at the Fig. 1 point with the check's 10
    angular nodes; on the calibration designs the shortcuts serve, float32 changed no
    decision, ``benchmarks/recheck_shortcut.py``). The check grid has no closed-form peaks
    (``_tier_plans``), so neither do its restatements here."""
    from jmse_jax._merit import _check_value, _compiled_check, _Static, _tier_plans

    check = jj.DEFAULT_TIERS[1][3].check
    options = _tier_plans(jj.jmse_options(), jj.DEFAULT_TIERS)[1][1][1]  # the plan's check
    float64 = jnp.dtype(jnp.float64)
    operands = (ab.without_tilt(), jnp.float64(field), jnp.float64(u), SIGNAL, NOISE)
    value = jax.jit(lambda ops: _check_value(options, float64, ops))(operands)
    assert value.dtype == jnp.float64
    # The eager path's check (tilt removed inside) is the traced path's, bit for bit.
    assert float(_compiled_check(_Static(options), float64, (ab, *operands[1:]))) == float(value)
    assert float(value) == _fixed32(ab, field, u, check)
    assert float(value) == pytest.approx(_fixed(ab, field, u, check), rel=2e-6)


def _lowered_independently(coarse_nodes, fine_nodes, drop):
    """Matrix taking values at ``coarse_nodes`` (Gauss nodes mapped to [-1, 1]) to the
    polynomial through them, less its top ``drop`` Legendre coefficients, at ``fine_nodes``:
    NumPy's Legendre fit and evaluation, column by column."""
    from numpy.polynomial import legendre

    k = len(coarse_nodes)
    columns = []
    for unit in np.eye(k):
        coefficients = legendre.legfit(coarse_nodes, unit, k - 1)
        coefficients[k - drop:] = 0.0
        columns.append(legendre.legval(fine_nodes, coefficients))
    return np.stack(columns, axis=1)


@pytest.mark.parametrize("ab, field, u, expected", [
    (*DESIGNS[1][:3], 6.0e-6), (*FIRST_KEPT[:3], 1.7e-6), (*DEFOCUS_M6[:3], 4.2e-4),
])
def test_first_grid_estimate_is_the_change_under_lowered_interpolants(
        monkeypatch, ab, field, u, expected):
    """The first grid's error estimate is the largest relative change of its value when
    its OTF interpolants lose their top Legendre coefficient, radially or angularly. The
    oracle restates it: the fixed grid's value with interpolation matrices built from
    NumPy's Legendre fits (patched in), against the same grid's plain value. The first grid
    has no closed-form peaks (``_tier_plans``), so neither has the oracle."""
    from jmse_jax import _merit
    from jmse_jax._numerics import gauss_legendre
    from jmse_jax._quadrature import _radial_counts, _radial_panels, angular_templates

    grid = jj.DEFAULT_TIERS[1][3].first
    coarse, fine = grid["nodes"], grid["se_nodes"]
    original = _merit.polar_interpolation_matrices

    def radial(drop):
        out = np.zeros((fine[0], coarse[0]))
        r = c = 0
        for (a, b), kc, kf in zip(_radial_panels(), _radial_counts(coarse[0]),
                                  _radial_counts(fine[0]), strict=True):
            xc, xf = ((2 * gauss_legendre(k, a, b)[0] - a - b) / (b - a) for k in (kc, kf))
            out[r:r + kf, c:c + kc] = _lowered_independently(xc, xf, drop)
            r, c = r + kf, c + kc
        return out

    def angular(drop, full):
        xc = 2 * angular_templates(coarse[1])[0][0] - 1
        xf = 2 * angular_templates(coarse[1], fine[1])[0][0] - 1
        out = np.array(full)
        out[0] = _lowered_independently(xc, xf, drop)  # the plain rule (u <= 1/sqrt(2))
        return out

    values = {}
    for name, drop in (("plain", (0, 0)), ("radial", (1, 0)), ("angular", (0, 1))):
        def patched(c, f, _drop=(0, 0), sub_panel=None, drop=drop):
            l_r, l_a = original(c, f, (0, 0), sub_panel)
            if (c, f) != (coarse, fine):
                return l_r, l_a
            return (radial(drop[0]) if drop[0] else l_r,
                    angular(drop[1], l_a) if drop[1] else l_a)

        monkeypatch.setattr(_merit, "polar_interpolation_matrices", patched)
        jax.clear_caches()
        values[name] = _fixed(ab, field, u, grid)
    monkeypatch.setattr(_merit, "polar_interpolation_matrices", original)
    jax.clear_caches()
    oracle = max(abs(values[k] - values["plain"]) for k in ("radial", "angular"))
    oracle /= values["plain"]
    estimate = _first_estimate(ab, field, u, grid)
    assert estimate == pytest.approx(oracle, rel=1e-6)
    assert estimate == pytest.approx(expected, rel=0.2)  # the figures quoted above


@pytest.mark.parametrize("scale", [1e30, 1e-40])
def test_shortcut_check_outside_float32_range_falls_back_to_the_tier_grid(scale):
    """Spectra far outside float32's range (``S_x S_n`` overflows or underflows there): the
    float32 check is not finite, so the trial is refused and the tier's own grid, in
    float64, gives the value. The oracle is the JMSE's scale invariance, ``JMSE(a S_x,
    a S_n) = a JMSE(S_x, S_n)``, against the tier's own grid at unit scale."""
    ab, field, u, _ = DESIGNS[1]
    signal = jj.MarkovSignal(scale * SIGNAL.variance, SIGNAL.correlation_length)
    noise = jj.WhiteNoise(scale * NOISE.variance)
    value, gradient = _default_value_and_grad(ab, field, u, signal, noise)
    expected, expected_grad = jmse_value_and_grad_fn(**jj.DEFAULT_TIERS[1][2])(
        ab, field, u, SIGNAL, NOISE)
    assert float(value) == pytest.approx(scale * float(expected), rel=1e-12)
    for name in ("w020", "w040", "w131", "w222", "w220"):
        np.testing.assert_allclose(getattr(gradient, name),
                                   scale * getattr(expected_grad, name), rtol=1e-9)


@pytest.mark.parametrize("ab, field, u, name", [
    (*DESIGNS[1][:3], "fig1"), (jj.Seidel(w020=-6.0), 0.0, 0.2, "defocus_m6"),
])
def test_shortcut_keeps_the_middle_tier_accurate(ab, field, u, name):
    """Whichever plan the middle tier returns (the shortcut's first grid for Fig. 1, 4.3e-7
    off; the one-ray plan for defocus -6 on the axis), it is within the shortcut's
    tolerance, 1e-5, of the bank's converged reference."""
    value = float(jmse_fn()(ab, field, u, SIGNAL, NOISE))
    reference = REFERENCES[name][1]
    assert abs(value - reference) <= 1e-5 * reference


@pytest.mark.parametrize("w131, tier", [(14.647, 2), (19.193, 4)])
def test_strong_coma_alone_is_accurate(w131, tier):
    """One strong term, outside the calibration's +-8-wave box: pure coma at full field,
    u = 0.3, strength 14.5 and 19. Its phase difference varies along the overlap lens's
    chords, which the tiers' order along them must follow (with 24 nodes the default was
    3.3e-3 and 2.4e-2 off; ``benchmarks/single_term_tiers.py``). Against a grid with every
    overlap order far past the tiers' (it agrees with a reference of (160, 96) / (8000,
    1920) / (96, 96) to 2e-11)."""
    ab = jj.Seidel(w131=w131)
    assert int(_tier_index(_strength(ab, 1.0, 0.3), 0.3, jj.DEFAULT_TIERS)) == tier
    value = float(jmse_fn()(ab, 1.0, 0.3, SIGNAL, NOISE))
    reference = float(jmse_fn(nodes=(96, 48), se_nodes=(2400, 256), overlap_nodes=(96, 72))(
        ab, 1.0, 0.3, SIGNAL, NOISE))
    assert abs(value / reference - 1) < 1e-4


#: The default's value and gradient in the coefficients, every input traced: the program
#: the README's example and other test modules compile (``tests/compiled.py``).
_default_value_and_grad = jmse_value_and_grad_fn()


@jax.jit
def _default_jvp_w020(ab, field, u):
    def along(t):
        return jj.jmse(jj.Seidel(**{**_coefficients(ab), "w020": ab.w020 + t}), field, u,
                       SIGNAL, NOISE)
    return jax.jvp(along, (0.0,), (1.0,))


def _coefficients(ab):
    return {k: getattr(ab, k) for k in ("w020", "w040", "w131", "w222", "w220", "w311", "w111")}


def test_default_gradient_matches_finite_differences_in_the_top_tier():
    ab, field, u, _ = DESIGNS[3]
    grad = _default_value_and_grad(ab, field, u, SIGNAL, NOISE)[1].w040
    h = 1e-4
    f = [float(jmse_fn()(jj.Seidel(**{**_coefficients(ab), "w040": 5.0 + s * h}), field, u,
                         SIGNAL, NOISE)) for s in (1, -1)]
    assert float(grad) == pytest.approx((f[0] - f[1]) / (2 * h), rel=1e-6)


def test_default_value_and_grad_scratch_stays_small():
    """Every tier, one-ray plan and shortcut grid sits in the one ``value_and_grad``
    program, whose scratch is sized for its largest branch, and XLA's CPU runtime maps
    scratch afresh on every call above about 32 MB, so the Fig. 1 point pays for the
    strongest grids' storage (``_merit._REMAT_OTF``). Session 100 stored the closed-form
    chords' blocks of the steep and balanced grids: 177 MB, and that point's
    ``value_and_grad`` 2.1 -> 4.2-5.1 ms (one core). Recomputed: 24 MB."""
    ab, field, u, _ = DESIGNS[0]
    compiled = _default_value_and_grad.lower(ab, field, u, SIGNAL, NOISE).compile()
    scratch = compiled.memory_analysis().temp_size_in_bytes
    assert scratch < 32e6, scratch


def test_vmap_over_designs_in_different_tiers(monkeypatch, vectorised_vmap):
    """The tiers' vectorised dispatch (a GPU's ``vmap``), value only, on ``SMALL_TIERS``
    (the default's own tiers, with ``value_and_grad``, compile for minutes: the slow
    test_vmap_gives_each_design_what_it_gets_alone): a batch spanning both tiers, the second
    one's shortcut included, gives each design what it gets alone."""
    _tiers_without_one_ray(monkeypatch, SMALL_TIERS)
    designs = [(jj.Seidel(**_coefficients(d[0])), d[1]) for d in DESIGNS]
    tiers = [int(_tier_index(jj.aberration_strength(ab, f, 0.2), 0.2, SMALL_TIERS))
             for ab, f in designs]
    assert set(tiers) == {0, 1}
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack([jnp.asarray(v, jnp.float64) for v in x]),
                                   *[ab for ab, _ in designs])
    field = jnp.asarray([f for _, f in designs])

    def merit(a, f):
        return jj.jmse(a, f, 0.2, SIGNAL, NOISE)

    values = jax.jit(jax.vmap(merit))(batch, field)
    single = jax.jit(merit)
    singles = [float(single(ab, jnp.float64(f))) for ab, f in designs]
    np.testing.assert_allclose(values, singles, rtol=1e-12)


def test_grid_override_fixes_the_grid():
    options = jj.jmse_options("default", nodes=(16, 8))
    assert options["tiers"] is None and options["se_nodes"] == jj.DEFAULT_TIERS[1][2]["se_nodes"]
    assert jj.jmse_options("default")["tiers"] is jj.DEFAULT_TIERS
    assert jj.jmse_options("fast")["tiers"] is None
    with pytest.raises(ValueError, match="unknown jmse option 'tiers'"):
        jj.jmse_options("default", tiers=None)


def test_sweep_runs_designs_one_by_one_on_cpu_and_equals_the_loop(monkeypatch):
    """A sweep of the default over designs in different tiers (``SMALL_TIERS``, which
    compile in a fraction of the default's time) runs them one at a time on CPU and equals
    the loop of single calls."""
    _tiers_without_one_ray(monkeypatch, SMALL_TIERS)
    ab = jj.Seidel(**{name: np.array([float(getattr(d[0], name)) for d in DESIGNS])
                      for name in ("w020", "w040", "w131", "w222", "w220")})
    field = np.array([d[1] for d in DESIGNS])
    result = jj.sweep_jmse(ab, field, 0.2, SIGNAL, NOISE, progress=False)
    assert result.metadata["batch_size"] == 1
    single = jax.jit(lambda a, f: jj.jmse(a, f, 0.2, SIGNAL, NOISE))
    loop = [float(single(a, f)) for a, f, _, _ in DESIGNS]
    tiers = {int(_tier_index(jj.aberration_strength(a, f, 0.2), 0.2, SMALL_TIERS))
             for a, f, _, _ in DESIGNS}
    assert tiers == {0, 1}
    np.testing.assert_allclose(result.value, loop, rtol=1e-12)


def _small_tiers_design_by_design(monkeypatch, balanced=None):
    """``SMALL_TIERS`` (and the balanced grid ``balanced``) without the one-ray plans, and the
    tiers' vectorised dispatch made to raise: for the tests that CPU's ``vmap`` runs the
    designs one at a time."""
    from jmse_jax import _merit

    _tiers_without_one_ray(monkeypatch, SMALL_TIERS, balanced)

    def vectorised(*args):
        raise AssertionError("the vectorised tier dispatch ran")

    monkeypatch.setattr(_merit, "_batched_tier", vectorised)


def test_float32_design_with_float64_spectra_differentiates(monkeypatch):
    """A float32 design with the signal and noise given as Python floats (float64 with x64
    on): the tier switch's derivative rule returns a float32 tangent (it raised a dtype
    error), and value and gradient equal the float64 ones of the grid that float32 runs to
    float32 accuracy."""
    from jmse_jax._otf import along_chord_order

    _tiers_without_one_ray(monkeypatch, SMALL_TIERS)
    ab, field, u, _ = DESIGNS[1]
    vag = jax.jit(jax.value_and_grad(lambda a, f: jj.jmse(a, f, u, SIGNAL, NOISE)))
    value32, grad32 = vag(_to_float32(ab), jnp.float32(field))
    ab64 = jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float64), ab)
    value64, _ = vag(ab64, jnp.float64(field))
    # The oracle: the fixed grid the tier runs (its shortcut is refused on such coarse grids);
    # in float32 the overlap engine takes 16 nodes along the chords for the grid's 10
    # (``along_chord_order``), so float32's oracle is that grid in float64.
    assert value32.dtype == jnp.float32 and grad32.w020.dtype == jnp.float32
    assert float(value64) == pytest.approx(_fixed(ab, field, u, _SMALL), rel=1e-13)
    n_phi, n_t = _SMALL["overlap_nodes"]
    grid32 = dict(_SMALL, overlap_nodes=(n_phi, along_chord_order(n_t, jnp.float32)))
    assert grid32["overlap_nodes"] == (10, 16)
    oracle = jax.jit(jax.value_and_grad(lambda a, f: jj.jmse(a, f, u, SIGNAL, NOISE, **grid32)))
    expected, grad64 = oracle(ab64, jnp.float64(field))
    assert float(value32) == pytest.approx(float(expected), rel=1e-5)
    for name in ("w020", "w040", "w131", "w222", "w220"):
        np.testing.assert_allclose(getattr(grad32, name), getattr(grad64, name),
                                   rtol=1e-4, atol=1e-5 * float(expected))


@pytest.mark.slow
def test_vmap_gives_each_design_what_it_gets_alone(monkeypatch, vectorised_vmap):
    """Under vmap (value_and_grad, vectorised as on a GPU: the dispatch's batching rule)
    every design gets its own tier's grid, in a batch
    that mixes tiers, holds one design that keeps the shortcut's trial and one that refuses
    it, and leaves one tier unused (the batching rule skips tiers and grids no design needs).
    Three designs on the axis take the one-ray plans of both groups of tiers
    (``_radial_plans``: tiers 0-1 and 2-3). The oracle is the unbatched evaluation, which
    the tests above (and tests/test_radial.py for the one-ray plans) check grid by grid."""
    trial = dict(nodes=(8, 4), se_nodes=(40, 16), overlap_nodes=(8, 8))
    check = dict(nodes=(6, 4), se_nodes=(30, 12), overlap_nodes=(6, 6))
    middle = [DESIGNS[1], DEFOCUS_M6]  # both in the middle tier below
    disagreement = [abs(_fixed(ab, f, u, trial) / _fixed(ab, f, u, check) - 1.0)
                    for ab, f, u, _ in middle]
    rtol = math.sqrt(disagreement[0] * disagreement[1])  # one keeps the trial, one refuses
    assert min(disagreement) < rtol < max(disagreement)
    tiers = (
        (1.0, math.inf, trial, None),
        (10.0, math.inf, _SMALL, jj.TierShortcut(trial=trial, check=check, rtol=rtol)),
        (12.0, math.inf, dict(nodes=(14, 8), se_nodes=(70, 28), overlap_nodes=(12, 12)), None),
        (math.inf, math.inf, dict(nodes=(16, 8), se_nodes=(80, 32), overlap_nodes=(12, 12)),
         None),
    )
    monkeypatch.setitem(jj.PRESETS["default"], "tiers", tiers)
    designs = [DESIGNS[0], *middle, ALL_5]  # strengths 0.2, 3.1, 3.4, 14.7: tier 2 unused
    assert [int(_tier_index(float(jj.aberration_strength(ab, f, u)), u, tiers))
            for ab, f, u, _ in designs] == [0, 1, 1, 3]

    # On the axis: strengths 0.11 and 1.7 (tiers 0 and 1, the first one-ray plan) and 13.6
    # (tier 3, the second).
    on_axis = [(jj.Seidel(w020=0.2), 0.0), (jj.Seidel(w020=8.0, w040=-4.0), 0.0),
               (jj.Seidel(w020=24.0), 0.0)]
    assert [int(_tier_index(float(jj.aberration_strength(ab, f, 0.2)), 0.2, tiers))
            for ab, f in on_axis] == [0, 1, 3]

    def merit(a, f):
        return jj.jmse(a, f, 0.2, SIGNAL, NOISE)

    # The value-only rule is checked with the real tiers above
    # (test_vmap_over_designs_in_different_tiers).
    assert_vmap_matches_singles(merit, [(ab, f) for ab, f, _, _ in designs] + on_axis)


#: Designs for the CPU ``vmap`` tests: tiers 0 and 1 of ``SMALL_TIERS``, defocus -6, and a
#: design whose terms cancel (the balanced grid).
CPU_VMAP_DESIGNS = [DESIGNS[0], DESIGNS[1], DEFOCUS_M6, MEDIAL_FOCUS]


def _cpu_vmap_batch(monkeypatch):
    """``_small_tiers_design_by_design`` with ``SMALL_BALANCED``, and the batch of
    ``CPU_VMAP_DESIGNS`` (coefficients, fields); the last design takes the balanced grid."""
    from jmse_jax import _merit

    assert jax.default_backend() in _merit.SEQUENTIAL_VMAP_BACKENDS
    _small_tiers_design_by_design(monkeypatch, SMALL_BALANCED)
    route = _merit._route(*MEDIAL_FOCUS[:3], SIGNAL, NOISE)
    assert route["balanced"] and route["tier"] == len(SMALL_TIERS)
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack([jnp.asarray(v, jnp.float64) for v in x]),
                                   *[jj.Seidel(**_coefficients(d[0])) for d in CPU_VMAP_DESIGNS])
    return batch, jnp.asarray([d[1] for d in CPU_VMAP_DESIGNS])


def _cpu_merit(a, f, u=0.2):
    return jj.jmse(a, f, u, SIGNAL, NOISE)


def test_vmap_runs_design_by_design_on_cpu(monkeypatch):
    """On CPU ``vmap`` of ``jmse`` runs the designs one at a time
    (``SEQUENTIAL_VMAP_BACKENDS``): the tiers' vectorised dispatch is never reached (it
    raises here), and every design, the one whose terms cancel (balanced grid) included,
    gets bit for bit what it gets alone, in a batch over designs. A batch over ``u`` only:
    the next test (slow); ``value_and_grad`` under ``vmap``: the one after (slow); forward
    mode and the Hessian: the one after that."""
    batch, fields = _cpu_vmap_batch(monkeypatch)
    values = jax.jit(jax.vmap(_cpu_merit))(batch, fields)
    single = jax.jit(_cpu_merit)
    for i, (ab, f, _, _) in enumerate(CPU_VMAP_DESIGNS):
        assert float(values[i]) == float(single(jj.Seidel(**_coefficients(ab)), jnp.float64(f)))


# Slow: two more programs of the small tiers (about 25 s on the CI machine); ``vmap`` over
# designs on CPU keeps its default-run check in the test above.
@pytest.mark.slow
def test_vmap_over_u_alone_runs_design_by_design_on_cpu(monkeypatch):
    """A batch over ``u`` alone (the design and field broadcast to it), as the test above:
    each ``u`` bit for bit what it gets alone."""
    _small_tiers_design_by_design(monkeypatch, SMALL_BALANCED)
    single = jax.jit(_cpu_merit)
    ab, f = jj.Seidel(**_coefficients(DESIGNS[1][0])), jnp.float64(DESIGNS[1][1])
    us = jnp.asarray([0.15, 0.2, 0.3])
    over_u = jax.jit(jax.vmap(lambda u: _cpu_merit(ab, f, u)))(us)
    for i, u in enumerate(us):
        assert float(over_u[i]) == float(single(ab, f, u))


# Slow: three more programs of the small tiers (about 70 s on the CI machine).
@pytest.mark.slow
def test_value_and_grad_under_vmap_runs_design_by_design_on_cpu(monkeypatch):
    """``vmap`` of ``value_and_grad`` on CPU, as the test above: each design gets bit for bit
    the value and gradient it gets alone (and the value's batch that value, to 1e-14), and
    the design whose terms cancel its balanced grid's (the oracle: that grid fixed)."""
    batch, fields = _cpu_vmap_batch(monkeypatch)
    vag = jax.value_and_grad(_cpu_merit, argnums=(0, 1))
    values = jax.jit(jax.vmap(_cpu_merit))(batch, fields)
    values_g, (grads, field_grads) = jax.jit(jax.vmap(vag))(batch, fields)
    single_vag = jax.jit(vag)
    for i, (ab, f, _, _) in enumerate(CPU_VMAP_DESIGNS):
        value, (grad, field_grad) = single_vag(jj.Seidel(**_coefficients(ab)), jnp.float64(f))
        assert float(values_g[i]) == float(value)
        # The value-only program is another program, whose sums XLA may order otherwise: with
        # jax 0.7.2 it differed from the gradient's value in the last bits (5.6190050536372724e-05
        # against 5.619005053637274e-05; jax 0.10.2 gives both to the bit).
        assert float(values[i]) == pytest.approx(float(value), rel=1e-14)
        assert float(field_grads[i]) == float(field_grad)
        for name in ("w020", "w040", "w131", "w222", "w220"):
            assert float(getattr(grads, name)[i]) == float(getattr(grad, name))
    ab, f, u, _ = MEDIAL_FOCUS
    oracle, oracle_grad = jax.value_and_grad(
        lambda a: jj.jmse(a, f, u, SIGNAL, NOISE, **SMALL_BALANCED))(ab)
    assert float(values_g[-1]) == pytest.approx(float(oracle), rel=1e-13)
    for name in ("w020", "w222"):
        np.testing.assert_allclose(float(getattr(grads, name)[-1]),
                                   float(getattr(oracle_grad, name)), rtol=1e-10)


@pytest.mark.slow
def test_forward_mode_and_hessian_under_vmap_on_cpu(monkeypatch):
    """The CPU ``vmap`` tests above, for forward mode and second derivatives (their programs
    take about a minute to compile, so they run with ``make test-slow``): on CPU ``jacfwd``
    equals the gradient, the Hessian equals central differences of the gradient, and a
    ``vmap`` of the Hessian gives each design what it gets alone, without reaching the
    vectorised dispatch."""
    _small_tiers_design_by_design(monkeypatch)

    def merit(a, f, u=0.2):
        return jj.jmse(a, f, u, SIGNAL, NOISE)

    ab, f = jj.Seidel(**_coefficients(DESIGNS[1][0])), jnp.float64(DESIGNS[1][1])
    # Forward mode and second derivatives, in the coefficient vector.
    c0 = jnp.asarray([getattr(ab, k) for k in ("w020", "w040", "w131", "w222", "w220")])

    def of_vector(c):
        return merit(jj.Seidel(**dict(zip(("w020", "w040", "w131", "w222", "w220"), c,
                                          strict=True))), f)

    gradient = jax.jit(jax.grad(of_vector))
    np.testing.assert_allclose(jax.jit(jax.jacfwd(of_vector))(c0), gradient(c0), rtol=1e-12)
    hessian = jax.jit(jax.hessian(of_vector))(c0)
    h = 1e-5
    for k in (0, 2):
        step = jnp.zeros(5).at[k].set(h)
        column = (gradient(c0 + step) - gradient(c0 - step)) / (2 * h)
        np.testing.assert_allclose(hessian[:, k], column, rtol=1e-5,
                                   atol=1e-6 * float(jnp.max(jnp.abs(hessian))))
    batched = jax.jit(jax.vmap(jax.hessian(of_vector)))(jnp.stack([c0, 0.5 * c0]))
    np.testing.assert_allclose(batched[0], hessian, rtol=1e-12,
                               atol=1e-14 * float(jnp.max(jnp.abs(hessian))))


@pytest.mark.parametrize("first_tol, kept", [
    (None, "trial"),
    pytest.param(math.inf, "first", marks=pytest.mark.slow),
    pytest.param(-1.0, "trial", marks=pytest.mark.slow),
])
def test_shortcut_is_tried_only_up_to_u_max(monkeypatch, first_tol, kept):
    """Above ``u_max`` a tier skips its shortcut and runs its own grid, in every path (eager,
    jit, value_and_grad, vmap over u mixing both sides). With ``rtol = 1`` an eligible
    design always agrees with the check, so it keeps the first grid when its estimate
    passes (``first_tol = inf``), else the trial (no first grid, or ``first_tol < 0``): the
    oracle is that grid below ``u_max`` and the tier's grid above it. (The default's
    ``u_max`` is 1/sqrt(2): beyond it a trial and the check missed H's edge at the cutoff
    alike and agreed on a value 2e-4 off.)"""
    trial = dict(nodes=(8, 4), se_nodes=(40, 16), overlap_nodes=(8, 8))
    check = dict(nodes=(6, 4), se_nodes=(30, 12), overlap_nodes=(6, 6))
    first = dict(nodes=(10, 6), se_nodes=(50, 20), overlap_nodes=(9, 9))
    shortcut = jj.TierShortcut(trial=trial, check=check, rtol=1.0, u_max=0.3)
    if first_tol is not None:
        shortcut = shortcut._replace(first=first, first_tol=first_tol)
    tiers = ((math.inf, math.inf, _SMALL, shortcut),)
    if kept == "first":
        trial = first  # the grid the oracle takes below u_max
    ab, field, _, _ = DESIGNS[1]
    assert abs(_fixed(ab, field, 0.2, first) / _fixed(ab, field, 0.2, shortcut.trial) - 1) > 1e-4
    assert jj.DEFAULT_TIERS[1][3].u_max == pytest.approx(1 / math.sqrt(2))
    _tiers_without_one_ray(monkeypatch, tiers)
    ab, field, _, _ = DESIGNS[1]
    us = (0.2, 0.3, 0.4)
    expected = [_fixed(ab, field, u, trial if u <= 0.3 else _SMALL) for u in us]
    assert abs(expected[2] / _fixed(ab, field, 0.4, trial) - 1) > 1e-3  # the grids differ
    eager = [float(jj.jmse(ab, field, u, SIGNAL, NOISE)) for u in us]
    vag = jax.jit(jax.value_and_grad(lambda a, u: jj.jmse(a, field, u, SIGNAL, NOISE)))
    batched = jax.jit(jax.vmap(vag, in_axes=(None, 0)))(ab, jnp.asarray(us))
    for i, u in enumerate(us):
        oracle = jax.value_and_grad(lambda a, u=u: jj.jmse(
            a, field, u, SIGNAL, NOISE, **(trial if u <= 0.3 else _SMALL)))(ab)
        value, gradient = vag(ab, u)
        np.testing.assert_allclose([eager[i], value, batched[0][i]], expected[i], rtol=1e-13)
        for name in ("w020", "w222"):
            np.testing.assert_allclose([getattr(gradient, name), getattr(batched[1], name)[i]],
                                       getattr(oracle[1], name), rtol=1e-10)


@pytest.mark.slow
def test_second_derivatives_of_the_default(monkeypatch):
    """The Hessian of the default (forward over reverse through the tier switch and its
    batching rule) equals central differences of its gradient, in a tier with a shortcut
    (it raised an error when the batching rule was first added)."""
    _tiers_without_one_ray(monkeypatch, SMALL_TIERS)
    ab, field, u, _ = DESIGNS[1]
    base = _coefficients(ab)

    def merit(x):
        return jj.jmse(jj.Seidel(**{**base, "w020": x[0], "w222": x[1]}), field, u,
                       SIGNAL, NOISE)

    x = jnp.asarray([base["w020"], base["w222"]], jnp.float64)
    hessian = jax.jit(jax.hessian(merit))(x)
    gradient = jax.jit(jax.grad(merit))
    h = 1e-4
    columns = [(gradient(x + h * e) - gradient(x - h * e)) / (2 * h) for e in jnp.eye(2)]
    np.testing.assert_allclose(hessian, jnp.stack(columns, axis=1), rtol=1e-5,
                               atol=1e-7 * float(jnp.max(jnp.abs(hessian))))


def test_calls_outside_jit_compile_once(monkeypatch):
    """Called outside ``jit``, the default compiles each grid a design needs once and then
    reuses it (a second design of the same tier compiles nothing), and ``jax.grad`` applied
    without ``jit`` compiles its program on the first call only (each call of it ran the
    tier switch primitive by primitive, ~30 s on the CPU). Values and gradients equal the
    jitted ones."""
    from jmse_jax import _merit

    _tiers_without_one_ray(monkeypatch, SMALL_TIERS)
    ab, field, u, _ = DESIGNS[1]
    other = jj.Seidel(**{**_coefficients(ab), "w020": -2.5})

    def merit(a):
        return jj.jmse(a, field, u, SIGNAL, NOISE)

    first = merit(ab)
    compiled = _merit._compiled_merit._cache_size()
    second = merit(other)
    assert _merit._compiled_merit._cache_size() == compiled
    np.testing.assert_allclose([first, second], [jax.jit(merit)(ab), jax.jit(merit)(other)],
                               rtol=1e-13)

    # Differentiated without jit, only the grid each design takes is compiled (once): the
    # tiers' program is not (an eager jax.grad of the Fig. 1 point compiled for 44 s).
    grad = jax.grad(merit)
    traced = _merit._traced_merit._cache_size()
    g_first = grad(ab)
    ruled = _merit._grid_with_rule._cache_size()
    g_second = grad(other)
    assert _merit._grid_with_rule._cache_size() == ruled
    assert _merit._traced_merit._cache_size() == traced
    for got, a in ((g_first, ab), (g_second, other)):
        want = jax.jit(jax.grad(merit))(a)
        for name in ("w020", "w040", "w131", "w222", "w220"):
            np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=1e-12,
                                       atol=1e-16)


def test_second_derivatives_outside_jit_differentiate_the_grid_taken(monkeypatch):
    """A Hessian taken without ``jit`` differentiates the grid the design takes alone
    (chosen on the concrete design its tracers carry), not the tiers' program: at the
    Fig. 1 point that compiled for 280 s and now for 15 s. It equals central differences
    of the gradient in the coefficients and in ``u``; so does reverse mode over reverse
    mode (``jax.jacrev`` of ``jax.jacrev``), which the tiers' program refuses."""
    from jmse_jax import _merit

    _tiers_without_one_ray(monkeypatch, SMALL_TIERS)
    ab, field, u, _ = DESIGNS[1]
    base = _coefficients(ab)

    def merit(x):
        return jj.jmse(jj.Seidel(**{**base, "w020": x[0], "w222": x[1]}), field, x[2],
                       SIGNAL, NOISE)

    x = jnp.asarray([base["w020"], base["w222"], u], jnp.float64)
    traced = _merit._traced_merit._cache_size()
    hessian = jax.hessian(merit)(x)
    reverse = jax.jacrev(jax.jacrev(merit))(x)
    assert _merit._traced_merit._cache_size() == traced
    gradient = jax.grad(merit)
    h = 1e-5  # d2/du2's central difference is 3e-5 off at 1e-4 (truncation)
    columns = [(gradient(x + h * e) - gradient(x - h * e)) / (2 * h) for e in jnp.eye(3)]
    scale = float(jnp.max(jnp.abs(hessian)))
    np.testing.assert_allclose(hessian, jnp.stack(columns, axis=1), rtol=1e-5,
                               atol=1e-7 * scale)
    np.testing.assert_allclose(reverse, hessian, rtol=1e-10, atol=1e-13 * scale)


def _on_the_axis(monkeypatch):
    """``SMALL_TIERS`` with the one-ray plans, and the merit of ``x = (w020, w040, field)``
    at the Fig. 1 design's other coefficients, for designs on the axis."""
    monkeypatch.setitem(jj.PRESETS["default"], "tiers", SMALL_TIERS)
    monkeypatch.setitem(jj.PRESETS["default"], "balanced", None)
    base = _coefficients(DESIGNS[1][0])

    def merit(x):
        return jj.jmse(jj.Seidel(**{**base, "w020": x[0], "w040": x[1]}), x[2], 0.2,
                       SIGNAL, NOISE)

    return merit, np.array([base["w020"], base["w040"], 0.0])


def test_derivatives_on_the_axis_outside_jit_take_the_one_ray(monkeypatch):
    """A design on the axis differentiated without ``jit`` compiles its one-ray plan alone,
    not the tiers' program (which compiled for 40 s at the default's tiers): the gradient
    in the radial terms equals Richardson differences of concrete calls (the one ray's
    values), and the one in the field is zero (coma and astigmatism carry a power of it)."""
    from jmse_jax import _merit

    merit, x = _on_the_axis(monkeypatch)
    traced = _merit._traced_merit._cache_size()
    grad = np.asarray(jax.grad(merit)(jnp.asarray(x)))
    assert _merit._traced_merit._cache_size() == traced
    for i in (0, 1):
        want = richardson_difference(merit, x, i, 1e-4)
        assert grad[i] == pytest.approx(want, rel=1e-8)
    assert grad[2] == 0.0


@pytest.mark.slow
def test_second_derivatives_on_the_axis_outside_jit_are_the_programs(monkeypatch):
    """The Hessian of a design on the axis taken without ``jit`` is the traced program's:
    the polar grid's second derivatives (``d^2 J / d field^2``, which the one ray gets
    wrong, ``tests/test_radial.py``), bit for bit those of the jitted Hessian."""
    from jmse_jax import _merit

    merit, x = _on_the_axis(monkeypatch)
    traced = _merit._traced_merit._cache_size()
    eager = np.asarray(jax.hessian(merit)(jnp.asarray(x)))
    assert _merit._traced_merit._cache_size() == traced
    jitted = np.asarray(jax.jit(jax.hessian(merit))(jnp.asarray(x)))
    np.testing.assert_allclose(eager, jitted, rtol=1e-12, atol=1e-15)
    assert eager[2, 2] < -1e-3


@pytest.mark.slow
def test_derivative_rule_differentiates_only_the_operands_with_tangents(monkeypatch):
    """The tier switch's derivative rule takes the gradient only in the operands that carry
    a tangent: forward mode in one coefficient did form the gradient in ``u``, the field and
    the spectra as well (through every node's position; 3x the time of ``value_and_grad``
    and 3x its compile time). Each directional derivative equals a central difference."""
    from jmse_jax import _merit

    _tiers_without_one_ray(monkeypatch, SMALL_TIERS)
    jax.clear_caches()  # the rule runs when a transformation is traced, not from a cache
    masks = []
    original = _merit._value_and_grad

    def spy(fn, wrt):
        masks.append(wrt)
        return original(fn, wrt)

    monkeypatch.setattr(_merit, "_value_and_grad", spy)
    ab, field, u, _ = DESIGNS[1]
    n_ab = len(jax.tree_util.tree_leaves(ab))

    def merit(w020=0.0, du=0.0, noise=0.0):
        a = jj.Seidel(**{**_coefficients(ab), "w020": ab.w020 + w020})
        return jj.jmse(a, field, u + du, SIGNAL, jj.WhiteNoise(NOISE.variance + noise))

    h = {"w020": 1e-5, "du": 1e-6, "noise": 1e-8}
    for name, step in h.items():
        masks.clear()
        _, tangent = jax.jit(lambda t, name=name: jax.jvp(
            lambda s: merit(**{name: s}), (t,), (1.0,)))(0.0)
        live = {i for mask in masks for i, w in enumerate(mask) if w}
        assert masks and all(len(m) == len(masks[0]) for m in masks)
        want = {"w020": {0}, "du": {n_ab + 1}, "noise": {len(masks[0]) - 1}}[name]
        assert live == want, (name, live)
        central = (merit(**{name: step}) - merit(**{name: -step})) / (2 * step)
        np.testing.assert_allclose(tangent, central, rtol=1e-6)


@pytest.mark.parametrize("overlap, floor, expected", [
    ((20, 20), 10, {(12, 12), (14, 14), (20, 20)}),
    ((28, 20), 10, {(13, 12), (18, 14), (28, 20)}),
    ((20, 20), 24, {(20, 20)}),
])
def test_overlap_floor_sets_each_radial_panel_order(monkeypatch, overlap, floor, expected):
    """On a radial panel that ends at ``t_max`` of the ray the overlap order is
    ``ceil(floor + (n - floor) t_max)`` per axis, at most ``n``: with 24 radial nodes the
    panels (7, 7 and 10 nodes) end at 0.15, 0.4 and 1."""
    from jmse_jax import _merit

    orders = []
    original = _merit._otf_overlap

    def spy(aberrations, nu_x, nu_y, field, nodes, remat=False):
        orders.append((tuple(nodes), nu_x.shape[-1]))
        return original(aberrations, nu_x, nu_y, field, nodes, remat)

    monkeypatch.setattr(_merit, "_otf_overlap", spy)
    ab, field, u, _ = DESIGNS[1]
    jax.jit(lambda a: jj.jmse(a, field, u, SIGNAL, NOISE, nodes=(24, 12), se_nodes=(96, 24),
                              overlap_nodes=overlap, overlap_floor=floor))(ab)
    assert {order for order, _ in orders} == expected
    assert sorted(count for _, count in orders) == [7, 7, 10]


@pytest.mark.parametrize("dtype, expected", [
    ("float64", {(12, 12), (14, 14), (20, 20)}),
    ("float32", {(12, 16), (14, 16), (20, 24)}),
])
def test_float32_rounds_the_order_along_the_chords_to_a_multiple_of_8(monkeypatch, dtype,
                                                                       expected):
    """The engine's order along the chords (``_otf.along_chord_order``): as asked in
    float64, rounded up to a multiple of 8 in float32 (the panel orders of
    ``test_overlap_floor_sets_each_radial_panel_order``'s first case)."""
    from jmse_jax import _otf

    orders = set()
    original = _otf._otf_overlap_flat

    def spy(aberrations, nu_x, nu_y, field, n_phi, n_t, dtype_, *rest):
        orders.add((n_phi, n_t))
        return original(aberrations, nu_x, nu_y, field, n_phi, n_t, dtype_, *rest)

    monkeypatch.setattr(_otf, "_otf_overlap_flat", spy)
    ab, field, u, _ = DESIGNS[1]
    ab = jax.tree.map(lambda c: jnp.asarray(c, dtype), ab)
    value = jax.jit(lambda a: jj.jmse(a, jnp.asarray(field, dtype), jnp.asarray(u, dtype),
                                      SIGNAL, NOISE, nodes=(24, 12), se_nodes=(96, 24),
                                      overlap_nodes=(20, 20), overlap_floor=10))(ab)
    assert value.dtype == jnp.dtype(dtype)
    assert orders == expected


def test_weak_tiers_floor_is_accurate_and_binds():
    """Tier 0's grid (also the shortcut's trial) with its lowered floor against the same
    grid with the full order on every panel: within 1e-7 on the tier-0 and Fig. 1 designs
    (the bank's references are checked in ``test_shortcut_keeps_the_middle_tier_accurate``),
    and the floor binds (it is below the grid's orders, so the inner panels use fewer)."""
    for ab, field, u, tier in DESIGNS[:2]:
        grid = dict(jj.DEFAULT_TIERS[0][2])
        assert grid["overlap_floor"] < min(grid["overlap_nodes"])
        reduced = float(jj.jmse(ab, field, u, SIGNAL, NOISE, **grid))
        full = float(jj.jmse(ab, field, u, SIGNAL, NOISE,
                             **dict(grid, overlap_floor=max(grid["overlap_nodes"]))))
        assert abs(reduced - full) <= 1e-7 * full, (tier, reduced, full)


def test_route_reports_the_one_ray_plan_and_fixed_grids():
    """``_route`` (the benchmarks' report of the plan ``jmse`` takes): a rotationally
    symmetric design runs a one-ray plan, an explicit grid has no tier; the value it
    returns is ``jmse``'s."""
    ab = jj.Seidel(w020=-1.5, w040=0.8)
    route = _route(ab, 0.0, 0.2, SIGNAL, NOISE)
    tier = int(_tier_index(float(jj.aberration_strength(ab, 0.0, 0.2)), 0.2, jj.DEFAULT_TIERS))
    assert route["one_ray"] and route["path"] == "grid" and route["tier"] == tier
    assert float(route["value"]) == float(jj.jmse(ab, 0.0, 0.2, SIGNAL, NOISE))
    grid = dict(nodes=(16, 8), se_nodes=(64, 16), overlap_nodes=(12, 12))
    fixed = _route(*DESIGNS[0][:3], SIGNAL, NOISE, **grid)
    assert (fixed["tier"], fixed["path"], fixed["one_ray"]) == (None, "grid", False)
    assert float(fixed["value"]) == float(jj.jmse(*DESIGNS[0][:3], SIGNAL, NOISE, **grid))

"""The one-ray integral for rotationally symmetric designs (``jmse_jax._radial``).

Oracles: SciPy's Cartesian double integral of the aberration-free lens (independent of any
polar geometry), the polar grid of ``_merit`` (a different integrator over the same band),
finite differences, and the symmetry of the JMSE in the field height.
"""

from __future__ import annotations

import functools
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import oracles
import problems
import pytest
from compiled import fast_value_and_grad_in_everything, jmse_fn

import jmse_jax as jj
from jmse_jax import _merit, _radial
from jmse_jax._merit import _radial_plans, _tier_index

SIGNAL, NOISE = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)
SYMMETRIC = jj.Seidel(w020=-2.0, w040=1.2, w220=0.7)  # rotationally symmetric at any field


def _planar(ab, field, u, signal=SIGNAL, noise=NOISE, **grid):
    """The polar-grid value of the given grid (a grid override turns the one-ray path off)."""
    grid = grid or dict(nodes=(64, 40), se_nodes=(1600, 960), overlap_nodes=(48, 48))
    return float(jmse_fn(**grid)(ab, field, u, signal, noise))


def _one_ray(ab, field, u, signal=SIGNAL, noise=NOISE, **grid):
    """``_merit_value`` of the one-ray plan of ``grid`` (the tier-1 grid by default)."""
    grid = grid or jj.DEFAULT_TIERS[1][2]
    program = _one_ray_program(tuple(sorted(grid.items())), _radial._SUBTRACT)
    return float(program(ab.without_tilt(), jnp.float64(field), jnp.float64(u), signal, noise))


@functools.cache
def _one_ray_program(grid, subtract):
    """The one-ray plan of the grid (a sorted tuple of options), jitted once per grid and
    setting of the peak correction (``_radial._SUBTRACT``, read when traced). Run eagerly, op
    by op, its first call took 16 s."""
    options = {**jj.jmse_options("default", **dict(grid)), "_radial": True}
    return jax.jit(functools.partial(_merit._merit_value, options, jnp.float64))


def test_symmetry_predicate():
    coma = jj.Seidel(w020=1.0, w131=0.5)
    astigmatism = jj.Seidel(w020=1.0, w222=0.5)
    assert bool(coma.radially_symmetric(0.0)) and not bool(coma.radially_symmetric(0.3))
    assert bool(astigmatism.radially_symmetric(0.0))
    assert not bool(astigmatism.radially_symmetric(1.0))
    assert bool(jj.Seidel(w020=1.0, w220=2.0, w311=1.0, w111=3.0).radially_symmetric(0.9))
    # Zernike: static when no angular term is listed (tilts do not count), else traced.
    assert jj.Zernike([0.1, 0.2, 0.3, 0.4], noll=(2, 3, 4, 11)).radially_symmetric(0.0) is True
    mixed = jj.Zernike([0.5, 0.0, 0.2], noll=(4, 5, 11))
    assert bool(mixed.radially_symmetric(0.0))
    assert not bool(jj.Zernike([0.5, 0.1, 0.2], noll=(4, 5, 11)).radially_symmetric(0.0))
    assert jj.AbstractAberrations.radially_symmetric(coma, 0.0) is False  # the safe default


@pytest.mark.parametrize("family", ["seidel", "zernike"])
def test_symmetric_part_is_the_angular_mean(family):
    """``symmetric_part`` (what the one ray integrates) against a brute-force oracle: the
    mean of the wavefront less its tilt over 64 angles at each radius, for random designs
    that are not symmetric (every term present), at a field off the axis. Its first
    derivatives then carry each term's radial part, which is what a change of that term
    does to the merit at a symmetric design (``first_order_symmetric``)."""
    rng = np.random.default_rng(3)
    field = 0.6
    if family == "seidel":
        ab = jj.Seidel(*rng.normal(size=7))
    else:
        ab = jj.Zernike(rng.normal(size=36), noll=tuple(range(2, 38)))
    rho = np.linspace(0.0, 1.0, 11)[:, None]
    theta = 2 * np.pi * np.arange(64)[None, :] / 64  # exact for every order below 64
    x, y = rho * np.sin(theta), rho * np.cos(theta)
    mean = np.mean(np.asarray(jj.wavefront(ab.without_tilt(), x, y, field)), axis=1)
    part = ab.without_tilt().symmetric_part(field)
    # Evaluated at 0.3 rad from the y axis: the part is rotationally symmetric.
    along = np.asarray(jj.wavefront(part, rho[:, 0] * math.sin(0.3), rho[:, 0] * math.cos(0.3),
                                    field))
    np.testing.assert_allclose(along, mean, rtol=0, atol=1e-13)
    assert bool(part.radially_symmetric(field))
    if family == "zernike":
        assert part.noll == (4, 11, 22, 37)
        assert not ab.first_order_symmetric(field)  # Z14, Z26: cos 4 theta
        assert jj.Zernike(np.ones(3), noll=(4, 6, 12)).first_order_symmetric(field)
    else:
        assert ab.first_order_symmetric(field)


@pytest.mark.parametrize("u", [0.3, 0.85, 1.2])
def test_aberration_free_lens_equals_cartesian_oracle(u):
    """Every piece of the ray: [0, u] and the corners before the cutoff (0.3), the cutoff
    inside the corners (0.85), the whole disc inside the band (1.2)."""
    def s_e(x, y):
        r = np.hypot(x, y)
        return oracles.error_spectral_density(oracles.diffraction_limited_otf(r),
                                              oracles.markov_psd(r, 1.0, 5.0), 1e-3)

    if u < 1:
        expected = oracles.square_integral(s_e, u, tol=1e-13) / (2 * math.pi)
    else:  # split at the cutoff circle, where S_e has a kink
        from scipy import integrate
        inside, _ = integrate.quad(lambda r: (s_e(r, 0.0) - oracles.markov_psd(r, 1.0, 5.0)) * r,
                                   0, 1, epsabs=1e-15, epsrel=1e-13, limit=200)
        outside = oracles.square_integral(
            lambda x, y: oracles.markov_psd(np.hypot(x, y), 1.0, 5.0), u, tol=1e-13)
        expected = (2 * math.pi * inside + outside) / (2 * math.pi)
    assert _one_ray(jj.Seidel(), 0.0, u) == pytest.approx(expected, rel=1e-10)
    # jmse takes this path for the aberration-free lens.
    assert float(jmse_fn()(jj.Seidel(), 0.0, u, SIGNAL, NOISE)) == pytest.approx(expected,
                                                                                 rel=1e-10)


@pytest.mark.parametrize("ab, field", [
    (SYMMETRIC, 0.6),
    (jj.Seidel(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198), 0.0),
    (jj.Zernike([0.3, -0.1, 0.05], noll=(4, 11, 22)), 0.0),
])
@pytest.mark.parametrize("u", [0.2, 0.6, 1.3])
def test_one_ray_equals_polar_grid(ab, field, u):
    """Two integrators of the same band: the default (its one-ray plan) and the high
    preset's polar grid agree to 1e-9 on designs of a few waves. (Not for 0.71 < u < 1: there
    the polar grid's rays reach the cutoff at some angles only, a kink in the angle that its
    Gauss rule resolves slowly, 2e-5 at u = 0.9 on the first design; the aberration-free
    oracle above covers the one-ray geometry there.)"""
    assert bool(ab.without_tilt().radially_symmetric(field))
    value = float(jmse_fn()(ab, field, u, SIGNAL, NOISE))
    assert value == pytest.approx(_planar(ab, field, u), rel=1e-9)


# "high" slow: its program compiles for about 30 s on the CI machine (its Fig. 1 value
# stays in the default run, tests/test_merit.py).
@pytest.mark.parametrize("preset, rtol", [("fast", 1e-4), ("default", 1e-9),
                                          pytest.param("high", 1e-9, marks=pytest.mark.slow)])
def test_every_preset_resolves_the_ridges_of_a_high_snr_design(preset, rtol):
    """Noise 1e-4 and 6 waves of defocus: S_e has narrow ridges along the OTF's zeros. The
    bank's reference (one ray at 4x the default's fine count, within 2.2e-7 of the polar
    grid's strict value, whose own estimate is 1.9e-5). The fine count's floor (12800) keeps
    the default and ``high`` within 1e-9 (before it, ``high``'s 3200 nodes along the ray were
    1.4e-4 off) and the fast preset within its coarse OTF's 1.3e-5 (its polar grid: 1.8e-3)."""
    problem = problems.PROBLEMS_BY_NAME["defocus_6_noise_1e-4"]
    value = float(jmse_fn(preset=preset)(*problem.arguments()))
    assert value == pytest.approx(problem.reference, rel=rtol)


def test_strong_design_near_the_cutoff_against_a_finer_ray():
    """Strength 23 at u = 0.84: the default's one-ray plan against one ray at every count
    doubled or more (its error was 5.8e-5 with 6400 fine nodes; the polar grid of ``high``
    is 7e-3 off here)."""
    ab = jj.Seidel(w020=9.6, w040=0.75, w220=7.3)
    args = (ab, 0.2, 0.84, SIGNAL, jj.WhiteNoise(1.5e-3))
    fine = dict(nodes=(240, 56), se_nodes=(20000, 1920), overlap_nodes=(128, 128))
    expected = _one_ray(*args[:3], noise=args[4], **fine)
    value = float(jmse_fn()(*args))
    assert value == pytest.approx(expected, rel=1e-6)


#: Defocus set against spherical aberration, ``W = c (rho^2 - 0.6 rho^4)``, noise 1e-4:
#: (w020, u, group of the default's one-ray plans). Strength 5 at u = 0.2 (slope 18, weak)
#: and 44.9 at u = 0.5 (slope 64, strong); the plans as they were until 2026-12-01 (each its
#: group's last tier grid) were 2.4e-2 and 1.5e-1 off (``benchmarks/balanced_one_ray.py``).
BALANCED = [(25.39, 0.2, 0), (91.3, 0.5, 1)]
#: One ray with every count well past the plans' (the benchmark's reference agrees with it
#: to 3e-13 on both designs).
BALANCED_REFERENCE = dict(nodes=(256, 48), se_nodes=(9600, 256), overlap_nodes=(192, 192))


@pytest.mark.parametrize("w020, u, group", BALANCED)
def test_balanced_spherical_on_the_axis(w020, u, group):
    """The default (as a user calls it) takes the one-ray plan of the design's group and is
    within 2e-5 of the converged ray, where the group's last tier grid alone is > 1e-3 off."""
    ab, noise = jj.Seidel(w020=w020, w040=-0.6 * w020), jj.WhiteNoise(1e-4)
    tier = int(_tier_index(float(jj.aberration_strength(ab, 0.0, u)), u, jj.DEFAULT_TIERS))
    plans = _merit._tier_plans(jj.jmse_options("default"), jj.DEFAULT_TIERS)
    _, split = _radial_plans(plans)
    assert int(tier >= split) == group
    expected = _one_ray(ab, 0.0, u, noise=noise, **BALANCED_REFERENCE)
    value = float(jj.jmse(ab, 0.0, u, SIGNAL, noise))
    assert value == pytest.approx(expected, rel=2e-5)
    last = plans[split - 1 if group == 0 else -1][0]
    bare = _one_ray(ab, 0.0, u, noise=noise,
                    **{k: last[k] for k in ("nodes", "se_nodes", "overlap_nodes")})
    assert abs(bare / expected - 1.0) > 1e-3


def test_balanced_spherical_off_the_axis_takes_the_balanced_tier():
    """``W = c (rho^2 - 0.7 rho^4)`` a hair off the axis (1e-7 waves of astigmatism at field
    1, which moves the JMSE by about 1e-8): its terms cancel (cancellation 6), so the default
    takes the balanced tier (``BALANCED_GRID``) without a warning, within 2e-5 of the
    symmetric design's converged ray, where its tier by strength (tier 2) alone was 8e-2
    off (``benchmarks/balanced_polar.py``); and so does the same design given as Zernike
    coefficients (``benchmarks/zernike_cancellation.py``)."""
    symmetric = jj.Seidel(w020=33.1, w040=-23.17)
    ab, u, noise = jj.Seidel(w020=33.1, w040=-23.17, w222=1e-7), 0.4, jj.WhiteNoise(1e-4)
    strength = float(jj.aberration_strength(ab, 1.0, u))
    assert int(_tier_index(strength, u, jj.DEFAULT_TIERS)) == 2
    expected = _one_ray(symmetric, 0.0, u, noise=noise, **BALANCED_REFERENCE)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        route = _merit._route(ab, 1.0, u, SIGNAL, noise)
    assert route["tier"] == len(jj.DEFAULT_TIERS) and not route["one_ray"]
    assert float(route["value"]) == pytest.approx(expected, rel=2e-5)
    tier2 = float(jj.jmse(ab, 1.0, u, SIGNAL, noise, **jj.DEFAULT_TIERS[2][2]))
    assert abs(tier2 / expected - 1.0) > 1e-2
    # The same wavefront as Zernike coefficients (Z4 and Z11, 1e-7 waves of Z6's kind): its
    # Zernike terms one by one cancel 2.5 at most, so it took tier 2 and was as far off;
    # measured in Seidel's shapes it takes the balanced tier too.
    zernike = jj.Zernike([(33.1 - 23.17) / (2 * math.sqrt(3)), 0.5e-7 / math.sqrt(6),
                          -23.17 / (6 * math.sqrt(5))], noll=(4, 6, 11))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        route = _merit._route(zernike, 1.0, u, SIGNAL, noise)
    assert route["tier"] == len(jj.DEFAULT_TIERS) and not route["one_ray"]
    assert float(route["value"]) == pytest.approx(expected, rel=2e-5)


#: ``"high"``'s own grid (its fixed options, without the balanced grid).
HIGH_OWN_GRID = {k: jj.PRESETS["high"][k]
                 for k in ("nodes", "se_nodes", "overlap_nodes", "overlap_floor", "peaks")}


def _high_route(ab, field, u, noise, expected, rtol, own, off):
    """``"high"``'s route for a design (``_merit._route``, no warning allowed), checked: its
    value within ``rtol`` of ``expected``, the jitted preset's the same, and ``own`` (the
    value of ``"high"``'s own grid) more than ``off`` from ``expected``."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        route = _merit._route(ab, field, u, SIGNAL, noise, preset="high")
    assert float(route["value"]) == pytest.approx(expected, rel=rtol)
    jitted = float(jmse_fn(preset="high")(ab, field, u, SIGNAL, noise))
    assert jitted == pytest.approx(float(route["value"]), rel=1e-12)
    assert abs(own / expected - 1.0) > off
    return route


# Slow: ``"high"``'s routes off its own grid (balanced, one ray, steep) compile the preset's
# program and their references, about 80 s together on the CI machine; the default's routes
# keep their checks in the default run, and ``"high"``'s Fig. 1 value and its strongest bank
# case theirs (tests/test_merit.py).
@pytest.mark.slow
def test_high_takes_its_balanced_grid_where_terms_cancel():
    """``W = c (rho^2 - 0.7 rho^4)`` at u = 0.2, strength 15, a hair off the axis: ``"high"``'s
    own grid was 2.6e-1 off there (``benchmarks/balanced_polar.py``). The preset takes its
    balanced grid (``HIGH_BALANCED_GRID``) without a warning, concrete and jitted alike,
    within 1e-6 of the symmetric design's converged ray (measured 4e-9,
    ``benchmarks/balanced_tier.py``)."""
    symmetric = jj.Seidel(w020=66.29, w040=-46.4)
    ab, u, noise = jj.Seidel(w020=66.29, w040=-46.4, w222=1e-7), 0.2, jj.WhiteNoise(1e-4)
    expected = _one_ray(symmetric, 0.0, u, noise=noise, **BALANCED_REFERENCE)
    own = float(jj.jmse(ab, 1.0, u, SIGNAL, noise, **HIGH_OWN_GRID))
    route = _high_route(ab, 1.0, u, noise, expected, 1e-6, own, 1e-1)
    assert route["balanced"] and route["tier"] is None and not route["one_ray"]


@pytest.mark.slow  # as the test above
def test_high_one_ray_plan_on_many_waves_on_the_axis():
    """32 waves of defocus on the axis at u = 0.5 (strength 45, slope 64): ``"high"``'s one
    ray with its own counts (overlap rule (48, 48)) was 1.5e-1 off at noise 1e-4 (5.1e-1 at
    1e-6). With ``HIGH_RAY_GRID`` the preset is within 1e-7 of the converged ray (measured
    1e-9), concrete and jitted."""
    ab, u, noise = jj.Seidel(w020=31.819805153394636), 0.5, jj.WhiteNoise(1e-4)
    expected = _one_ray(ab, 0.0, u, noise=noise, **BALANCED_REFERENCE)
    own = _one_ray(ab, 0.0, u, noise=noise, **HIGH_OWN_GRID)
    route = _high_route(ab, 0.0, u, noise, expected, 1e-7, own, 1e-2)
    assert route["one_ray"] and not route["steep"] and not route["balanced"]


#: The reference grid of ``benchmarks/small_u_single_terms.py``.
SMALL_U_REFERENCE = dict(nodes=(160, 96), se_nodes=(8000, 1920), overlap_nodes=(96, 96),
                         overlap_floor=96)


@pytest.mark.slow  # as the tests above
def test_high_takes_its_steep_grid_on_many_waves_at_small_u():
    """25 waves of coma at u = 0.3 (slope 58, past ``STEEP_SLOPE``): ``"high"``'s own grid was
    1.7e-2 off (``benchmarks/high_steep.py``). The preset takes its steep grid
    (``HIGH_STEEP_GRID``) without a warning, concrete and jitted alike, within 1e-5 of a
    finer polar grid."""
    ab, u = jj.Seidel(w131=24.74873734152916), 0.3
    expected = _planar(ab, 1.0, u, **SMALL_U_REFERENCE)
    own = _planar(ab, 1.0, u, **HIGH_OWN_GRID)
    route = _high_route(ab, 1.0, u, NOISE, expected, 1e-5, own, 1e-2)
    assert route["steep"] and not route["balanced"] and not route["one_ray"]
    # The Fig. 1 point keeps "high"'s own grid.
    fig1 = _merit._route(jj.Seidel(**problems.FIG1), 0.95, 0.2, SIGNAL, NOISE, preset="high")
    assert not (fig1["steep"] or fig1["balanced"] or fig1["one_ray"])


@pytest.mark.slow
@pytest.mark.parametrize("preset", ["default", "high"])
def test_balanced_tier_gradient_against_finite_differences(preset):
    """The balanced grid's gradient (jitted ``value_and_grad`` of the default or ``"high"``,
    which route the design there) against central differences of its own concrete values,
    in w020, w040 and the astigmatism, and its value against the concrete call's."""
    ab, u, noise = jj.Seidel(w020=33.1, w040=-23.17, w222=0.3), 0.4, jj.WhiteNoise(1e-4)
    assert _merit._route(ab, 1.0, u, SIGNAL, noise, preset=preset)["balanced"]
    merit = functools.partial(jj.jmse, preset=preset)
    value, grad = jax.jit(jax.value_and_grad(merit))(ab, 1.0, u, SIGNAL, noise)
    assert float(value) == pytest.approx(float(merit(ab, 1.0, u, SIGNAL, noise)), rel=1e-12)
    h = 1e-4
    for name in ("w020", "w040", "w222"):
        plus = jj.Seidel(**{**ab.__dict__, name: getattr(ab, name) + h})
        minus = jj.Seidel(**{**ab.__dict__, name: getattr(ab, name) - h})
        fd = (float(merit(plus, 1.0, u, SIGNAL, noise))
              - float(merit(minus, 1.0, u, SIGNAL, noise))) / (2 * h)
        assert float(getattr(grad, name)) == pytest.approx(fd, rel=1e-5, abs=1e-9), name


#: On-axis JMSE at high SNR as a 1-D adaptive integral (``scipy.integrate.quad``, relative
#: tolerance 1e-11, breakpoints at the OTF's zeros, the OTF at an overlap rule of (96, 96);
#: ``benchmarks/low_noise.py``, ``results/low_noise.json``): (Seidel coefficients, u,
#: noise, reference). MarkovSignal(1, 5): a noise of 1e-8 is a peak S_x/S_n of 1.6e10.
QUAD_REFERENCES = [
    (dict(w020=6.0), 0.2, 1e-6, 0.00195412615639988),
    (dict(w020=6.0), 0.2, 1e-7, 0.0006213250980252992),
    (dict(w020=6.0), 0.2, 1e-8, 0.00019660117798625857),
    (dict(w020=1.0), 0.2, 1e-8, 2.239323463124088e-05),
    (dict(w020=-2.0, w040=1.2), 0.5, 1e-8, 0.00011082578905453385),
]


@pytest.mark.parametrize("coefficients, u, noise, expected", QUAD_REFERENCES)
def test_peaks_at_the_otf_zeros_at_high_snr(coefficients, u, noise, expected):
    """At high SNR the peaks of S_e at the OTF's zero rings (height S_x, half-width
    sqrt(S_n / S_x) / |H'|) are narrower than the fine nodes along the ray; ``_zero_peaks``
    integrates each in closed form. Without it the default was 7.4e-5, 1.6e-3 and 2.6e-2 off
    on the three 6-wave cases and 1.1e-5 on defocus 1 (``test_the_peak_correction_matters``)."""
    value = float(jmse_fn()(jj.Seidel(**coefficients), 0.0, u, SIGNAL, jj.WhiteNoise(noise)))
    assert value == pytest.approx(expected, rel=1e-8)


@pytest.mark.parametrize("noise, warned", [(1e-6, False), (1e-7, True)])
def test_a_design_on_the_axis_warns_past_the_one_ray_plans_checked_snr(noise, warned):
    """One-ray designs are held to ``CHECKED_SNR_PEAKS`` (2e8; a noise of 1e-6 is a peak
    ``S_x / S_n`` of 1.57e8, 1e-7 of 1.57e9), not to the polar grids' ``CHECKED_SNR``:
    defocus balanced against spherical aberration was 1.4e-2 off at 1.6e10."""
    assert 2 * math.pi * 25 / 1e-6 < jj.CHECKED_SNR_PEAKS < 2 * math.pi * 25 / 1e-7
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        jj.jmse(jj.Seidel(w020=1.0), 0.0, 0.2, SIGNAL, jj.WhiteNoise(noise))
    messages = [str(w.message) for w in caught]
    assert [("one-ray plans" in m and "2e+08" in m) for m in messages] == ([True] * warned)


def test_the_peak_correction_matters(monkeypatch):
    """The references above tell the corrected ray from the plain one: with
    ``_zero_peaks`` off, 6 waves of defocus at a noise of 1e-8 are percents off."""
    coefficients, u, noise, expected = QUAD_REFERENCES[2]
    monkeypatch.setattr(_radial, "_SUBTRACT", False)
    value = _one_ray(jj.Seidel(**coefficients), 0.0, u, noise=jj.WhiteNoise(noise))
    assert abs(value - expected) > 1e-2 * expected
    monkeypatch.setattr(_radial, "_SUBTRACT", True)
    value = _one_ray(jj.Seidel(**coefficients), 0.0, u, noise=jj.WhiteNoise(noise))
    assert value == pytest.approx(expected, rel=1e-8)


# Slow: a float32 program of its own (about 20 s on the CI machine); float32 keeps its
# default-run check through the tier switch in tests/test_tiers.py
# (``test_float32_design_with_float64_spectra_differentiates``).
@pytest.mark.slow
def test_float32_at_high_snr_on_the_axis():
    """float32 through the peak correction (the fast preset's one-ray plan, whose correction
    is the default's): the value within 1e-4 of the float64 quad reference and a finite
    gradient. (Its gradient is only good to about 0.3 % at a peak ratio of 1.6e8 and 30 % at
    1.6e10: near a zero float32's OTF has too few digits for the peak's shape.)"""
    coefficients, u, noise, expected = QUAD_REFERENCES[2]  # 6 waves, noise 1e-8
    f32 = jnp.float32

    def merit(w020):
        return jj.jmse(jj.Seidel(w020=w020), f32(0.0), f32(u),
                       jj.MarkovSignal(f32(1.0), f32(5.0)), jj.WhiteNoise(f32(noise)),
                       preset="fast")

    value, gradient = jax.jit(jax.value_and_grad(merit))(f32(coefficients["w020"]))
    assert value.dtype == jnp.float32 and gradient.dtype == jnp.float32
    assert float(value) == pytest.approx(expected, rel=1e-4)
    assert np.isfinite(float(gradient))


def test_power_law_signal_and_noise_level():
    signal = jj.PowerLawSignal(1e-3, 2.0, 0.01)
    noise = jj.WhiteNoise(1e-4)
    expected = _planar(SYMMETRIC, 0.3, 0.4, signal, noise)
    assert _one_ray(SYMMETRIC, 0.3, 0.4, signal, noise) == pytest.approx(expected, rel=1e-9)


def test_default_dispatch_runs_the_one_ray_plan_of_its_group():
    """Eager and jit give the one-ray plan of the group of the design's tier; the same design
    a hair off the axis (a non-symmetric one) runs the polar grid and agrees to 1e-7."""
    ab = jj.Seidel(w020=-6.0, w040=1.0, w131=0.8)
    u = 0.2
    strength = float(jj.aberration_strength(ab, 0.0, u))
    plans = _merit._tier_plans(jj.jmse_options("default"), jj.DEFAULT_TIERS)
    radial, split = _radial_plans(plans)
    group = int(int(_tier_index(strength, u, jj.DEFAULT_TIERS)) >= split)
    grid = {k: radial[group][0][k] for k in ("nodes", "se_nodes", "overlap_nodes")}
    expected = _one_ray(ab, 0.0, u, **grid)
    assert float(jj.jmse(ab, 0.0, u, SIGNAL, NOISE)) == pytest.approx(expected, rel=1e-13)
    assert float(jmse_fn()(ab, 0.0, u, SIGNAL, NOISE)) == pytest.approx(expected, rel=1e-13)
    off_axis = float(jmse_fn()(ab, 1e-5, u, SIGNAL, NOISE))
    assert off_axis == pytest.approx(expected, rel=1e-7)
    assert off_axis != expected  # a different integrator ran


class _TiltedNoise(jj.WhiteNoise):
    """White noise that does not declare itself isotropic (as a user's noise model would not)."""

    @property
    def isotropic(self):
        return False


def test_anisotropic_spectra_or_a_grid_override_keep_the_polar_grid(monkeypatch):
    expected = float(jj.jmse(SYMMETRIC, 0.0, 0.2, SIGNAL, NOISE))  # the one-ray plan
    value = float(jj.jmse(SYMMETRIC, 0.0, 0.2, SIGNAL, _TiltedNoise(1e-3)))
    monkeypatch.setitem(jj.PRESETS["default"], "radial", False)
    assert value == float(jj.jmse(SYMMETRIC, 0.0, 0.2, SIGNAL, NOISE))  # the polar grid ran
    # The polar default keeps its shortcut's first grid here (6e-7 from the one-ray value),
    # within the shortcut's tolerance of 1e-5.
    assert value == pytest.approx(expected, rel=1e-5) and value != expected
    assert jj.jmse_options("default", nodes=(16, 8))["radial"] is False
    with pytest.raises(ValueError, match="unknown jmse option 'radial'"):
        jj.jmse_options("default", radial=False)


def _coefficients(ab):
    return {k: getattr(ab, k) for k in oracles.SEIDEL_KEYS}


def _value_and_grad(ab, field, u, variance, mu):
    """Value and gradient ``(d_ab, d_field, d_u, d_noise, d_mu)`` of the fast preset with
    ``MarkovSignal(1, mu)`` and ``WhiteNoise(variance)``, from the program of every
    operand's gradient that tests/test_merit.py uses too (``tests/compiled.py``).

    The fast preset: its one-ray plan takes the same derivative rules as the default's two
    (whose dispatch on the axis is checked by test_vmap_mixes_symmetric_and_other_designs
    and by the second-derivative tests) and compiles in 15 s instead of 80 s with every
    operand differentiated (d/du alone doubles the default's compile)."""
    value, (d_ab, d_p) = fast_value_and_grad_in_everything(
        ab, dict(field=field, u=u, noise=variance, variance=1.0, mu=mu))
    return value, (d_ab, d_p["field"], d_p["u"], d_p["noise"], d_p["mu"])


_AXIS_DESIGN = dict(w020=-1.5, w040=0.8, w131=0.6, w222=-0.4)


@pytest.mark.parametrize("coefficients, u, variance", [
    (_AXIS_DESIGN, 0.3, 1e-3), (_AXIS_DESIGN, 0.85, 1e-3), (_AXIS_DESIGN, 1.2, 1e-3),
    # A peak S_x/S_n of 1.6e10, 6 waves of defocus: several narrow peaks, so the zero's
    # position, slope and curvature and the spectra's slopes at it carry derivatives
    # through the closed-form peaks (``_radial._zero_peaks``).
    (dict(w020=6.0, w040=0.5), 0.3, 1e-8),
])
def test_gradients_on_the_axis(coefficients, u, variance):
    """Central differences in w020, w040, u, the noise and the correlation length (every
    evaluation on the axis runs the one-ray plan), and the exact zeros: the JMSE is even in
    the field height, and coma and astigmatism are multiplied by it."""
    ab = jj.Seidel(**coefficients)
    args = dict(field=0.0, u=u, variance=variance, mu=5.0)
    value, (grad, d_field, d_u, d_noise, d_mu) = _value_and_grad(ab, *args.values())

    def f(ab=ab, **change):
        return float(_value_and_grad(ab, *{**args, **change}.values())[0])

    def central(fn, x, h):
        return (fn(x + h) - fn(x - h)) / (2 * h)

    for name in ("w020", "w040"):
        def along(x, name=name):
            return f(jj.Seidel(**{**_coefficients(ab), name: x}))
        expected = central(along, float(getattr(ab, name)), 1e-5)
        assert float(getattr(grad, name)) == pytest.approx(expected, rel=1e-6)
    assert float(d_u) == pytest.approx(central(lambda x: f(u=x), u, 1e-6), rel=1e-6)
    assert float(d_noise) == pytest.approx(
        central(lambda x: f(variance=x), variance, 1e-5 * variance), rel=1e-6)
    assert float(d_mu) == pytest.approx(central(lambda x: f(mu=x), 5.0, 1e-5), rel=1e-6)
    scale = abs(float(grad.w020))
    for zero in (d_field, grad.w131, grad.w222, grad.w311, grad.w111):
        assert abs(float(zero)) <= 1e-12 * scale
    assert np.isfinite(float(value))


_FAST_SEIDEL = ("w020", "w040", "w131", "w222", "w220")


@functools.partial(jax.jit, static_argnames=("plane", "preset"))
def _fast_theta(theta, field, plane=False, preset="fast"):
    """The fast preset's JMSE of ``Seidel(*theta)`` (five coefficients) at u = 0.3;
    ``plane``: the polar grid of ``preset`` given explicitly, so that no design takes the
    one-ray plan."""
    ab = jj.Seidel(**dict(zip(_FAST_SEIDEL, theta, strict=True)))
    grid = dict(nodes=jj.PRESETS[preset]["nodes"]) if plane else {}
    return jj.jmse(ab, field, 0.3, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3),
                   preset=preset, **grid)


# Defocus, spherical and field curvature only: no coma or astigmatism, so rotationally
# symmetric at any field (the one-ray plan).
SYMMETRIC_THETA = np.array([1.0, 0.5, 0.0, 0.0, 0.3])


@pytest.mark.parametrize("field", [0.7, 0.0])
def test_derivatives_break_the_symmetry_correctly(field):
    """A design symmetric only because coma and astigmatism are zero (off the axis) or
    vanish (on it) takes the one-ray plan, for its value and, under differentiation, for its
    first derivatives: the one ray integrates the wavefront's radial part
    (``Seidel.symmetric_part``), and the band's turns and mirrors leave the merit unchanged,
    so a change that breaks the symmetry acts at first order as its radial part does.
    Oracles: central differences of the merit itself in the directions that keep the
    symmetry (defocus, spherical, field curvature, the field); off the axis, the exact
    identity d/dw222 = (h^2 / 2) d/dw020 (w222 h^2 y^2 is w222 h^2 rho^2 / 2 and a term
    cos 2 theta, which a quarter turn flips), and differences of the default's polar grid,
    an independent method 3e-5 more accurate than the fast polar grid here, which keeps
    the same identities; d/dw131 = 0 (a half turn flips coma). The one ray's derivative
    in w222 came out 0 before the radial part, so off the axis the gradient used to be the
    polar grid's, and the value under differentiation was the polar grid's too, not the
    plain call's. (Second derivatives, not zero in coma and astigmatism, nor in the field
    on the axis, where the one ray got the sign wrong, are always the polar grid's: the
    next two tests, run with ``make test-slow``.)"""
    theta = SYMMETRIC_THETA
    x = jnp.asarray(theta)
    value, (grad, d_field) = jax.jit(jax.value_and_grad(_fast_theta, argnums=(0, 1)))(
        x, field)
    grad = np.asarray(grad)
    scale = abs(grad[0])
    # Under differentiation the value is the one ray's, as in the plain call: from the
    # gradient's own pass since 2026-12-06 (not computed a second time), so equal to
    # rounding rather than to the bit (the fast polar grid is 3e-5 away).
    assert float(value) == pytest.approx(float(_fast_theta(x, field)), rel=1e-14)
    for i in (0, 1, 4):
        own = oracles.richardson_difference(lambda t: _fast_theta(jnp.asarray(t), field),
                                            theta, i, 1e-4)
        assert grad[i] == pytest.approx(own, rel=1e-8)
    assert grad[2] == 0.0
    tangent = jax.jvp(lambda t: _fast_theta(t, field), (x,), (jnp.eye(5)[3],))[1]
    assert float(tangent) == pytest.approx(grad[3], rel=1e-12, abs=1e-15)
    if field > 0:
        assert grad[3] == pytest.approx(0.5 * field**2 * grad[0], rel=1e-12)
        assert grad[3] > 1e-3
        along = oracles.richardson_difference(
            lambda h: _fast_theta(x, float(h[0])), np.array([field]), 0, 1e-4)
        assert float(d_field) == pytest.approx(along, rel=1e-8)
        plane = np.array([oracles.richardson_difference(
            lambda t: _fast_theta(jnp.asarray(t), field, plane=True, preset="default"),
            theta, i, 1e-4) for i in range(5)])
        np.testing.assert_allclose(grad, plane, rtol=0, atol=1e-8 * scale)
        # The polar grid keeps the same symmetry (its nodes are mirror images about the
        # band's diagonal, so a cos 2 theta change integrates to zero on it): where its
        # derivatives differ from the one ray's, the difference is its error in the radial
        # part, not in the integral of the change that breaks the symmetry.
        assert plane[3] == pytest.approx(0.5 * field**2 * plane[0], rel=1e-7)
        assert abs(plane[2]) <= 1e-9 * scale
    else:
        # Even in the field; coma and astigmatism carry a power of it.
        assert grad[3] == 0.0 and float(d_field) == 0.0

@pytest.mark.slow
def test_second_derivatives_break_the_symmetry_correctly():
    """The test above's design off the axis (field 0.7): second derivatives in coma and
    astigmatism, and across, are the polar grid's, not zero."""
    x, field = jnp.asarray(SYMMETRIC_THETA), 0.7
    # From the polar grid's gradient's differences (exact to ~1e-12, so a plain central
    # step suffices).
    hess = np.asarray(jax.jit(jax.hessian(_fast_theta))(x, field))
    plane_grad = jax.jit(jax.grad(functools.partial(_fast_theta, plane=True)))
    for i in (2, 3):
        e = np.zeros(5)
        e[i] = 1e-4
        column = (np.asarray(plane_grad(x + e, field))
                  - np.asarray(plane_grad(x - e, field))) / 2e-4
        np.testing.assert_allclose(hess[:, i], column, rtol=1e-4, atol=1e-9)
    assert abs(hess[2, 2]) > 1e-5 and abs(hess[3, 3]) > 1e-6


@pytest.mark.slow
def test_second_derivative_in_the_field_on_the_axis():
    """On the axis the field moves coma and astigmatism in at second order: d^2 J / dh^2
    there is the polar grid's (the one ray gave +7.6e-3 against -4.9e-2 on the Fig. 1
    design). Against the even function's difference quotient 2 (J(h) - J(0)) / h^2 with
    a Richardson step (J(h) for h > 0 is the polar grid's)."""
    ab = jj.Seidel(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)

    @jax.jit
    def merit(h):
        return jj.jmse(ab, h, 0.2, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3),
                       preset="fast")

    @jax.jit
    def plane(h):
        return jj.jmse(ab, h, 0.2, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3),
                       preset="fast", nodes=jj.PRESETS["fast"]["nodes"])

    second = float(jax.jit(jax.grad(jax.grad(merit)))(0.0))
    quotient = [2 * (float(plane(h)) - float(plane(0.0))) / h**2 for h in (1e-2, 5e-3)]
    assert second == pytest.approx((4 * quotient[1] - quotient[0]) / 3, rel=1e-3)
    assert second < 0
    assert float(jax.jit(jax.grad(merit))(0.0)) == 0.0  # even in h


# Z14's case slow: two more Zernike programs (about 17 s on the CI machine); the polar
# grid's Zernike derivatives keep their default-run check in tests/test_merit.py.
@pytest.mark.parametrize("noll", [(4, 6, 11, 12),
                                  pytest.param((4, 6, 11, 14), marks=pytest.mark.slow)])
def test_zernike_derivatives_off_the_symmetric_terms(noll):
    """A Zernike set with zero non-radial terms takes the one-ray plan for its value.
    Without a term cos(4k theta) (Z6 and Z12 are of m = 2) the one ray's first derivatives
    stand: those in the radial terms against differences of the merit itself (the changes
    keep the symmetry) and of the default's polar grid, and those in m = 2 terms zero, as a
    quarter turn flips them and leaves the merit unchanged (the one ray integrating the
    whole wavefront used to give -5e-3 and -4e-3 here). Z14 (cos 4 theta) keeps the band's
    symmetries and changes the merit at first order, which the one ray cannot see: there
    the derivatives are the polar grid's (against its differences), Z14's not zero."""

    @functools.partial(jax.jit, static_argnames=("plane", "preset"))
    def merit(c, plane=False, preset="fast"):
        grid = dict(nodes=jj.PRESETS[preset]["nodes"]) if plane else {}
        return jj.jmse(jj.Zernike(c, noll=noll), 0.0, 0.3, jj.MarkovSignal(1.0, 5.0),
                       jj.WhiteNoise(1e-3), preset=preset, **grid)

    c = np.array([0.8, 0.0, 0.3, 0.0])
    value, grad = jax.jit(jax.value_and_grad(merit))(jnp.asarray(c))
    grad = np.asarray(grad)
    scale = abs(grad[0])
    if 14 not in noll:
        assert float(value) == float(merit(jnp.asarray(c)))
        for i in (0, 2):
            own = oracles.richardson_difference(lambda t: merit(jnp.asarray(t)), c, i, 1e-4)
            assert grad[i] == pytest.approx(own, rel=1e-8)
        assert grad[1] == 0.0 and grad[3] == 0.0
        plane = np.array([oracles.richardson_difference(
            lambda t: merit(jnp.asarray(t), plane=True, preset="default"), c, i, 1e-4)
            for i in range(4)])
        np.testing.assert_allclose(grad, plane, rtol=0, atol=1e-8 * scale)
    else:
        fd = np.array([oracles.richardson_difference(
            lambda t: merit(jnp.asarray(t), plane=True), c, i, 1e-4) for i in range(4)])
        np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-10)
        assert abs(grad[1]) <= 1e-9 * scale and abs(grad[3]) > 0.03 * scale

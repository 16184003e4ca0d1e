"""OTF engines against SPEC §5 values and independent float64 oracles (tests/oracles.py)."""

from __future__ import annotations

import functools
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import oracles
import pytest

import jmse_jax as jj
from jmse_jax import AccuracyWarning

HIGH = (64, 64)  # overlap nodes for the high-order comparisons

# Coma + astigmatism + defocus at field 0.95, and the paper's Fig. 1 set with distortion/tilt.
ABERRATED = dict(w020=-1.0, w131=1.5, w222=1.2)
FIG1_ALL = dict(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198, w311=0.4,
                w111=-0.3)
FIELD = 0.95
_PAD = 32
NODES = np.array([(0.05, 0.1), (0.2, 0.0), (0.0, 0.3), (-0.25, 0.35), (0.5, -0.4), (0.1, 0.8),
                  (0.7, 0.6)])


@pytest.fixture(scope="module")
def oracle_values():
    """Oracle OTF at NODES for ABERRATED and FIG1_ALL (about 4 s of SciPy)."""
    return {
        name: np.array([oracles.otf(coefficients, a, b, FIELD) for a, b in NODES])
        for name, coefficients in (("aberrated", ABERRATED), ("fig1", FIG1_ALL))
    }


@functools.partial(jax.jit, static_argnames=("method", "nodes", "B"))
def _otf_jit(aberrations, nu_x, nu_y, field, method="overlap", nodes=(32, 32), B=64):
    return jj.otf(aberrations, nu_x, nu_y, field, method, nodes=nodes, B=B)


def otf_at(aberrations, points, field=FIELD, **kwargs):
    """Compiled ``jj.otf`` at ``points`` (n, 2), padded to a fixed length so that each
    engine setting compiles once per session."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n = points.shape[0]
    assert n <= _PAD
    padded = np.zeros((_PAD, 2))
    padded[:n] = points
    h = _otf_jit(aberrations, jnp.asarray(padded[:, 0]), jnp.asarray(padded[:, 1]), field,
                 **kwargs)
    return np.asarray(h)[:n]


def _otf(coefficients, points=NODES, field=FIELD, **kwargs):
    return otf_at(jj.Seidel(**coefficients), points, field, **kwargs)


# -------------------------------------------------------------------------------------
# Closed forms and SPEC §5
# -------------------------------------------------------------------------------------


def test_diffraction_limited_formula():
    r = np.concatenate([np.linspace(0.0, 1.0, 21), [1e-9, 0.999999, 1.0 + 1e-12, 1.3]])
    np.testing.assert_allclose(jj.diffraction_limited_otf(jnp.asarray(r)),
                               oracles.diffraction_limited_otf(r), atol=1e-15)
    assert math.isnan(float(jj.diffraction_limited_otf(jnp.asarray(np.nan))))  # was 0.0
    angle = np.linspace(0.0, 2.0 * np.pi, r.size, endpoint=False)
    h = otf_at(jj.Seidel(), np.stack([r * np.cos(angle), r * np.sin(angle)], axis=1), 0.0)
    np.testing.assert_allclose(h, oracles.diffraction_limited_otf(r), atol=1e-13)


@pytest.mark.parametrize(
    ("w020", "nu_x", "expected"),
    [(0.5, 0.2, 0.43481896), (0.5, 0.4, 0.12569082), (1.0, 0.2, -0.01441369)],
)
def test_hopkins_defocus_values(w020, nu_x, expected):
    """SPEC §5 (Hopkins 1955), rounded to 8 decimals there: hence atol 1e-8."""
    h = complex(otf_at(jj.Seidel(w020=w020), [(nu_x, 0.0)], 0.0, nodes=HIGH)[0])
    assert h.real == pytest.approx(expected, abs=1e-8)
    assert abs(h.imag) < 1e-14
    # The oracle reproduces the same published value (it is not fitted to the package).
    assert oracles.otf({"w020": w020}, nu_x, 0.0, 0.0).real == pytest.approx(expected, abs=1e-8)


_SYMMETRIC_DESIGNS = [
    jj.Seidel(w020=0.5),
    jj.Seidel(w020=3.0, w040=-2.5),
    jj.Zernike(jnp.asarray([1.5, -0.7, 0.3]), noll=(4, 11, 22)),
]


@pytest.mark.parametrize("design", range(len(_SYMMETRIC_DESIGNS)))
@pytest.mark.parametrize("order", [(24, 24), (9, 7)])
def test_symmetric_path_is_the_whole_rule(design, order):
    """The rotationally symmetric path (one half of the lens, the chords' nodes t >= 0, the
    cosine alone; the one-ray plans') against the whole rule at the same order: values,
    forward and reverse derivatives in the coefficients and in the frequency, to rounding,
    at even and odd orders, at nu = 0 and past the cutoff (the rule's singular points).
    Where the phase is quadratic along the chords (the Seidel designs) the symmetric path
    integrates each chord in closed form (``_chords.even_chord_integral``), so the whole
    rule takes 48 nodes along them (converged here) and the same order across."""
    from jmse_jax._otf import _otf_overlap, _quadratic_chords

    ab = _SYMMETRIC_DESIGNS[design]
    r = jnp.concatenate([jnp.asarray([0.0]), jnp.linspace(0.0, 1.0, 19)[1:-1],
                         jnp.asarray([1.0, 1.2])])
    whole_order = (order[0], 48) if _quadratic_chords(ab) else order
    assert _quadratic_chords(ab) == (design < 2)

    def h(ab, r, symmetric):
        return jnp.real(_otf_overlap(ab, r, jnp.zeros_like(r), 0.0,
                                     order if symmetric else whole_order, symmetric=symmetric))

    whole, half = h(ab, r, False), h(ab, r, True)
    np.testing.assert_allclose(half, whole, rtol=0, atol=1e-14)
    assert float(half[0]) == 1.0 and float(half[-1]) == 0.0 and float(half[-2]) == 0.0
    assert np.all(np.asarray(jnp.imag(_otf_overlap(ab, r, 0 * r, 0.0, order, symmetric=True)))
                  == 0.0)
    for jac in (jax.jacfwd, jax.jacrev):
        expected = jac(h, argnums=(0, 1))(ab, r, False)
        got = jac(h, argnums=(0, 1))(ab, r, True)
        for e, g in zip(jax.tree_util.tree_leaves(expected), jax.tree_util.tree_leaves(got),
                        strict=True):
            np.testing.assert_allclose(g, e, rtol=0, atol=2e-13 * (1 + float(jnp.max(jnp.abs(e)))))
            assert np.all(np.isfinite(g))
    # Hopkins's defocus values (SPEC §5) from the symmetric path as well.
    if design == 0 and order == (24, 24):
        values = h(ab, jnp.asarray([0.2, 0.4]), True)
        np.testing.assert_allclose(values, [0.43481896, 0.12569082], atol=1e-8)


def test_symmetric_path_against_the_oracle():
    """Defocus balanced against spherical aberration, several waves: the symmetric path at a
    high order against the SciPy oracle (independent of the engine)."""
    from jmse_jax._otf import _otf_overlap

    coefficients = dict(w020=4.0, w040=-3.0)
    r = np.asarray([0.05, 0.2, 0.45, 0.7, 0.93])
    h = np.asarray(jnp.real(_otf_overlap(jj.Seidel(**coefficients), jnp.asarray(r),
                                         jnp.zeros(r.size), 0.0, HIGH, symmetric=True)))
    expected = np.array([oracles.otf(coefficients, x, 0.0, 0.0).real for x in r])
    np.testing.assert_allclose(h, expected, rtol=0, atol=1e-10)


def test_oracle_agrees_with_scipy_dblquad():
    """The oracle (rotated coordinates, Gauss inner) against plain dblquad at one node."""
    a = oracles.otf(ABERRATED, 0.0, 0.3, FIELD)
    b = oracles.otf_dblquad(ABERRATED, 0.0, 0.3, FIELD)
    assert abs(a - b) < 1e-10


@pytest.mark.parametrize("case", ["aberrated", "fig1"])
def test_overlap_matches_oracle_at_high_order(oracle_values, case):
    coefficients = ABERRATED if case == "aberrated" else FIG1_ALL
    h = _otf(coefficients, method="overlap", nodes=HIGH)
    assert np.max(np.abs(h - oracle_values[case])) <= 1e-8
    assert np.max(np.abs(h.imag)) > 1e-2  # a genuinely complex OTF


def test_nudft_converges_first_order(oracle_values):
    """SPEC §6: square pupil + exact DFT is first order in 1/B (staircase edge)."""
    errors = {}
    for B in (32, 128):
        h = _otf(ABERRATED, method="nudft", B=B)
        errors[B] = np.max(np.abs(h - oracle_values["aberrated"]))
    assert errors[128] < 2e-3  # SPEC §6: ~9e-4 at B = 128
    assert errors[128] < errors[32] / 3  # roughly 4x for 4x the grid


def test_fft_engine_equals_numpy_baseline_at_lag_nodes():
    B = 32
    grid = oracles.pupil_otf_lag_grid(FIG1_ALL, FIELD, B)
    k = np.array([(0, 0), (1, 0), (0, 1), (3, -2), (-5, 4), (7, 7), (-12, -9), (20, 5), (0, -25)])
    nodes = k / B
    h = _otf(FIG1_ALL, points=nodes, method="fft", B=B)
    inside = np.hypot(nodes[:, 0], nodes[:, 1]) < 1
    expected = np.where(inside, grid[k[:, 1] % (2 * B), k[:, 0] % (2 * B)], 0.0)
    np.testing.assert_allclose(h, expected, rtol=0, atol=1e-12)
    # The whole lag grid as well.
    np.testing.assert_allclose(jj.otf_fft_grid(jj.Seidel(**FIG1_ALL), FIELD, B), grid, atol=1e-12)


def test_fft_engine_is_first_order_accurate(oracle_values):
    h = _otf(ABERRATED, method="fft", B=128)
    assert np.max(np.abs(h - oracle_values["aberrated"])) < 1e-2


# -------------------------------------------------------------------------------------
# Sign conventions and symmetries (SPEC §2)
# -------------------------------------------------------------------------------------


def test_tilt_is_a_phase_ramp():
    a, field = 0.3, 0.7  # W = w111 h y = a' y with a' = w111 h
    base = dict(w020=0.8, w131=-0.6)
    nodes = np.array([(0.1, 0.2), (-0.3, 0.1), (0.2, -0.45), (0.0, 0.6)])
    ab0 = jj.Seidel(**base)
    ab1 = jj.Seidel(**base, w111=a)
    h0 = otf_at(ab0, nodes, field, nodes=HIGH)
    h1 = otf_at(ab1, nodes, field, nodes=HIGH)
    np.testing.assert_allclose(h1, np.exp(4j * math.pi * a * field * nodes[:, 1]) * h0,
                               atol=1e-13)
    # Pure tilt: a phase ramp on the diffraction-limited OTF.
    h_tilt = otf_at(jj.Seidel(w111=a), nodes, 1.0)
    expected = np.exp(4j * math.pi * a * nodes[:, 1]) * oracles.diffraction_limited_otf(
        np.hypot(nodes[:, 0], nodes[:, 1]))
    np.testing.assert_allclose(h_tilt, expected, atol=1e-13)


@pytest.mark.parametrize("method", ["overlap", "nudft", "fft"])
def test_hermitian_and_x_mirror_symmetry(method):
    nodes = NODES[:5]
    h = _otf(FIG1_ALL, points=nodes, method=method, B=32)
    h_neg = _otf(FIG1_ALL, points=-nodes, method=method, B=32)
    np.testing.assert_allclose(h_neg, np.conj(h), atol=1e-12)
    mirrored = nodes * np.array([-1.0, 1.0])
    np.testing.assert_allclose(_otf(FIG1_ALL, points=mirrored, method=method, B=32), h,
                               atol=1e-12)


@pytest.mark.parametrize("method", ["overlap", "fft", "nudft"])
def test_zero_beyond_cutoff_and_one_at_origin(method):
    nodes = np.array([(1.0, 0.0), (0.0, -1.0), (0.8, 0.6), (1.2, 0.3), (-0.9, 0.9), (0.0, 0.0)])
    h = _otf(FIG1_ALL, points=nodes, method=method, B=32)
    np.testing.assert_array_equal(h[:5], 0.0)
    assert h[5] == pytest.approx(1.0, abs=1e-14)


def test_nudft_is_one_at_origin():
    h = complex(otf_at(jj.Seidel(**FIG1_ALL), [(0.0, 0.0)], method="nudft", B=32)[0])
    assert h == pytest.approx(1.0, abs=1e-13)


def test_otf_of_fitted_zernike_equals_seidel_otf(oracle_values):
    grid = jj.PolarGrid(6, 40)
    fit = jj.zernike_fit(jj.sample_opd(jj.Seidel(**ABERRATED), grid, FIELD), grid)
    h = otf_at(fit, NODES, nodes=HIGH)
    np.testing.assert_allclose(h, oracle_values["aberrated"], atol=1e-8)


def test_otf_follows_input_dtype():
    ab32 = jj.Seidel(w020=jnp.float32(-1.0), w131=jnp.float32(1.5), w222=jnp.float32(1.2))
    nx, ny = jnp.asarray(NODES[:, 0], jnp.float32), jnp.asarray(NODES[:, 1], jnp.float32)
    h32 = _otf_jit(ab32, nx, ny, jnp.float32(FIELD))
    assert h32.dtype == jnp.complex64
    np.testing.assert_allclose(h32, _otf(ABERRATED), atol=2e-5)


# -------------------------------------------------------------------------------------
# Bad input
# -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(method="bogus"), r"method must be one of 'overlap', 'nudft', 'fft', got 'bogus'"),
        (dict(field=-0.1), r"field must be in \[0\.0, 1\.0\], got -0\.1"),
        (dict(field=1.2), r"field must be in \[0\.0, 1\.0\], got 1\.2"),
        (dict(nodes=(0, 8)), r"nodes\[0\] \(n_phi\) must be an integer >= 1, got 0"),
        (dict(nodes=(8, 0)), r"nodes\[1\] \(n_t\) must be an integer >= 1, got 0"),
        (dict(method="nudft", B=0), r"B must be an integer >= 1, got 0"),
        (dict(method="fft", B=0), r"B must be an integer >= 1, got 0"),
        (dict(nu_x=float("nan")), r"nu_x must be finite"),
    ],
)
def test_bad_input_raises(kwargs, match):
    arguments = dict(nu_x=0.1, nu_y=0.2, field=0.5)
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=match):
        jj.otf(jj.Seidel(w020=1.0), **arguments)


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_non_finite_coefficient_raises(value):
    with pytest.raises(ValueError, match=r"aberrations\.w131 must be finite, got (nan|inf)"):
        jj.otf(jj.Seidel(w131=value), 0.1, 0.2, 0.5)


@pytest.mark.parametrize("method", ["overlap", "nudft"])
def test_bad_traced_input_gives_nan_not_a_plausible_number(method):
    """Under jit nothing can be checked: a non-finite frequency gives NaN at that node only
    (a NaN frequency gave 1 + NaN j), a bad design NaN everywhere (field 1.5 gave a finite
    OTF), and the gradient at the good nodes is the one without the bad node."""
    settings = dict(nodes=(24, 24)) if method == "overlap" else dict(B=32)

    @jax.jit
    def h(w020, nu_x, field):
        return jj.otf(jj.Seidel(w020=w020, w131=0.4), nu_x, 0.1, field, method, **settings)

    good = jnp.array([0.3, -0.2])
    expected = h(1.0, good, 0.5)
    assert np.all(np.isfinite(np.asarray(expected).view(float)))
    for bad in (jnp.nan, jnp.inf):
        value = np.asarray(h(1.0, jnp.array([0.3, bad, -0.2]), 0.5))
        assert np.isnan(value[1].real) and np.isnan(value[1].imag)
        np.testing.assert_allclose(value[[0, 2]], expected, rtol=1e-12)
    for w020, field in ((jnp.nan, 0.5), (1.0, jnp.nan), (1.0, 1.5), (1.0, -0.1)):
        assert np.all(np.isnan(np.asarray(h(w020, good, field)).view(float)))

    def real_part(w020, nu_x):
        return jnp.nansum(h(w020, nu_x, 0.5).real)

    gradient = jax.grad(real_part)(1.0, jnp.array([0.3, jnp.nan, -0.2]))
    assert np.isfinite(gradient)
    assert float(gradient) == pytest.approx(float(jax.grad(real_part)(1.0, good)), rel=1e-12)


def test_aberration_strength_of_bad_traced_input_is_inf():
    """As jmse: +inf (was NaN, or a finite number for a field outside [0, 1] or u < 0)."""
    strength = jax.jit(lambda w, f, u: jj.aberration_strength(jj.Seidel(w020=w), f, u))
    assert float(strength(1.0, 0.0, 0.5)) == pytest.approx(2.0 * math.sqrt(2.0) * 0.5, rel=1e-12)
    for w, f, u in ((jnp.nan, 0.0, 0.5), (1.0, jnp.nan, 0.5), (1.0, 0.0, jnp.inf),
                    (1.0, 2.0, 0.5), (1.0, 0.0, -1.0), (1.0, 0.0, 0.0), (1.0, 0.0, 1.6)):
        assert float(strength(w, f, u)) == math.inf, (w, f, u)


def test_too_few_overlap_nodes_warn():
    """Concrete calls warn when the nodes look too few for 1e-6 (here 12 waves of coma at
    the default (32, 32): 1.8e-5 off near nu = (0.05, 0.2) against (160, 160)); enough
    nodes, or a mild design, are quiet."""
    coma = jj.Seidel(w131=12.0)
    nu = jnp.linspace(0.05, 0.95, 10)
    with pytest.warns(AccuracyWarning, match=r"nodes=\(32, 32\) may be too few .* about "
                                         r"nodes=\((\d+), \1\) holds 1e-6"):
        coarse = jj.otf(coma, nu, 0.2, 1.0)
    fine = jj.otf(coma, nu, 0.2, 1.0, nodes=(160, 160))
    assert float(jnp.max(jnp.abs(coarse - fine))) > 1e-5  # the warning was warranted
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        enough = jj.otf(coma, nu, 0.2, 1.0, nodes=(56, 56))
        jj.otf(jj.Seidel(w131=4.0), nu, 0.2, 1.0)
        jj.otf(jj.Seidel(w020=8.0), nu, 0.2, 1.0)  # a linear phase difference: 1e-6 held
        jax.jit(lambda c: jj.otf(jj.Seidel(w131=c), nu, 0.2, 1.0))(12.0)  # traced: no check
    assert float(jnp.max(jnp.abs(enough - fine))) < 1e-6


def test_coma_warns_where_its_curved_phase_difference_needs_more_nodes():
    """Coma's phase difference is quadratic across the overlap lens and needs about twice
    the nodes of a linear one (defocus's) of the same spread: 10 waves of coma at field 1
    are 5e-5 off at (32, 32) near the cutoff against (160, 160), and ``otf`` warns (the
    former rule, ``2 E + 14`` with ``E`` the spread alone, asked for 32 and was quiet;
    session 79's audit)."""
    coma = jj.Seidel(w131=10.0)
    nu = jnp.linspace(0.0, 0.999, 120)
    with pytest.warns(AccuracyWarning, match=r"nodes=\(32, 32\) may be too few"):
        coarse = jj.otf(coma, 0.0 * nu, nu, 1.0)
    fine = jj.otf(coma, 0.0 * nu, nu, 1.0, nodes=(160, 160))
    assert float(jnp.max(jnp.abs(coarse - fine))) > 1e-5

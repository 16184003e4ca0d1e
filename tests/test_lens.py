"""Lens model: SPEC §3.7 test vector, closed forms, stop shift, and the exact real-ray oracle."""

import math

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import raytrace_oracle as oracle  # noqa: E402

import jmse_jax  # noqa: E402
from jmse_jax import lens as jl  # noqa: E402

# SPEC §3.7: R1 = 60, R2 = -200, t = 6, n = 1.6, stop 20 mm in front, EP semi-diameter 5, 10°.
SPEC_SUMS = (0.0023708064, -0.0001641306, 0.0079474046, 0.0063154008, 0.0240160437)


def spec_lens(**overrides):
    options = dict(stop_position=-20.0, ep_radius=5.0, field_angle=10.0)
    options.update(overrides)
    return jl.Lens([1 / 60, -1 / 200], [6.0], [1.6, 1.0], **options)


def sums_tuple(sums):
    return np.array([float(s) for s in (sums.S_I, sums.S_II, sums.S_III, sums.S_IV, sums.S_V)])


def test_spec_test_vector():
    sums = sums_tuple(jl.seidel_sums(spec_lens()))
    # The SPEC quotes 10 decimals: agreement to half a unit in the last place (5e-11 mm).
    np.testing.assert_allclose(sums, SPEC_SUMS, rtol=0.0, atol=5.01e-11)
    per_surface = np.asarray(jl.seidel_sums(spec_lens()).per_surface)
    np.testing.assert_allclose(per_surface.sum(axis=1), sums, rtol=1e-15)


def test_spec_test_vector_in_waves():
    lens = spec_lens(wavelength=0.55)
    s = sums_tuple(jl.seidel_sums(lens))
    waves = jl.seidel_waves(lens)
    lam = 0.55e-3
    expected = dict(w040=s[0] / 8, w131=s[1] / 2, w222=s[2] / 2, w220=(s[2] + s[3]) / 4,
                    w311=s[4] / 2)
    for name, value in expected.items():
        assert float(getattr(waves, name)) == pytest.approx(value / lam, rel=1e-14)
    assert float(waves.w020) == 0.0
    shifted = jl.seidel_waves(spec_lens(wavelength=0.55, image_shift=0.3))
    n = float(jl.working_f_number(lens))
    assert float(shifted.w020) == pytest.approx(0.3 / (8 * n * n) / lam, rel=1e-14)
    assert isinstance(waves, jmse_jax.Seidel)


def test_first_order_matches_closed_forms_and_real_rays():
    c1, c2, t, n = 1 / 60, -1 / 200, 6.0, 1.6
    lens = spec_lens()
    power = (n - 1) * (c1 - c2) + (n - 1) ** 2 * t * c1 * c2 / n
    efl = 1 / power
    bfl = efl * (1 - (n - 1) * t * c1 / n)
    assert float(jl.effective_focal_length(lens)) == pytest.approx(efl, rel=1e-14)
    assert float(jl.back_focal_length(lens)) == pytest.approx(bfl, rel=1e-14)
    assert float(jl.working_f_number(lens)) == pytest.approx(efl / 10.0, rel=1e-14)
    lam_mm = 0.5875618e-3
    assert float(jl.cutoff_frequency(lens)) == pytest.approx(10.0 / (lam_mm * efl), rel=1e-14)
    system = oracle.System((c1, c2), (t,), (n, 1.0), -20.0)
    efl_real, bfl_real = oracle.focal_lengths(system)
    assert efl_real == pytest.approx(efl, rel=1e-9)
    assert bfl_real == pytest.approx(bfl, rel=1e-9)


@pytest.mark.parametrize("bending", [-1.0, 0.0, 0.714, 1.0, 2.5])
def test_thin_lens_closed_forms(bending):
    """Welford (1986) Sec. 8.5: thin lens, stop at the lens, object at infinity (Y = -1)."""
    n, power, y, angle = 1.5, 0.02, 4.0, 7.0
    c_diff = power / (n - 1)
    c1, c2 = 0.5 * c_diff * (bending + 1), 0.5 * c_diff * (bending - 1)
    lens = jl.Lens([c1, c2], [0.0], [n, 1.0], stop_position=0.0, ep_radius=y,
                   field_angle=angle)
    big_h = math.tan(math.radians(angle)) * y
    x, conj = bending, -1.0
    s1 = y**4 * power**3 / 4 * (
        (n / (n - 1)) ** 2 + (n + 2) / (n * (n - 1) ** 2) * (x + 2 * (n * n - 1) / (n + 2)
                                                           * conj) ** 2
        - n / (n + 2) * conj**2
    )
    # Welford's Lagrange invariant has the opposite sign to H = n (u_bar y - u y_bar) used
    # here (positive for a field on +y); the real-ray test pins the sign of S_II.
    s2 = (y * y * power**2 * big_h / 2) * ((n + 1) / (n * (n - 1)) * x + (2 * n + 1) / n * conj)
    expected = np.array([s1, s2, big_h**2 * power, big_h**2 * power / n, 0.0])
    got = sums_tuple(jl.seidel_sums(lens))
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15 * abs(s1))


def test_petzval_sum_of_thick_singlet():
    lens = spec_lens()
    big_h = math.tan(math.radians(10.0)) * 5.0
    expected = big_h**2 * (1 - 1 / 1.6) * (1 / 60 + 1 / 200)
    assert float(jl.seidel_sums(lens).S_IV) == pytest.approx(expected, rel=1e-14)


@pytest.mark.parametrize("new_stop", [-35.0, -5.0, 0.0])
def test_stop_shift_identities_front_stop(new_stop):
    """Moving a front stop by delta changes y_bar by u_bar delta at every surface."""
    before = jl.seidel_sums(spec_lens())
    after = jl.seidel_sums(spec_lens(stop_position=new_stop))
    slope = math.tan(math.radians(10.0))
    eccentricity = slope * (-new_stop - 20.0) / 5.0
    predicted = jl.stop_shift(before, eccentricity)
    np.testing.assert_allclose(sums_tuple(after), sums_tuple(predicted), rtol=1e-12,
                               atol=1e-16)
    np.testing.assert_allclose(np.asarray(after.per_surface), np.asarray(predicted.per_surface),
                               rtol=1e-11, atol=1e-16)


def test_stop_shift_identities_internal_and_rear_stop():
    base = spec_lens()
    trace = jl.paraxial_trace(base)
    for stop in (2.5, 15.0):
        moved = spec_lens(stop_position=stop)
        moved_trace = jl.paraxial_trace(moved)
        ratios = (np.asarray(moved_trace.y_bar) - np.asarray(trace.y_bar)) / np.asarray(trace.y)
        assert np.ptp(ratios) < 1e-12 * max(1.0, abs(ratios[0]))  # E is the same everywhere
        predicted = jl.stop_shift(jl.seidel_sums(base), ratios[0])
        np.testing.assert_allclose(sums_tuple(jl.seidel_sums(moved)), sums_tuple(predicted),
                                   rtol=1e-11, atol=1e-16)
        # The chief ray crosses the axis at the stop.
        vertices = np.array([0.0, 6.0])
        seg = 0 if stop < 6.0 else 1
        height = moved_trace.y_bar[seg] + moved_trace.u_bar[seg + 1] * (stop - vertices[seg])
        assert abs(float(height)) < 1e-13


def _seidel_transverse(lens, pupil_x, pupil_y):
    """Third-order transverse aberration [mm] from the Seidel sums: (1 / n'u') grad W."""
    s = sums_tuple(jl.seidel_sums(lens))
    f_number = float(jl.working_f_number(lens))
    w020 = float(lens.image_shift) / (8 * f_number**2)
    w040, w131, w222, w220, w311 = s[0] / 8, s[1] / 2, s[2] / 2, (s[2] + s[3]) / 4, s[4] / 2
    r2 = pupil_x**2 + pupil_y**2
    dw_dy = (2 * w020 * pupil_y + 4 * w040 * r2 * pupil_y + w131 * (r2 + 2 * pupil_y**2)
             + 2 * (w222 + w220) * pupil_y + w311)
    dw_dx = 2 * w020 * pupil_x + 4 * w040 * r2 * pupil_x + 2 * w131 * pupil_x * pupil_y \
        + 2 * w220 * pupil_x
    image_slope = -1.0 / (2.0 * f_number)  # n' = 1
    return dw_dx / image_slope, dw_dy / image_slope


RAY_CASES = {
    "front stop": dict(stop_position=-20.0),
    "front stop, defocused": dict(stop_position=-20.0, image_shift=0.002),
    "stop inside the glass": dict(stop_position=3.0),
    "rear stop": dict(stop_position=12.0),
    "conic and aspheric": dict(stop_position=-5.0, conics=(-0.8, 1.5), aspheric4=(1e-6, -2e-6)),
}


@pytest.mark.parametrize("case", list(RAY_CASES))
def test_seidel_matches_exact_real_ray_trace(case):
    """At small aperture and field the real transverse aberrations tend to the Seidel ones.

    The remaining error is fifth order, so halving aperture and field divides the relative
    error by about 4.
    """
    options = dict(RAY_CASES[case])
    theta = np.linspace(0.0, 2 * np.pi, 9)[:-1]
    pupil_x = np.concatenate([np.sin(theta), 0.5 * np.sin(theta)])
    pupil_y = np.concatenate([np.cos(theta), 0.5 * np.cos(theta)])
    errors = []
    for scale in (1.0, 0.5):
        shift = options.get("image_shift", 0.0) * scale**2
        lens_options = {**options, "image_shift": shift}
        lens = spec_lens(ep_radius=0.5 * scale, field_angle=1.0 * scale, **lens_options)
        system = oracle.System(
            (1 / 60, -1 / 200), (6.0,), (1.6, 1.0), options["stop_position"],
            options.get("conics"), options.get("aspheric4"),
        )
        real_x, real_y = oracle.transverse_aberrations(system, 0.5 * scale, 1.0 * scale,
                                                       pupil_x, pupil_y, shift)
        seidel_x, seidel_y = _seidel_transverse(lens, pupil_x, pupil_y)
        size = np.max(np.hypot(seidel_x, seidel_y))
        errors.append(np.max(np.hypot(real_x - seidel_x, real_y - seidel_y)) / size)
    assert errors[0] < 1e-3
    assert 3.0 < errors[0] / errors[1] < 5.0


def test_glass_models():
    bk7 = jl.AbbeGlass(1.5168, 64.17)
    n_d, n_f, n_c = (float(bk7.index(w)) for w in
                     (jl.FRAUNHOFER_D, jl.FRAUNHOFER_F, jl.FRAUNHOFER_C))
    assert n_d == pytest.approx(1.5168, rel=1e-14)
    assert (n_d - 1) / (n_f - n_c) == pytest.approx(64.17, rel=1e-12)
    # Catalogue N-BK7 (Schott): n_F = 1.52238, n_C = 1.51432.
    assert n_f == pytest.approx(1.52238, abs=3e-4)
    assert n_c == pytest.approx(1.51432, abs=3e-4)
    cauchy = jl.CauchyGlass(1.5, 0.004, 1e-4)
    assert float(cauchy.index(0.5)) == pytest.approx(1.5 + 0.004 / 0.25 + 1e-4 / 0.0625)
    assert float(jl.ConstantGlass(1.7).index(0.4)) == 1.7
    with pytest.raises(ValueError, match="glass vd"):
        jl.AbbeGlass(1.5, -3.0)


def test_chromatic_focal_shift_thin_lens():
    """Thin lens: f(lambda) = 1 / ((n(lambda) - 1) (c1 - c2)); the image plane stays put."""
    glass = jl.AbbeGlass(1.5168, 64.17)
    c1, c2 = 0.05, -0.05
    lens = jl.Lens([c1, c2], [0.0], [glass, 1.0], ep_radius=2.0, field_angle=5.0,
                   wavelength=jl.FRAUNHOFER_D)
    for wl in (jl.FRAUNHOFER_F, jl.FRAUNHOFER_C):
        f = 1.0 / ((float(glass.index(wl)) - 1) * (c1 - c2))
        f_d = 1.0 / ((1.5168 - 1) * (c1 - c2))
        assert float(jl.effective_focal_length(lens, wl)) == pytest.approx(f, rel=1e-13)
        waves = jl.seidel_waves(lens, wl, check=False)  # t = 0: no edge thickness
        n_wl = f / 4.0
        expected = -(f - f_d) / (8 * n_wl**2) / (wl * 1e-3)
        assert float(waves.w020) == pytest.approx(expected, rel=1e-12)
    # F focuses shorter than C: F is defocused the other way from C.
    assert float(jl.seidel_waves(lens, jl.FRAUNHOFER_F, check=False).w020) > 0
    assert float(jl.seidel_waves(lens, jl.FRAUNHOFER_C, check=False).w020) < 0


def test_singlet_constructor_and_f_number_solve():
    lens = jl.Singlet(1 / 60, -1 / 200, 6.0, 1.6, stop_distance=20.0, ep_radius=5.0,
                      field_angle=10.0)
    np.testing.assert_allclose(sums_tuple(jl.seidel_sums(lens)), SPEC_SUMS, atol=5.01e-11)
    lens = jl.Singlet(1 / 60, -1 / 200, 6.0, 1.6, stop_distance=20.0, f_number=4.6)
    assert float(jl.working_f_number(lens)) == pytest.approx(4.6, rel=1e-14)
    solved = jl.solve_last_curvature(spec_lens(), 3.0)
    assert float(jl.working_f_number(solved)) == pytest.approx(3.0, rel=1e-13)
    assert float(solved.curvatures[0]) == 1 / 60
    with pytest.raises(ValueError, match="exactly one"):
        jl.Singlet(0.01, 0.0, 1.0, 1.5)


def test_rms_wavefront_closed_form_matches_quadrature():
    ab = jmse_jax.Seidel(w020=-0.7, w040=1.3, w131=-0.9, w222=0.6, w220=0.4, w311=2.0)
    h = 0.8
    # Independent: Gauss-Legendre in rho^2 x trapezoid in theta, piston and tilt fitted out.
    s, ws = np.polynomial.legendre.leggauss(12)
    rho = np.sqrt(0.5 * (s + 1))
    theta = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    rr, tt = np.meshgrid(rho, theta, indexing="ij")
    x, y = rr * np.sin(tt), rr * np.cos(tt)
    weights = np.broadcast_to((0.25 * ws)[:, None] * (2 * np.pi / 64) / np.pi, rr.shape)
    w = np.asarray(jmse_jax.wavefront(ab, x, y, h))
    basis = np.stack([np.ones_like(x), x, y], axis=-1).reshape(-1, 3)
    sw = np.sqrt(weights.ravel())
    coeffs, *_ = np.linalg.lstsq(basis * sw[:, None], w.ravel() * sw, rcond=None)
    residual = w.ravel() - basis @ coeffs
    rms = math.sqrt(np.sum(weights.ravel() * residual**2))
    assert float(jl.rms_wavefront_error(ab, h)) == pytest.approx(rms, rel=1e-12)
    grad = jax.grad(jl.rms_wavefront_error)(jmse_jax.Seidel(), 0.5)
    assert all(np.isfinite(float(g)) for g in jax.tree_util.tree_leaves(grad))


def test_gradients_of_seidel_sums_match_finite_differences():
    def s1_of(params):
        c1, c2, t, stop = params
        lens = jl.Lens(jnp.stack([c1, c2]), jnp.stack([t]), [1.6, 1.0], stop_position=stop,
                       ep_radius=5.0, field_angle=10.0)
        s = jl.seidel_sums(lens)
        return s.S_I + 3 * s.S_II + 0.5 * s.S_III + s.S_V

    params = jnp.array([1 / 60, -1 / 200, 6.0, -20.0])
    grad = np.asarray(jax.grad(s1_of)(params))
    for i, step in enumerate((1e-6, 1e-6, 1e-4, 1e-3)):
        e = np.zeros(4)
        e[i] = step
        fd = (float(s1_of(params + e)) - float(s1_of(params - e))) / (2 * step)
        assert grad[i] == pytest.approx(fd, rel=1e-7)


def test_vmap_over_designs_equals_loop():
    curvatures = jnp.linspace(-0.05, 0.05, 4)

    def w131(c1):
        lens = jl.Singlet(c1, -0.1, 1.5, jl.N_BK7, stop_distance=1.0, ep_radius=1.0,
                          field_angle=10.0)
        return jl.seidel_waves(jl.solve_last_curvature(lens, 4.6), check=False).w131

    batched = np.asarray(jax.vmap(w131)(curvatures))
    looped = np.array([float(w131(c)) for c in curvatures])
    np.testing.assert_allclose(batched, looped, rtol=1e-13)


def test_float32_gives_sensible_sums():
    lens32 = jl.Lens(jnp.asarray([1 / 60, -1 / 200], jnp.float32), jnp.asarray([6.0], jnp.float32),
                     [1.6, 1.0], stop_position=jnp.float32(-20.0), ep_radius=jnp.float32(5.0),
                     field_angle=jnp.float32(10.0), wavelength=jnp.float32(0.55))
    sums = jl.seidel_sums(lens32)
    assert sums.S_I.dtype == jnp.float32
    np.testing.assert_allclose(sums_tuple(sums), SPEC_SUMS, rtol=2e-4)


# -------------------------------------------------------------------------------------
# Non-physical lenses: ValueError when concrete, a status (never NaN) under tracing
# -------------------------------------------------------------------------------------

ZERO_POWER = dict(curvatures=[0.05, 0.05], thicknesses=[0.0], media=[1.5, 1.0])
NEGATIVE_EDGE = dict(curvatures=[0.2, -0.2], thicknesses=[0.3], media=[1.5, 1.0])
TIR = dict(curvatures=[0.0, -0.45], thicknesses=[1.0], media=[1.9, 1.0])
NEGATIVE_POWER = dict(curvatures=[-0.05, 0.05], thicknesses=[2.0], media=[1.5, 1.0])


@pytest.mark.parametrize("spec, message", [
    (ZERO_POWER, "power must be positive"),
    (NEGATIVE_POWER, "power must be positive"),
    (NEGATIVE_EDGE, "gap thickness, on the axis and at the edge, must be >= 0"),
    (TIR, "total internal reflection"),
])
def test_non_physical_lenses_raise(spec, message):
    lens = jl.Lens(spec["curvatures"], spec["thicknesses"], spec["media"], ep_radius=1.5,
                   field_angle=5.0)
    with pytest.raises(ValueError, match=message):
        jl.seidel_waves(lens)
    with pytest.raises(ValueError, match=message):
        jl.validate_lens(lens)
    assert not bool(jl.lens_status(lens).ok)


def test_non_physical_lens_under_jit_gives_status_not_nan():
    @jax.jit
    def waves_and_status(c2):
        lens = jl.Lens(jnp.stack([jnp.asarray(0.05), c2]), [2.0], [1.5, 1.0], ep_radius=1.5,
                       field_angle=5.0)
        return jl.seidel_waves(lens), jl.lens_status(lens).ok

    afocal = 0.05 / (1 - 0.5 * 2.0 * 0.05 / 1.5)  # thick meniscus of zero power
    waves, ok = waves_and_status(jnp.asarray(afocal))
    assert not bool(ok)
    assert all(np.isfinite(float(leaf)) for leaf in jax.tree_util.tree_leaves(waves))
    grad = jax.grad(lambda c2: waves_and_status(c2)[0].w020)(jnp.asarray(afocal))
    assert np.isfinite(float(grad))
    _, ok = waves_and_status(jnp.asarray(-0.05))
    assert bool(ok)


def test_negative_lens_with_f_number_under_jit_is_flagged():
    """``with_f_number`` on a negative lens gives a negative pupil radius, which flips the
    marginal ray: the image-space slope then looks like a positive lens's. The status must
    still flag the design and the merit be +inf (it was valid with a finite merit)."""
    @jax.jit
    def radius_ok_merit(c1):
        lens = jl.Singlet(c1, 1 / 200, 6.0, 1.6, stop_distance=5.0, f_number=4.0,
                          field_angle=5.0)
        status = jl.lens_status(lens)
        return lens.ep_radius, status.ok, status.aperture_ok, jmse_jax.lens_merit(
            lens, merit="rms")

    radius, ok, aperture_ok, merit = radius_ok_merit(jnp.asarray(-1 / 60))
    assert float(radius) < 0 and not bool(ok) and not bool(aperture_ok)
    assert float(merit) == math.inf
    radius, ok, aperture_ok, merit = radius_ok_merit(jnp.asarray(1 / 60))
    assert float(radius) > 0 and bool(ok) and np.isfinite(float(merit))
    flipped = eqx.tree_at(lambda lens: lens.ep_radius, spec_lens(), jnp.asarray(-5.0))
    with pytest.raises(ValueError, match=r"ep_radius must be in \(0, inf\) mm, got -5.0"):
        jl.validate_lens(flipped)


def test_crossed_vertices_in_an_air_gap_are_flagged():
    """A negative centre thickness whose edge stays positive (a gap thicker at the rim)."""
    lens = jl.Lens([0.1, -0.05, 0.2, 0.1], [2.0, 0.5, 1.0], [1.6, 1.0, 1.7, 1.0],
                   ep_radius=1.0, field_angle=5.0)
    assert bool(jl.lens_status(lens).ok)

    @jax.jit
    def status_and_merit(gap):
        crossed = jl.Lens(lens.curvatures, jnp.stack([jnp.asarray(2.0), gap, jnp.asarray(1.0)]),
                          lens.media, ep_radius=1.0, field_angle=5.0)
        status = jl.lens_status(crossed)
        return status.ok, status.min_edge_thickness, jmse_jax.lens_merit(crossed, merit="rms")

    ok, thinnest, merit = status_and_merit(jnp.asarray(-0.05))
    assert not bool(ok) and float(thinnest) == pytest.approx(-0.05, rel=1e-12)
    assert float(merit) == math.inf
    ok, _, merit = status_and_merit(jnp.asarray(0.5))
    assert bool(ok) and np.isfinite(float(merit))


def test_merit_over_wavelengths_checks_every_wavelength():
    """Valid at d, total internal reflection at F: the polychromatic merit refuses it (a
    concrete lens) or gives +inf (traced), instead of averaging a non-physical design."""
    lens = jl.Singlet(0.275, -0.0825, 3.0, jl.AbbeGlass(1.75, 25), stop_distance=0.0,
                      ep_radius=1.5, field_angle=36.0)
    assert bool(jl.lens_status(lens).ok)
    assert not bool(jl.lens_status(lens, jl.FRAUNHOFER_F).ok)
    wavelengths = [jl.FRAUNHOFER_F, jl.FRAUNHOFER_D]
    with pytest.raises(ValueError, match=r"at wavelength 0\.486\d* µm: total internal"):
        jmse_jax.lens_merit(lens, merit="rms", wavelengths=wavelengths)
    traced = jax.jit(lambda design: jmse_jax.lens_merit(design, merit="rms",
                                                        wavelengths=wavelengths))
    assert float(traced(lens)) == math.inf
    # A dispersion formula outside its range: Cauchy's n = a + b / lambda^2 below 1.
    cauchy = jl.Singlet(0.05, -0.02, 3.0, jl.CauchyGlass(1.5, -0.05), ep_radius=1.5,
                        field_angle=5.0)
    assert float(cauchy.media[0].index(0.2)) == pytest.approx(0.25)
    assert not bool(jl.lens_status(cauchy, 0.2).indices_ok)
    with pytest.raises(ValueError, match=r"refractive indices must be in \[1, 4\], got "
                                         r"\[1\.0, 0\.25, 1\.0\]"):
        jmse_jax.lens_merit(cauchy, merit="rms", wavelengths=[0.2, jl.FRAUNHOFER_D])


def test_surface_beyond_its_reach_is_named():
    lens = jl.Lens([0.05, -0.3], [3.0], [1.5, 1.0], ep_radius=1.5, field_angle=5.0,
                   conics=[5.0, 5.0])
    # 1 - (1 + k) c^2 r^2 = 0 at r = 1 / (|c| sqrt(1 + k)) = 1.36083 mm
    with pytest.raises(ValueError, match=r"surface 1 does not extend .* ends at 1\.36083 mm"):
        jl.validate_lens(lens)


def test_argument_validation_messages():
    with pytest.raises(ValueError, match="curvatures must list at least one surface"):
        jl.Lens([], [], [])
    with pytest.raises(ValueError, match=r"f_number must be in \(0\.0, inf\], got 0\.0"):
        jl.defocus_waves(0.1, 0.0, 0.5876)
    with pytest.raises(ValueError, match=r"field must be in \[0\.0, 1\.0\], got 2\.0"):
        jl.rms_wavefront_error(jmse_jax.Seidel(w222=1.0), 2.0)
    with pytest.raises(ValueError, match=r"ep_radius must be in \(0.0, inf\], got -1.0"):
        jl.Lens([0.01, -0.01], [1.0], [1.5, 1.0], ep_radius=-1.0)
    with pytest.raises(ValueError, match="field_angle"):
        jl.Lens([0.01, -0.01], [1.0], [1.5, 1.0], field_angle=75.0)
    with pytest.raises(ValueError, match="thicknesses"):
        jl.Lens([0.01, -0.01], [-1.0], [1.5, 1.0])
    with pytest.raises(ValueError, match="media must list one medium per surface"):
        jl.Lens([0.01, -0.01], [1.0], [1.5])
    with pytest.raises(ValueError, match="thicknesses must have shape"):
        jl.Lens([0.01, -0.01], [1.0, 2.0], [1.5, 1.0])
    with pytest.raises(ValueError, match="f_number"):
        jl.solve_last_curvature(spec_lens(), -2.0)

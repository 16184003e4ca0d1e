"""Lens optimisation: gradients vs finite differences, JMSE vs RMS optima, bounds, solvers."""

import dataclasses
import math

import equinox as eqx
import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from checked_range import eager_warns  # noqa: E402
from small_tiers import SMALL_TIERS, tiers_without_one_ray  # noqa: E402

import jmse_jax  # noqa: E402
from jmse_jax import (  # noqa: E402
    AccuracyWarning,
    lens as jl,
)
from jmse_jax._merit import _route  # noqa: E402
from jmse_jax._optimise import (  # noqa: E402
    _get,
    _parse,
    _RescaledNoise,
    _RescaledSignal,
    _set,
    lens_beyond_checked,
    lens_merit,
    optimise,
)

FAST = {"preset": "fast"}
VARIABLES = ("curvatures[0]", "stop_position", "image_shift")


def start_design(stop_distance=1.0, front_curvature=0.05, image_shift=0.0):
    return jl.paper_singlet(stop_distance, front_curvature, image_shift=image_shift)


@pytest.fixture(scope="module")
def jmse_optimum():
    return optimise(start_design(), VARIABLES, f_number=4.6, jmse_options=FAST)


@pytest.fixture(scope="module")
def rms_optimum():
    return optimise(start_design(), VARIABLES, f_number=4.6, merit="rms", jmse_options=FAST)


def test_objective_gradient_matches_finite_differences():
    """d(mean JMSE)/d(lens parameters), polychromatic, F-number solve, vs central FD."""
    wavelengths = (jl.FRAUNHOFER_F, jl.FRAUNHOFER_D)

    def merit(params):
        c1, stop, shift, thickness = params
        lens = jl.Singlet(c1, 0.0, thickness, jl.N_BK7, stop_distance=-stop, ep_radius=0.978,
                          field_angle=10.0, image_shift=shift)
        lens = jl.solve_last_curvature(lens, 4.6)
        return lens_merit(lens, fields=(0.3, 1.0), wavelengths=wavelengths,
                          reference_scale=0.5875618 * 4.6, jmse_options=FAST)

    params = jnp.array([0.04, -1.2, -0.15, 1.5])
    value_and_grad = jax.jit(jax.value_and_grad(merit))  # one compilation serves both

    def value(p):
        return float(value_and_grad(p)[0])

    grad = np.asarray(value_and_grad(params)[1])
    for i, step in enumerate((1e-6, 1e-4, 1e-5, 1e-4)):
        e = np.zeros(4)
        e[i] = step
        fd = (value(params + e) - value(params - e)) / (2 * step)
        assert grad[i] == pytest.approx(fd, rel=1e-6), f"parameter {i}"
    assert np.all(np.abs(grad) > 1e-8)  # every parameter matters


def test_jmse_optimal_design_beats_rms_optimal_design(jmse_optimum, rms_optimum):
    """The computational-imaging thesis: the JMSE optimum is not the RMS-wavefront optimum."""
    assert jmse_optimum.result == "converged"
    assert rms_optimum.result == "converged"
    start_jmse = float(lens_merit(start_design(), jmse_options=FAST))
    assert jmse_optimum.start_jmse == pytest.approx(start_jmse, rel=1e-12)
    # result.jmse is the merit the optimiser saw: u and the spectra in the start's lambda N.
    assert jmse_optimum.reference_scale == pytest.approx(0.5875618 * 4.6, rel=1e-12)
    final = lens_merit(jmse_optimum.lens, reference_scale=jmse_optimum.reference_scale,
                       jmse_options=FAST)
    assert jmse_optimum.jmse == pytest.approx(float(final), rel=1e-12)
    assert jmse_optimum.jmse < 0.9 * start_jmse
    # Each design wins on its own merit, by a clear margin.
    assert jmse_optimum.jmse < 0.8 * rms_optimum.jmse
    assert rms_optimum.rms_wavefront < 0.9 * jmse_optimum.rms_wavefront
    # And they are different lenses.
    c_jmse = jmse_optimum.parameters["curvatures[0]"]
    c_rms = rms_optimum.parameters["curvatures[0]"]
    assert abs(c_jmse - c_rms) > 1e-3
    assert float(jl.working_f_number(jmse_optimum.lens)) == pytest.approx(4.6, rel=1e-12)
    summary = jmse_optimum.summary()
    assert "JMSE" in summary and "iterations" in summary
    # The result names the options it ran (FAST), so a "fast" optimum can be confirmed.
    assert jmse_optimum.jmse_options == FAST
    assert "merit=jmse (preset='fast')" in summary


def test_different_starts_reach_the_same_jmse(jmse_optimum):
    other = optimise(start_design(2.5, -0.02, -0.1), VARIABLES, f_number=4.6,
                     jmse_options=FAST)
    assert other.result == "converged"
    assert other.jmse == pytest.approx(jmse_optimum.jmse, rel=1e-3)


def test_second_solver_reaches_the_bfgs_optimum(rms_optimum):
    cg = optimise(start_design(), VARIABLES, f_number=4.6, merit="rms", solver="nonlinear_cg",
                  jmse_options=FAST)
    assert cg.solver == "NonlinearCG"
    assert cg.rms_wavefront == pytest.approx(rms_optimum.rms_wavefront, rel=1e-6)


# jaxopt's import-time notice that it is unmaintained is not the user's to act on: optimise
# imports it under a filter, so no DeprecationWarning reaches the caller.
@pytest.mark.filterwarnings("error::DeprecationWarning")
def test_bounds_use_lbfgsb_and_find_the_constrained_optimum(rms_optimum):
    # The unconstrained RMS optimum has the stop ~2.4 mm in front; allow at most 1 mm.
    assert rms_optimum.parameters["stop_position"] < -1.5
    bounded = optimise(start_design(), VARIABLES, f_number=4.6, merit="rms",
                       bounds={"stop_position": (-1.0, 0.0), "curvatures[0]": (-0.1, 0.1)},
                       jmse_options=FAST)
    assert bounded.solver == "jaxopt.LBFGSB"
    assert bounded.parameters["stop_position"] == pytest.approx(-1.0, abs=1e-9)
    # Same constrained optimum as optimistix with the stop pinned at the bound.
    pinned = optimise(start_design(stop_distance=1.0), ("curvatures[0]", "image_shift"),
                      f_number=4.6, merit="rms", jmse_options=FAST)
    assert bounded.rms_wavefront == pytest.approx(pinned.rms_wavefront, rel=1e-5)
    assert bounded.rms_wavefront > rms_optimum.rms_wavefront


def test_default_preset_merit_is_the_field_mean_of_jmse(monkeypatch):
    """With the default's tiers the fields go one at a time (each runs its own grid): value
    and gradient equal the mean over the fields of ``jmse`` and of its gradient, taken field
    by field through the lens's Seidel sums by the chain rule (an on-axis, a middle and an
    outer field). The default's tiers are two small ones here (``SMALL_TIERS`` of
    ``tests/small_tiers.py`` with the first up to strength 2, so that the field on the axis
    takes it and the others the second), without the one-ray plans: the same dispatch,
    field by field, in programs that compile in seconds (the default's own lens program
    took 54 s of compilation on the CI machine)."""
    tiers_without_one_ray(monkeypatch, ((2.0, *SMALL_TIERS[0][1:]), SMALL_TIERS[1]))
    fields = (0.0, 0.7, 1.0)
    signal, noise = jmse_jax.MarkovSignal(1.0, 5.0), jmse_jax.WhiteNoise(1e-3)

    def lens_at(shift):
        return jl.Singlet(0.04, -0.17, 1.5, 1.5168, stop_distance=1.0, f_number=4.6,
                          field_angle=10.0, image_shift=shift)

    shift = jnp.asarray(-0.1)
    # ``preset="default"`` spelled out: the same merit as no options, under a static key of
    # its own, so that no program of the real default is reused here, nor this one later.
    value, grad = jax.jit(jax.value_and_grad(
        lambda s: lens_merit(lens_at(s), fields=fields,
                             jmse_options={"preset": "default"})))(shift)

    # The oracle, by the chain rule: the default's value and gradient in the coefficients,
    # dotted with d(waves)/d(shift), field by field.
    waves, d_waves = jax.jvp(lambda s: jl.seidel_waves(lens_at(s)), (shift,), (1.0,))
    oracle = jax.jit(jax.value_and_grad(
        lambda a, f: jmse_jax.jmse(a, f, 0.2, signal, noise)))
    assert [_route(waves, f, 0.2, signal, noise)["tier"] for f in fields] == [0, 1, 1]
    per_field = []
    for f in fields:
        v, g = oracle(waves, f)
        per_field.append((v, sum(jnp.sum(a * b) for a, b in zip(
            jax.tree_util.tree_leaves(g), jax.tree_util.tree_leaves(d_waves), strict=True))))
    assert float(value) == pytest.approx(np.mean([float(v) for v, _ in per_field]), rel=1e-12)
    assert float(grad) == pytest.approx(np.mean([float(g) for _, g in per_field]), rel=1e-9)
    assert abs(float(grad)) > 1e-6


def test_polychromatic_merit_rescales_band_and_spectra():
    """Constant index: at lambda the merit is the JMSE with u s, mu / s, S_n / s² (s = l/l0)."""
    lens = jl.Singlet(0.04, -0.17, 1.5, 1.5168, stop_distance=1.0, f_number=4.6,
                      field_angle=10.0, image_shift=-0.1)
    wl = 0.65
    s = wl / float(lens.wavelength)
    got = float(lens_merit(lens, fields=(0.7,), wavelengths=(wl,), jmse_options=FAST))
    jmse = jax.jit(lambda *args: jmse_jax.jmse(*args, preset="fast"))
    expected = float(jmse(jl.seidel_waves(lens, wl), 0.7, 0.2 * s,
                          jmse_jax.MarkovSignal(1.0, 5.0 / s), jmse_jax.WhiteNoise(1e-3 / s**2)))
    assert got == pytest.approx(expected, rel=1e-12)
    mono = float(lens_merit(lens, fields=(0.7,), jmse_options=FAST))
    same = float(lens_merit(lens, fields=(0.7,), wavelengths=(float(lens.wavelength),),
                            jmse_options=FAST))
    assert same == pytest.approx(mono, rel=1e-12)
    assert abs(got - mono) > 1e-3 * mono


def _dispersion_free(image_shift):
    """A singlet of constant index 1.5168 (its F-number the same at every wavelength), 20
    degrees of field, focused ``image_shift`` mm off."""
    return jl.Singlet(0.04, -0.17, 1.5, 1.5168, stop_distance=1.0, f_number=4.6,
                      field_angle=20.0, image_shift=image_shift)


def _lens_oracle(monkeypatch, lens, u, noise, fields, wavelengths, options):
    """Per field, whether a concrete ``jmse`` call warns on a design ``lens_merit`` gives it
    at any of the wavelengths: the lens's Seidel waves there, ``u s`` and the spectra
    ``S(nu / s) / s²`` with ``s = lambda / lambda_0`` (constant index: ``lambda N`` scales
    with ``lambda`` alone). The spectra are ``lens_merit``'s own rescaled models: its noise
    model does not say it is isotropic, so on the axis ``jmse`` takes the polar grid (and
    its checks, e.g. of terms that cancel) rather than the one-ray plans that a plain
    ``WhiteNoise`` gets."""
    reference = float(lens.wavelength)

    def warns(wl, h):
        s = jnp.asarray(wl / reference)
        return eager_warns(monkeypatch, jl.seidel_waves(lens, wl), h, u * wl / reference,
                           _RescaledSignal(jmse_jax.MarkovSignal(1.0, 5.0), s),
                           _RescaledNoise(jmse_jax.WhiteNoise(noise), s), **options)

    return np.array([any(warns(wl, h) for wl in (wavelengths or (reference,)))
                     for h in fields])


def test_lens_beyond_checked_answers_as_concrete_jmse_calls_warn(monkeypatch):
    """``lens_beyond_checked`` marks the fields at which ``jmse`` would warn on the design
    ``lens_merit`` hands it (the oracle: concrete calls on the lens's Seidel waves with the
    band and spectra rescaled by hand), for designs beyond the checked strength and slope
    at some fields only, terms that cancel for ``fast`` (the default has the balanced
    grid), a peak ``S_x / S_n`` beyond ``CHECKED_SNR`` (off the axis only) and inside,
    with one wavelength and with two."""
    fields = (0.0, 0.5, 1.0)
    peak = float(jmse_jax.MarkovSignal(1.0, 5.0)(jnp.zeros(()), jnp.zeros(())))
    cases = [  # image_shift, u, noise, jmse_options, wavelengths
        (1.5, 0.4, 1e-3, {}, None),
        (1.5, 0.4, 1e-3, {}, (0.486, 0.656)),
        (0.7, 0.4, 1e-3, FAST, (0.486, 0.656)),
        (-0.5, 0.4, 1e-3, FAST, None),
        (-0.5, 0.4, 1e-3, {}, None),
        (0.0, 0.2, peak / 1e7, {}, (0.486, 0.656)),
        (0.0, 0.2, 1e-3, {}, None),
    ]
    seen = set()
    for shift, u, noise, options, wavelengths in cases:
        lens = _dispersion_free(shift)
        got = lens_beyond_checked(lens, u=u, noise=jmse_jax.WhiteNoise(noise), fields=fields,
                                  wavelengths=wavelengths, jmse_options=options)
        expected = _lens_oracle(monkeypatch, lens, u, noise, fields, wavelengths, options)
        assert got.dtype == bool and got.shape == (3,)
        np.testing.assert_array_equal(got, expected, err_msg=str((shift, u, noise, options)))
        seen.add(tuple(expected))
    # Not vacuous: mixed answers across the fields, all False and all True among the cases.
    assert (False, False, False) in seen and (False, True, True) in seen
    assert (True, True, False) in seen and (False, True, True) in seen
    assert (False, False, True) in seen


def test_lens_beyond_checked_refuses_what_it_cannot_answer():
    """Grid options (no checked range), traced values, a non-physical lens, a field or
    ``u`` out of range: clear errors naming what is wrong."""
    lens = _dispersion_free(0.0)
    with pytest.raises(ValueError, match=r"grid options \(nodes\) have no checked range"):
        lens_beyond_checked(lens, jmse_options={"nodes": (24, 16)})
    with pytest.raises(TypeError, match="needs concrete values"):
        jax.jit(lambda u: lens_beyond_checked(lens, u=u))(0.2)
    with pytest.raises(ValueError, match=r"fields .*\[0\.0, 1\.0\]"):
        lens_beyond_checked(lens, fields=(0.5, 1.2))
    with pytest.raises(ValueError, match=r"u must be in \(0\.0, 1\.5\]"):
        lens_beyond_checked(lens, u=0.0)
    with pytest.raises(TypeError, match="lens must be a jmse_jax.lens.Lens"):
        lens_beyond_checked(jmse_jax.Seidel(w020=1.0))
    flat = jl.Singlet(0.0, 0.0, 1.5, 1.5168, stop_distance=1.0, ep_radius=1.0,
                      field_angle=20.0)  # no power: no focus
    with pytest.raises(ValueError):
        lens_beyond_checked(flat)


def test_optimisation_result_says_which_fields_are_beyond_the_checked_range(monkeypatch,
                                                                           jmse_optimum):
    """``OptimisationResult.beyond_checked``: per field, whether ``jmse`` would warn on the
    final design (the oracle of ``lens_beyond_checked``'s test), shown in the summary; all
    False at the paper singlet's optimum. A run held far from focus (one variable, two
    steps) ends beyond the checked strength at the outer fields."""
    assert jmse_optimum.beyond_checked == (False, False, False)
    assert "beyond" not in jmse_optimum.summary()
    far = optimise(_dispersion_free(1.5), ("stop_position",), merit="rms", u=0.4,
                   max_steps=2, jmse_options=FAST)
    # The stop moves no focal length: u and the spectra refer to the final design's own
    # lambda N, as the oracle takes them.
    assert far.reference_scale == pytest.approx(
        float(far.lens.wavelength * jl.working_f_number(far.lens)), rel=1e-12)
    expected = _lens_oracle(monkeypatch, far.lens, 0.4, 1e-3, far.fields, None, FAST)
    assert far.beyond_checked == tuple(expected) == (False, True, True)
    assert far.summary().count("(beyond the checked range)") == 2
    # Grid options have no checked range: nothing is said.
    assert dataclasses.replace(far, beyond_checked=None).summary().count("beyond") == 0


def test_polychromatic_optimise_reaches_a_minimum_of_its_merit(rms_optimum):
    """optimise with wavelengths: they ride in the jitted objective as traced values (until
    2026-12-03 that raised a TracerArrayConversionError in the argument checks). The RMS merit
    keeps it cheap; the oracle is lens_merit, called on its own, at and around the result."""
    wavelengths = (jl.FRAUNHOFER_F, jl.FRAUNHOFER_D, jl.FRAUNHOFER_C)
    poly = optimise(start_design(), VARIABLES, f_number=4.6, merit="rms",
                    wavelengths=wavelengths, jmse_options=FAST)
    assert poly.result == "converged"
    assert math.isfinite(poly.jmse)

    def variance(lens):
        return float(lens_merit(lens, merit="rms", wavelengths=wavelengths,
                                reference_scale=poly.reference_scale, jmse_options=FAST))

    at_result = variance(poly.lens)
    assert poly.value == pytest.approx(at_result, rel=1e-12)
    for name in VARIABLES:  # a minimum: a step either way in each variable costs merit
        parsed = _parse(name, poly.lens)
        for step in (-1e-3, 1e-3):
            moved = _set(poly.lens, parsed, _get(poly.lens, parsed) + step)
            assert variance(jl.solve_last_curvature(moved, 4.6)) > at_result, (name, step)
    # Colour moves the optimum: the best focus of F, d and C is not that of d alone.
    shift = poly.parameters["image_shift"] - rms_optimum.parameters["image_shift"]
    assert abs(shift) > 0.01


def test_rms_merit_is_the_closed_form():
    lens = start_design()
    ab = jl.seidel_waves(lens)
    fields = (0.0, 0.7, 1.0)
    expected = np.mean([float(jl.rms_wavefront_error(ab, h)) ** 2 for h in fields])
    assert float(lens_merit(lens, merit="rms")) == pytest.approx(expected, rel=1e-14)


def test_non_physical_design_gives_inf_merit_and_finite_gradient():
    @jax.jit
    def merit(thickness):
        lens = jl.Lens([0.2, -0.2], jnp.reshape(thickness, (1,)), [1.5, 1.0], ep_radius=1.5,
                       field_angle=5.0)
        return lens_merit(lens, merit="rms")

    assert math.isinf(float(merit(jnp.asarray(0.3))))  # negative edge thickness
    assert np.isfinite(float(merit(jnp.asarray(1.0))))
    grad = jax.grad(merit)(jnp.asarray(0.3))
    assert float(grad) == 0.0
    bad = jl.Lens([0.2, -0.2], [0.3], [1.5, 1.0], ep_radius=1.5, field_angle=5.0)
    with pytest.raises(ValueError, match="gap thickness, on the axis and at the edge"):
        lens_merit(bad, merit="rms")


@pytest.mark.parametrize("name", ["image_shift", "stop_position", "curvatures"])
def test_nan_in_a_traced_lens_gives_inf_merit_and_zero_gradient(name):
    """A NaN reaching a traced lens (a diverging optimiser): +inf with a zero gradient, as for
    any non-physical design. The RMS merit was 0.0 (its best value) for a NaN image_shift,
    and stop_position or a curvature gave NaN gradients."""
    start = start_design()

    @jax.jit
    def merit(x):
        value = jnp.where(jnp.arange(2) == 0, x, start.curvatures) if name == "curvatures" \
            else x
        return lens_merit(eqx.tree_at(lambda lens: getattr(lens, name), start, value),
                          merit="rms")

    x0 = start.curvatures[0] if name == "curvatures" else getattr(start, name)
    assert float(merit(x0)) == pytest.approx(float(lens_merit(start, merit="rms")), rel=1e-12)
    value, grad = jax.value_and_grad(merit)(jnp.asarray(jnp.nan))
    assert math.isinf(float(value)) and float(grad) == 0.0
    lens = eqx.tree_at(lambda lens: lens.image_shift, start, jnp.asarray(jnp.nan))
    assert not bool(jl.lens_status(lens).finite) and not bool(jl.lens_status(lens).ok)


def test_lens_merit_and_otf_under_jit_with_constant_inputs():
    """A lens (or an otf design) closed over by the caller's jit is constant there: its
    checks run at trace time instead of failing on the tracers of their own jitted parts."""
    lens = start_design()
    eager = float(lens_merit(lens, merit="rms", u=0.25, fields=(0.0, 0.7),
                             field_weights=(1.0, 2.0), wavelengths=(0.4861, 0.6563)))
    program = jax.jit(lambda u: lens_merit(lens, merit="rms", u=u, fields=(0.0, 0.7),
                                           field_weights=(1.0, 2.0),
                                           wavelengths=(0.4861, 0.6563)))
    assert float(program(0.25)) == pytest.approx(eager, rel=1e-13)
    bad = jl.Lens([0.2, -0.2], [0.3], [1.5, 1.0], ep_radius=1.5, field_angle=5.0)
    with pytest.raises(ValueError, match="gap thickness, on the axis and at the edge"):
        jax.jit(lambda u: lens_merit(bad, merit="rms", u=u))(0.2)
    # jmse options given as NumPy arrays are static, as lists and tuples are.
    options = {"preset": "fast", "nodes": np.array([24, 16])}
    assert float(lens_merit(lens, merit="rms", jmse_options=options)) == pytest.approx(
        float(lens_merit(lens, merit="rms")), rel=1e-14)
    ab = jmse_jax.Seidel(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
    expected = complex(jmse_jax.otf(ab, 0.1, 0.05, 0.95))
    assert complex(jax.jit(lambda s: s * jmse_jax.otf(ab, 0.1, 0.05, 0.95))(1.0)) \
        == pytest.approx(expected, rel=1e-13)


def test_glass_parameters_are_optimisation_variables():
    start = start_design()
    result = optimise(start, ("media[0].nd", "image_shift"), f_number=4.6, merit="rms",
                      scales={"media[0].nd": 0.01}, max_steps=50, jmse_options=FAST)
    assert set(result.parameters) == {"media[0].nd", "image_shift"}
    assert result.parameters["media[0].nd"] != pytest.approx(1.5168, abs=1e-4)
    assert float(result.lens.media[0].nd) == result.parameters["media[0].nd"]
    assert result.rms_wavefront < result.start_rms_wavefront


def test_optimise_checks_the_merit_arguments_before_running():
    """The arguments optimise shares with lens_merit are checked alike, before any step."""
    lens = start_design()
    cases = [
        (dict(u=2.0), ValueError, r"u must be in \(0\.0, 1\.5\], got 2\.0"),
        (dict(u=float("nan")), ValueError, r"u must be finite and in \(0\.0, 1\.5\]"),
        (dict(fields=(1.5,)), ValueError, r"fields must be in \[0\.0, 1\.0\], got \[1\.5\]"),
        (dict(fields=()), ValueError, r"fields must be a non-empty 1-D sequence"),
        (dict(field_weights=(0, 0, 0)), ValueError, r"field_weights must have a positive sum"),
        (dict(wavelengths=[50.0]), ValueError, r"wavelengths must be in \[0\.2, 20\.0\]"),
        (dict(wavelengths=0.55), ValueError, r"wavelengths must be a non-empty sequence"),
        (dict(signal="markov"), TypeError, r"signal must be a jmse_jax signal model"),
        (dict(jmse_options=["fast"]), TypeError, r"jmse_options must be a dict"),
    ]
    for changes, kind, match in cases:
        for fn in (lambda **kw: lens_merit(lens, **kw),
                   lambda **kw: optimise(lens, ("image_shift",), **kw)):
            with pytest.raises(kind, match=match):
                fn(**changes)
    with pytest.raises(ValueError, match=r"reference_scale must be in \(0\.0, inf\]"):
        lens_merit(lens, reference_scale=-2.0)
    with pytest.raises(TypeError, match=r"variables must be a sequence of parameter names"):
        optimise(lens, "image_shift")
    with pytest.raises(ValueError, match=r"bounds\['image_shift'\] must be a pair"):
        optimise(lens, ("image_shift",), bounds={"image_shift": 1.0})
    for side, pair in (("low", (float("nan"), None)), ("high", (None, "1"))):
        with pytest.raises(ValueError, match=rf"bounds\['image_shift'\]'s {side} must be a "
                                             rf"real number or None, got"):
            optimise(lens, ("image_shift",), merit="rms", bounds={"image_shift": pair})


def test_optimise_argument_errors():
    lens = start_design()
    with pytest.raises(ValueError, match="does not name a lens parameter"):
        optimise(lens, ("curvature[0]",))
    with pytest.raises(ValueError, match="out of range"):
        optimise(lens, ("curvatures[5]",))
    with pytest.raises(ValueError, match="fixed by the f_number solve"):
        optimise(lens, ("curvatures[1]",), f_number=4.6)
    with pytest.raises(ValueError, match="fixed by the f_number solve"):  # the same index
        optimise(lens, ("curvatures[01]",), f_number=4.6)
    with pytest.raises(ValueError, match=r"the start's image_shift = 0\.0 lies outside "
                                         r"bounds\['image_shift'\] = \(0\.05, 0\.2\)"):
        optimise(lens, ("image_shift",), merit="rms", bounds={"image_shift": (0.05, 0.2)})
    with pytest.raises(ValueError, match="bounds names"):
        optimise(lens, ("curvatures[0]",), merit="rms", bounds={"image_shift": (-1, 1)})
    with pytest.raises(ValueError, match="low < high"):
        optimise(lens, ("image_shift",), merit="rms", bounds={"image_shift": (1, -1)})
    # jaxopt's LBFGSB has no relative tolerance: an rtol given with bounds was ignored
    with pytest.raises(ValueError, match=r"rtol = 1e-05 has no effect with bounds"):
        optimise(lens, ("image_shift",), merit="rms", bounds={"image_shift": (-1, 1)},
                 rtol=1e-5)
    with pytest.raises(ValueError, match="merit must be one of"):
        optimise(lens, ("image_shift",), merit="strehl")
    with pytest.raises(ValueError, match="solver must be one of"):
        optimise(lens, ("image_shift",), merit="rms", solver="newton")
    with pytest.raises(ValueError, match=r"fields must be in \[0.0, 1.0\]"):
        lens_merit(lens, merit="rms", fields=(0.5, 1.5))


def test_noise_beyond_the_checked_snr_warns_in_lens_merit_and_optimise():
    """lens_merit and optimise warn as jmse does when max S_x / S_n exceeds CHECKED_SNR with
    a preset's grids (MarkovSignal(1, 5): S_x(0) = 157, so a noise of 1e-8 is 1.6e10). The
    warning comes with the argument checks, before anything is compiled (here a bad field
    list then stops the call); no warning with grids of the caller's own."""
    import warnings

    lens = start_design()
    noisy = dict(signal=jmse_jax.MarkovSignal(1.0, 5.0), noise=jmse_jax.WhiteNoise(1e-8),
                 fields=(1.5,))
    for fn in (lambda **kw: lens_merit(lens, **kw),
               lambda **kw: optimise(lens, ("image_shift",), **kw)):
        with pytest.warns(AccuracyWarning, match=r"max S_x/S_n = 1\.57e\+10 is beyond"):
            with pytest.raises(ValueError, match="fields must be in"):
                fn(**noisy)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(ValueError, match="fields must be in"):
                fn(**noisy, jmse_options={"se_nodes": (800, 96), "nodes": (24, 12)})
            with pytest.raises(ValueError, match="fields must be in"):
                fn(**{**noisy, "noise": jmse_jax.WhiteNoise(1e-4)})  # 1.6e6
    # "high"'s values hold to CHECKED_SNR_PEAKS, its gradients off the axis with its own
    # counts (960 angular fine S_e nodes, 80 radial OTF nodes) only to CHECKED_SNR (sessions
    # 85 and 87's climbs): at 1.6e8 lens_merit does not warn, and optimise warns when told to
    # keep 960 (it otherwise takes more by itself, tests/test_se_angular.py).
    high = dict(noisy, noise=jmse_jax.WhiteNoise(1e-6), jmse_options={"preset": "high"})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="fields must be in"):
            lens_merit(lens, **high)
    with pytest.warns(AccuracyWarning,
                      match=r"max S_x/S_n = 1\.57e\+08 is beyond what the gradients "
                            r"of the polar grids were checked at off the axis"):
        with pytest.raises(ValueError, match="fields must be in"):
            optimise(lens, ("image_shift",),
                     **dict(high, jmse_options={"preset": "high", "se_angular": 960}))
    # merit="rms": lens_merit computes no JMSE, so no check; optimise follows the wavefront's
    # gradient and reports the JMSE, so it checks the value only (session 87).
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="fields must be in"):
            lens_merit(lens, merit="rms", **noisy)
        with pytest.raises(ValueError, match="fields must be in"):
            optimise(lens, ("image_shift",), merit="rms",
                     **dict(high, jmse_options={"preset": "high", "se_angular": 960}))
    with pytest.warns(AccuracyWarning, match=r"max S_x/S_n = 1\.57e\+10 is beyond"):
        with pytest.raises(ValueError, match="fields must be in"):
            optimise(lens, ("image_shift",), merit="rms", **noisy)

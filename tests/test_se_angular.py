"""``jmse``'s low-noise counts: ``se_angular`` and ``otf_radial`` (with their ``grad_`` twins),
``se_angular_for``, ``otf_radial_for``, and the choice ``jmse``, ``lens_merit`` and
``optimise`` make of them by themselves.

``se_angular`` raises the angular count of fine S_e nodes in every polar grid a preset may
take without fixing the grid (its branches and one-ray plans stay). The oracle here is the
same grid given explicitly: ``preset="fast", se_angular=n`` must be ``fast``'s grid with
``se_nodes=(800, n)``, value and gradient; ``otf_radial=n`` likewise with ``nodes=(n, 16)``.
The counts' calibration against converged grids (``"high"`` at peak ratios 2e6-2e8) is too
heavy for the suite: ``benchmarks/se_angular.py``, ``benchmarks/otf_radial.py`` and
``benchmarks/default_climb.py --preset high --gradient --noise``.
"""

import functools
import warnings

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import AccuracyWarning  # noqa: E402
from jmse_jax._merit import (  # noqa: E402
    CHECKED_SNR,
    CHECKED_SNR_PEAKS,
    HIGH_RAY_GRID,
    PRESETS,
    _base_plans,
    _low_noise_statics,
    _prepare,
    _radial_plans,
    _tier_plans_of,
    jmse_options,
)
from jmse_jax._optimise import _with_gradient_counts  # noqa: E402

FIG1 = dict(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
FAST = PRESETS["fast"]
#: ``fast``'s grid given explicitly, with the fine angular count left to the caller.
FAST_GRID = dict(nodes=FAST["nodes"], overlap_nodes=FAST["overlap_nodes"],
                 overlap_floor=FAST["overlap_floor"], peaks=False)


def _design(noise=1e-4, field=0.95):
    return (jj.Seidel(**FIG1), field, 0.2, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(noise))


def test_se_angular_is_the_preset_grid_with_more_angular_fine_nodes():
    """Value and gradient of ``fast`` with ``se_angular=96`` are those of ``fast``'s grid
    given with ``se_nodes=(800, 96)`` (to rounding); on a grid of the caller's own too."""
    design = _design()
    own = float(jj.jmse(*design, preset="fast"))
    raised = float(jj.jmse(*design, preset="fast", se_angular=96))
    explicit = float(jj.jmse(*design, se_nodes=(800, 96), **FAST_GRID))
    assert raised == pytest.approx(explicit, rel=1e-13)
    assert raised == pytest.approx(own, rel=1e-10)  # 48 angular nodes hold this design
    # A grid of the caller's own, whose 8 angular fine nodes do not hold it: se_angular
    # gives the finer grid's value.
    coarse = dict(FAST_GRID, nodes=(24, 8))
    values = [float(jj.jmse(*design, se_nodes=(800, 8), **coarse, **extra))
              for extra in ({}, {"se_angular": 64})]
    assert values[1] == pytest.approx(float(jj.jmse(*design, se_nodes=(800, 64), **coarse)),
                                      rel=1e-13)
    assert abs(values[1] / values[0] - 1.0) > 1e-8

    def merit(c, u, **options):
        return jj.jmse(jj.Seidel(*c), 0.95, u, design[3], design[4], **options)

    c = jnp.array([FIG1[k] for k in ("w020", "w040", "w131", "w222", "w220")])
    grad = jax.jit(jax.grad(lambda c, u: merit(c, u, preset="fast", se_angular=96),
                            argnums=(0, 1)))(c, 0.2)
    grad_explicit = jax.jit(jax.grad(lambda c, u: merit(c, u, se_nodes=(800, 96),
                                                         **FAST_GRID),
                                     argnums=(0, 1)))(c, 0.2)
    np.testing.assert_allclose(np.asarray(grad[0]), np.asarray(grad_explicit[0]), rtol=1e-11)
    assert float(grad[1]) == pytest.approx(float(grad_explicit[1]), rel=1e-11)


def test_otf_radial_is_the_preset_grid_with_more_radial_otf_nodes():
    """``fast`` with ``otf_radial=40`` is ``fast``'s grid given with ``nodes=(40, 16)``,
    and a count below its own 24 changes nothing."""
    design = _design()
    raised = float(jj.jmse(*design, preset="fast", otf_radial=40))
    explicit = float(jj.jmse(*design, se_nodes=FAST["se_nodes"],
                             **dict(FAST_GRID, nodes=(40, FAST["nodes"][1]))))
    assert raised == pytest.approx(explicit, rel=1e-13)
    assert raised != float(jj.jmse(*design, preset="fast"))
    assert float(jj.jmse(*design, preset="fast", otf_radial=8)) == float(
        jj.jmse(*design, preset="fast"))


def test_se_angular_below_the_preset_count_and_on_the_axis_changes_nothing():
    """A count below the grid's own keeps it (``max``), and a design on the axis keeps its
    one-ray plan (no angular nodes), whose value ``fast``'s ``se_angular`` leaves alone."""
    design = _design()
    assert float(jj.jmse(*design, preset="fast", se_angular=8)) == float(
        jj.jmse(*design, preset="fast"))
    on_axis = (jj.Seidel(w020=-1.5, w040=0.8),) + _design(field=0.0)[1:]
    assert float(jj.jmse(*on_axis, preset="fast", se_angular=96)) == pytest.approx(
        float(jj.jmse(*on_axis, preset="fast")), rel=1e-14)


def test_se_angular_reaches_every_branch_of_high():
    """``"high"``'s own, steep and balanced grids all get the count (the balanced one of a
    Zernike design of high degree too, which replaces its S_e nodes by ``DEGREE_SE_NODES``);
    the one-ray plan keeps ``HIGH_RAY_GRID``'s counts. ``otf_radial`` alike: each grid gets
    at least that many radial OTF nodes (the balanced grid has more already)."""
    for aberrations in (jj.Seidel(**FIG1), jj.Zernike([0.3, 0.2, 0.1], noll=(4, 11, 22))):
        static, _ = _prepare((aberrations, 0.95, 0.2, jj.MarkovSignal(1.0, 5.0),
                              jj.WhiteNoise(1e-4)),
                             jj.jmse_options("high", se_angular=4800, otf_radial=144))
        plans = _base_plans(static, aberrations)
        assert len(plans) == 3  # own, steep, balanced
        for plan, _ in plans:
            assert plan["se_nodes"][1] == 4800
        assert [plan["nodes"][0] for plan, _ in plans] == [
            144, 144, (jj.DEGREE_NODES if isinstance(aberrations, jj.Zernike)
                       else jj.HIGH_BALANCED_GRID["nodes"])[0]]
        assert {plan["se_nodes"][0] for plan, _ in plans} == {
            PRESETS["high"]["se_nodes"][0], jj.HIGH_STEEP_GRID["se_nodes"][0],
            (jj.DEGREE_SE_NODES if isinstance(aberrations, jj.Zernike)
             else jj.HIGH_BALANCED_GRID["se_nodes"])[0]}
        (ray, _), = _radial_plans(_tier_plans_of(static, plans), static.value[6])[0]
        assert ray["se_nodes"] == HIGH_RAY_GRID["se_nodes"]
        assert ray["nodes"] == HIGH_RAY_GRID["nodes"]


@pytest.mark.parametrize("name", ["se_angular", "grad_se_angular", "otf_radial",
                                  "grad_otf_radial"])
@pytest.mark.parametrize("kwargs, match", [
    (dict(preset="default", count=1920), r"{name} applies to fixed grids.*"
                                         r"{name}=1920 with preset='default'"),
    (dict(preset="high", count=0), r"{name} must be"),
    (dict(preset="high", count=-5), r"{name} must be"),
    (dict(preset="fast", count=2.5), r"{name} must be"),
    (dict(preset="high", quadrature="gauss", nodes=16, count=96),
     r"{name} needs the polar rule.*quadrature='gauss'"),
])
def test_bad_counts_are_refused(name, kwargs, match):
    """``se_angular``, ``grad_se_angular`` (session 87), ``otf_radial`` and
    ``grad_otf_radial`` (session 88) are refused alike."""
    kwargs = {(name if key == "count" else key): value for key, value in kwargs.items()}
    with pytest.raises(ValueError, match="(^|[^_])" + match.format(name=name)):
        jj.jmse(*_design(), **kwargs)


@pytest.mark.parametrize("name", ["otf_radial", "grad_otf_radial"])
def test_radial_counts_beyond_the_fine_nodes_are_refused(name):
    with pytest.raises(ValueError, match=rf"^{name} must be at most se_nodes\[0\] = 800 .*"
                                         rf"got {name}=801"):
        jj.jmse(*_design(), preset="fast", **{name: 801})


def test_se_angular_for_follows_the_peak_snr():
    """960 (``"high"``'s own) up to ``CHECKED_SNR``, the table's counts beyond, rising with
    the ratio (MarkovSignal(1, 5): S_x(0) = 157.08, so the noise sets the ratio)."""
    signal = jj.MarkovSignal(1.0, 5.0)
    peak = float(signal(jnp.zeros(()), jnp.zeros(())))
    assert peak == pytest.approx(157.08, rel=1e-4)
    counts = [jj.se_angular_for(0.2, signal, jj.WhiteNoise(peak / ratio))
              for ratio in (1e3, 0.99 * CHECKED_SNR, 1.01 * CHECKED_SNR, CHECKED_SNR_PEAKS)]
    assert counts[:2] == [960, 960]
    assert counts[2] > 960
    assert counts[3] == jj.SE_ANGULAR_BY_SNR[-1][1]
    assert counts == sorted(counts)
    for (bound, count) in jj.SE_ANGULAR_BY_SNR:
        assert jj.se_angular_for(0.2, signal, jj.WhiteNoise(peak / bound * 1.0001)) == count
    with pytest.raises(ValueError, match="u must be"):
        jj.se_angular_for(-0.1, signal, jj.WhiteNoise(1e-3))
    with pytest.raises(TypeError, match="noise must be"):
        jj.se_angular_for(0.2, signal, 1e-3)
    # The radial OTF nodes alike: "high"'s own 80 up to CHECKED_SNR, the table's beyond.
    radial = [jj.otf_radial_for(0.2, signal, jj.WhiteNoise(peak / ratio))
              for ratio in (1e3, 0.99 * CHECKED_SNR, 1.01 * CHECKED_SNR, CHECKED_SNR_PEAKS)]
    assert radial[:2] == [80, 80] == [PRESETS["high"]["nodes"][0]] * 2
    assert radial[2] > 80
    assert radial == sorted(radial)
    for (bound, count) in jj.OTF_RADIAL_BY_SNR:
        assert jj.otf_radial_for(0.2, signal, jj.WhiteNoise(peak / bound * 1.0001)) == count
    with pytest.raises(ValueError, match="u must be"):
        jj.otf_radial_for(0.0, signal, jj.WhiteNoise(1e-3))


def test_optimise_takes_the_counts_for_high_beyond_the_checked_snr():
    """``optimise`` (through ``_with_gradient_counts``) gives ``"high"`` the counts of
    ``se_angular_for`` and ``otf_radial_for`` past ``CHECKED_SNR``, and nothing else: not
    below it, not for the default or ``fast``, not when the caller gave a count or a
    grid."""
    signal = jj.MarkovSignal(1.0, 5.0)
    low, high_snr = jj.WhiteNoise(1e-3), jj.WhiteNoise(1e-6)  # 1.6e5, 1.6e8
    count = jj.se_angular_for(0.2, signal, high_snr)
    radial = jj.otf_radial_for(0.2, signal, high_snr)
    assert count > 960 and radial > 80
    assert _with_gradient_counts({"preset": "high"}, 0.2, signal, high_snr) == {
        "preset": "high", "se_angular": count, "otf_radial": radial}
    # lens_merit's: the radial count holds the value too, so it is not the gradient's alone.
    assert _with_gradient_counts({"preset": "high"}, 0.2, signal, high_snr,
                                 prefix="grad_") == {
        "preset": "high", "grad_se_angular": count, "otf_radial": radial}
    for options in ({"preset": "fast"}, {}, None, {"preset": "high", "se_angular": 1920},
                    {"preset": "high", "grad_otf_radial": 120},
                    {"preset": "high", "se_nodes": (2800, 960)}):
        assert _with_gradient_counts(options, 0.2, signal, high_snr) == options
    # Within it the own count, as checked (no run-time check of the ratio in the gradient).
    assert _with_gradient_counts({"preset": "high"}, 0.2, signal, low) == {
        "preset": "high", "grad_se_angular": 960}


def test_optimise_warns_for_high_only_with_too_few_angular_nodes():
    """At a peak ratio of 1.6e8 ``optimise`` with ``"high"`` takes the count by itself and
    does not warn; with ``se_angular=960`` given it warns and names the count. (A bad field
    list stops each call after the checks, before anything is compiled.)"""
    from jmse_jax.lens import paper_singlet

    lens = paper_singlet(1.0, 0.05)
    kwargs = dict(signal=jj.MarkovSignal(1.0, 5.0), noise=jj.WhiteNoise(1e-6), fields=(1.5,))
    count = jj.se_angular_for(0.2, kwargs["signal"], kwargs["noise"])
    radial = jj.otf_radial_for(0.2, kwargs["signal"], kwargs["noise"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="fields must be in"):
            jj.optimise(lens, ("image_shift",), jmse_options={"preset": "high"}, **kwargs)
    with pytest.warns(AccuracyWarning, match=rf"1\.57e\+08 .* with their own counts .* "
                                         rf"Give se_angular={count}, otf_radial={radial} "):
        with pytest.raises(ValueError, match="fields must be in"):
            jj.optimise(lens, ("image_shift",),
                        jmse_options={"preset": "high", "se_angular": 960}, **kwargs)
    # The angular count given, the radial count named alone.
    with pytest.warns(AccuracyWarning, match=rf"Give otf_radial={radial} "):
        with pytest.raises(ValueError, match="fields must be in"):
            jj.optimise(lens, ("image_shift",),
                        jmse_options={"preset": "high", "se_angular": count}, **kwargs)


def test_gradient_in_u_does_not_store_the_fine_grid():
    """A ``value_and_grad`` in ``u`` differentiates the fine stage by ordinary means; its
    blocks are rematerialised (``_FINE_REMAT``), so XLA's scratch does not grow with the
    fine nodes (before session 86: 20.8 MB with 48 angular fine nodes, 86 MB with 768;
    now 16.7 and 18.8 MB), and the gradient is that of the plain program."""
    import jmse_jax._merit as merit_module

    c0 = jnp.array([FIG1[k] for k in ("w020", "w040", "w131", "w222", "w220")])

    def program(n):
        def f(c, u):
            return jj.jmse(jj.Seidel(*c), 0.95, u, jj.MarkovSignal(1.0, 5.0),
                           jj.WhiteNoise(1e-3), nodes=(24, 16), se_nodes=(800, n),
                           overlap_nodes=(28, 16))
        return jax.jit(jax.value_and_grad(f, argnums=(0, 1))).lower(c0, 0.2).compile()

    small, large = program(48), program(768)
    scratch = [p.memory_analysis().temp_size_in_bytes for p in (small, large)]
    assert scratch[1] < 1.5 * scratch[0], scratch
    assert scratch[1] < 40e6, scratch
    # The plain program (blocks not rematerialised) gives the same gradient.
    value, (g_c, g_u) = large(c0, 0.2)
    remat = merit_module._FINE_REMAT
    try:
        merit_module._FINE_REMAT = lambda f: f
        jax.clear_caches()
        plain = program(768)
    finally:
        merit_module._FINE_REMAT = remat
        jax.clear_caches()
    assert plain.memory_analysis().temp_size_in_bytes > 3 * scratch[1]
    value_p, (g_c_p, g_u_p) = plain(c0, 0.2)
    assert float(value) == pytest.approx(float(value_p), rel=1e-14)
    np.testing.assert_allclose(np.asarray(g_c), np.asarray(g_c_p), rtol=1e-13, atol=0)
    assert float(g_u) == pytest.approx(float(g_u_p), rel=1e-13)


# --- grad_se_angular: the gradient's own count (session 87) ---------------------------------
#: Session 85's steep design (``benchmarks/se_angular.py``), under its power-law spectrum at
#: a peak S_x / S_n of 1.5e7 (``se_angular_for``: 1920). ``fast`` with ``peaks=True`` has the
#: peaks without the default's tiers, as ``"high"`` does, so it takes the count by itself as
#: ``"high"`` would, on a grid that compiles in seconds; its own 48 angular fine nodes leave
#: this design's gradient 9.7e-2 off the 1920's.
STEEP = dict(w020=6.644932297844935, w040=2.724906347815633, w131=3.085795717363572,
             w222=-5.3801335287493135, w220=-7.617778976339013)
STEEP_FIELD, STEEP_U = 0.9469066664934074, 0.85
STEEP_SIGNAL = jj.PowerLawSignal(1.8291638495696567e-4, 2.946692010240536,
                                 0.06186467434113549)
STEEP_PEAK = float(STEEP_SIGNAL(jnp.zeros(()), jnp.zeros(())))  # per unit white noise
PEAKED_FAST = dict(preset="fast", peaks=True)


def _steep(c, noise, **options):
    return jj.jmse(jj.Seidel(*c), STEEP_FIELD, STEEP_U, STEEP_SIGNAL, jj.WhiteNoise(noise),
                   **PEAKED_FAST, **options)


def _relative(a, b):
    return float(jnp.max(jnp.abs(a - b)) / jnp.max(jnp.abs(b)))


STEEP_C = jnp.array([STEEP[k] for k in ("w020", "w040", "w131", "w222", "w220")])
STEEP_NOISE = STEEP_PEAK / 1.5e7  # se_angular_for: 1920
#: ``OTF_RADIAL_BY_SNR``'s count past ``CHECKED_SNR`` in the tests that compile the steep
#: design (``small_radial_table``): the mechanism is the same as with the real 160, which
#: would give ``fast`` 160 radial OTF nodes in place of its 24 and make those tests twice as
#: slow (session 88: 69 and 44 s).
STEEP_RADIAL = 32


@pytest.fixture
def small_radial_table(monkeypatch):
    import jmse_jax._merit as merit_module

    monkeypatch.setattr(merit_module, "OTF_RADIAL_BY_SNR",
                        ((CHECKED_SNR, PRESETS["high"]["nodes"][0]),
                         (CHECKED_SNR_PEAKS, STEEP_RADIAL)))


@functools.cache
def _steep_gradient(se_angular, otf_radial=None):
    """The gradient in the coefficients of the steep design with ``se_angular`` (and
    ``otf_radial``) given (no count of ``jmse``'s own on top): the oracles."""
    return jax.grad(lambda c: _steep(c, STEEP_NOISE, se_angular=se_angular,
                                     otf_radial=otf_radial))(STEEP_C)


def test_gradient_takes_the_count_by_itself_with_concrete_spectra(small_radial_table):
    """With ``u`` and the spectra concrete, the peaks without the tiers take
    ``otf_radial_for``'s count (session 88), and differentiated ``se_angular_for``'s for
    the gradient alone: the gradient is the grid's with 1920 angular fine nodes and those
    radial OTF nodes, the value that of the grid with those radial nodes and its own 48
    angular ones, as the eager call's. With a count given nothing is added, below
    ``CHECKED_SNR`` neither, and the ``grad_`` counts given are taken with traced spectra
    too (``_low_noise_statics``; the program is the same). Spectra differentiated without
    ``jit`` count as concrete (their tracers carry the values)."""
    assert jj.se_angular_for(STEEP_U, STEEP_SIGNAL, jj.WhiteNoise(STEEP_NOISE)) == 1920
    assert jj.otf_radial_for(STEEP_U, STEEP_SIGNAL, jj.WhiteNoise(STEEP_NOISE)) == STEEP_RADIAL
    assert STEEP_RADIAL > PRESETS["fast"]["nodes"][0]
    own, fine = _steep_gradient(48), _steep_gradient(1920, STEEP_RADIAL)
    assert _relative(own, fine) > 1e-2  # the preset's own count does not hold it
    value, grad = jax.jit(jax.value_and_grad(lambda c: _steep(c, STEEP_NOISE)))(STEEP_C)
    assert _relative(grad, fine) < 1e-12
    assert float(value) == pytest.approx(float(_steep(STEEP_C, STEEP_NOISE)), rel=1e-13)
    assert float(value) == pytest.approx(
        float(_steep(STEEP_C, STEEP_NOISE, otf_radial=STEEP_RADIAL)), rel=1e-13)
    assert float(value) != float(_steep(STEEP_C, STEEP_NOISE, otf_radial=24))  # the own
    static, _ = _prepare(_design(), jmse_options(**PEAKED_FAST))

    def choice(noise, angular=None, radial=None, auto=True):
        """The counts (angular, radial) of the value's and of the gradient's programs (None
        where the gradient's is the value's), and the run-time check."""
        given = dict.fromkeys(("se_angular", "otf_radial"), None)
        given.update(grad_se_angular=angular, grad_otf_radial=radial)
        value, gradient, watch = _low_noise_statics(
            static, (STEEP_U, STEEP_SIGNAL, noise), given, auto)

        def counts(chosen):
            return None if chosen is None else (chosen.value[0]["se_angular"],
                                                chosen.value[0]["otf_radial"])
        return counts(value), counts(gradient), watch

    # The radial count holds the value too, the angular one the gradient alone.
    assert choice(jj.WhiteNoise(STEEP_NOISE)) == (
        (None, STEEP_RADIAL), (1920, STEEP_RADIAL), False)
    assert choice(jj.WhiteNoise(100 * STEEP_NOISE)) == ((None, None), None, False)  # 1.5e5
    # A grid option given (auto off): nothing.
    assert choice(jj.WhiteNoise(STEEP_NOISE), auto=False) == ((None, None), None, False)

    def traced(**given):  # the choice with the noise level a tracer
        out = []
        jax.make_jaxpr(lambda n: out.append(choice(jj.WhiteNoise(n), **given)) or n)(
            STEEP_NOISE)
        return out[0]

    assert traced() == ((None, None), None, True)
    assert traced(angular=1920) == ((None, None), (1920, None), False)
    assert traced(radial=96) == ((None, None), (None, 96), False)
    # Below the grid's own 48 and 24: nothing, and no run-time check (the counts are given).
    assert traced(angular=32, radial=16) == ((None, None), None, False)

    def differentiated(transform):  # the noise a tracer of a derivative taken without jit
        out = []
        transform(lambda n: out.append(choice(jj.WhiteNoise(n))) or n)
        return out[0]

    # Its tracers carry the concrete noise: the counts of a concrete call.
    concrete = ((None, STEEP_RADIAL), (1920, STEEP_RADIAL), False)
    assert differentiated(lambda f: jax.grad(f)(STEEP_NOISE)) == concrete
    assert differentiated(lambda f: jax.jvp(f, (STEEP_NOISE,), (1.0,))) == concrete
    assert differentiated(lambda f: jax.jit(jax.grad(f))(STEEP_NOISE)) == (
        (None, None), None, True)


def test_traced_spectra_warn_at_run_time(small_radial_table, with_run_time_checks):
    """With the noise traced (an argument of the caller's ``jit``, differentiated, here
    under ``vmap``) the counts cannot be chosen: each gradient checks the peak ratio when
    it runs and warns beyond ``CHECKED_SNR``, naming the counts; inside it, silence. The
    value and the gradient are the call's own grid's, and a value alone warns too, naming
    the radial count. (A ``jax.grad``, which drops the value: the check must not be dropped
    with it.)"""
    program = jax.jit(jax.vmap(jax.grad(_steep, argnums=(0, 1)), in_axes=(None, 0)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        jax.block_until_ready(program(STEEP_C, jnp.full(2, 100 * STEEP_NOISE)))
    with pytest.warns(AccuracyWarning, match=r"peak S_x / S_n of 1\.5e\+07.*with 48 angular fine "
                                         r"S_e nodes, 24 radial OTF nodes.*pass "
                                         rf"grad_se_angular=1920, grad_otf_radial="
                                         rf"{STEEP_RADIAL} "):
        grad, _ = program(STEEP_C, jnp.array([100 * STEEP_NOISE, STEEP_NOISE]))
        jax.block_until_ready(grad)
    assert _relative(grad[1], _steep_gradient(48)) < 1e-12
    # The value too is the own grid's (24 radial OTF nodes; a count given turns the
    # choice off), not the eager call's, which takes the radial count.
    own_value = float(_steep(STEEP_C, STEEP_NOISE, otf_radial=24))
    assert own_value != float(_steep(STEEP_C, STEEP_NOISE))
    # A value alone warns as well, naming the radial count that holds values (the angular
    # one holds gradients alone); within CHECKED_SNR, silence.
    values = jax.jit(jax.vmap(_steep, in_axes=(None, 0)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        jax.block_until_ready(values(STEEP_C, jnp.full(2, 100 * STEEP_NOISE)))
    with pytest.warns(AccuracyWarning, match=r"jmse's value at a peak S_x / S_n of 1\.5e\+07.*"
                                         r"with 24 radial OTF nodes: .*OTF_RADIAL_BY_SNR\).*"
                                         rf"pass otf_radial={STEEP_RADIAL} "):
        traced = jax.block_until_ready(
            values(STEEP_C, jnp.array([100 * STEEP_NOISE, STEEP_NOISE])))
    assert float(traced[1]) == pytest.approx(own_value, rel=1e-13)
    # Without the run-time checks (jj.run_time_checks(False)): silence, the same values.
    with jj.run_time_checks(False), warnings.catch_warnings():
        warnings.simplefilter("error")
        quiet = jax.jit(jax.vmap(lambda c, n: _steep(c, n), in_axes=(None, 0)))(
            STEEP_C, jnp.array([100 * STEEP_NOISE, STEEP_NOISE]))
    assert np.array_equal(np.asarray(quiet), np.asarray(traced))
    # Beyond CHECKED_SNR_PEAKS no count was checked, and the warning says so.
    with pytest.warns(AccuracyWarning, match=r"peak S_x / S_n of 1\.5e\+09.*pass otf_radial="
                                         rf"{STEEP_RADIAL} .*beyond 2e\+08 "
                                         r"\(CHECKED_SNR_PEAKS\) no counts were checked"):
        jax.block_until_ready(values(STEEP_C, jnp.array([STEEP_NOISE, STEEP_NOISE / 100])))


def test_run_time_check_runs_once_per_batch():
    """The run-time check sees a ``vmap``'s ratios in one host call (``jax.debug.callback``
    unrolled a batch into one callback per design: 59 s more to compile 5000), and its zero
    leaves values and derivatives as they are."""
    from jmse_jax._merit import _run_time_zero

    seen = []

    def f(x):
        zero = _run_time_zero(lambda r: seen.append(np.array(r)), 3.0 * x)
        return x ** 2 * (1 + zero)

    x = jnp.linspace(0.5, 2.0, 500)
    values, grads = jax.jit(jax.vmap(jax.value_and_grad(f)))(x)
    jax.block_until_ready(grads)
    assert len(seen) == 1 and seen[0].shape == (500,)
    np.testing.assert_array_equal(seen[0], 3.0 * np.asarray(x))
    np.testing.assert_array_equal(values, x ** 2)
    np.testing.assert_allclose(grads, 2.0 * x, rtol=1e-15)
    assert float(jax.grad(jax.grad(f))(1.5)) == 2.0


def test_lens_merit_passes_the_count_on(monkeypatch, small_radial_table):
    """``lens_merit`` traces ``u`` and the spectra inside (the band follows ``lambda N``),
    so it chooses the counts from its concrete arguments and gives them to ``jmse`` as
    ``grad_se_angular`` and ``otf_radial`` (what ``jmse`` does with them is the tests'
    above); within
    ``CHECKED_SNR`` the grid's own 48, which spares the gradient its run-time check.
    ``optimise`` keeps a count the caller gave."""
    import jmse_jax._optimise as optimise_module
    from jmse_jax.lens import paper_singlet

    seen = []

    def spy(aberrations, field, u, signal, noise, **options):
        seen.append(options)
        return u * jnp.sum(aberrations.w020)  # the plumbing only: no grid compiled

    monkeypatch.setattr(optimise_module, "jmse", spy)
    noise = jj.WhiteNoise(STEEP_NOISE)
    for level, count, radial in ((noise, 1920, STEEP_RADIAL),
                                 (jj.WhiteNoise(100 * STEEP_NOISE), 48, None)):
        seen.clear()
        jax.grad(lambda s, level=level: jj.lens_merit(
            paper_singlet(1.0, 0.05, image_shift=s), u=STEEP_U, signal=STEEP_SIGNAL,
            noise=level, fields=(1.0,), jmse_options=PEAKED_FAST))(0.0)
        assert seen and all(o.get("grad_se_angular") == count
                            and o.get("otf_radial") == radial for o in seen), seen
    given = dict(PEAKED_FAST, grad_se_angular=960)  # the caller's: kept, by optimise too
    assert _with_gradient_counts(given, STEEP_U, STEEP_SIGNAL, noise) == given


def test_sweep_jmse_passes_the_counts_on(monkeypatch, small_radial_table):
    """Inside ``sweep_jmse`` ``u`` is a batched input, traced, so the sweep chooses the
    counts from its concrete ``u`` (the in-range one with the largest peak ratio) and gives
    them to ``jmse`` as ``lens_merit`` does: ``otf_radial`` and ``grad_se_angular`` past
    ``CHECKED_SNR``, the grid's own angular count within it; nothing for the default's
    tiers or with a count or grid option given."""
    import jmse_jax._sweep as sweep_module

    seen = []

    def spy(aberrations, field, u, signal, noise, **options):
        seen.append(options)
        return u * aberrations.w020  # the plumbing only: no grid compiled

    monkeypatch.setattr(sweep_module, "jmse", spy)

    def passed(u, noise, preset="fast", **options):
        seen.clear()
        jj.sweep_jmse(jj.Seidel(w020=np.ones(3)), 0.5, u, STEEP_SIGNAL, jj.WhiteNoise(noise),
                      grad=True, preset=preset, progress=False, **options)
        assert seen and all(o == seen[0] for o in seen)
        return {k: v for k, v in seen[0].items() if k not in ("preset", "peaks")}

    # An out-of-range and a non-finite u (INVALID, NONFINITE_INPUT) do not take part.
    u = np.array([STEEP_U, 2.0, np.nan])
    assert passed(u, STEEP_NOISE, peaks=True) == dict(grad_se_angular=1920,
                                                      otf_radial=STEEP_RADIAL)
    assert passed(u, 100 * STEEP_NOISE, peaks=True) == dict(grad_se_angular=48)
    # "high"'s own 80 radial OTF nodes are more than the small table's count.
    assert passed(STEEP_U, STEEP_NOISE, preset="high") == dict(grad_se_angular=1920)
    assert passed(STEEP_U, STEEP_NOISE, preset="default") == {}
    assert passed(STEEP_U, STEEP_NOISE, peaks=True, otf_radial=40) == dict(otf_radial=40)
    assert passed(STEEP_U, STEEP_NOISE, peaks=True, nodes=(24, 8)) == dict(nodes=(24, 8))
    assert passed(np.array([np.nan, 3.0, 0.0]), STEEP_NOISE, peaks=True) == {}


def test_sweep_jmse_of_the_steep_design_is_the_eager_call(small_radial_table):
    """The sweep's value at a peak ratio of 1.5e7 is the eager ``jmse``'s (which takes the
    radial count by itself), not the own grid's. (The gradient's count is the plumbing
    above and ``_low_noise_statics``' tests; compiling it here would cost half a minute.)"""
    result = jj.sweep_jmse(jj.Seidel(*STEEP_C), STEEP_FIELD, np.array([STEEP_U]),
                           STEEP_SIGNAL, jj.WhiteNoise(STEEP_NOISE), progress=False,
                           **PEAKED_FAST)
    eager = float(_steep(STEEP_C, STEEP_NOISE))
    assert eager != float(_steep(STEEP_C, STEEP_NOISE, otf_radial=24))  # the own grid's
    assert float(result.value[0]) == pytest.approx(eager, rel=1e-12)

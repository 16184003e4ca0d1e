"""Bad input to the public helpers: a clear error naming the argument, the value and the
range (each case a user could plausibly hit: a float Noll index, an empty list, NaN samples,
a field outside [0, 1], a pair where an int was meant)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import jmse_jax as jj

CASES = [
    (lambda: jj.Zernike([0.5], noll=(4.7,)), ValueError,
     r"noll index must be an integer >= 1, got 4\.7"),
    (lambda: jj.Zernike([]), ValueError, r"coefficients must hold at least one Zernike term"),
    (lambda: jj.zernike_fit(np.full((6, 40), np.nan), jj.PolarGrid()), ValueError,
     r"samples must be finite"),
    (lambda: jj.zernike_fit(np.zeros((6, 40)), jj.PolarGrid(), noll=()), ValueError,
     r"noll must name at least one Zernike term"),
    (lambda: jj.otf_fft_grid(jj.Seidel(), float("nan"), 8), ValueError,
     r"field must be finite and in \[0\.0, 1\.0\], got nan"),
    (lambda: jj.otf_fft_grid(jj.Seidel(), 1.5, 8), ValueError,
     r"field must be in \[0\.0, 1\.0\], got 1\.5"),
    (lambda: jj.otf_fft_grid(jj.Seidel(w020=float("nan")), 0.5, 8), ValueError,
     r"aberrations\.w020 must be finite, got nan"),
    (lambda: jj.otf_fft_grid(jj.Seidel(), 0.5, 0), ValueError, r"B must be an integer >= 1"),
    (lambda: jj.wavefront(jj.Seidel(), 0.1, 0.2, 1.5), ValueError,
     r"field must be in \[0\.0, 1\.0\], got 1\.5"),
    (lambda: jj.sample_opd(jj.Seidel(w040=float("inf")), jj.PolarGrid()), ValueError,
     r"aberrations\.w040 must be finite, got inf"),
    (lambda: jj.frequency_quadrature("gauss", -0.2, 4), ValueError,
     r"u must be in \(0\.0, inf\], got -0\.2"),
    (lambda: jj.frequency_quadrature("polar", 0.2, (4,)), ValueError,
     r"p must be an int or a pair \(radial, angular\) for 'polar', got \(4,\)"),
    (lambda: jj.frequency_quadrature("polar", 0.2, (2, 8)), ValueError,
     r"nodes \(radial\) must be an integer >= 3, got 2"),
    (lambda: jj.MarkovSignal("1.0", 5.0), TypeError,
     r"variance must be a real number \(or array of them\), got '1\.0'"),
    (lambda: jj.WhiteNoise("1e-3"), TypeError, r"noise variance must be a real number"),
    # Spectra and designs with array parameters: one design per call (vmap for many).
    (lambda: jj.jmse(jj.Seidel(), 0.3, 0.2, jj.MarkovSignal(1.0, 5.0),
                     jj.WhiteNoise(jnp.array([1e-3, 1e-2]))), ValueError,
     r"noise\.variance must be a scalar \(one design; vmap over designs\), got shape \(2,\)"),
    (lambda: jj.baseline_jmse(jj.Seidel(), 0.3, 0.2, jj.MarkovSignal(jnp.array([1.0, 2.0]), 5.0),
                              jj.WhiteNoise(1e-3)), ValueError,
     r"signal\.variance must be a scalar \(one design; vmap over designs\), got shape"),
    (lambda: jj.otf(jj.Seidel(), 0.2, 0.0, jnp.array([0.1, 0.2, 0.3])), ValueError,
     r"field must be a scalar \(one design\), got shape \(3,\); the frequencies may be arrays"),
    (lambda: jj.otf(jj.Seidel(w020=jnp.array([0.1, 0.2])), 0.2, 0.0, 0.5), ValueError,
     r"aberrations\.w020 must be a scalar \(one design\), got shape \(2,\)"),
    (lambda: jj.jmse(jj.Seidel(w131=None), 0.3, 0.2, jj.MarkovSignal(1.0, 5.0),
                     jj.WhiteNoise(1e-3)), TypeError,
     r"aberrations\.w131 must be a real number, got None"),
    (lambda: jj.otf(jj.Seidel(w222=None), 0.2, 0.0, 0.5), TypeError,
     r"aberrations\.w222 must be a real number, got None"),
    # A bool passed as one wave (session 79's audit; docs/conventions.md says it raises).
    (lambda: jj.jmse(jj.Seidel(w020=True), 0.0, 0.2, jj.MarkovSignal(1.0, 5.0),
                     jj.WhiteNoise(1e-3)), TypeError,
     r"aberrations\.w020 must be a real number \(or array of them\), got True"),
]


@pytest.mark.parametrize(("call", "kind", "match"), CASES,
                         ids=[match.split(" must")[0].strip("\\") for _, _, match in CASES])
def test_bad_input_is_a_clear_error(call, kind, match):
    with pytest.raises(kind, match=match):
        call()


def test_good_input_still_passes():
    """The checks do not reject what the helpers accept: Noll indices as a NumPy array, a
    scalar p for the polar rule, a field of exactly 0 or 1."""
    ab = jj.Zernike(np.array([0.5, 0.2]), noll=np.array([4, 11]))
    assert ab.noll == (4, 11)
    assert jj.Zernike([0.1] * 3, noll=(1.0, 2.0, 4.0)).noll == (1, 2, 4)
    fit = jj.zernike_fit(np.zeros(jj.PolarGrid().x.shape), jj.PolarGrid(), noll=jnp.arange(1, 6))
    assert fit.noll == (1, 2, 3, 4, 5)
    assert jj.frequency_quadrature("polar", 0.3, np.array([8, 6]))[0].shape == (192,)
    # jmse's grid sizes as NumPy integers or an integer array, as frequency_quadrature takes
    assert jj.jmse_options(nodes=np.int64(30))["nodes"] == (30, 30)
    assert jj.jmse_options(nodes=np.array([24, 16]))["nodes"] == (24, 16)
    nu_x, _, weights = jj.frequency_quadrature("polar", 0.2, 4)
    assert nu_x.shape == weights.shape == (64,)
    assert float(np.sum(weights)) == pytest.approx(4 * 0.2**2, rel=1e-5)  # the band's area
    for field in (0.0, 1.0):
        assert np.isfinite(float(jj.wavefront(jj.Seidel(w131=0.3), 0.0, 1.0, field)))

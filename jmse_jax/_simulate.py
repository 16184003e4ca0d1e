"""Imaging simulation and Wiener restoration: the experiment the JMSE predicts.

Everything lives on a periodic sensor grid of ``n_y x n_x`` pixels at pitch
``p = 1 / (2 u)`` (in units of ``lambda N``, the inverse of the frequency unit, so that the
sensor's Nyquist frequency is ``u`` cutoffs; SPEC §2). Axis 0 is ``y``, axis 1 is ``x``.
The DFT frequencies of the grid are ``nu = k / (n p) = 2 u k / n`` for the integer FFT
indices ``k``; their cells of side ``Delta nu = 2 u / n`` tile the sensor band
``[-u, u]**2`` exactly when ``n`` is odd.

Conventions shared by every function here:

- **Scenes** are zero-mean stationary Gaussian fields with power spectral density ``S_x``
  (``signal(nu_x, nu_y)``) restricted to the sensor band. A field of PSD ``S`` sampled at
  rate ``1 / p = 2 u`` has the DFT-coefficient variance
  ``E |a_k|**2 = S(nu_k) Delta nu_x Delta nu_y`` (``a_k = DFT / (n_x n_y)``), so it is made
  by filtering unit white noise with ``2 u sqrt(S(nu_k))``.
- **Blur** multiplies the scene's DFT (NumPy sign, ``exp(-2 pi i k n / N)``) by the system's
  OTF ``H(nu_k)`` from ``jmse_jax.otf``; the PSF is real, so ``H(-nu) = conj(H(nu))`` and a
  real scene stays real.
- **Noise** with PSD ``S_n`` (``noise(nu_x, nu_y)``): for ``WhiteNoise(variance)`` the
  per-pixel variance is ``S_n (2 u)**2`` (the PSD times the area of the sensor band).
- **Restoration** multiplies the capture's DFT by ``G = conj(H) S_x / (|H|^2 S_x + S_n)``
  (``jmse_jax.wiener_filter``).

Link to the merit
-----------------
With these conventions the restoration error ``e = x_hat - x`` has DFT coefficients
``e_k = (G_k H_k - 1) a_k + G_k b_k`` with independent signal and noise coefficients, so
``E |e_k|**2 = S_e(nu_k) Delta nu**2`` and by Parseval the expected per-pixel MSE is

.. math::

    \\mathrm{MSE}_{pixel} = \\Delta\\nu_x \\Delta\\nu_y \\sum_k S_e(\\nu_k)
    \\xrightarrow{n \\to \\infty} \\iint_{|\\nu_x|,|\\nu_y|<u} S_e\\, d^2\\nu
    = 2\\pi\\,\\mathrm{JMSE}(u).

The first form (``discrete_prediction``) is exact for any odd ``n``: it is the midpoint
rule over the cells that tile the band. The factor between the paper's merit and the
per-pixel MSE is therefore ``PIXEL_MSE_PER_JMSE = 2 pi``, with no dependence on ``u`` or
``n`` (because ``WhiteNoise`` and the signal models are densities in the cutoff-unit
frequency plane and ``MarkovSignal`` integrates to its variance).

The merit assumes the sensor sees only the band: no aliasing of the blurred image from
``|nu| > u`` and no pixel MTF. ``monte_carlo_mse`` with ``oversample > 1`` synthesises the
scene on a finer grid covering the optics' support, blurs it there and then samples it
with an ideal anti-alias filter (assumptions hold), by point sampling (aliasing), or by
averaging over square pixels (aliasing and a pixel MTF).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._aberrations import AbstractAberrations
from ._merit import PRESETS, U_MAX, _sanitise, jmse
from ._numerics import (
    abs2,
    all_finite,
    check_choice,
    check_count,
    check_finite_tree,
    check_range,
    common_dtype,
    is_concrete,
)
from ._otf import otf
from ._spectra import AbstractNoise, AbstractSignal, error_spectral_density, wiener_filter

__all__ = [
    "PIXEL_MSE_PER_JMSE",
    "SAMPLINGS",
    "MonteCarloResult",
    "monte_carlo_mse",
    "predicted_pixel_mse",
    "random_scene",
    "restore",
    "sensor_frequencies",
    "simulate_capture",
]

#: Expected per-pixel MSE of the Wiener restoration divided by the paper's JMSE (Eq. 7):
#: ``MSE_pixel = iint_band S_e d^2 nu = 2 pi JMSE`` (see the module docstring).
PIXEL_MSE_PER_JMSE = 2.0 * math.pi

#: How the fine (oversampled) image reaches the sensor in ``monte_carlo_mse``.
SAMPLINGS = ("ideal", "point", "pixel")

#: Default overlap-quadrature nodes for OTFs on simulation grids (converged to ~1e-14 for
#: the Seidel bank's polynomial wavefronts of up to 6 waves per term, |nu| <= 1).
DEFAULT_OTF_NODES = (48, 48)


# --------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------


def _check_system(aberrations, field, u, signal=None, noise=None):
    if not isinstance(aberrations, AbstractAberrations):
        raise TypeError(
            f"aberrations must be a jmse_jax.Seidel or jmse_jax.Zernike, got {type(aberrations)}"
        )
    if signal is not None and not isinstance(signal, AbstractSignal):
        raise TypeError(f"signal must be a jmse_jax signal model, got {type(signal)}")
    if noise is not None and not isinstance(noise, AbstractNoise):
        raise TypeError(f"noise must be a jmse_jax noise model, got {type(noise)}")
    check_finite_tree("aberrations", aberrations)
    check_range("field", field, 0.0, 1.0)
    check_range("u", u, 0.0, U_MAX, low_inclusive=False)


def _check_image(name, image):
    shape = np.shape(image)
    if len(shape) != 2:
        raise ValueError(
            f"{name} must be a 2-D array (rows along y, columns along x), got shape {shape}"
        )
    if min(shape) < 1:
        raise ValueError(f"{name} must have at least one pixel per axis, got shape {shape}")
    if is_concrete(image):
        pixels = np.asarray(image)
        if pixels.dtype.kind not in "iuf":
            raise TypeError(f"{name} must hold real numbers, got dtype {pixels.dtype}")
        bad = np.argwhere(~np.isfinite(pixels))
        if bad.size:
            y, x = (int(i) for i in bad[0])
            raise ValueError(f"{name} must be finite, got {pixels[y, x]} at pixel (y={y}, "
                             f"x={x}) and {len(bad) - 1} more")


def _check_shape(shape):
    if not (isinstance(shape, (tuple, list)) and len(shape) == 2):
        raise ValueError(f"shape must be a pair (n_y, n_x) of pixel counts, got {shape!r}")
    check_count("shape[0] (n_y)", shape[0])
    check_count("shape[1] (n_x)", shape[1])
    return (int(shape[0]), int(shape[1]))


def _check_positive_psd(name, psd):
    if is_concrete(psd) and not bool(np.all(np.asarray(psd) > 0)):
        raise ValueError(
            f"{name} must be > 0 at every sensor frequency (the Wiener filter divides by it), "
            f"got minimum {float(np.min(np.asarray(psd)))!r}"
        )


def _check_nodes(otf_nodes):
    if not (isinstance(otf_nodes, (tuple, list)) and len(otf_nodes) == 2):
        raise ValueError(f"otf_nodes must be a pair (n_phi, n_t), got {otf_nodes!r}")
    check_count("otf_nodes[0] (n_phi)", otf_nodes[0])
    check_count("otf_nodes[1] (n_t)", otf_nodes[1])
    return (int(otf_nodes[0]), int(otf_nodes[1]))


# --------------------------------------------------------------------------------------
# Grids, OTF on a grid, filters
# --------------------------------------------------------------------------------------


def _fft_indices(n: int) -> np.ndarray:
    """Integer DFT indices ``k`` in NumPy FFT order (``-n//2 .. (n-1)//2``)."""
    return np.rint(np.fft.fftfreq(n, 1.0 / n)).astype(np.int64)


def sensor_frequencies(shape, u):
    """DFT frequencies of a periodic sensor grid, in cutoff units, in NumPy FFT order.

    Parameters
    ----------
    shape : (int, int)
        ``(n_y, n_x)`` pixels.
    u : float in (0, 1.5] [sensor Nyquist / optical cutoff]
        Sets the pitch ``p = 1 / (2 u)`` [``lambda N``].

    Returns
    -------
    nu_x, nu_y : arrays of shape ``(n_y, n_x)`` [cutoff units]
        ``nu = 2 u k / n`` for the FFT indices ``k``; spacing ``Delta nu = 2 u / n``. For odd
        ``n`` every frequency lies strictly inside ``(-u, u)``.

    Examples
    --------
    >>> import jmse_jax
    >>> nu_x, nu_y = jmse_jax.sensor_frequencies((3, 5), 0.25)
    >>> [round(float(v), 3) for v in nu_x[0]]
    [0.0, 0.1, 0.2, -0.2, -0.1]
    """
    shape = _check_shape(shape)
    check_range("u", u, 0.0, U_MAX, low_inclusive=False)
    if np.ndim(u) != 0:
        raise ValueError(f"u must be a scalar, got shape {np.shape(u)}")
    dtype = common_dtype(u)
    u = jnp.asarray(u, dtype)
    k_y, k_x = (jnp.asarray(_fft_indices(n), dtype) for n in shape)
    nu_x = (2.0 * u / shape[1]) * k_x
    nu_y = (2.0 * u / shape[0]) * k_y
    return jnp.broadcast_arrays(nu_x[None, :], nu_y[:, None])


def _otf_on_grid(aberrations, field, spacing, shape, otf_nodes, dtype):
    """OTF at the DFT frequencies ``(k_x spacing_x, k_y spacing_y)`` of an FFT-ordered grid.

    Uses ``H(-nu) = conj(H(nu))`` (real PSF) and, for wavefronts even in ``x``,
    ``H(-nu_x, nu_y) = H(nu_x, nu_y)``, so the OTF engine runs on about a half (a quarter)
    of the grid. The index bookkeeping is host-side NumPy on the static shape.
    """
    d_y, d_x = spacing
    k_y, k_x = _fft_indices(shape[0]), _fft_indices(shape[1])
    ky_unique = np.unique(np.abs(k_y))
    iy = np.searchsorted(ky_unique, np.abs(k_y))
    flip = (k_y < 0)[:, None]  # rows evaluated at -nu and conjugated
    if aberrations.x_symmetric:
        kx_unique = np.unique(np.abs(k_x))
        ix_pos = ix_neg = np.searchsorted(kx_unique, np.abs(k_x))
    else:
        kx_unique = np.unique(np.concatenate([k_x, -k_x]))
        ix_pos = np.searchsorted(kx_unique, k_x)
        ix_neg = np.searchsorted(kx_unique, -k_x)
    # The OTF engine compiles once per node count: pad the flat node list to a bucket size
    # so that grids of similar size share one compiled program (padding nodes sit at 0).
    grid_kx, grid_ky = np.meshgrid(kx_unique, ky_unique, indexing="xy")
    count = grid_kx.size
    bucket = max(1024, 1 << (count - 1).bit_length()) if count <= 4096 else -(-count // 4096) * 4096
    flat_kx = np.zeros(bucket)
    flat_ky = np.zeros(bucket)
    flat_kx[:count], flat_ky[:count] = grid_kx.ravel(), grid_ky.ravel()
    flat = otf(aberrations, d_x * jnp.asarray(flat_kx, dtype), d_y * jnp.asarray(flat_ky, dtype),
               field, method="overlap", nodes=otf_nodes)
    table = flat[:count].reshape(grid_kx.shape)
    direct = table[iy][:, ix_pos]
    mirrored = jnp.conj(table[iy][:, ix_neg])
    return jnp.where(flip, mirrored, direct)


def _image_system(name, image, aberrations, field, u, signal, noise, otf_nodes):
    """Checks, common dtype and the frequency-domain system of an image: returns ``image``
    (cast), ``u``, the FFT frequency grid ``nu_x, nu_y``, the noise PSD on it and the OTF."""
    _check_image(name, image)
    _check_system(aberrations, field, u, signal, noise)
    otf_nodes = _check_nodes(otf_nodes)
    image = jnp.asarray(image)
    dtype = common_dtype(image, aberrations, field, u, signal, noise)  # None has no leaves
    image = image.astype(dtype)
    u = jnp.asarray(u, dtype)
    if not is_concrete((image, aberrations, field, u, signal, noise)):
        caller = {"image": "restore", "scene": "simulate_capture"}[name]
        image = _traced_checks(caller, image, u, image_name=name, aberrations=aberrations,
                               field=field, signal=signal, noise=noise)
    nu_x, nu_y, spacing = _grid(image.shape, u, dtype)
    s_n = noise(nu_x, nu_y)
    _check_positive_psd("noise PSD", s_n)
    h = _otf_on_grid(aberrations, jnp.asarray(field, dtype), spacing, image.shape, otf_nodes,
                     dtype)
    return image, u, nu_x, nu_y, s_n, h


def _traced_checks(caller, x, u, *, image_name=None, aberrations=None, field=None,
                   signal=None, noise=None):
    """``x`` behind runtime errors (``equinox.error_if``) for traced input that the concrete
    checks would have refused: an image has no ``+inf`` convention like the merit's, and one
    made from such input would be NaN or silently wrong. Under ``vmap`` any bad batch
    element raises. With ``image_name``, ``x`` is that image and its pixels are checked;
    arguments left ``None`` are not checked."""
    u = jnp.asarray(u)
    checks = [((u > 0) & (u <= U_MAX),
               f"u must be in (0, {U_MAX}] (the traced value is outside it or not finite)")]
    if image_name is not None:
        checks.append((all_finite(x), f"{image_name} must be finite (a traced pixel is not)"))
    if aberrations is not None:
        checks.append((all_finite(aberrations),
                       "aberrations must be finite (a traced coefficient is not)"))
    if field is not None:
        field = jnp.asarray(field)
        checks.append(((field >= 0) & (field <= 1),
                       "field must be in [0, 1] (the traced value is outside it or not "
                       "finite)"))
    for label, spectrum in (("signal", signal), ("noise", noise)):
        if spectrum is not None:
            checks.append((jnp.asarray(spectrum.valid(), bool),
                           f"{label} parameters must be finite and > 0 (a traced value is "
                           f"not)"))
    for ok, message in checks:
        x = eqx.error_if(x, jnp.logical_not(ok), f"{caller}: {message}")
    return x


def _grid(shape, u, dtype):
    """``(nu_x, nu_y)`` of the FFT grid and the spacings ``(d_y, d_x)`` [cutoff units]."""
    k_y, k_x = (jnp.asarray(_fft_indices(n), dtype) for n in shape)
    d_y, d_x = 2.0 * u / shape[0], 2.0 * u / shape[1]
    nu_x, nu_y = jnp.broadcast_arrays((d_x * k_x)[None, :], (d_y * k_y)[:, None])
    return nu_x, nu_y, (d_y, d_x)


def _apply_transfer(image, transfer):
    """``real(ifft2(transfer * fft2(image)))``: a real-PSF filter applied on the periodic grid.

    For even sizes the imaginary part at the Nyquist row/column is discarded (the grid has
    no conjugate partner for it).
    """
    return jnp.real(jnp.fft.ifft2(transfer * jnp.fft.fft2(image)))


def _coloured_noise(key, shape, amplitude, dtype):
    """Real Gaussian field whose DFT-coefficient variance is ``amplitude**2 / (n_y n_x)``."""
    white = jax.random.normal(key, shape, dtype)
    return _apply_transfer(white, amplitude)


# --------------------------------------------------------------------------------------
# Public: scene, capture, restoration
# --------------------------------------------------------------------------------------


def random_scene(signal: AbstractSignal, shape, u, key):
    """A random scene with PSD ``S_x`` on a periodic sensor grid (band-limited to the band).

    Parameters
    ----------
    signal : MarkovSignal, PowerLawSignal or WhiteSignal (``S_x``)
    shape : (int, int)
        ``(n_y, n_x)`` pixels (odd sizes give an exactly real, exactly band-limited field).
    u : float in (0, 1.5] [sensor Nyquist / optical cutoff]
    key : jax.random key

    Returns
    -------
    array ``(n_y, n_x)``, zero-mean Gaussian with DFT coefficients
    ``E |a_k|**2 = S_x(nu_k) Delta nu_x Delta nu_y``: unit white noise filtered by
    ``2 u sqrt(S_x(nu_k))``. Its per-pixel variance is the midpoint rule of
    ``iint_band S_x d^2 nu`` (for ``MarkovSignal(v, mu)`` it tends to ``v`` as ``u`` grows).

    Examples
    --------
    >>> import jax, jmse_jax
    >>> scene = jmse_jax.random_scene(jmse_jax.MarkovSignal(1.0, 5.0), (65, 65), 0.2,
    ...                               jax.random.key(0))
    >>> scene.shape
    (65, 65)
    """
    if not isinstance(signal, AbstractSignal):
        raise TypeError(f"signal must be a jmse_jax signal model, got {type(signal)}")
    shape = _check_shape(shape)
    check_range("u", u, 0.0, U_MAX, low_inclusive=False)
    dtype = common_dtype(signal, u)
    u = jnp.asarray(u, dtype)
    nu_x, nu_y, _ = _grid(shape, u, dtype)
    amplitude = 2.0 * u * jnp.sqrt(signal(nu_x, nu_y))
    if not is_concrete((signal, u)):
        amplitude = _traced_checks("random_scene", amplitude, u, signal=signal)
    return _coloured_noise(key, shape, amplitude, dtype)


def simulate_capture(
    scene,
    aberrations: AbstractAberrations,
    field,
    u,
    noise: AbstractNoise,
    key,
    *,
    otf_nodes=DEFAULT_OTF_NODES,
):
    """Blur a sensor-grid scene by the system's OTF and add noise of PSD ``S_n``.

    ``capture = real(ifft2(H(nu_k) fft2(scene))) + n`` with ``H`` from ``jmse_jax.otf`` at
    the grid's DFT frequencies and ``n`` Gaussian with DFT-coefficient variance
    ``S_n(nu_k) Delta nu_x Delta nu_y`` (per-pixel variance ``S_n (2 u)**2`` for white
    noise). This is exactly the merit's imaging model: the blurred image is band-limited to
    the sensor band, so it is sampled without aliasing and without a pixel MTF.

    Parameters
    ----------
    scene : array ``(n_y, n_x)`` (NumPy or JAX) [signal units], sampled at pitch
        ``p = 1 / (2 u)`` [``lambda N``], axis 0 along ``y``.
    aberrations : Seidel or Zernike [waves]
    field : float in [0, 1] [fraction of full field]
    u : float in (0, 1.5] [sensor Nyquist / optical cutoff]
    noise : WhiteNoise (``S_n > 0``) [signal units squared per unit frequency area]
    key : jax.random key (noise)
    otf_nodes : (int, int)
        Overlap-quadrature nodes of ``jmse_jax.otf``.

    Returns
    -------
    array ``(n_y, n_x)``: the blurred, noisy capture. Under ``jit``/``vmap``/``grad``
    out-of-range traced input raises a runtime error naming the argument, as ``restore``.

    Examples
    --------
    >>> import jax, jmse_jax
    >>> scene = jmse_jax.random_scene(jmse_jax.MarkovSignal(1.0, 5.0), (33, 33), 0.2,
    ...                               jax.random.key(0))
    >>> capture = jmse_jax.simulate_capture(scene, jmse_jax.Seidel(w020=1.0), 0.0, 0.2,
    ...                                     jmse_jax.WhiteNoise(1e-3), jax.random.key(1))
    >>> capture.shape
    (33, 33)
    """
    scene, u, nu_x, nu_y, s_n, h = _image_system("scene", scene, aberrations, field, u, None,
                                                 noise, otf_nodes)
    blurred = _apply_transfer(scene, h)
    return blurred + _coloured_noise(key, scene.shape, 2.0 * u * jnp.sqrt(s_n), scene.dtype)


def restore(
    image,
    aberrations: AbstractAberrations,
    field,
    u,
    signal: AbstractSignal,
    noise: AbstractNoise,
    *,
    otf_nodes=DEFAULT_OTF_NODES,
):
    """Wiener-restore a captured image of the given system (Berkner & Shroff Eq. 4).

    .. math::

        \\hat x = \\mathcal{F}^{-1}\\left[ G(\\nu_k) \\, \\mathcal{F}[y] \\right], \\qquad
        G = \\frac{H^* S_x}{|H|^2 S_x + S_n}

    on the image's periodic DFT grid, ``nu_k = 2 u k / n`` cutoffs (pitch ``1 / (2 u)``
    ``lambda N``). The image is treated as periodic; pad or window real photographs first.

    Parameters
    ----------
    image : array ``(n_y, n_x)`` (NumPy or JAX) [signal units]
        The capture, axis 0 along ``y`` (the field direction of ``Seidel``), axis 1 along
        ``x``, sampled at the sensor pitch that ``u`` implies.
    aberrations : Seidel or Zernike [waves]
    field : float in [0, 1] [fraction of full field]
    u : float in (0, 1.5] [sensor Nyquist / optical cutoff, ``lambda N / (2 p)``]
    signal : MarkovSignal, PowerLawSignal or WhiteSignal (``S_x``, the scene prior)
    noise : WhiteNoise (``S_n > 0``): per-pixel noise variance ``S_n (2 u)**2``
    otf_nodes : (int, int)
        Overlap-quadrature nodes of ``jmse_jax.otf`` (the default is converged to about
        1e-14 for Seidel wavefronts of a few waves).

    Returns
    -------
    JAX array ``(n_y, n_x)`` of the image's floating dtype: the restored scene.

    Notes
    -----
    Only ``S_x / S_n`` matters, so the filter is unchanged by a common rescaling of both.
    For a scene drawn from ``signal`` and captured by ``simulate_capture`` the expected
    per-pixel squared error of the result is ``Delta nu**2 sum_k S_e(nu_k)``, which tends to
    ``2 pi JMSE`` (see ``monte_carlo_mse``). Jit-compatible; differentiable in the floats.
    Under ``jit``/``vmap``/``grad`` a non-finite or out-of-range traced input (pixels,
    coefficients, ``field``, ``u``, the spectra's parameters) raises a runtime error that
    names the argument (``equinox.error_if``) instead of returning NaN pixels.

    Examples
    --------
    >>> import jax, numpy as np, jmse_jax
    >>> ab, signal, noise = jmse_jax.Seidel(w020=0.5), jmse_jax.MarkovSignal(1.0, 5.0), \\
    ...     jmse_jax.WhiteNoise(1e-3)
    >>> capture = np.zeros((32, 32)); capture[16, 16] = 1.0
    >>> restored = jmse_jax.restore(capture, ab, 0.0, 0.2, signal, noise)
    >>> restored.shape
    (32, 32)
    """
    image, _, nu_x, nu_y, s_n, h = _image_system("image", image, aberrations, field, u,
                                                 signal, noise, otf_nodes)
    g = wiener_filter(h, signal(nu_x, nu_y), s_n)
    return _apply_transfer(image, g)


def predicted_pixel_mse(
    aberrations: AbstractAberrations,
    field,
    u,
    signal: AbstractSignal,
    noise: AbstractNoise,
    *,
    size: int | None = None,
    otf_nodes=DEFAULT_OTF_NODES,
    jmse_preset: str = "default",
):
    """Expected per-pixel MSE of Wiener restoration that the merit predicts.

    .. math::

        \\mathrm{MSE}_{pixel} = \\iint_{|\\nu_x|,|\\nu_y|<u} S_e\\, d^2\\nu
            = 2\\pi\\,\\mathrm{JMSE}(u)
        \\quad\\text{or, on a } n \\times n \\text{ sensor,}\\quad
        \\Delta\\nu^2 \\sum_k S_e(\\nu_k), \\ \\Delta\\nu = 2u/n.

    Parameters
    ----------
    aberrations, field, u, signal, noise
        The system, as in ``jmse_jax.jmse``.
    size : odd int >= 3 or None
        ``None``: the continuous value ``2 pi JMSE`` (``jmse`` with ``jmse_preset``).
        An odd ``n``: the exact expectation on the periodic ``n x n`` sensor grid (the
        midpoint rule over the cells that tile the band), which is what ``restore`` of a
        ``simulate_capture`` of a ``random_scene`` of that size leaves on average.
    otf_nodes : (int, int)
        Overlap-quadrature nodes of ``jmse_jax.otf`` (``size`` given).
    jmse_preset : str
        Preset of ``jmse`` (``size=None``).

    Returns
    -------
    scalar [signal units squared per pixel]

    Examples
    --------
    >>> import jax, jmse_jax as jj
    >>> jax.config.update("jax_enable_x64", True)
    >>> ab = jj.Seidel(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
    >>> args = (ab, 0.95, 0.2, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3))
    >>> round(float(jj.predicted_pixel_mse(*args)), 7)  # 2 pi * 2.6539432e-3
    0.0166752
    """
    _check_system(aberrations, field, u, signal, noise)
    check_choice("jmse_preset", jmse_preset, tuple(PRESETS))
    if size is None:
        return PIXEL_MSE_PER_JMSE * jmse(aberrations, field, u, signal, noise,
                                         preset=jmse_preset)
    check_count("size", size, 3)
    if size % 2 == 0:
        raise ValueError(f"size must be an odd integer >= 3 (so the DFT cells tile the band), "
                         f"got {size}")
    otf_nodes = _check_nodes(otf_nodes)
    dtype = common_dtype(aberrations, field, u, signal, noise)
    # Under jit: +inf for non-finite or out-of-range values, as jmse gives.
    (aberrations, field, u, signal, noise), ok = _sanitise(
        (aberrations, jnp.asarray(field, dtype), jnp.asarray(u, dtype), signal, noise))
    shape = (int(size), int(size))
    nu_x, nu_y, spacing = _grid(shape, u, dtype)
    s_n = noise(nu_x, nu_y)
    _check_positive_psd("noise PSD", s_n)
    h = _otf_on_grid(aberrations, field, spacing, shape, otf_nodes, dtype)
    s_e = error_spectral_density(h, signal(nu_x, nu_y), s_n)
    return jnp.where(ok, spacing[0] * spacing[1] * jnp.sum(s_e), jnp.inf)


# --------------------------------------------------------------------------------------
# Monte-Carlo estimate of the restoration MSE
# --------------------------------------------------------------------------------------


class MonteCarloResult(NamedTuple):
    """Monte-Carlo per-pixel MSE of Wiener restoration and its predictions.

    Attributes
    ----------
    mse : scalar
        Mean over trials of the per-pixel squared restoration error
        ``mean((x_hat - x)**2)`` [signal units squared].
    standard_error : scalar
        Standard error of ``mse``: sample standard deviation (ddof 1) / sqrt(trials).
    per_trial : array ``(trials,)``
        Per-pixel MSE of each trial.
    discrete_prediction : scalar
        ``Delta nu_x Delta nu_y sum_k S_e(nu_k)`` over the sensor's DFT grid: the exact
        expectation of ``mse`` when the merit's assumptions hold.
    model_prediction : scalar
        The exact expectation of ``mse`` for the sampling actually simulated, aliasing and
        pixel MTF included (equals ``discrete_prediction`` for ``sampling="ideal"``).
    continuous_prediction : scalar
        ``2 pi JMSE(u)`` from ``jmse_jax.jmse`` (the ``n -> infinity`` limit of
        ``discrete_prediction``).
    predicted_standard_error : scalar
        Standard error of ``mse`` implied by the Gaussian model under the merit's assumptions,
        ``sqrt(sum_k Var |e_k|**2 / trials)`` (``sampling="ideal"``; NaN otherwise).
    """

    mse: jax.Array
    standard_error: jax.Array
    per_trial: jax.Array
    discrete_prediction: jax.Array
    model_prediction: jax.Array
    continuous_prediction: jax.Array
    predicted_standard_error: jax.Array

    @property
    def trials(self) -> int:
        """The number of Monte-Carlo trials (scenes) behind ``mse``."""
        return int(self.per_trial.shape[0])


def _block_view(spectrum_like, m, n):
    """Centre an FFT-ordered ``(m n, m n)`` array and view it as ``(m, n, m, n)`` alias blocks.

    Block ``[a, :, b, :]`` holds the fine frequencies ``k + n (a - (m-1)/2)`` (rows) and
    ``k + n (b - (m-1)/2)`` (columns), ``k`` the centred sensor index: the frequencies that
    fold onto sensor bin ``k`` when the fine grid is decimated by ``m`` (``m``, ``n`` odd).
    """
    return jnp.fft.fftshift(spectrum_like).reshape(m, n, m, n)


def _pixel_mtf(n, m, dtype):
    """Transfer of the centred ``m``-sample box average on the fine grid (Dirichlet kernel).

    ``D(k) = sin(pi k / n) / (m sin(pi k / (m n)))`` for fine index ``k``; ``D(0) = 1``. It is
    ``sinc(nu p)`` sampled, ``p`` the sensor pitch: the MTF of a 100 %-fill-factor pixel.
    """
    k = _fft_indices(m * n).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.sin(np.pi * k / n) / (m * np.sin(np.pi * k / (m * n)))
    d[k == 0] = 1.0
    d = jnp.asarray(d, dtype)
    return d[:, None] * d[None, :]


@functools.partial(jax.jit, static_argnames=("shape", "oversample", "sampling", "batch"))
def _mc_trials(keys, scene_amplitude, blur, lowpass, noise_amplitude, restoration, *, shape,
               oversample, sampling, batch):
    """Per-pixel restoration MSE for each key; trials vmapped in batches under ``lax.map``."""
    m = oversample
    fine_shape = (m * shape[0], m * shape[1])
    dtype = scene_amplitude.dtype
    half = (m - 1) // 2

    def trial(key):
        key_scene, key_noise = jax.random.split(key)
        white = jax.random.normal(key_scene, fine_shape, dtype)
        scene_spectrum = jnp.fft.fft2(white) * scene_amplitude
        blurred_spectrum = scene_spectrum * blur
        if m == 1:
            truth = jnp.real(jnp.fft.ifft2(scene_spectrum))
            sensed = jnp.real(jnp.fft.ifft2(blurred_spectrum))
        else:
            truth = jnp.real(jnp.fft.ifft2(scene_spectrum * lowpass))[::m, ::m]
            if sampling == "ideal":
                sensed = jnp.real(jnp.fft.ifft2(blurred_spectrum * lowpass))[::m, ::m]
            elif sampling == "point":
                sensed = jnp.real(jnp.fft.ifft2(blurred_spectrum))[::m, ::m]
            else:  # "pixel": average over the m x m fine samples of each square pixel
                fine = jnp.real(jnp.fft.ifft2(blurred_spectrum))
                fine = sum(jnp.roll(fine, -a, axis=0) for a in range(-half, half + 1)) / m
                fine = sum(jnp.roll(fine, -a, axis=1) for a in range(-half, half + 1)) / m
                sensed = fine[::m, ::m]
        capture = sensed + _coloured_noise(key_noise, shape, noise_amplitude, dtype)
        restored = _apply_transfer(capture, restoration)
        return jnp.mean((restored - truth) ** 2)

    n_batches = keys.shape[0] // batch
    batched = keys.reshape((n_batches, batch) + keys.shape[1:])
    return jax.lax.map(jax.vmap(trial), batched).reshape(-1)


def monte_carlo_mse(
    aberrations: AbstractAberrations,
    field,
    u,
    signal: AbstractSignal,
    noise: AbstractNoise,
    key,
    *,
    size: int = 129,
    trials: int = 64,
    batch: int = 8,
    oversample: int = 1,
    sampling: str = "ideal",
    otf_nodes=DEFAULT_OTF_NODES,
    jmse_preset: str | None = "default",
) -> MonteCarloResult:
    """Monte-Carlo per-pixel MSE of Wiener restoration, with the merit's predictions.

    Each trial draws a scene from ``signal``, blurs it by the system's OTF, samples it on a
    ``size x size`` periodic sensor at pitch ``1 / (2 u)``, adds noise of PSD ``S_n`` and
    restores it with the Wiener filter of the system (``restore``); the trial's value is
    the per-pixel mean of ``(x_hat - x)**2`` against the band-limited scene ``x``.

    With ``oversample = 1`` the scene is drawn directly on the sensor grid (band-limited),
    which is exactly the merit's model. With ``oversample = m > 1`` (odd) the scene is drawn
    on an ``m``-times finer grid (band ``[-m u, m u]**2``; choose ``m u >= 1`` to cover the
    optics' support), blurred there, and sampled by

    - ``"ideal"``: an ideal low-pass to the sensor band, then decimation (assumptions hold);
    - ``"point"``: decimation alone: the blurred image's content at ``|nu| > u`` aliases;
    - ``"pixel"``: the mean over each ``m x m`` block centred on the sample (a square pixel
      of 100 % fill factor, MTF ``~ sinc(nu_x p) sinc(nu_y p)``), then decimation: pixel
      MTF and aliasing.

    Parameters
    ----------
    aberrations, field, u, signal, noise
        The system, as in ``jmse_jax.jmse``.
    key : jax.random key (one split per trial)
    size : odd int >= 3
        Sensor pixels per axis. Odd, so the DFT cells tile the band ``[-u, u]**2`` exactly.
    trials : int >= 2
    batch : int >= 1
        Trials vectorised together (memory ~ ``batch * (oversample * size)**2 * 64`` bytes).
    oversample : odd int >= 1
    sampling : {"ideal", "point", "pixel"}
        ``"point"`` and ``"pixel"`` need ``oversample > 1``.
    otf_nodes : (int, int)
        Overlap-quadrature nodes of ``jmse_jax.otf``.
    jmse_preset : str or None
        Preset of ``jmse_jax.jmse`` for ``continuous_prediction`` (NaN if None).

    Returns
    -------
    MonteCarloResult

    Notes
    -----
    Expected value (derivation in the module docstring): with ``T`` the transfer from the
    fine scene to the sensor (``H`` times the pixel MTF ``D``) and alias frequencies
    ``nu_k + 2 u j`` (``j`` a nonzero integer pair),

    .. math::

        E[\\mathrm{MSE}] = \\Delta\\nu^2 \\sum_k \\Big[ |G T_0 - 1|^2 S_x
            + |G|^2 \\big(S_n + \\sum_{j \\ne 0} |T_j|^2 S_x(\\nu_k + 2uj)\\big) \\Big],

    which reduces to ``Delta nu**2 sum_k S_e(nu_k)`` when ``T_0 = H`` and ``T_j = 0``; that
    is ``2 pi JMSE(u)`` up to the midpoint-rule error of the ``size x size`` grid.

    Examples
    --------
    >>> import jax, jmse_jax as jj
    >>> jax.config.update("jax_enable_x64", True)
    >>> ab = jj.Seidel(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
    >>> res = jj.monte_carlo_mse(ab, 0.95, 0.2, jj.MarkovSignal(1.0, 5.0),
    ...                          jj.WhiteNoise(1e-3), jax.random.key(0), size=33, trials=16)
    >>> abs(float(res.mse / res.discrete_prediction) - 1) < 4 * float(
    ...     res.standard_error / res.discrete_prediction)
    True
    """
    _check_system(aberrations, field, u, signal, noise)
    if jmse_preset is not None:
        check_choice("jmse_preset", jmse_preset, tuple(PRESETS))
    check_count("size", size, 3)
    if size % 2 == 0:
        raise ValueError(f"size must be an odd integer >= 3 (so the DFT cells tile the band), "
                         f"got {size}")
    check_count("trials", trials, 2)
    check_count("batch", batch, 1)
    check_count("oversample", oversample, 1)
    if oversample % 2 == 0:
        raise ValueError(f"oversample must be an odd integer >= 1, got {oversample}")
    check_choice("sampling", sampling, SAMPLINGS)
    if oversample == 1 and sampling != "ideal":
        raise ValueError(
            f"sampling={sampling!r} needs a fine grid: oversample must be an odd integer >= 3, "
            f"got {oversample}"
        )
    otf_nodes = _check_nodes(otf_nodes)
    if not is_concrete((aberrations, field, u, signal, noise)):
        raise ValueError("monte_carlo_mse needs concrete (non-traced) system parameters")

    dtype = common_dtype(aberrations, field, u, signal, noise)
    field_value = jnp.asarray(field, dtype)
    u_value = jnp.asarray(u, dtype)
    n, m = int(size), int(oversample)
    shape = (n, n)

    # Sensor-grid filters (the restoration knows only the merit's model).
    nu_x, nu_y, spacing = _grid(shape, u_value, dtype)
    h = _otf_on_grid(aberrations, field_value, spacing, shape, otf_nodes, dtype)
    s_x, s_n = signal(nu_x, nu_y), noise(nu_x, nu_y)
    _check_positive_psd("noise PSD", s_n)
    g = wiener_filter(h, s_x, s_n)
    s_e = error_spectral_density(h, s_x, s_n)
    cell = spacing[0] * spacing[1]
    discrete = cell * jnp.sum(s_e)
    noise_amplitude = 2.0 * u_value * jnp.sqrt(s_n)
    # A trial's MSE is sum_k |e_k|^2. Each conjugate pair (k, -k) carries 2|e_k|^2 with
    # |e_k|^2 exponential (variance mean_k^2, so 4 mean_k^2 per pair); the real k = 0 term
    # is mean_0 chi^2_1 (variance 2 mean_0^2). Together: 2 sum_k mean_k^2.
    mean_k = cell * s_e
    per_trial_var = 2.0 * jnp.sum(mean_k**2)

    if m == 1:
        scene_amplitude = 2.0 * u_value * jnp.sqrt(s_x)
        blur, lowpass = h, jnp.ones((), dtype)
        model = discrete
        predicted_se = jnp.sqrt(per_trial_var / trials)
    else:
        fine_shape = (m * n, m * n)
        fnu_x, fnu_y, fspacing = _grid(fine_shape, m * u_value, dtype)
        fine_h = _otf_on_grid(aberrations, field_value, fspacing, fine_shape, otf_nodes, dtype)
        fine_s_x = signal(fnu_x, fnu_y)
        scene_amplitude = 2.0 * m * u_value * jnp.sqrt(fine_s_x)
        k = np.abs(_fft_indices(m * n))
        in_band = k <= (n - 1) // 2
        lowpass = jnp.asarray(in_band[:, None] & in_band[None, :], dtype)
        blur = fine_h
        if sampling == "ideal":
            transfer = fine_h * lowpass
        elif sampling == "point":
            transfer = fine_h
        else:
            transfer = fine_h * _pixel_mtf(n, m, dtype)
        blocks_t = _block_view(transfer, m, n)
        blocks_s = _block_view(fine_s_x, m, n)
        c = (m - 1) // 2
        t0 = blocks_t[c, :, c, :]
        g_c = jnp.fft.fftshift(g)
        aliased = jnp.sum(abs2(blocks_t) * blocks_s, axis=(0, 2)) - abs2(t0) * blocks_s[c, :, c, :]
        per_bin = abs2(g_c * t0 - 1.0) * blocks_s[c, :, c, :] + abs2(g_c) * (
            jnp.fft.fftshift(s_n) + aliased
        )
        model = cell * jnp.sum(per_bin)
        predicted_se = (jnp.sqrt(per_trial_var / trials) if sampling == "ideal"
                        else jnp.asarray(jnp.nan, dtype))

    n_batches = -(-trials // batch)
    keys = jax.random.split(key, n_batches * batch)
    per_trial = _mc_trials(
        keys, scene_amplitude, blur, lowpass, noise_amplitude, g,
        shape=shape, oversample=m, sampling=sampling, batch=batch,
    )[:trials]
    mean = jnp.mean(per_trial)
    standard_error = jnp.std(per_trial, ddof=1) / math.sqrt(trials)
    if jmse_preset is None:
        continuous = jnp.asarray(jnp.nan, dtype)
    else:
        continuous = PIXEL_MSE_PER_JMSE * jmse(aberrations, field, u, signal, noise,
                                               preset=jmse_preset)
    return MonteCarloResult(
        mse=mean,
        standard_error=standard_error,
        per_trial=per_trial,
        discrete_prediction=discrete,
        model_prediction=model,
        continuous_prediction=continuous,
        predicted_standard_error=predicted_se,
    )

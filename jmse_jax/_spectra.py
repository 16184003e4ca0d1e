"""Signal and noise power spectra, the Wiener filter and its error spectral density.

Frequencies are in units of the incoherent cutoff ``1/(lambda N)`` (SPEC §2); the package's
models are isotropic functions of ``r = |nu|``. A model of one's own (a subclass of
``AbstractSignal`` that overrides ``__call__``, or of ``AbstractNoise``) may depend on the
direction of ``nu`` too; it must be even, ``S(-nu) = S(nu)``, as the spectrum of every real
image or noise field is. ``jmse`` integrates the band's x-mirrored quadrants apart unless
the model says it is mirror symmetric (``x_symmetric``), so a model that is not, such as an
oriented texture's, is integrated as it is.
"""

from __future__ import annotations

import abc
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from ._numerics import abs2, check_range, safe_norm

__all__ = [
    "AbstractNoise",
    "AbstractSignal",
    "MarkovSignal",
    "PowerLawSignal",
    "WhiteNoise",
    "WhiteSignal",
    "error_spectral_density",
    "wiener_filter",
]


def _float64_of(formula, *parameters):
    """``formula`` of concrete parameters in float64 NumPy (overflow gives inf, quietly);
    ``None`` when a parameter is traced (``valid`` covers those)."""
    try:
        values = [np.asarray(p, np.float64) for p in parameters]
    except (TypeError, jax.errors.TracerArrayConversionError):
        return None
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        return float(formula(*values))


def _check_peak(model, formula, *parameters):
    """Concrete check that the spectrum's largest value ``S_x(0) = formula(*parameters)``,
    computed in float64, is finite: beyond that ``S_e`` would be ``inf / inf`` (NaN)."""
    peak = _float64_of(lambda *v: np.max(formula(*v)), *parameters)
    if peak is not None and not math.isfinite(peak):
        raise ValueError(f"{model!r}: S_x(0) = {peak} overflows float64; rescale the "
                         f"parameters (the spectrum's peak must be finite)")


def _positive(*values):
    """All ``values`` finite and > 0, as a traceable boolean."""
    ok = jnp.asarray(True)
    for value in values:
        value = jnp.asarray(value)
        ok = ok & jnp.all(jnp.isfinite(value) & (value > 0))
    return ok


class AbstractSignal(eqx.Module):
    """An isotropic signal power spectral density ``S_x(nu)`` (a subclass may override
    ``__call__`` for one that depends on the direction of ``nu``; it must be even, see the
    module's notes)."""

    @abc.abstractmethod
    def radial(self, r):
        """``S_x`` at radial frequency ``r = |nu|`` [cutoff units]."""

    def __call__(self, nu_x, nu_y):
        """``S_x`` at ``(nu_x, nu_y)``."""
        return self.radial(safe_norm(nu_x, nu_y))

    @property
    def isotropic(self) -> bool:
        """True when ``S_x(nu) = radial(|nu|)`` (a subclass that overrides ``__call__`` is
        not assumed to be)."""
        return type(self).__call__ is AbstractSignal.__call__

    @property
    def x_symmetric(self) -> bool:
        """True when ``S_x(-nu_x, nu_y) = S_x(nu_x, nu_y)``: ``jmse`` then integrates one
        of the band's x-mirrored quadrants for a wavefront even in x, and otherwise both
        (isotropic models are; a subclass that overrides ``__call__`` may say so)."""
        return self.isotropic

    def valid(self):
        """Whether the parameters are in range, as a (traceable) boolean: ``jmse`` under
        ``jit`` returns ``+inf`` where they are not (the constructors raise for concrete
        values). True unless a subclass says otherwise."""
        return jnp.asarray(True)


class MarkovSignal(AbstractSignal):
    """Exponentially correlated (first-order Markov) random field.

    ``S_x(r) = variance * 2 pi mu**2 / (1 + (2 pi mu r)**2)**(3/2)``, the spectrum of the
    autocorrelation ``variance * exp(-|x| / mu)``; it integrates to ``variance`` over the plane.

    Parameters
    ----------
    variance : float > 0 [signal units squared]
    correlation_length : float > 0 [``lambda N`` units, the inverse of the frequency unit]
    """

    variance: ArrayLike = 1.0
    correlation_length: ArrayLike = 5.0

    def __check_init__(self):
        check_range("variance", self.variance, 0.0, None, low_inclusive=False)
        check_range("correlation_length", self.correlation_length, 0.0, None, low_inclusive=False)
        _check_peak(self, lambda v, mu: 2.0 * math.pi * v * mu * mu, self.variance,
                    self.correlation_length)

    def valid(self):
        return _positive(self.variance, self.correlation_length) & jnp.isfinite(
            self.radial(jnp.zeros(())))

    def radial(self, r):
        mu = self.correlation_length
        two_pi_mu = 2.0 * math.pi * mu
        q = 1.0 + (two_pi_mu * r) ** 2
        return self.variance * two_pi_mu * mu / (q * jnp.sqrt(q))  # q**1.5 without pow


class PowerLawSignal(AbstractSignal):
    """Power-law (natural-scene) spectrum ``S_x(r) = amplitude / (knee**2 + r**2)**(exponent/2)``.

    Parameters
    ----------
    amplitude : float > 0
    exponent : float > 0 (``gamma``; natural images have about 2)
    knee : float > 0 [cutoff units] (``nu_0``; keeps ``S_x(0)`` finite)
    """

    amplitude: ArrayLike = 1.0
    exponent: ArrayLike = 2.0
    knee: ArrayLike = 0.01

    def __check_init__(self):
        check_range("amplitude", self.amplitude, 0.0, None, low_inclusive=False)
        check_range("exponent", self.exponent, 0.0, None, low_inclusive=False)
        check_range("knee", self.knee, 0.0, None, low_inclusive=False)
        _check_peak(self, lambda a, g, k: a * k ** (-g), self.amplitude, self.exponent,
                    self.knee)

    def valid(self):
        return _positive(self.amplitude, self.exponent, self.knee) & jnp.isfinite(
            self.radial(jnp.zeros(())))

    def radial(self, r):
        return self.amplitude * (self.knee**2 + r * r) ** (-0.5 * self.exponent)


class WhiteSignal(AbstractSignal):
    """Flat signal spectrum ``S_x = level``."""

    level: ArrayLike = 1.0

    def __check_init__(self):
        check_range("level", self.level, 0.0, None, low_inclusive=False)

    def valid(self):
        return _positive(self.level)

    def radial(self, r):
        return jnp.full_like(r, 1.0) * self.level


class AbstractNoise(eqx.Module):
    """A noise power spectral density ``S_n(nu)``."""

    @abc.abstractmethod
    def __call__(self, nu_x, nu_y):
        """``S_n`` at ``(nu_x, nu_y)``."""

    @property
    def isotropic(self) -> bool:
        """True when ``S_n`` depends on ``|nu|`` only (False unless a subclass says so)."""
        return False

    @property
    def x_symmetric(self) -> bool:
        """True when ``S_n(-nu_x, nu_y) = S_n(nu_x, nu_y)`` (see
        ``AbstractSignal.x_symmetric``): isotropic models are; a subclass may say so."""
        return self.isotropic

    def valid(self):
        """Whether the parameters are in range, as a (traceable) boolean (see
        ``AbstractSignal.valid``). True unless a subclass says otherwise."""
        return jnp.asarray(True)


class WhiteNoise(AbstractNoise):
    """White detector noise ``S_n = variance``.

    Parameters
    ----------
    variance : float > 0 [signal units squared, per unit area of the frequency plane]
    """

    variance: ArrayLike = 1e-3

    def __check_init__(self):
        check_range("noise variance", self.variance, 0.0, None, low_inclusive=False)
        smallest = _float64_of(np.min, self.variance)
        if smallest is not None and smallest < np.finfo(np.float64).tiny:
            raise ValueError(
                f"noise variance must be at least float64's smallest normal number "
                f"({np.finfo(np.float64).tiny:.3g}; a subnormal one loses its precision in "
                f"S_x S_n and gives NaN past the cutoff), got {smallest!r}")

    def valid(self):
        variance = jnp.asarray(self.variance)
        tiny = jnp.finfo(variance.dtype).tiny if jnp.issubdtype(variance.dtype,
                                                                 jnp.floating) else 0.0
        return _positive(self.variance) & jnp.all(variance >= tiny)

    def __call__(self, nu_x, nu_y):
        return jnp.zeros_like(nu_x * nu_y) + self.variance

    @property
    def isotropic(self) -> bool:
        return True


class _MirroredSignal(AbstractSignal):
    """``S_x(-nu_x, nu_y)`` of a signal model (the x-mirrored quadrant's spectrum)."""

    base: AbstractSignal

    def radial(self, r):
        return self.base.radial(r)

    def __call__(self, nu_x, nu_y):
        return self.base(-nu_x, nu_y)

    def valid(self):
        return self.base.valid()


class _MirroredNoise(AbstractNoise):
    """``S_n(-nu_x, nu_y)`` of a noise model."""

    base: AbstractNoise

    def __call__(self, nu_x, nu_y):
        return self.base(-nu_x, nu_y)

    def valid(self):
        return self.base.valid()


def x_mirrored(signal, noise):
    """The spectra as seen from the band's x-mirrored quadrant (``S(-nu_x, nu_y)``); a
    model that is ``x_symmetric`` as it is."""
    return (signal if signal.x_symmetric else _MirroredSignal(signal),
            noise if noise.x_symmetric else _MirroredNoise(noise))


def error_spectral_density(otf, signal_psd, noise_psd):
    """Error spectral density of the Wiener restoration, ``S_e = S_x S_n / (|H|^2 S_x + S_n)``.

    Berkner & Shroff Eq. (8); ``|H|^2`` is formed as ``Re(H)^2 + Im(H)^2`` so the gradient
    is finite at OTF zeros.

    Parameters
    ----------
    otf : complex array (``H``)
    signal_psd, noise_psd : arrays broadcastable to ``otf`` (``S_x``, ``S_n``), ``S_n > 0``
    """
    return signal_psd * noise_psd / (abs2(otf) * signal_psd + noise_psd)


def wiener_filter(otf, signal_psd, noise_psd):
    """Wiener restoration filter ``G = conj(H) S_x / (|H|^2 S_x + S_n)`` (Eq. 4 of the paper)."""
    return jnp.conj(otf) * signal_psd / (abs2(otf) * signal_psd + noise_psd)

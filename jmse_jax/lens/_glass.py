"""Refractive-index models (glass dispersion) with differentiable parameters.

Wavelengths are in micrometres throughout. Every model is an ``eqx.Module`` whose floats are
leaves, so the index at any wavelength is differentiable in the glass parameters.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax.numpy as jnp
from jax.typing import ArrayLike

from .._numerics import check_range

__all__ = [
    "AIR",
    "AbbeGlass",
    "AbstractGlass",
    "CauchyGlass",
    "ConstantGlass",
    "FRAUNHOFER_C",
    "FRAUNHOFER_D",
    "FRAUNHOFER_F",
    "N_BK7",
]

#: Fraunhofer lines [µm]: helium d (587.56 nm), hydrogen F (486.13 nm) and C (656.27 nm).
FRAUNHOFER_D = 0.5875618
FRAUNHOFER_F = 0.4861327
FRAUNHOFER_C = 0.6562725


class AbstractGlass(eqx.Module):
    """An optical medium: ``index(wavelength)`` with the wavelength in µm."""

    @abc.abstractmethod
    def index(self, wavelength):
        """Refractive index at ``wavelength`` [µm] (array-valued, broadcasting)."""


class ConstantGlass(AbstractGlass):
    """A non-dispersive medium of index ``n`` (air: ``n = 1``).

    Parameters
    ----------
    n : float >= 1 [dimensionless]
    """

    n: ArrayLike = 1.0

    def __check_init__(self):
        check_range("glass index n", self.n, 1.0, 4.0)

    def index(self, wavelength):
        return jnp.zeros_like(jnp.asarray(wavelength)) + self.n


class CauchyGlass(AbstractGlass):
    """Cauchy dispersion ``n(lambda) = a + b / lambda**2 + c / lambda**4`` (lambda in µm).

    Parameters
    ----------
    a : float [dimensionless]
    b : float [µm²]
    c : float [µm⁴], default 0
    """

    a: ArrayLike
    b: ArrayLike
    c: ArrayLike = 0.0

    def __check_init__(self):
        check_range("Cauchy a", self.a, 1.0, 4.0)

    def index(self, wavelength):
        inv2 = 1.0 / (jnp.asarray(wavelength) ** 2)
        return self.a + inv2 * (self.b + self.c * inv2)


class AbbeGlass(AbstractGlass):
    """Glass given by its catalogue ``n_d`` and Abbe number ``V_d`` (two-term Cauchy fit).

    ``n(lambda) = A + B / lambda**2`` with ``B = (n_d - 1) / (V_d (1/lambda_F² - 1/lambda_C²))``
    and ``A = n_d - B / lambda_d²``, so that ``n(lambda_d) = n_d`` and
    ``n_F - n_C = (n_d - 1) / V_d`` exactly (Fraunhofer d, F, C lines).

    Parameters
    ----------
    nd : float in [1, 4] [dimensionless], index at 587.56 nm
    vd : float > 0 [dimensionless], Abbe number ``(n_d - 1) / (n_F - n_C)``

    Notes
    -----
    Inside the visible band (0.45–0.70 µm) the two-term fit reproduces catalogue (Sellmeier)
    indices of ordinary crowns and flints to a few 1e-4, ample for chromatic focal shifts.

    Examples
    --------
    >>> from jmse_jax.lens import AbbeGlass
    >>> round(float(AbbeGlass(1.5168, 64.17).index(0.5875618)), 6)
    1.5168
    """

    nd: ArrayLike = 1.5168
    vd: ArrayLike = 64.17

    def __check_init__(self):
        check_range("glass nd", self.nd, 1.0, 4.0)
        check_range("glass vd (Abbe number)", self.vd, 0.0, None, low_inclusive=False)

    def index(self, wavelength):
        spread = 1.0 / FRAUNHOFER_F**2 - 1.0 / FRAUNHOFER_C**2
        b = (self.nd - 1.0) / (self.vd * spread)
        a = self.nd - b / FRAUNHOFER_D**2
        return a + b / (jnp.asarray(wavelength) ** 2)


#: Air (index 1, non-dispersive) for object and image space.
AIR = ConstantGlass(1.0)
#: Schott N-BK7 (catalogue n_d = 1.5168, V_d = 64.17) in the Abbe model.
N_BK7 = AbbeGlass(1.5168, 64.17)

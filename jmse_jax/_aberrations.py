"""Wavefront models: Seidel (field-dependent) and Noll-indexed Zernike coefficients.

Conventions (SPEC §2): pupil coordinates normalised to the pupil radius, polar angle
``theta`` measured from the +y axis (``y = rho cos theta``, ``x = rho sin theta``), field
point on the +y axis at fractional height ``field``; the wavefront is in waves.
"""

from __future__ import annotations

import abc
import functools
import math
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from ._numerics import check_count, check_finite_tree, check_range, common_dtype

__all__ = ["AbstractAberrations", "Seidel", "Zernike", "noll_to_nm", "wavefront"]


class AbstractAberrations(eqx.Module):
    """A wavefront model ``W(x, y; field)`` in waves over the normalised pupil."""

    @abc.abstractmethod
    def __call__(self, x, y, field):
        """Wavefront in waves at pupil points ``(x, y)`` for fractional field height ``field``."""

    @property
    @abc.abstractmethod
    def x_symmetric(self) -> bool:
        """True when ``W(-x, y) = W(x, y)`` for every coefficient value (a static property).

        Then ``H(-nu_x, nu_y) = H(nu_x, nu_y)`` and one quadrant of the band suffices.
        """

    @property
    def chord_degree(self) -> int | None:
        """Largest degree in ``t`` of ``W(xi + nu) - W(xi - nu)`` along any line ``xi(t)``.

        For a polynomial wavefront of total degree ``d`` this is at most ``d - 1`` (the
        top-degree terms cancel). The overlap OTF engine then evaluates the wavefront at only
        ``chord_degree + 1`` points per chord. ``None`` (the default for models that do not
        know) makes the engine evaluate the wavefront at every quadrature node.
        """
        return None

    @property
    def perpendicular_chord_degree(self) -> int | None:
        """Like ``chord_degree``, but along lines perpendicular to ``nu`` only (the chords of
        the overlap OTF engine). ``<= 2`` lets the engine integrate each chord in closed form.
        The default is ``chord_degree``.
        """
        return self.chord_degree

    def beyond_seidel_degree(self):
        """Whether the wavefront may have terms of higher degree than Seidel's (4) in the
        pupil coordinates: a Python bool, or a traced boolean where the answer depends on the
        coefficient values. ``jmse``'s tiers were calibrated on Seidel designs, so the
        default sends such designs to its steep tier or its balanced plan (with the overlap
        rule ``DEGREE_OVERLAP`` where this is not statically False). The default answer follows
        ``chord_degree`` (True when it is unknown)."""
        return self.chord_degree is None or self.chord_degree > 3

    def difference(self, x, y, dx, dy, field):
        """``W(x + dx, y + dy) - W(x - dx, y - dy)``: the phase difference the overlap OTF
        engine integrates (``(dx, dy) = nu``). The default evaluates the wavefront twice;
        a model can give a cheaper closed form (``Seidel`` does)."""
        return self(x + dx, y + dy, field) - self(x - dx, y - dy, field)

    def radially_symmetric(self, field):
        """Whether ``W`` less its tilt depends on ``rho`` only at this ``field``.

        Returns a Python bool when the answer does not depend on the coefficient values, else
        a traced boolean scalar. Then ``|H(nu)|`` depends on ``|nu|`` only, and ``jmse`` can
        integrate along one ray (``jmse_jax._radial``). The default, ``False``, is always safe.
        """
        del field
        return False

    def first_order_symmetric(self, field):
        """Whether, at a design where ``radially_symmetric`` holds, every first-order change
        of the coefficients and of ``field`` changes ``jmse`` as its part in
        ``symmetric_part`` does (the one-ray plan's first derivatives are then exact). A
        Python bool or a traced boolean; the default, ``False``, is always safe (``jmse``
        then takes the derivatives from the polar grid)."""
        del field
        return False

    def symmetric_part(self, field) -> AbstractAberrations:
        """A model whose wavefront at ``field`` is this one's less every non-radial term
        (less its tilt too; evaluated at the same ``field``), as a differentiable function of
        this model's coefficients and of ``field``: what the one-ray plan integrates.

        At a design where ``radially_symmetric`` holds it equals the wavefront less its tilt,
        so the merit is unchanged. Its derivatives matter where ``first_order_symmetric``
        holds: the merit is unchanged by the band's symmetries (turns by 90 degrees and
        mirrors, with isotropic spectra), so at a symmetric design a first-order change of
        the wavefront acts as its average over them, which for terms ``cos m theta`` with
        ``m`` not a multiple of 4, and every ``sin m theta``, is zero: their change acts as
        its radial part alone. The default returns ``self`` (with the default
        ``first_order_symmetric``, ``False``, its derivatives are never used)."""
        del field
        return self

    def without_tilt(self) -> AbstractAberrations:
        """The same wavefront less its best-fit tilt (its projection on ``x`` and ``y``).

        A tilt only shifts the PSF: it multiplies the OTF by a unit-modulus phase ramp, so
        ``|H|`` and every Wiener quantity are unchanged, while the OTF over the band becomes
        smoother (fewer nodes resolve it). The default returns ``self`` unchanged.
        """
        return self


class Seidel(AbstractAberrations):
    """Primary (Seidel) wavefront coefficients in waves, for a field point on the +y axis.

    .. math::

        W = w_{020}\\rho^2 + w_{040}\\rho^4 + w_{131} h \\rho^2 y + w_{222} h^2 y^2
            + w_{220} h^2 \\rho^2 + w_{311} h^3 y + w_{111} h y

    Parameters
    ----------
    w020, w040, w131, w222, w220, w311, w111 : float [waves]
        Defocus, spherical, coma, astigmatism, (sagittal) field curvature, distortion and
        tilt. Every coefficient is a differentiable leaf.

    Examples
    --------
    >>> import jmse_jax
    >>> ab = jmse_jax.Seidel(w020=-2.75, w040=1.5578)
    >>> round(float(jmse_jax.wavefront(ab, 0.0, 1.0, 0.0)), 6)  # -2.75 + 1.5578
    -1.1922
    """

    w020: ArrayLike = 0.0
    w040: ArrayLike = 0.0
    w131: ArrayLike = 0.0
    w222: ArrayLike = 0.0
    w220: ArrayLike = 0.0
    w311: ArrayLike = 0.0
    w111: ArrayLike = 0.0

    def __call__(self, x, y, field):
        rho2 = x * x + y * y
        h = field
        h2 = h * h
        radial = (self.w020 + self.w220 * h2) + self.w040 * rho2
        linear_y = self.w131 * h * rho2 + self.w311 * h2 * h + self.w111 * h
        return rho2 * radial + y * linear_y + self.w222 * h2 * y * y

    def difference(self, x, y, dx, dy, field):
        # Each term's difference in closed form, with p = (x, y).(dx, dy) and
        # S = |(x, y)|^2 + |(dx, dy)|^2 (so |(x, y) +- (dx, dy)|^2 = S +- 2p):
        # d(rho^2) = 4p, d(rho^4) = 8pS, d(y rho^2) = 4py + 2S dy, d(y) = 2 dy, d(y^2) = 4y dy.
        # About half the operations of two evaluations, no cancellation between two large
        # values, and a reverse pass whose per-coefficient sums are as short.
        h = field
        h2 = h * h
        p = x * dx + y * dy
        s = (x * x + y * y) + (dx * dx + dy * dy)
        radial = (self.w020 + self.w220 * h2) + (2.0 * self.w040) * s
        coma = self.w131 * h
        tilt = self.w311 * h2 * h + self.w111 * h
        return (4.0 * p * (radial + coma * y) + (2.0 * dy) * (coma * s + tilt)
                + (4.0 * self.w222 * h2) * (y * dy))

    @property
    def x_symmetric(self) -> bool:
        return True

    def radially_symmetric(self, field):
        # Coma and astigmatism are the only non-radial terms besides the tilts (w311, w111);
        # on the axis (field 0) both vanish. The products are the ones W is built from, so
        # the answer matches the evaluated wavefront even when h**2 underflows.
        h = jnp.asarray(field)
        return (self.w131 * h == 0) & (self.w222 * (h * h) == 0)

    def first_order_symmetric(self, field):
        # Every non-radial term is of angular order m = 1 (coma, distortion, tilt) or m = 2
        # (astigmatism's h^2 y^2 = h^2 rho^2 / 2 less a cos 2 theta term): a rotation by pi
        # (m = 1) or pi / 2 (m = 2) flips its non-radial part, so at a symmetric design only
        # the radial part a change adds (``symmetric_part``) moves the merit at first order.
        del field
        return True

    def symmetric_part(self, field) -> Seidel:
        # The radial part of W less its tilt: (w020 + w220 h^2 + w222 h^2 / 2) rho^2 +
        # w040 rho^4, as one defocus coefficient (the others zero, so the field only enters
        # through it). Where the design is symmetric, w222 h^2 == 0 and the defocus is
        # bit for bit the wavefront's.
        h2 = jnp.asarray(field) ** 2
        zero = jnp.zeros_like(jnp.asarray(self.w131))
        return Seidel(w020=(self.w020 + self.w220 * h2) + 0.5 * (self.w222 * h2),
                      w040=self.w040, w131=zero, w222=zero, w220=zero, w311=zero, w111=zero)

    def without_tilt(self) -> Seidel:
        # Least-squares tilt of the y-odd terms: rho^2 y projects onto y with factor 2/3
        # (int rho^2 y^2 / int y^2 over the unit disc); w311 h^3 y and w111 h y are pure tilt.
        return Seidel(
            w020=self.w020, w040=self.w040, w131=self.w131, w222=self.w222, w220=self.w220,
            w311=jnp.zeros_like(jnp.asarray(self.w311)),
            w111=-(2.0 / 3.0) * jnp.asarray(self.w131),
        )

    @property
    def chord_degree(self) -> int:
        # Degree 4 wavefront; its only quartic term (rho^4) leaves a difference that is
        # quadratic along lines perpendicular to nu, but cubic along general lines.
        return 3

    @property
    def perpendicular_chord_degree(self) -> int:
        # Along xi = a e + t e_perp (e = nu / |nu|): nu . grad(rho^4) = 4 rho^2 (nu . xi) with
        # nu . xi constant, so every term leaves at most t^2.
        return 2


def noll_to_nm(j: int) -> tuple[int, int]:
    """Radial order ``n`` and signed azimuthal order ``m`` of Noll index ``j >= 1``.

    ``m > 0`` is the ``cos(m theta)`` term (even ``j``), ``m < 0`` the ``sin`` term (odd ``j``).
    """
    check_count("noll index", j)
    n = int((-1.0 + math.sqrt(8 * (j - 1) + 1)) / 2.0)
    p = j - n * (n + 1) // 2
    k = n % 2
    m = ((p + k) // 2) * 2 - k
    if m != 0 and j % 2 == 1:
        m = -m
    return n, m


@functools.cache
def _radial_coefficients(n: int, m: int) -> tuple[float, ...]:
    """Coefficients of ``R_n^m(rho) / rho^m`` as a polynomial in ``rho**2``, lowest first."""
    m = abs(m)
    coeffs = [0.0] * ((n - m) // 2 + 1)
    for k in range((n - m) // 2 + 1):
        c = (-1) ** k * math.factorial(n - k)
        c /= math.factorial(k) * math.factorial((n + m) // 2 - k) * math.factorial((n - m) // 2 - k)
        coeffs[(n - m) // 2 - k] = c
    return tuple(coeffs)


def zernike_polynomial(j: int, x, y):
    """Noll-normalised Zernike polynomial ``Z_j`` (unit RMS over the unit disc) at ``(x, y)``.

    ``theta`` is measured from +y, so the even-``j`` (cosine) terms are even in ``x``.
    """
    n, m = noll_to_nm(j)
    rho2 = x * x + y * y
    radial = jnp.zeros_like(rho2)
    for c in reversed(_radial_coefficients(n, m)):
        radial = radial * rho2 + c
    re, im = _angular_power(abs(m), x, y)
    if m == 0:
        return math.sqrt(n + 1) * radial
    angular = re if m > 0 else im
    return math.sqrt(2 * (n + 1)) * radial * angular


def _angular_powers(orders, x, y):
    """``rho^m e^{i m theta} = (y + i x)^m`` (``theta`` from +y) as (real, imaginary) for each
    ``m`` of the rising ``orders``, each built from the one before, without dividing by
    ``rho``."""
    re, im = jnp.ones_like(x * y), jnp.zeros_like(x * y)
    degree = 0
    for m in orders:
        for _ in range(m - degree):
            re, im = re * y - im * x, re * x + im * y
        degree = m
        yield re, im


def _angular_power(m: int, x, y):
    """``(y + i x)^m`` as (real, imaginary) (``_angular_powers``)."""
    return next(_angular_powers((m,), x, y))


@functools.cache
def _outside_seidel(noll: tuple[int, ...]):
    """Positions in ``noll`` of the terms outside Seidel's shapes: radial order ``n > 4``, or
    angular order ``|m| >= 3`` (trefoil, quadrafoil), which no Seidel term has (its terms
    are of angular order 0, 1 and 2)."""
    orders = [noll_to_nm(j) for j in noll]
    return tuple(i for i, (n, m) in enumerate(orders) if n > 4 or abs(m) >= 3)


@functools.cache
def _split_by_order(noll: tuple[int, ...]):
    """Positions in ``noll`` of the terms of Seidel's degree (radial order <= 4) and of the
    higher ones."""
    low = tuple(i for i, j in enumerate(noll) if noll_to_nm(j)[0] <= 4)
    high = tuple(i for i, j in enumerate(noll) if noll_to_nm(j)[0] > 4)
    return low, high


def noll_indices(noll) -> tuple[int, ...]:
    """``noll`` (a sequence or array of Noll indices) as a tuple of ints, each checked to be
    an integer >= 1 (integer-valued floats pass; 4.7 does not)."""
    out = []
    for j in np.atleast_1d(np.asarray(noll)).tolist():
        if isinstance(j, float) and j.is_integer():
            j = int(j)
        check_count("noll index", j)
        out.append(int(j))
    return tuple(out)


class Zernike(AbstractAberrations):
    """Wavefront as a sum of Noll-indexed Zernike polynomials, coefficients in waves (RMS).

    The field height is ignored: the coefficients describe one field point.

    Parameters
    ----------
    coefficients : array, shape (len(noll),) [waves]
        Coefficient of each polynomial (its RMS contribution over the pupil).
    noll : tuple of int (static)
        Noll indices, default ``1 .. len(coefficients)``.

    Examples
    --------
    >>> import jmse_jax
    >>> ab = jmse_jax.Zernike([0.0, 0.0, 0.0, 0.5], noll=(1, 2, 3, 4))
    >>> round(float(jmse_jax.wavefront(ab, 0.0, 1.0, 0.0)), 6)  # sqrt(3) * 0.5
    0.866025
    """

    coefficients: jax.Array
    noll: tuple[int, ...] = eqx.field(static=True)

    def __init__(self, coefficients, noll=None):
        coefficients = jnp.asarray(coefficients, dtype=common_dtype(coefficients))
        if coefficients.ndim != 1:
            raise ValueError(
                f"coefficients must be a 1-D array, got shape {tuple(coefficients.shape)}"
            )
        if coefficients.shape[0] == 0:
            raise ValueError("coefficients must hold at least one Zernike term, got none")
        if noll is None:
            noll = tuple(range(1, coefficients.shape[0] + 1))
        noll = noll_indices(noll)
        if len(noll) != coefficients.shape[0]:
            raise ValueError(
                f"noll must list one index per coefficient: {len(noll)} indices for "
                f"{coefficients.shape[0]} coefficients"
            )
        self.coefficients = coefficients
        self.noll = noll

    def __call__(self, x, y, field):
        # Grouped by angular order m: one power (y + i x)^m for all the terms of that m and
        # one Horner sum in rho^2 for their radial parts, instead of each polynomial on its
        # own (Noll 4-37: about a sixth of the arithmetic; the overlap engine evaluates the
        # wavefront at every collocation point of every chord).
        del field
        c = self.coefficients
        rho2 = x * x + y * y
        total = jnp.zeros_like(x * y * c[0])
        groups = _grouped_weights(self.noll)
        powers = _angular_powers([m for m, _, _ in groups], x, y)
        for (_, weights, parts), (re, im) in zip(groups, powers, strict=True):
            amplitudes = jnp.asarray(weights, c.dtype) @ c  # (powers of rho^2, cos / sin)
            for part, angular in zip((0, 1), (re, im), strict=True):
                if part not in parts:
                    continue
                radial = amplitudes[-1, part]
                for k in range(amplitudes.shape[0] - 2, -1, -1):
                    radial = radial * rho2 + amplitudes[k, part]
                total = total + radial * angular
        return total

    @property
    def x_symmetric(self) -> bool:
        return all(noll_to_nm(j)[1] >= 0 for j in self.noll)

    @property
    def chord_degree(self) -> int:
        return max(0, max(noll_to_nm(j)[0] for j in self.noll) - 1)

    @property
    def perpendicular_chord_degree(self) -> int:
        # A rotationally symmetric quartic part (only Z11, m = 0, at n = 4) leaves a quadratic
        # along lines perpendicular to nu, as for Seidel's rho^4.
        orders = [noll_to_nm(j) for j in self.noll]
        if max(n for n, _ in orders) == 4 and all(m == 0 for n, m in orders if n == 4):
            return 2
        return self.chord_degree

    def radially_symmetric(self, field):
        del field
        angular = [i for i, j in enumerate(self.noll) if j not in (2, 3) and noll_to_nm(j)[1] != 0]
        if not angular:
            return True
        return jnp.all(self.coefficients[np.asarray(angular)] == 0)

    def first_order_symmetric(self, field):
        # Every term but cos(m theta) with m a positive multiple of 4 (Z14, Z26, Z40, Z44) is
        # flipped by one of the band's turns or mirrors (``symmetric_part``); such a term
        # keeps the band's symmetries and changes the merit at first order in a way the one
        # ray cannot see.
        del field
        return not any(m > 0 and m % 4 == 0 for m in (noll_to_nm(j)[1] for j in self.noll))

    def symmetric_part(self, field) -> Zernike:
        # The radial terms (m = 0) alone; piston (zero) where there are none. The other
        # terms are zero wherever the design is symmetric, and dropping them leaves each
        # wavefront value bit for bit as it was (they add exact zeros).
        del field
        keep = [i for i, j in enumerate(self.noll) if noll_to_nm(j)[1] == 0]
        if not keep:
            return Zernike(0.0 * self.coefficients[:1], noll=(1,))
        return Zernike(self.coefficients[np.asarray(keep)], noll=tuple(self.noll[i] for i in keep))

    def without_tilt(self) -> Zernike:
        # Z2 and Z3 are exactly the tilt (the basis is orthogonal over the pupil).
        keep = jnp.asarray([0.0 if j in (2, 3) else 1.0 for j in self.noll],
                           self.coefficients.dtype)
        return Zernike(self.coefficients * keep, noll=self.noll)

    def beyond_seidel_degree(self):
        # Terms outside Seidel's shapes (``_outside_seidel``: radial order 5 or more, or
        # angular order 3 or more, such as trefoil Z9/Z10 and quadrafoil Z14/Z15) of more than
        # 1e-6 of the wavefront's RMS (piston and tilt aside; the basis is orthonormal): a fit
        # of a Seidel wavefront (``zernike_fit``) leaves rounding there. The tiers were
        # calibrated on Seidel's shapes: 2.5 waves of trefoil with 0.5 of defocus at u = 0.3
        # (strength 10.5) was 4.3e-3 off in them, quadrafoil 5.4e-3 (session 79).
        high = _outside_seidel(self.noll)
        if not high:
            return False
        rest = [i for i, j in enumerate(self.noll) if j > 3]
        c = self.coefficients
        return jnp.sum(jnp.square(c[np.asarray(high)])) > 1e-12 * jnp.sum(
            jnp.square(c[np.asarray(rest)]))

    def seidel_like_terms(self) -> list:
        """The wavefront, less piston and tilt, as a list of terms ``f(x, y)`` in the shapes
        of Seidel's terms, for ``jmse``'s measure of how much the terms cancel.

        A Zernike polynomial is itself a balanced combination (``Z11`` holds defocus against
        spherical aberration; coma holds its tilt), so taken one by one the Zernike terms
        hide the cancellation that the same wavefront shows in Seidel's terms. The part of
        Seidel's degree (radial order ``n <= 4``) is split instead by angular order ``m`` and
        power ``P`` of ``rho``: one term ``rho^P (a cos m theta + b sin m theta)`` per pair
        (any orientation), the coma (``m = 1``, ``P = 3``) less its best-fit tilt, as
        Seidel's, and the astigmatism ``rho^2 cos 2(theta - phi)`` taken as Seidel takes it,
        ``rho^2 cos^2``, whose mean, ``rho^2 / 2``, moves to the defocus. That mean's sign
        (which of the two axes the ``cos^2`` is along) is chosen to make the defocus term
        larger, so a wavefront that Seidel's coefficients give exactly cancels at least as
        much here as there. Pure defocus and spherical aberration, and coma and astigmatism
        along ``y``, give Seidel's terms exactly. Each polynomial of higher order is a term
        of its own (split into powers of ``rho`` they would cancel by construction: 10 to 30
        times on random designs of Noll 4-37, against at most 7 for Seidel's terms)."""
        low, high = _split_by_order(self.noll)
        c = self.coefficients[np.asarray(low, dtype=int)]
        groups = {key: (jnp.dot(w[0], c), jnp.dot(w[1], c))
                  for key, w in _seidel_like_groups(tuple(self.noll[i] for i in low))}
        defocus: tuple[Any, Any] | None = groups.pop((0, 2), None)
        astigmatism = groups.pop((2, 2), None)
        groups.pop((0, 0), None)  # piston
        groups.pop((1, 1), None)  # tilt (Z2, Z3 and the linear parts of coma)
        terms: list[Callable[..., Any]] = []
        if astigmatism is not None:
            a, b = astigmatism
            amplitude = jnp.hypot(a, b)
            c2 = jnp.zeros_like(amplitude) if defocus is None else defocus[0]
            shift = jnp.where(c2 >= 0, -amplitude, amplitude)  # |c2 - shift| = |c2| + A
            terms.append(lambda x, y, a=a, b=b, s=shift: (
                a * (y * y - x * x) + b * (2.0 * x * y) + s * (x * x + y * y)))
            defocus = (c2 - shift, None)
        if defocus is not None:
            terms.append(lambda x, y, c2=defocus[0]: c2 * (x * x + y * y))
        for (m, power), (a, b) in sorted(groups.items()):
            terms.append(functools.partial(_seidel_like_term, m, power, a, b))
        for i in high:
            terms.append(lambda x, y, j=self.noll[i], a=self.coefficients[i]: (
                a * zernike_polynomial(j, x, y)))
        return terms


@functools.cache
def _seidel_like_groups(noll: tuple[int, ...]):
    """Host constants of ``Zernike.seidel_like_terms``: for each ``(|m|, P)`` the weights that
    take the coefficients to the ``cos`` (row 0) and ``sin`` (row 1) amplitudes of
    ``rho^P e^{i |m| theta}``."""
    groups: dict[tuple[int, int], np.ndarray] = {}
    for i, j in enumerate(noll):
        n, m = noll_to_nm(j)
        norm = math.sqrt(n + 1) if m == 0 else math.sqrt(2 * (n + 1))
        for k, coefficient in enumerate(_radial_coefficients(n, m)):
            weights = groups.setdefault((abs(m), abs(m) + 2 * k), np.zeros((2, len(noll))))
            weights[0 if m >= 0 else 1, i] += norm * coefficient
    return tuple(sorted(groups.items()))


@functools.cache
def _grouped_weights(noll: tuple[int, ...]):
    """Host constants of ``Zernike.__call__``: for each angular order ``m`` present (rising),
    the weights ``(K, 2, len(noll))`` that take the coefficients to the ``cos`` and ``sin``
    amplitudes of ``rho^(m + 2k) e^{i m theta}``, ``k < K``, and which of the two parts
    (0: cos, 1: sin) is nonzero."""
    by_m: dict[int, dict[int, np.ndarray]] = {}
    for (m, power), weights in _seidel_like_groups(noll):
        by_m.setdefault(m, {})[(power - m) // 2] = weights
    out = []
    for m in sorted(by_m):
        stack = np.zeros((max(by_m[m]) + 1, 2, len(noll)))
        for k, weights in by_m[m].items():
            stack[k] = weights
        parts = tuple(p for p in (0, 1) if np.any(stack[:, p]))
        out.append((m, stack, parts))
    return tuple(out)


def _seidel_like_term(m, power, a, b, x, y):
    """``rho^power (a cos m theta + b sin m theta)`` (``theta`` from +y), less its best-fit
    tilt (``4 / (power + 3)`` of ``rho cos theta``) when ``m = 1``."""
    re, im = _angular_power(m, x, y)
    term = (x * x + y * y) ** ((power - m) // 2) * (a * re + b * im)
    if m == 1:
        term = term - (4.0 / (power + 3)) * (a * y + b * x)
    return term


def wavefront(aberrations: AbstractAberrations, x, y, field=0.0):
    """Wavefront (OPD) in waves at normalised pupil points ``(x, y)``.

    Parameters
    ----------
    aberrations : Seidel or Zernike
    x, y : array [pupil radii]
        Pupil coordinates; broadcast against each other. Points outside the unit disc are
        evaluated by the same polynomial (the pupil stop is applied elsewhere).
    field : float [fraction of full field, 0..1]

    Returns
    -------
    array [waves], the broadcast shape of ``x`` and ``y``.
    """
    if not isinstance(aberrations, AbstractAberrations):
        raise TypeError(
            f"aberrations must be a jmse_jax.Seidel or jmse_jax.Zernike, got {type(aberrations)}"
        )
    check_finite_tree("aberrations", aberrations)
    check_range("field", field, 0.0, 1.0)
    dtype = common_dtype(aberrations, x, y, field)
    x = jnp.asarray(x, dtype)
    y = jnp.asarray(y, dtype)
    return aberrations(x, y, jnp.asarray(field, dtype))

"""Seidel sums (Welford form) and their conversion to ``jmse_jax.Seidel`` coefficients in waves.

Welford, *Aberrations of Optical Systems* (1986), Ch. 8: with the refraction invariants
``A = n (y c + u)`` and ``A_bar = n (y_bar c + u_bar)`` of the marginal and chief rays, the
Lagrange invariant ``H`` and ``Delta(q) = q' - q`` across a surface,

.. math::

    S_I = -\\sum A^2 y \\Delta(u/n), \\quad S_{II} = -\\sum A \\bar A y \\Delta(u/n), \\quad
    S_{III} = -\\sum \\bar A^2 y \\Delta(u/n), \\quad S_{IV} = -\\sum H^2 c \\Delta(1/n),

    S_V = \\sum \\bar A \\left[-\\bar A^2 y \\Delta(1/n^2) + c \\bar y (\\bar A y + H)
          \\Delta(1/n)\\right],

the last being ``(A_bar / A)(S_III + S_IV)`` per surface rewritten without the division by
``A`` (which vanishes at aplanatic surfaces). A conic/aspheric surface with 4th-order sag
excess ``b = k c³ / 8 + a_4`` over its sphere adds ``8 b (n' - n) y⁴ (y_bar / y)^j`` to the
sums ``j = 0, 1, 2`` (I–III) and ``j = 3`` (V).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._aberrations import Seidel
from .._numerics import check_range, is_concrete, safe_sqrt
from ._paraxial import ParaxialTrace, _guard, _raise_for, _status, paraxial_trace
from ._surfaces import Lens

__all__ = [
    "SeidelSums",
    "defocus_waves",
    "rms_wavefront_error",
    "seidel_sums",
    "seidel_waves",
    "stop_shift",
]


class SeidelSums(eqx.Module):
    """Seidel sums ``S_I .. S_V`` [mm] and their per-surface contributions.

    Attributes
    ----------
    S_I, S_II, S_III, S_IV, S_V : scalars [mm] (spherical, coma, astigmatism, Petzval,
        distortion)
    per_surface : array (5, S) [mm]
    """

    S_I: jax.Array
    S_II: jax.Array
    S_III: jax.Array
    S_IV: jax.Array
    S_V: jax.Array
    per_surface: jax.Array


def _sums_from_trace(lens: Lens, trace: ParaxialTrace) -> SeidelSums:
    c = lens.curvatures
    n, n_after = trace.n[:-1], trace.n[1:]
    u, u_after = trace.u[:-1], trace.u[1:]
    y, y_bar = trace.y, trace.y_bar
    big_h = trace.lagrange
    a = n * (y * c + u)
    a_bar = n * (y_bar * c + trace.u_bar[:-1])
    d_u_n = u_after / n_after - u / n
    d_inv_n = 1.0 / n_after - 1.0 / n
    d_inv_n2 = 1.0 / n_after**2 - 1.0 / n**2
    s1 = -a * a * y * d_u_n
    s2 = -a * a_bar * y * d_u_n
    s3 = -a_bar * a_bar * y * d_u_n
    s4 = -big_h * big_h * c * d_inv_n
    s5 = a_bar * (-a_bar * a_bar * y * d_inv_n2 + c * y_bar * (a_bar * y + big_h) * d_inv_n)
    excess = 8.0 * (lens.conics * c**3 / 8.0 + lens.aspheric4) * (n_after - n)
    s1 = s1 + excess * y**4
    s2 = s2 + excess * y**3 * y_bar
    s3 = s3 + excess * y**2 * y_bar**2
    s5 = s5 + excess * y * y_bar**3
    per_surface = jnp.stack([s1, s2, s3, s4, s5])
    totals = jnp.sum(per_surface, axis=1)
    return SeidelSums(totals[0], totals[1], totals[2], totals[3], totals[4],
                      per_surface=per_surface)


def seidel_sums(lens: Lens, wavelength=None) -> SeidelSums:
    """Seidel sums ``S_I .. S_V`` [mm] of ``lens`` at full field (Welford form).

    Parameters
    ----------
    lens : Lens
    wavelength : float [µm], optional (default ``lens.wavelength``)

    Returns
    -------
    SeidelSums

    Notes
    -----
    The sums need no real image, so no validity check is made here (``seidel_waves`` makes
    one). SPEC §3.7 test vector: ``S_I = 0.0023708064`` mm for R1 = 60, R2 = -200, t = 6,
    n = 1.6, stop 20 mm in front, entrance-pupil semi-diameter 5 mm, 10° field.
    """
    return _sums_from_trace(lens, paraxial_trace(lens, wavelength))


def stop_shift(sums: SeidelSums, eccentricity) -> SeidelSums:
    """Seidel sums after a stop shift with ``E = delta(y_bar) / y`` (Welford Sec. 8.4).

    ``S_I* = S_I``, ``S_II* = S_II + E S_I``, ``S_III* = S_III + 2 E S_II + E² S_I``,
    ``S_IV* = S_IV``, ``S_V* = S_V + E (3 S_III + S_IV) + 3 E² S_II + E³ S_I``.
    """
    e = eccentricity
    s1, s2, s3, s4, s5 = sums.S_I, sums.S_II, sums.S_III, sums.S_IV, sums.S_V
    new = (
        s1,
        s2 + e * s1,
        s3 + 2 * e * s2 + e * e * s1,
        s4,
        s5 + e * (3 * s3 + s4) + 3 * e * e * s2 + e**3 * s1,
    )
    p = sums.per_surface
    per_surface = jnp.stack([
        p[0], p[1] + e * p[0], p[2] + 2 * e * p[1] + e * e * p[0], p[3],
        p[4] + e * (3 * p[2] + p[3]) + 3 * e * e * p[1] + e**3 * p[0],
    ])
    return SeidelSums(*new, per_surface=per_surface)


def defocus_waves(image_shift, f_number, wavelength):
    """Defocus coefficient ``w020 = delta_z / (8 N²) / lambda`` [waves] (SPEC §3.7).

    Parameters
    ----------
    image_shift : float [mm], image plane from focus, positive away from the lens
    f_number : float > 0, working F-number
    wavelength : float [µm]
    """
    check_range("f_number", f_number, 0.0, None, low_inclusive=False)
    check_range("wavelength", wavelength, 0.2, 20.0)
    return image_shift / (8.0 * f_number**2) / (wavelength * 1e-3)


def seidel_waves(lens: Lens, wavelength=None, *, check: bool = True) -> Seidel:
    """Primary aberrations of ``lens`` as ``jmse_jax.Seidel`` coefficients in waves.

    ``w040 = S_I/8``, ``w131 = S_II/2``, ``w222 = S_III/2``, ``w220 = (S_III + S_IV)/4``,
    ``w311 = S_V/2``, each divided by the wavelength (SPEC §3.7), at full field (the pipeline
    applies the powers of the fractional field ``h``). ``w020`` is the defocus of the image
    plane, which sits ``lens.image_shift`` behind the paraxial focus at the *reference*
    wavelength ``lens.wavelength``: at another wavelength it also carries the longitudinal
    colour ``-(BFL(lambda) - BFL(lambda_ref))``. ``w111 = 0``: lateral colour is a pure tilt
    at each field and leaves ``|H|`` (hence the JMSE) unchanged.

    Parameters
    ----------
    lens : Lens
    wavelength : float [µm], optional (default ``lens.wavelength``)
    check : bool
        Raise ``ValueError`` for a concrete non-physical lens (see ``validate_lens``).

    Returns
    -------
    Seidel [waves]
    """
    monochromatic = wavelength is None
    wavelength = lens.wavelength if monochromatic else jnp.asarray(wavelength)
    check_range("wavelength", wavelength, 0.2, 20.0)
    trace = paraxial_trace(lens, wavelength)
    reference = trace if monochromatic else paraxial_trace(lens)
    if check and is_concrete((lens, trace)):
        _raise_for(_status(lens, trace), lens, None if monochromatic else wavelength)
    return _waves_from_traces(lens, trace, reference, wavelength)


def _waves_from_traces(lens: Lens, trace: ParaxialTrace, reference: ParaxialTrace,
                       wavelength) -> Seidel:
    """``seidel_waves`` from the traces at ``wavelength`` and at the reference wavelength."""
    sums = _sums_from_trace(lens, trace)
    image_slope = _guard(trace.u[-1])
    f_number = -1.0 / (2.0 * trace.n[-1] * image_slope)
    shift = lens.image_shift
    if trace is not reference:
        bfl = -trace.y[-1] / image_slope
        bfl_reference = -reference.y[-1] / _guard(reference.u[-1])
        shift = shift - (bfl - bfl_reference)
    to_waves = 1.0 / (wavelength * 1e-3)
    return Seidel(
        w020=defocus_waves(shift, f_number, wavelength),
        w040=sums.S_I / 8.0 * to_waves,
        w131=sums.S_II / 2.0 * to_waves,
        w222=sums.S_III / 2.0 * to_waves,
        w220=(sums.S_III + sums.S_IV) / 4.0 * to_waves,
        w311=sums.S_V / 2.0 * to_waves,
        w111=jnp.zeros_like(sums.S_I),
    )


def rms_wavefront_error(aberrations: Seidel, field):
    """RMS wavefront error [waves] over the unit pupil, piston and tilt removed (closed form).

    With ``a = w020 + (w220 + w222/2) h²`` (total ``rho²`` term), ``b = w040``,
    ``c = w131 h`` (``rho³ cos``) and ``e = w222 h² / 2`` (``rho² cos 2 theta``), the
    Zernike decomposition gives

    .. math::

        \\sigma^2 = \\frac{(a + b)^2}{12} + \\frac{b^2}{180} + \\frac{c^2}{72} + \\frac{e^2}{6}.

    Distortion and tilt (``w311``, ``w111``) are tilts and do not contribute.

    Parameters
    ----------
    aberrations : Seidel [waves]
    field : float in [0, 1] [fraction of full field]
    """
    check_range("field", field, 0.0, 1.0)
    h2 = field * field
    a = aberrations.w020 + (aberrations.w220 + 0.5 * aberrations.w222) * h2
    b = aberrations.w040
    c = aberrations.w131 * field
    e = 0.5 * aberrations.w222 * h2
    variance = (a + b) ** 2 / 12.0 + b * b / 180.0 + c * c / 72.0 + e * e / 6.0
    return safe_sqrt(variance)  # finite gradient at a perfect wavefront

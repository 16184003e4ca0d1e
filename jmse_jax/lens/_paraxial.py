"""Paraxial marginal and chief ray trace, first-order properties and lens validity.

Sign conventions (Welford, *Aberrations of Optical Systems*, 1986): distances along +z (the
direction of light), heights along +y, angles ``u`` are slopes ``dy/dz`` (a ray converging
to the axis after a positive lens has ``u' < 0``). Refraction ``n' u' = n u - y c (n' - n)``,
transfer ``y_{i+1} = y_i + t_i u'_i``. The marginal ray enters parallel to the axis at the
entrance-pupil rim; the chief ray enters at slope ``tan(field_angle)`` and crosses the axis
at the stop.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._numerics import all_finite, check_range, is_concrete
from ._surfaces import Lens, surface_sag

__all__ = [
    "LensStatus",
    "ParaxialTrace",
    "back_focal_length",
    "cutoff_frequency",
    "effective_focal_length",
    "lens_status",
    "paraxial_trace",
    "solve_last_curvature",
    "validate_lens",
    "with_f_number",
    "working_f_number",
]


def _guard(x):
    """``x`` with exact zeros replaced by 1 before a division (double-where stand-in).

    The results are then finite (and their gradients too) but meaningless where ``x = 0``;
    every such case is flagged by ``lens_status`` and rejected by ``validate_lens``.
    """
    return jnp.where(x == 0, jnp.ones_like(x), x)


class ParaxialTrace(eqx.Module):
    """Marginal (``y, u``) and chief (``y_bar, u_bar``) paraxial rays of a ``Lens``.

    Attributes
    ----------
    y, y_bar : arrays (S,) [mm], ray heights at the surfaces
    u, u_bar : arrays (S + 1,) [rad, slopes], ``u[0]`` in object space, ``u[i + 1]`` after
        surface ``i``
    n : array (S + 1,), the indices of the spaces (``n[0] = 1``)
    lagrange : scalar [mm], Lagrange invariant ``H = n (u_bar y - u y_bar)``
    stop_gain : scalar, height at the stop of a ray entering parallel at unit height (0 when
        the stop sits at an image of the object, where no chief ray exists)
    """

    y: jax.Array
    u: jax.Array
    y_bar: jax.Array
    u_bar: jax.Array
    n: jax.Array
    lagrange: jax.Array
    stop_gain: jax.Array


def _trace_ray(curvatures, thicknesses, n, y0, u0):
    """Heights at the surfaces and slopes in every space of one paraxial ray."""
    ys, us = [], [u0]
    y, u = y0, u0
    for i in range(curvatures.shape[0]):
        u = (n[i] * u - y * curvatures[i] * (n[i + 1] - n[i])) / n[i + 1]
        ys.append(y)
        us.append(u)
        if i < thicknesses.shape[0]:
            y = y + thicknesses[i] * u
    return jnp.stack(ys), jnp.stack(us)


def _height_at(z, vertices, ys, us):
    """Height at axial position ``z`` [mm from vertex 0] of a ray given by ``ys``, ``us``."""
    last = vertices.shape[0] - 1
    height = ys[last] + us[last + 1] * (z - vertices[last])
    for i in range(last - 1, -1, -1):
        inside = z < vertices[i + 1]
        height = jnp.where(inside, ys[i] + us[i + 1] * (z - vertices[i]), height)
    return jnp.where(z < vertices[0], ys[0] + us[0] * (z - vertices[0]), height)


def paraxial_trace(lens: Lens, wavelength=None) -> ParaxialTrace:
    """Trace the paraxial marginal and chief rays through ``lens``.

    Parameters
    ----------
    lens : Lens
    wavelength : float [µm], optional (default ``lens.wavelength``); selects the indices.

    Returns
    -------
    ParaxialTrace
    """
    n = jnp.stack(lens.indices(wavelength))
    c, t = lens.curvatures, lens.thicknesses
    vertices = jnp.concatenate([jnp.zeros((1,), t.dtype), jnp.cumsum(t)])
    zero = jnp.zeros_like(lens.ep_radius)
    y, u = _trace_ray(c, t, n, lens.ep_radius, zero)
    # The chief ray is linear in its entrance height: aim it at the stop centre.
    y_unit, u_unit = _trace_ray(c, t, n, zero + 1.0, zero)
    slope = jnp.tan(jnp.deg2rad(lens.field_angle))
    y_tilt, u_tilt = _trace_ray(c, t, n, zero, slope)
    gain = _height_at(lens.stop_position, vertices, y_unit, u_unit)
    offset = _height_at(lens.stop_position, vertices, y_tilt, u_tilt)
    entry = -offset / _guard(gain)
    y_bar, u_bar = y_tilt + entry * y_unit, u_tilt + entry * u_unit
    lagrange = n[0] * (u_bar[0] * y[0] - u[0] * y_bar[0])
    return ParaxialTrace(y, u, y_bar, u_bar, n, lagrange, gain)


def _image_slope(trace: ParaxialTrace):
    return trace.u[-1]


def _power(lens, trace):
    return -trace.n[-1] * _image_slope(trace) / lens.ep_radius


def effective_focal_length(lens: Lens, wavelength=None):
    """Effective (equivalent) focal length ``1 / phi`` [mm], ``phi = -n' u'_S / y_0``.

    Raises ``ValueError`` for a concrete lens of zero power (afocal).
    """
    trace = paraxial_trace(lens, wavelength)
    power = _power(lens, trace)
    if is_concrete(power) and float(power) == 0.0:
        raise ValueError("lens power must be nonzero (got 0 1/mm: an afocal lens has no EFL)")
    return 1.0 / _guard(power)


def back_focal_length(lens: Lens, wavelength=None):
    """Distance [mm] from the last vertex to the paraxial focus, ``-y_S / u'_S``."""
    trace = paraxial_trace(lens, wavelength)
    _raise_if_concrete(lens, trace)
    return -trace.y[-1] / _guard(_image_slope(trace))


def working_f_number(lens: Lens, wavelength=None):
    """Working F-number ``N = 1 / (2 n' |u'_S|)`` for the object at infinity (dimensionless)."""
    trace = paraxial_trace(lens, wavelength)
    _raise_if_concrete(lens, trace)
    return -1.0 / (2.0 * trace.n[-1] * _guard(_image_slope(trace)))


def cutoff_frequency(lens: Lens, wavelength=None):
    """Incoherent cutoff ``1 / (lambda N)`` [cycles/mm] (lambda in mm)."""
    wavelength = lens.wavelength if wavelength is None else wavelength
    return 1.0 / (wavelength * 1e-3 * working_f_number(lens, wavelength))


def with_f_number(lens: Lens, f_number) -> Lens:
    """``lens`` with the entrance-pupil radius set for working F-number ``f_number``.

    ``ep_radius = EFL / (2 N)`` (EFL does not depend on the pupil size).
    """
    check_range("f_number", f_number, 0.0, None, low_inclusive=False)
    efl = effective_focal_length(lens)
    if is_concrete(efl) and float(efl) <= 0:
        raise ValueError(f"with_f_number needs a positive lens; EFL is {float(efl)!r} mm")
    radius = efl / (2.0 * jnp.asarray(f_number, efl.dtype))
    return eqx.tree_at(lambda lens: lens.ep_radius, lens, radius)


def solve_last_curvature(lens: Lens, f_number) -> Lens:
    """``lens`` with the last curvature solved so its working F-number is ``f_number``.

    Zemax's "F-number solve": with the marginal ray ``(y, u)`` incident on the last surface
    (media ``n -> n'``), ``c = (n u + n' / (2 N)) / (y (n' - n))`` makes
    ``u' = -1 / (2 n' N)``. Closed form, differentiable in every other parameter.

    Parameters
    ----------
    lens : Lens (the last curvature is ignored)
    f_number : float > 0
    """
    check_range("f_number", f_number, 0.0, None, low_inclusive=False)
    trace = paraxial_trace(lens)
    n_in, n_out = trace.n[-2], trace.n[-1]
    y, u_in = trace.y[-1], trace.u[-2]
    target = -1.0 / (2.0 * n_out * f_number)
    curvature = (n_in * u_in - n_out * target) / _guard(y * (n_out - n_in))
    return eqx.tree_at(lambda lens: lens.curvatures, lens,
                       lens.curvatures.at[-1].set(curvature))


#: Smallest image-space marginal slope ``n' |u'|`` accepted as a real image: working
#: F-number below 1e6 (rounding leaves zero-power lenses with slopes of ~1e-17, not 0).
_MIN_IMAGE_SLOPE = 5e-7


class LensStatus(eqx.Module):
    """Validity flags and diagnostics of a lens (every field an array; usable under jit).

    Attributes
    ----------
    aperture_ok : bool, the entrance-pupil radius is positive (``with_f_number`` on a lens of
        negative power makes it negative, which would flip the marginal ray and hide the sign
        of the power)
    indices_ok : bool, every medium's index lies in [1, 4] at this wavelength (a dispersion
        formula can leave that range far from its reference wavelength)
    positive_power : bool, ``EFL > 0`` and working F-number ``< 1e6`` (a real image of the
        object at infinity)
    no_total_internal_reflection : bool, ``|n i / n'| < 1`` for the marginal and both rim
        rays at every surface (``i`` the paraxial incidence angle, taken as ``sin I``)
    surfaces_reached : bool, every surface exists out to the beam footprint
        (``1 - (1 + k) c² a² >= 0``, ``a = |y| + |y_bar|``)
    edge_thickness_ok : bool, every axial gap keeps a non-negative thickness on the axis and
        at the edge (the larger footprint of its two surfaces)
    stop_ok : bool, the chief ray exists (the stop is not at an image of the object)
    finite : bool, every number of the lens is finite (a concrete lens is checked at
        construction; this catches NaN or inf reaching a traced one, e.g. from a diverging
        optimiser)
    power : [1/mm], ``1 / EFL``; max_sine : largest ``|n i / n'|``; min_edge_thickness : [mm],
    the smallest gap thickness, on the axis or at the edge
    """

    aperture_ok: jax.Array
    indices_ok: jax.Array
    positive_power: jax.Array
    no_total_internal_reflection: jax.Array
    surfaces_reached: jax.Array
    edge_thickness_ok: jax.Array
    stop_ok: jax.Array
    finite: jax.Array
    power: jax.Array
    max_sine: jax.Array
    min_edge_thickness: jax.Array

    @property
    def ok(self):
        """True when every check passes (array-valued under jit)."""
        return (
            self.aperture_ok & self.indices_ok
            & self.positive_power & self.no_total_internal_reflection & self.surfaces_reached
            & self.edge_thickness_ok & self.stop_ok & self.finite
        )


def _status(lens: Lens, trace: ParaxialTrace) -> LensStatus:
    power = _power(lens, trace)
    c = lens.curvatures
    n_before, n_after = trace.n[:-1], trace.n[1:]
    sines = []
    for sign in (0.0, 1.0, -1.0):
        height = trace.y + sign * trace.y_bar
        slope = trace.u[:-1] + sign * trace.u_bar[:-1]
        sines.append(jnp.abs(n_before * (height * c + slope) / n_after))
    max_sine = jnp.max(jnp.stack(sines))
    footprint = jnp.abs(trace.y) + jnp.abs(trace.y_bar)
    if lens.n_surfaces > 1:
        gap_radius = jnp.maximum(footprint[:-1], footprint[1:])
        sag_front, front_ok = surface_sag(c[:-1], lens.conics[:-1], lens.aspheric4[:-1],
                                          gap_radius)
        sag_back, back_ok = surface_sag(c[1:], lens.conics[1:], lens.aspheric4[1:], gap_radius)
        edge = lens.thicknesses + sag_back - sag_front
        # The centre too: where the edge is the thicker, crossed vertices leave it positive.
        min_edge = jnp.minimum(jnp.min(edge), jnp.min(lens.thicknesses))
        reached = jnp.all(front_ok & back_ok)
    else:
        _, reached = surface_sag(c, lens.conics, lens.aspheric4, footprint)
        reached = jnp.all(reached)
        min_edge = jnp.asarray(jnp.inf, c.dtype)
    return LensStatus(
        aperture_ok=lens.ep_radius > 0,
        indices_ok=jnp.all((trace.n >= 1.0) & (trace.n <= 4.0)),
        positive_power=(power > 0) & (-trace.n[-1] * trace.u[-1] > _MIN_IMAGE_SLOPE),
        no_total_internal_reflection=max_sine < 1.0,
        surfaces_reached=reached,
        edge_thickness_ok=min_edge >= 0.0,
        stop_ok=trace.stop_gain != 0,
        finite=all_finite(lens),
        power=power,
        max_sine=max_sine,
        min_edge_thickness=min_edge,
    )


def lens_status(lens: Lens, wavelength=None) -> LensStatus:
    """Validity of ``lens`` as an imaging system (see ``LensStatus``); never raises.

    Under ``jit``/``vmap`` this is the documented way to learn that a design is non-physical;
    the merit functions return ``+inf`` (with a zero gradient) for such designs.
    """
    return _status(lens, paraxial_trace(lens, wavelength))


def _raise_if_concrete(lens: Lens, trace: ParaxialTrace) -> None:
    if not is_concrete((lens, trace)):
        return
    _raise_for(_status(lens, trace), lens)


def _raise_for(status: LensStatus, lens: Lens, wavelength=None) -> None:
    """Raise ``ValueError`` for the first failed check of ``status`` (of ``lens`` traced at
    ``wavelength``)."""
    if not bool(status.aperture_ok):
        raise ValueError(
            f"ep_radius must be in (0, inf) mm, got {float(lens.ep_radius)!r} (with_f_number "
            f"on a lens of negative power gives a negative radius)"
        )
    if not bool(status.indices_ok):
        wl = lens.wavelength if wavelength is None else wavelength
        indices = [round(float(n), 6) for n in lens.indices(wavelength)]
        raise ValueError(
            f"refractive indices must be in [1, 4], got {indices} at wavelength "
            f"{float(wl)!r} µm (outside the glass model's range of validity)"
        )
    if not bool(status.stop_ok):
        raise ValueError(
            "stop_position puts the stop at an image of the object (no chief ray); move it"
        )
    if not bool(status.positive_power):
        raise ValueError(
            f"lens power must be positive to form a real image of the object at infinity: "
            f"got {float(status.power)!r} 1/mm, allowed (0, inf) with a working F-number "
            f"below 1e6"
        )
    if not bool(status.no_total_internal_reflection):
        raise ValueError(
            f"total internal reflection: the paraxial marginal/rim rays reach |n i / n'| = "
            f"{float(status.max_sine)!r} (i the paraxial incidence angle, standing for "
            f"sin I), allowed [0, 1); at wide fields this can also mean that the field is "
            f"beyond the paraxial model's reach (reduce field_angle)"
        )
    if not bool(status.surfaces_reached):
        trace = paraxial_trace(lens, wavelength)
        footprint = np.abs(np.asarray(trace.y)) + np.abs(np.asarray(trace.y_bar))
        # As _status tests it: each gap at the larger footprint of its two surfaces.
        radius = footprint.copy()
        radius[:-1] = np.maximum(radius[:-1], footprint[1:])
        radius[1:] = np.maximum(radius[1:], footprint[:-1])
        c, k = np.asarray(lens.curvatures), np.asarray(lens.conics)
        i = int(np.argmin(1.0 - (1.0 + k) * c**2 * radius**2))
        raise ValueError(
            f"surface {i} does not extend to the beam footprint: the marginal and chief "
            f"rays need a semi-aperture of {radius[i]:.6g} mm there, but with curvature "
            f"{c[i]:.6g} 1/mm and conic {k[i]:.6g} it ends at "
            f"{1.0 / (abs(c[i]) * np.sqrt(max(1.0 + k[i], 1e-300))):.6g} mm (reduce the "
            f"curvature, the aperture or the field)"
        )
    if not bool(status.edge_thickness_ok):
        raise ValueError(
            f"gap thickness, on the axis and at the edge, must be >= 0 mm, got "
            f"{float(status.min_edge_thickness)!r} mm (increase the thickness or reduce the "
            f"curvatures)"
        )
    if not bool(status.finite):
        raise ValueError(f"every parameter of the lens must be finite, got a NaN or inf in "
                         f"{lens!r}")


def validate_lens(lens: Lens, wavelength=None) -> LensStatus:
    """Raise ``ValueError`` naming the failed check when a concrete lens is non-physical.

    Returns the ``LensStatus`` (unchecked when values are traced).
    """
    status = lens_status(lens, wavelength)
    if is_concrete(status):
        _raise_for(status, lens, wavelength)
    return status

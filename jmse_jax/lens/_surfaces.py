"""The lens description: a sequence of (conic, 4th-order aspheric) spherical surfaces.

Physical units: lengths in mm, curvatures in 1/mm, angles in degrees, wavelengths in µm.
The object is at infinity in air; the field lies along +y (SPEC §2).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._numerics import check_finite_tree, check_range, common_dtype, safe_sqrt
from ._glass import AIR, AbstractGlass, ConstantGlass

__all__ = ["Lens", "Singlet", "surface_sag"]


def _as_vector(name, value, size, dtype):
    value = jnp.asarray(value, dtype)
    if value.ndim == 0:
        value = jnp.full((size,), value, dtype)
    if value.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {tuple(value.shape)}")
    return value


def _as_glass(name, medium):
    if isinstance(medium, AbstractGlass):
        return medium
    if isinstance(medium, (int, float)) or (hasattr(medium, "shape") and medium.shape == ()):
        return ConstantGlass(medium)
    raise ValueError(f"{name} must be a glass model or a refractive index, got {medium!r}")


class Lens(eqx.Module):
    """A rotationally symmetric lens imaging an object at infinity, all floats as leaves.

    Surface ``i`` (0-based, in the order light meets them) has curvature ``curvatures[i]``,
    conic constant ``conics[i]`` and 4th-order aspheric coefficient ``aspheric4[i]``:

    .. math::

        z_i(r) = \\frac{c r^2}{1 + \\sqrt{1 - (1 + k) c^2 r^2}} + a_4 r^4 .

    ``thicknesses[i]`` is the axial distance from surface ``i`` to surface ``i + 1`` and
    ``media[i]`` the medium after surface ``i``; object space is air.

    Parameters
    ----------
    curvatures : array (S,) [1/mm]
    thicknesses : array (S - 1,) [mm]
    media : sequence of S glass models (or plain indices) [dimensionless]
    stop_position : float [mm]
        Axial position of the aperture stop relative to the vertex of surface 0 (negative: in
        front of the lens). The stop may lie in any space, inside glass included.
    ep_radius : float > 0 [mm]
        Entrance-pupil semi-diameter (use ``with_f_number`` to set a working F-number).
    field_angle : float in [0, 60] [degrees]
        Full-field angle; fractional field ``h = 1`` of the pipeline.
    wavelength : float in [0.2, 20] [µm]
        Reference wavelength (paraxial focus, F-number, conversion to waves).
    image_shift : float [mm]
        Image plane relative to the paraxial focus at ``wavelength``, positive away from the
        lens (SPEC §3.7; gives ``w020``).
    conics, aspheric4 : arrays (S,) [dimensionless], [1/mm³], default 0

    Notes
    -----
    Construction checks concrete values (``ValueError`` naming the argument, its value and the
    allowed range); value-dependent physical checks (positive power, total internal reflection,
    edge thickness) are in ``lens_status`` / ``validate_lens``.

    Examples
    --------
    >>> import jax
    >>> jax.config.update("jax_enable_x64", True)
    >>> from jmse_jax.lens import Lens, seidel_sums
    >>> lens = Lens([1 / 60, -1 / 200], [6.0], [1.6, 1.0], stop_position=-20.0,
    ...             ep_radius=5.0, field_angle=10.0)
    >>> round(float(seidel_sums(lens).S_I), 10)
    0.0023708064
    """

    curvatures: jax.Array
    thicknesses: jax.Array
    media: tuple[AbstractGlass, ...]
    conics: jax.Array
    aspheric4: jax.Array
    stop_position: jax.Array
    ep_radius: jax.Array
    field_angle: jax.Array
    wavelength: jax.Array
    image_shift: jax.Array

    def __init__(
        self,
        curvatures,
        thicknesses,
        media,
        *,
        stop_position=0.0,
        ep_radius=1.0,
        field_angle=0.0,
        wavelength=0.5875618,
        image_shift=0.0,
        conics=0.0,
        aspheric4=0.0,
    ):
        dtype = common_dtype(
            curvatures, thicknesses, stop_position, ep_radius, field_angle, wavelength,
            image_shift, conics, aspheric4,
        )
        curvatures = jnp.atleast_1d(jnp.asarray(curvatures, dtype))
        if curvatures.ndim != 1:
            raise ValueError(f"curvatures must be 1-D, got shape {tuple(curvatures.shape)}")
        n_surfaces = curvatures.shape[0]
        if n_surfaces == 0:
            raise ValueError("curvatures must list at least one surface, got none")
        media = tuple(media)
        if len(media) != n_surfaces:
            raise ValueError(
                f"media must list one medium per surface: {len(media)} media for "
                f"{n_surfaces} surfaces"
            )
        self.curvatures = curvatures
        self.thicknesses = _as_vector("thicknesses", thicknesses, n_surfaces - 1, dtype)
        self.media = tuple(_as_glass(f"media[{i}]", m) for i, m in enumerate(media))
        self.conics = _as_vector("conics", conics, n_surfaces, dtype)
        self.aspheric4 = _as_vector("aspheric4", aspheric4, n_surfaces, dtype)
        self.stop_position = jnp.asarray(stop_position, dtype)
        self.ep_radius = jnp.asarray(ep_radius, dtype)
        self.field_angle = jnp.asarray(field_angle, dtype)
        self.wavelength = jnp.asarray(wavelength, dtype)
        self.image_shift = jnp.asarray(image_shift, dtype)

    def __check_init__(self):
        check_finite_tree("lens", self)
        check_range("ep_radius", self.ep_radius, 0.0, None, low_inclusive=False)
        check_range("field_angle", self.field_angle, 0.0, 60.0)
        check_range("wavelength", self.wavelength, 0.2, 20.0)
        check_range("thicknesses", self.thicknesses, 0.0, None)

    @property
    def n_surfaces(self) -> int:
        """Number of refracting surfaces (static)."""
        return int(self.curvatures.shape[0])

    def indices(self, wavelength=None):
        """Refractive indices ``(n_0, ..., n_S)`` before surface 0 and after each surface.

        Returns a list of S + 1 arrays; ``n_0 = 1`` (object space is air).
        """
        wavelength = self.wavelength if wavelength is None else wavelength
        one = AIR.index(wavelength) + jnp.zeros_like(self.ep_radius)
        return [one] + [m.index(wavelength) + jnp.zeros_like(one) for m in self.media]


def surface_sag(curvature, conic, aspheric4, r):
    """Sag ``z(r)`` [mm] of a conic + 4th-order aspheric surface at radial height ``r`` [mm].

    Also returns whether the surface exists at that height (``1 - (1 + k) c² r² >= 0``);
    where it does not, the sag is the value at the edge of existence (finite, zero gradient
    through the square root).
    """
    arg = 1.0 - (1.0 + conic) * curvature * curvature * r * r
    sag = curvature * r * r / (1.0 + safe_sqrt(arg)) + aspheric4 * r**4
    return sag, arg >= 0.0


def Singlet(  # noqa: N802 - a constructor, named like the class it returns
    c1,
    c2,
    thickness,
    glass,
    *,
    stop_distance=0.0,
    ep_radius=None,
    f_number=None,
    field_angle=0.0,
    wavelength=0.5875618,
    image_shift=0.0,
    conics=0.0,
    aspheric4=0.0,
):
    """A singlet in air with its stop ``stop_distance`` in front of the first surface.

    Parameters
    ----------
    c1, c2 : float [1/mm], front and back curvatures
    thickness : float >= 0 [mm], centre thickness
    glass : glass model or float (index)
    stop_distance : float [mm], stop to first vertex (positive: stop in front)
    ep_radius : float > 0 [mm], entrance-pupil semi-diameter; or
    f_number : float > 0, working F-number ``EFL / (2 ep_radius)`` (exactly one of the two)
    field_angle : float [degrees], full field
    wavelength : float [µm]
    image_shift : float [mm], image plane from the paraxial focus, + away from the lens
    conics, aspheric4 : float or (2,) arrays

    Returns
    -------
    Lens

    Examples
    --------
    >>> from jmse_jax.lens import Singlet, working_f_number
    >>> lens = Singlet(1 / 60, -1 / 200, 6.0, 1.6, stop_distance=20.0, f_number=4.6)
    >>> round(float(working_f_number(lens)), 6)
    4.6
    """
    if (ep_radius is None) == (f_number is None):
        raise ValueError("give exactly one of ep_radius and f_number")
    lens = Lens(
        jnp.stack(jnp.broadcast_arrays(*(jnp.asarray(c) for c in (c1, c2)))),
        jnp.reshape(jnp.asarray(thickness), (1,)),
        (glass, AIR),
        stop_position=-jnp.asarray(stop_distance),
        ep_radius=1.0 if ep_radius is None else ep_radius,
        field_angle=field_angle,
        wavelength=wavelength,
        image_shift=image_shift,
        conics=conics,
        aspheric4=aspheric4,
    )
    if f_number is not None:
        from ._paraxial import with_f_number

        lens = with_f_number(lens, f_number)
    return lens


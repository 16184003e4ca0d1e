"""Exact real-ray trace through conic/aspheric surfaces (NumPy float64): the lens-model oracle.

Independent of ``jmse_jax.lens``: rays are straight lines between surfaces, intersections are
found by Newton's method on the exact sag, refraction is Snell's law in vector form. First-order
quantities (EFL, BFL) come from real rays of vanishing aperture, not from a paraxial trace.

Conventions match the package: light along +z, object at infinity, field on +y (a field angle
``theta`` is the direction ``(0, sin theta, cos theta)``), vertex of surface 0 at ``z = 0``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np


@dataclasses.dataclass(frozen=True)
class System:
    """Surfaces in order: curvature [1/mm], conic, a4 [1/mm³]; gaps [mm]; indices after each."""

    curvatures: tuple[float, ...]
    thicknesses: tuple[float, ...]
    indices: tuple[float, ...]
    stop_position: float
    conics: tuple[float, ...] | None = None
    aspheric4: tuple[float, ...] | None = None

    @property
    def vertices(self) -> np.ndarray:
        return np.concatenate([[0.0], np.cumsum(self.thicknesses)])

    def surface(self, i):
        k = 0.0 if self.conics is None else self.conics[i]
        a4 = 0.0 if self.aspheric4 is None else self.aspheric4[i]
        return self.curvatures[i], k, a4


def _sag_and_slope(c, k, a4, r):
    root = math.sqrt(1.0 - (1.0 + k) * c * c * r * r)
    sag = c * r * r / (1.0 + root) + a4 * r**4
    slope = c * r / root + 4.0 * a4 * r**3
    return sag, slope


def _intersect(point, direction, c, k, a4, z_vertex):
    """Point where the ray meets the surface (Newton on ``z - z_v - sag(r)`` along the ray)."""
    s = (z_vertex - point[2]) / direction[2]
    for _ in range(60):
        p = point + s * direction
        r = math.hypot(p[0], p[1])
        sag, slope = _sag_and_slope(c, k, a4, r)
        f = p[2] - z_vertex - sag
        dr_ds = 0.0 if r == 0.0 else (p[0] * direction[0] + p[1] * direction[1]) / r
        step = f / (direction[2] - slope * dr_ds)
        s -= step
        if abs(step) < 1e-16 * max(1.0, abs(s)):
            break
    p = point + s * direction
    r = math.hypot(p[0], p[1])
    _, slope = _sag_and_slope(c, k, a4, r)
    if r == 0.0:
        normal = np.array([0.0, 0.0, -1.0])
    else:
        normal = np.array([slope * p[0] / r, slope * p[1] / r, -1.0])
    return p, normal / np.linalg.norm(normal)


def _refract(direction, normal, n1, n2):
    cos_i = float(np.dot(direction, normal))
    if cos_i < 0:
        normal, cos_i = -normal, -cos_i
    mu = n1 / n2
    radicand = 1.0 - mu * mu * (1.0 - cos_i * cos_i)
    if radicand < 0:
        raise ValueError("total internal reflection")
    return mu * direction + (math.sqrt(radicand) - mu * cos_i) * normal


def trace(system: System, point, direction):
    """Trace a ray from ``point`` (in object space) along unit ``direction``.

    Returns the point on the last surface and the direction in image space.
    """
    point = np.asarray(point, float)
    direction = np.asarray(direction, float)
    direction = direction / np.linalg.norm(direction)
    n1 = 1.0
    for i, z_v in enumerate(system.vertices):
        point, normal = _intersect(point, direction, *system.surface(i), z_v)
        direction = _refract(direction, normal, n1, system.indices[i])
        n1 = system.indices[i]
    return point, direction


def _position_at(system: System, point, direction, z):
    """Where a ray from object space crosses the plane ``z`` (any space)."""
    point = np.asarray(point, float)
    direction = np.asarray(direction, float) / np.linalg.norm(direction)
    n1 = 1.0
    for i, z_v in enumerate(system.vertices):
        hit, normal = _intersect(point, direction, *system.surface(i), z_v)
        if z < hit[2]:
            break
        direction = _refract(direction, normal, n1, system.indices[i])
        n1 = system.indices[i]
        point = hit
    return point + (z - point[2]) / direction[2] * direction


def focal_lengths(system: System, height=1e-7):
    """EFL and BFL [mm] from a real ray of vanishing ``height`` (the paraxial limit)."""
    point, direction = trace(system, [0.0, height, -1.0], [0.0, 0.0, 1.0])
    slope = direction[1] / direction[2]
    efl = -height / (system.indices[-1] * slope)
    z_focus = point[2] - point[1] / slope
    return efl, z_focus - system.vertices[-1]


def stop_magnification(system: System, height=1e-7):
    """Height at the stop of a parallel ray entering at unit height (paraxial limit)."""
    start = [0.0, height, min(system.stop_position, 0.0) - 1.0]
    return _position_at(system, start, [0.0, 0.0, 1.0], system.stop_position)[1] / height


def aimed_ray(system: System, field_angle, stop_x, stop_y):
    """Start point and direction of the ray at ``field_angle`` [deg] through the stop point."""
    theta = math.radians(field_angle)
    direction = np.array([0.0, math.sin(theta), math.cos(theta)])
    z0 = min(system.stop_position, 0.0) - 1.0
    if system.stop_position <= 0.0:
        back = (system.stop_position - z0) / direction[2]
        return np.array([stop_x, stop_y, system.stop_position]) - back * direction, direction
    target = np.array([stop_x, stop_y])
    entry = target / stop_magnification(system)
    for _ in range(50):
        def miss(e):
            p = _position_at(system, [e[0], e[1], z0], direction, system.stop_position)
            return p[:2] - target

        f = miss(entry)
        h = 1e-7 * max(1.0, float(np.max(np.abs(entry))))
        jac = np.column_stack([(miss(entry + h * np.eye(2)[j]) - f) / h for j in range(2)])
        step = np.linalg.solve(jac, f)
        entry = entry - step
        if np.max(np.abs(step)) < 1e-15:
            break
    return np.array([entry[0], entry[1], z0]), direction


def transverse_aberrations(system: System, ep_radius, field_angle, pupil_x, pupil_y,
                           image_shift=0.0):
    """Real-ray transverse aberrations ``(eps_x, eps_y)`` [mm] at the image plane.

    The image plane is ``image_shift`` behind the paraxial focus; aberrations are measured
    from the paraxial chief ray's intercept with it, ``EFL tan(theta) + u_bar' image_shift``
    (the paraxial chief slope ``u_bar'`` taken from a real chief ray of vanishing field).
    Pupil coordinates are normalised to the stop radius that ``ep_radius`` implies.
    """
    efl, bfl = focal_lengths(system)
    z_image = system.vertices[-1] + bfl + image_shift
    stop_radius = abs(stop_magnification(system)) * ep_radius
    tiny = 1e-6
    _, tiny_out = trace(system, *aimed_ray(system, tiny, 0.0, 0.0))
    chief_slope = tiny_out[1] / tiny_out[2] / math.tan(math.radians(tiny))
    slope = math.tan(math.radians(field_angle))
    gaussian = slope * (efl + chief_slope * image_shift)
    eps = []
    for px, py in zip(np.ravel(pupil_x), np.ravel(pupil_y), strict=True):
        start, direction = aimed_ray(system, field_angle, px * stop_radius, py * stop_radius)
        point, out = trace(system, start, direction)
        hit = point + (z_image - point[2]) / out[2] * out
        eps.append((hit[0], hit[1] - gaussian))
    eps = np.array(eps)
    return eps[:, 0], eps[:, 1]

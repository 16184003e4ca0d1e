"""Pupil sampling grids with quadrature weights, OPD sampling and Zernike projection.

The polar grid is the ray-trace budget of Berkner & Shroff (their Sec. III-C): ``L`` rings at
Gauss–Legendre nodes in ``rho**2`` (Forbes, JOSA A 5, 1988) and ``K`` equally spaced arms. Its
weights integrate exactly every polynomial of degree ``<= 2 L - 1`` in ``rho**2`` times a
trigonometric polynomial of degree ``< K`` in ``theta``, so the projection of sampled OPD onto
Zernike polynomials is exact up to that order.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from ._aberrations import (
    AbstractAberrations,
    Zernike,
    noll_indices,
    noll_to_nm,
    wavefront,
    zernike_polynomial,
)
from ._numerics import EXACT, check_count, check_finite_tree, gauss_legendre

__all__ = ["PolarGrid", "SquareGrid", "sample_opd", "zernike_fit"]


class PupilGrid:
    """Points ``(x, y)`` in the unit pupil with weights summing to the pupil area ``pi``.

    Grids are host-side constants (read-only NumPy float64 arrays), not pytrees.
    """

    x: np.ndarray
    y: np.ndarray
    weights: np.ndarray

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.size} points)"

    @property
    def size(self) -> int:
        return int(self.x.size)


def _frozen(a):
    a = np.ascontiguousarray(a, dtype=np.float64)
    a.setflags(write=False)
    return a


class PolarGrid(PupilGrid):
    """Polar pupil grid: ``rings`` Gauss rings in ``rho**2`` times ``arms`` equally spaced arms.

    Parameters
    ----------
    rings : int >= 1 (``L`` in the paper)
    arms : int >= 1 (``K`` in the paper); arm ``k`` lies at ``theta = 2 pi k / arms`` from +y.

    Notes
    -----
    The weights are ``(1/2) w_l (2 pi / K)`` with ``w_l`` the Gauss–Legendre weights on
    ``[0, 1]`` in ``s = rho**2``; they sum to ``pi``.
    """

    def __init__(self, rings: int = 6, arms: int = 40):
        check_count("rings", rings)
        check_count("arms", arms)
        s, ws = gauss_legendre(rings, 0.0, 1.0)
        theta = 2.0 * math.pi * np.arange(arms) / arms
        rho = np.sqrt(s)
        self.rings = int(rings)
        self.arms = int(arms)
        self.x = _frozen(rho[:, None] * np.sin(theta)[None, :])
        self.y = _frozen(rho[:, None] * np.cos(theta)[None, :])
        self.weights = _frozen(np.repeat(0.5 * ws[:, None] * (2.0 * math.pi / arms), arms, axis=1))


class SquareGrid(PupilGrid):
    """``B x B`` cell-centred square grid over ``[-1, 1]**2``; cells outside the disc weigh 0.

    This is the baseline's sampling (Berkner & Shroff Sec. III-A): the pupil edge is a
    staircase, so quantities integrated on it converge only to first order in ``1/B``.
    """

    def __init__(self, B: int = 64):
        check_count("B", B)
        coords = (np.arange(B) - B / 2 + 0.5) * (2.0 / B)
        x, y = np.meshgrid(coords, coords, indexing="xy")
        inside = x * x + y * y <= 1.0
        self.B = int(B)
        self.x = _frozen(x)
        self.y = _frozen(y)
        self.weights = _frozen(np.where(inside, (2.0 / B) ** 2, 0.0))


def sample_opd(aberrations: AbstractAberrations, grid: PupilGrid, field=0.0):
    """Wavefront in waves at the points of ``grid`` (what a ray tracer would deliver)."""
    return wavefront(aberrations, grid.x, grid.y, field)


def zernike_fit(samples, grid: PupilGrid, noll=None) -> Zernike:
    """Project wavefront samples on ``grid`` onto Noll-normalised Zernike polynomials.

    ``c_j = (1/pi) sum_i w_i W_i Z_j(x_i, y_i)``: the quadrature form of the orthogonal
    projection. On a ``PolarGrid`` it is exact for a wavefront that is a combination of the
    requested polynomials when ``max n <= 2 * rings - 1`` and ``2 * max |m| < arms`` (``max``
    over the requested ``noll``; fewer arms raise ``ValueError``); a Seidel wavefront (radial
    order 4) is therefore recovered exactly from ``rings >= 3, arms >= 9`` with ``noll``
    covering ``n <= 4`` (``noll = range(1, 16)``, whose quadrafoil has ``|m| = 4``).

    Parameters
    ----------
    samples : array, shape of ``grid.x`` [waves]
    grid : PolarGrid (exact) or SquareGrid (approximate: staircase edge)
    noll : sequence of int, default ``1 .. 15`` (all terms with ``n <= 4``)

    Returns
    -------
    Zernike
    """
    if noll is None:
        noll = tuple(range(1, 16))
    noll = noll_indices(noll)
    if not noll:
        raise ValueError("noll must name at least one Zernike term")
    check_finite_tree("samples", samples)
    samples = jnp.asarray(samples)
    if samples.shape != grid.x.shape:
        raise ValueError(
            f"samples must have the grid's shape {grid.x.shape}, got {tuple(samples.shape)}"
        )
    if isinstance(grid, PolarGrid):
        n_max = max(noll_to_nm(j)[0] for j in noll)
        m_max = max(abs(noll_to_nm(j)[1]) for j in noll)
        if n_max > 2 * grid.rings - 1 or 2 * m_max >= grid.arms:
            raise ValueError(
                f"a PolarGrid with rings={grid.rings}, arms={grid.arms} cannot resolve Zernike "
                f"terms up to n={n_max}, |m|={m_max}: need "
                f"rings >= {math.ceil((n_max + 1) / 2)} and arms > {2 * m_max}"
            )
    # Integer samples take JAX's default float (float64 when x64 is on), as jnp does.
    dtype = samples.dtype if jnp.issubdtype(samples.dtype, jnp.floating) else \
        jnp.result_type(float)
    weighted = samples * jnp.asarray(grid.weights, dtype) / math.pi
    basis = jnp.stack([zernike_polynomial(j, jnp.asarray(grid.x, dtype), jnp.asarray(grid.y, dtype))
                       for j in noll])
    coefficients = jnp.tensordot(basis, weighted, axes=weighted.ndim, precision=EXACT)
    return Zernike(coefficients, noll=noll)


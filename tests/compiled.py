"""Compiled merits shared by the test modules (one compilation per option set per session)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from oracles import SEIDEL_KEYS

import jmse_jax as jj


@functools.cache
def jmse_fn(**options):
    """``jax.jit`` of ``jmse`` with the static ``options`` bound (cached per options)."""
    return jax.jit(functools.partial(jj.jmse, **options))


@functools.cache
def jmse_value_and_grad_fn(**options):
    """``jax.jit`` of ``jax.value_and_grad`` of ``jmse`` in the aberrations (the first
    argument), the static ``options`` bound (cached per options).

    Without options it is ``jax.jit(jax.value_and_grad(jj.jmse))``, the program of the
    README's example: JAX's persistent compilation cache, which the test processes share
    (``conftest.py``), keys a program by its name and operations, so every test and
    process that calls it with inputs of the same types compiles it once between them.
    A Python float is weakly typed and ``jnp.float64(0.95)`` is not, so the two make two
    programs: the tests pass Python floats (in a ``Seidel``, ``MarkovSignal`` and
    ``WhiteNoise`` too), as the README does."""
    return jax.jit(jax.value_and_grad(functools.partial(jj.jmse, **options)))


@jax.jit
def fast_value_and_grad_in_everything(ab, p):
    """The fast preset's value and its gradients in the coefficients ``ab`` and in each
    scalar of the dict ``p``: ``field``, ``u``, ``noise`` (``WhiteNoise``), ``variance`` and
    ``mu`` (``MarkovSignal``). The spectra are built inside the program, so out-of-range
    parameters reach ``jmse`` traced (their constructors reject concrete ones). Shared by
    tests/test_merit.py, tests/test_radial.py and tests/test_transforms.py, which pass
    Python floats."""
    def merit(ab, p):
        return jj.jmse(ab, p["field"], p["u"], *spectra_of(p), preset="fast")
    return jax.value_and_grad(merit, argnums=(0, 1))(ab, p)


def spectra_of(p):
    """``MarkovSignal(p["variance"], p["mu"])`` and ``WhiteNoise(p["noise"])``."""
    return jj.MarkovSignal(p["variance"], p["mu"]), jj.WhiteNoise(p["noise"])


def assert_vmap_matches_singles(merit, designs):
    """``vmap(value_and_grad(merit))`` over the Seidel ``designs`` (a list of
    ``(aberrations, field)``) equals the unbatched evaluation of each design: value to
    1e-13, gradients in the coefficients and the field to 1e-10."""
    def plain(ab):
        return jj.Seidel(**{k: getattr(ab, k) for k in SEIDEL_KEYS})

    batch = jax.tree_util.tree_map(lambda *x: jnp.stack([jnp.asarray(v, jnp.float64) for v in x]),
                                   *[plain(ab) for ab, _ in designs])
    field = jnp.asarray([f for _, f in designs], jnp.float64)
    vag = jax.value_and_grad(merit, argnums=(0, 1))
    values, (grads, field_grads) = jax.jit(jax.vmap(vag))(batch, field)
    single = jax.jit(vag)
    for i, (ab, f) in enumerate(designs):
        value, (grad, field_grad) = single(plain(ab), jnp.float64(f))
        np.testing.assert_allclose(values[i], float(value), rtol=1e-13)
        np.testing.assert_allclose(field_grads[i], field_grad, rtol=1e-10, atol=1e-14)
        for name in ("w020", "w040", "w131", "w222", "w220"):
            np.testing.assert_allclose(getattr(grads, name)[i], getattr(grad, name),
                                       rtol=1e-10, atol=1e-14)

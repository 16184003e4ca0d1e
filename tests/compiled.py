"""Compiled merits shared by the test modules (one compilation per option set per session)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

import jmse_jax as jj


@functools.cache
def jmse_fn(**options):
    """``jax.jit`` of ``jmse`` with the static ``options`` closed over (cached per options)."""
    return jax.jit(lambda ab, field, u, signal, noise: jj.jmse(ab, field, u, signal, noise,
                                                               **options))


@functools.cache
def jmse_value_and_grad_fn(**options):
    """``jax.jit`` of ``jax.value_and_grad`` of ``jmse`` in the aberrations (the first
    argument), the static ``options`` closed over (cached per options)."""
    return jax.jit(jax.value_and_grad(
        lambda ab, field, u, signal, noise: jj.jmse(ab, field, u, signal, noise, **options)))


_SEIDEL_KEYS = ("w020", "w040", "w131", "w222", "w220", "w311", "w111")


def assert_vmap_matches_singles(merit, designs):
    """``vmap(value_and_grad(merit))`` over the Seidel ``designs`` (a list of
    ``(aberrations, field)``) equals the unbatched evaluation of each design: value to
    1e-13, gradients in the coefficients and the field to 1e-10."""
    def plain(ab):
        return jj.Seidel(**{k: getattr(ab, k) for k in _SEIDEL_KEYS})

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

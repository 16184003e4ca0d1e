"""Compiled merits shared by the test modules (one compilation per option set per session)."""

from __future__ import annotations

import functools

import jax

import jmse_jax as jj


@functools.cache
def jmse_fn(**options):
    """``jax.jit`` of ``jmse`` with the static ``options`` closed over (cached per options)."""
    return jax.jit(lambda ab, field, u, signal, noise: jj.jmse(ab, field, u, signal, noise,
                                                               **options))



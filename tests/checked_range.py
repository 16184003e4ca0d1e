"""The oracle of the checked-range flags (``beyond_checked``, ``lens_beyond_checked``,
``SweepResult.beyond_checked``, ``OptimisationResult.beyond_checked``): whether a concrete
``jmse`` call on one design warns."""

from __future__ import annotations

import warnings

import pytest

import jmse_jax as jj
from jmse_jax import AccuracyWarning


def eager_warns(monkeypatch, aberrations, field, u, signal, noise, **options) -> bool:
    """Whether a concrete ``jmse`` call on one design gives an ``AccuracyWarning``. Its
    computation, which comes after its checks, is replaced by a stand-in that stops the
    call (``_merit._eager_tier_choice``), so no merit is computed."""
    import jmse_jax._merit as merit

    class Stop(Exception):
        pass

    def stop(*args, **kwargs):
        raise Stop

    with monkeypatch.context() as patch:
        patch.setattr(merit, "_eager_tier_choice", stop)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with pytest.raises(Stop):
                jj.jmse(aberrations, field, u, signal, noise, **options)
    return any(issubclass(w.category, AccuracyWarning) for w in caught)

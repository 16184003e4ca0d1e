"""The oldest versions of the dependencies that jmse_jax is tested with, checked at import.

``pyproject.toml`` states the same floors (``tests/test_requirements.py`` keeps the two
equal), and pip installs satisfy them. The check catches an environment that does not (an
installation with ``--no-deps``, an older JAX pinned by another package), where the failures
would otherwise come late and obscure. Found with older versions (session 94):

- jax before 0.7 linearizes through JVP and partial evaluation, not directly, so the refusal
  of reverse mode over a derivative of ``jmse`` never fires (JAX's "Linearization failed"
  comes instead); jax 0.6.0 has no ``jax.shard_map`` (``sweep`` over several devices), and
  jax 0.4.30 neither ``lax.map(batch_size=...)`` nor ``pure_callback(vmap_method=...)``;
- jaxopt before 0.8.2 imports ``jax.config`` as a module, which jax has removed
  (``optimise`` with bounds, L-BFGS-B);
- optimistix 0.0.11 (beside jax 0.7.2) runs a computation when imported, which starts
  XLA's backend, so that ``jax.distributed.initialize`` (a sweep over several hosts) must
  come before ``import jmse_jax``;
- jax 0.7.2 requires numpy 2.0 or later, and equinox 0.11 does not import beside it;
  equinox 0.13.0 and matplotlib 3.9.0 (beside numpy 2.0) are the oldest versions tested.

The floors are the versions that the whole test suite passed with (``make test-oldest``,
``constraints-oldest.txt``).
"""

from __future__ import annotations

import importlib.metadata
import re

#: Distribution name -> oldest version tested (``make test-oldest`` installs these).
MINIMUM_VERSIONS = {
    "jax": "0.7.2",
    "jaxopt": "0.8.2",
    "optimistix": "0.1.0",
    "equinox": "0.13.0",
    "numpy": "2.0",
    "matplotlib": "3.9",
    "tqdm": "4.60",
}


def release(version: str) -> tuple[int, ...]:
    """The leading numeric release of a version string: ``"0.10.3.dev20261201"`` ->
    ``(0, 10, 3)``, ``"0.7.2rc1"`` -> ``(0, 7, 2)``, ``"2.0"`` -> ``(2, 0)``."""
    leading = re.match(r"\d+(?:\.\d+)*", version)
    return tuple(int(part) for part in leading.group().split(".")) if leading else ()


def check(installed: dict[str, str | None] | None = None) -> None:
    """Raise ``ImportError`` naming every dependency older than ``MINIMUM_VERSIONS``.

    ``installed`` maps a distribution to its version (``None``: not installed, as for a
    source tree used without installation; not checked); by default it is read from the
    installed distributions' metadata, without importing them."""
    if installed is None:
        installed = {}
        for name in MINIMUM_VERSIONS:
            try:
                installed[name] = importlib.metadata.version(name)
            except importlib.metadata.PackageNotFoundError:
                installed[name] = None
    too_old = {name: found for name, found in installed.items()
               if found is not None and name in MINIMUM_VERSIONS
               and release(found) < release(MINIMUM_VERSIONS[name])}
    if too_old:
        found = ", ".join(f"{name} {version} (needs >= {MINIMUM_VERSIONS[name]})"
                          for name, version in too_old.items())
        upgrade = " ".join(f'"{name}>={MINIMUM_VERSIONS[name]}"' for name in too_old)
        raise ImportError(f"jmse_jax needs newer versions of: {found}. Upgrade them, e.g. "
                          f"pip install --upgrade {upgrade}.")


check()

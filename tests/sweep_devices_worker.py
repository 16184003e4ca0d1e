"""Run sweeps on several fake CPU devices and save them; driven by ``tests/test_sweep.py``.

JAX fixes its device count when its backend starts, so a pytest session that already used
JAX cannot switch to 4 devices. The test runs this script in a fresh interpreter with
``XLA_FLAGS=--xla_force_host_platform_device_count=4`` and compares the saved results.

Usage: ``python sweep_devices_worker.py OUT_DIR``
"""

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

import jmse_jax as jj  # noqa: E402

#: Cheap jmse options: compile and run fast; accuracy is irrelevant for these checks. The
#: fine S_e grid is on (three blocks of angular rows) so its matrix products are covered by
#: the bit-for-bit comparisons.
CHEAP = dict(preset="fast", nodes=(8, 8), se_nodes=(1200, 64), overlap_nodes=(8, 8))


def designs():
    """Nine designs (uneven for 2 and 4 devices), one with a NaN coefficient."""
    w020 = np.array([-2.0, -1.0, 0.0, 0.5, np.nan, 1.0, 1.5, 2.0, 3.0])
    w222 = np.linspace(0.0, 1.2, 9)
    field = np.linspace(0.1, 1.0, 9)
    return jj.Seidel(w020=w020, w222=w222, w131=0.3, w040=0.4), field


def main(out_dir: Path) -> None:
    if jax.device_count() != 4:
        raise SystemExit(f"expected 4 fake CPU devices, got {jax.devices()}")
    aberrations, field = designs()
    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)
    for n_devices in (1, 2, 4):
        result = jj.sweep_jmse(aberrations, field, 0.2, signal, noise, grad=True, batch_size=2,
                               devices=n_devices, progress=False, **CHEAP)
        result.save(out_dir / f"grad_{n_devices}")
    # The progress bar changes nothing but the display.
    result = jj.sweep_jmse(aberrations, field, 0.2, signal, noise, grad=True, batch_size=2,
                           devices=4, progress=True, **CHEAP)
    result.save(out_dir / "grad_4_progress")
    for n_devices in (1, 4):
        # Two lax.map chunks of 2 designs per device and call: 3 calls on 1 device, 1 on 4.
        result = jj.sweep_jmse(aberrations, field, 0.2, signal, noise, grad=False, batch_size=2,
                               chunks_per_call=2, devices=n_devices, progress=False, **CHEAP)
        result.save(out_dir / f"value_{n_devices}")
    # Order: each design returns its own index; 13 designs on 4 devices x 3 per chunk.
    index = np.arange(13, dtype=np.float64)
    result = jj.sweep(lambda d: jnp.stack([d["index"], 2.0 * d["index"]]), {"index": index},
                      batch_size=3, progress=False)
    result.save(out_dir / "order_4")


if __name__ == "__main__":
    main(Path(sys.argv[1]))

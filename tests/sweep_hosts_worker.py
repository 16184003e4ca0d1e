"""One of two processes ("hosts") running a sweep together; driven by ``tests/test_sweep.py``.

Each process has 2 fake CPU devices, joins the other through ``jax.distributed.initialize``
(CPU collectives over gloo) and calls ``sweep_jmse`` with the same batch, so the sweep runs
on a 4-device mesh spanning both processes, exactly as it would on two machines. Every
process receives the whole result; each saves its own copy for the test to compare.

Usage: ``python sweep_hosts_worker.py PROCESS_ID PORT OUT_DIR``
"""

import os
import sys
from pathlib import Path

os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=2"
os.environ["JAX_PLATFORMS"] = "cpu"

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_cpu_collectives_implementation", "gloo")

from sweep_devices_worker import CHEAP, designs  # noqa: E402

import jmse_jax as jj  # noqa: E402


def main(process_id: int, port: int, out_dir: Path) -> None:
    jax.distributed.initialize(coordinator_address=f"127.0.0.1:{port}", num_processes=2,
                               process_id=process_id, initialization_timeout=120)
    if (jax.process_count(), jax.local_device_count(), jax.device_count()) != (2, 2, 4):
        raise SystemExit(f"expected 2 processes x 2 devices, got {jax.devices()}")
    aberrations, field = designs()
    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)
    result = jj.sweep_jmse(aberrations, field, 0.2, signal, noise, grad=True, batch_size=2,
                           progress=False, **CHEAP)
    result.save(out_dir / f"hosts_grad_{process_id}")
    jax.distributed.shutdown()


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]), Path(sys.argv[3]))

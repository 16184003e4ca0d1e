"""Does headline 1's lower bound depend on how the square-grid baseline is written?

``accuracy_speed.py`` bounds the equal-accuracy speed-up from below by the time of
``baseline_jmse`` at B = 2048 over the default's (no B up to 2048 reaches the default's
worst error). ``baseline_jmse`` follows the paper's recipe as written: a complex FFT of the
PSF, and ``S_e`` on every lag of the ``2B x 2B`` grid, masked to the band. A leaner program
computes the same sums: the PSF is real, so a real FFT gives half the lags and the other
half mirror them (``|H(-nu)| = |H(nu)|`` and the spectra are even); and ``S_e`` is needed
only on the lags inside the band (``|k| < u B`` per axis: 4 % of the grid at ``u = 0.2``).
This script builds that program for the Fig. 1 point (its ``u`` is static here), checks that
it gives ``baseline_jmse``'s value, and times both and the default in alternation (warm,
jitted, closed by ``block_until_ready``; 7 rounds, 5 calls per round for the default and
B = 512, one for the larger grids; medians). The pupil's own transform, which the lean
program keeps, dominates: a pruned first transform (the pupil fills a quarter of the padded
grid) could save at most about a quarter of it, which is not built here.

Usage (from the repository root; about 3 min on 2 cores)::

    .venv/bin/python benchmarks/lean_baseline.py [--sizes 512 1024 2048] [--rounds 7]

Writes ``benchmarks/results/lean_baseline.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import math
import statistics

import jax

jax.config.update("jax_enable_x64", True)

import _common as common  # noqa: E402
import accuracy_speed  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax._otf import pupil_psf  # noqa: E402


def lean_baseline(B: int, u: float):
    """``baseline_jmse`` at grid size ``B`` for a fixed band ``u < 1``, in a leaner form."""
    if not 0 < u < 1:
        raise ValueError(f"u = {u}: the lean form needs 0 < u < 1")
    # Per axis the band's lags are k = 0, +-1, ..., +-(K - 1): those with k / B < u, compared
    # in floating point exactly as baseline_jmse compares them.
    K = int(np.sum(np.arange(B + 1) / B < u))

    def fn(aberrations, field, u_traced, signal, noise):
        psf = pupil_psf(aberrations, field, B)
        lag = jnp.fft.rfft2(psf)  # (2B, B + 1): k_x = 0 .. B, conjugate of ifft2's lags
        lag = lag / jnp.real(lag[0, 0])
        rows = jnp.concatenate([lag[:K, :K], lag[2 * B - (K - 1):, :K]], axis=0)
        k_y = jnp.concatenate([jnp.arange(K), jnp.arange(-(K - 1), 0)]).astype(psf.dtype)
        k_x = jnp.arange(K).astype(psf.dtype)
        nu_x, nu_y = jnp.meshgrid(k_x / B, k_y / B, indexing="xy")
        s_e = jj.error_spectral_density(rows, signal(nu_x, nu_y), noise(nu_x, nu_y))
        mirror = jnp.where(k_x == 0, 1.0, 2.0)  # k_x > 0 stands for -k_x as well
        return jnp.sum(s_e * mirror[None, :]) / (B * B) / (2.0 * math.pi)

    return fn


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args(argv)
    machine = common.machine_info()
    cases = common.load_bank(reference_fallback="strict")
    fig1 = next(c for c in cases if c.name == "fig1")
    call_args = fig1.arguments
    u = float(call_args[2])

    methods = {"default": jj.jmse}
    for B in args.sizes:
        methods[f"baseline_jmse B={B}"] = accuracy_speed._baseline(B)
        methods[f"lean B={B}"] = lean_baseline(B, u)
    compiled, values = {}, {}
    for name, fn in methods.items():
        value_fn, vag_fn = jax.jit(fn), jax.jit(jax.value_and_grad(fn))
        values[name] = float(value_fn(*call_args))
        jax.block_until_ready(vag_fn(*call_args))
        compiled[name] = (value_fn, vag_fn)
        print(f"{name:22s} {values[name]:.15e}", flush=True)
    times = accuracy_speed._alternate(
        compiled, call_args, args.rounds,
        {name: 5 if name == "default" or name.endswith("=512") else 1 for name in compiled})
    med = {name: tuple(statistics.median(t) for t in pair) for name, pair in times.items()}
    d_value, d_vag = med["default"]
    rows = []
    for name in compiled:
        twin = name.replace("lean", "baseline_jmse")
        agreement = (abs(values[name] - values[twin]) / abs(values[twin])
                     if name.startswith("lean") else None)
        rows.append(dict(name=name, value=values[name], value_s=med[name][0],
                         value_and_grad_s=med[name][1], over_default=med[name][0] / d_value,
                         vag_over_default=med[name][1] / d_vag,
                         relative_difference_from_baseline_jmse=agreement))
    report = dict(description=__doc__.splitlines()[0], machine=machine, case="fig1",
                  rounds=args.rounds, rows=rows)
    lines = ["# The square-grid baseline, as written and leaner", "",
             common.machine_line(machine, common.load_average()), "",
             f"The Fig. 1 point (u = {u}); medians of {args.rounds} alternated rounds (5 calls "
             "per round for the default and B = 512, one for larger grids). `lean`: real FFT "
             "of the PSF, `S_e` on the band's lags only (`benchmarks/lean_baseline.py`).", "",
             "| method | value | relative difference from `baseline_jmse` | value time | "
             "/ default | value_and_grad | / default |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        diff = r["relative_difference_from_baseline_jmse"]
        lines.append(f"| {r['name']} | {r['value']:.12e} | "
                     f"{'–' if diff is None else f'{diff:.1e}'} | "
                     f"{common.fmt_seconds(r['value_s'])} | {r['over_default']:.1f}× | "
                     f"{common.fmt_seconds(r['value_and_grad_s'])} | "
                     f"{r['vag_over_default']:.1f}× |")
    common.write_report("lean_baseline", report, lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

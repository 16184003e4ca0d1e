"""What the closed-form peaks (``peaks=True``) cost under ``vmap`` and in a loop of single calls.

The peaks' branch (``jmse_jax._ridges``) runs only where a design's ``S_e`` has narrow minima
along the fine grid's rays. Alone, a design without them skips it (``lax.cond``); under
``vmap`` the branch is skipped for a whole batch when no design in it needs it
(``jmse_jax._numerics.batch_skipping_cond``), and runs vectorised over the batch otherwise.
On the backends of ``_numerics.SEQUENTIAL_BRANCH_BACKENDS`` (CPU) that branch runs member by
member (``lax.map`` of the plain cond, so only the designs that need it run it); elsewhere
vectorised over the batch. This script measures both forms (the module constant is set and
JAX's caches cleared before each), per design, against the same preset with ``peaks=False``.

Problem: ``--designs`` random designs (generator seed ``--seed``), the five Seidel
coefficients w020, w040, w131, w222, w220 uniform in ``[-scale, scale]`` waves, field uniform
in [0, 1], ``u = 0.3``, ``MarkovSignal(1, 5)``, ``WhiteNoise(noise)``, float64. Each
scenario is timed for ``jit(vmap(jmse))`` and ``jit(vmap(value_and_grad(jmse)))`` (with
respect to the coefficients and the field), and for a Python loop of the jitted single
design call (value_and_grad), all warm, closed by ``block_until_ready``; one process runs the
two settings of ``peaks`` one after the other, so that their ratio is measured in the same run.

The default scenarios: ``small`` (scale 0.7 waves, noise 1e-3: no design has narrow minima,
so the batched branch is skipped) and ``large`` (scale 3 waves, noise 1e-4: about half of
the designs have them, and every batch runs the branch).

Usage (from the repository root; about 6 min on 2 cores, most of it compilation)::

    .venv/bin/python benchmarks/vmap_peaks.py [--preset fast] [--scenario small|large|both]
        [--designs 32] [--seed 7]

Writes ``benchmarks/results/vmap_peaks.json`` and ``.md`` (``--tag`` adds a suffix).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _common  # noqa: E402  (turns on float64)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _numerics  # noqa: E402

#: (label, peaks, backends that run the peaks' branch member by member under vmap)
SETTINGS = (("off", False, ()), ("loop", True, (jax.default_backend(),)),
            ("vectorised", True, ()))
SCENARIOS = {"small": dict(scale=0.7, noise=1e-3), "large": dict(scale=3.0, noise=1e-4)}
COEFFICIENTS = ("w020", "w040", "w131", "w222", "w220")
U = 0.3


def designs(n, scale, seed):
    """``n`` random designs: coefficients uniform in ``[-scale, scale]``, field in [0, 1]."""
    rng = np.random.default_rng(seed)
    coefs = rng.uniform(-scale, scale, size=(n, len(COEFFICIENTS)))
    field = rng.uniform(0.0, 1.0, size=n)
    return jnp.asarray(coefs), jnp.asarray(field)


def merit_fn(preset, peaks, noise):
    signal = jj.MarkovSignal(1.0, 5.0)
    white = jj.WhiteNoise(noise)

    def merit(coefs, field):
        ab = jj.Seidel(**dict(zip(COEFFICIENTS, coefs, strict=True)))
        return jj.jmse(ab, field, U, signal, white, preset=preset, peaks=peaks)

    return merit


def time_loop(single, coefs, field, repeats):
    """Median over ``repeats`` of the time of a loop of single calls, per design."""
    jax.block_until_ready(single(coefs[0], field[0]))
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        for i in range(coefs.shape[0]):
            jax.block_until_ready(single(coefs[i], field[i]))
        times.append((time.perf_counter() - start) / coefs.shape[0])
    return statistics.median(times)


def run_scenario(name, scale, noise, args):
    coefs, field = designs(args.designs, scale, args.seed)
    rows = []
    values = {}
    for label, peaks, backends in SETTINGS:
        _numerics.SEQUENTIAL_BRANCH_BACKENDS = backends
        jax.clear_caches()  # the inner jits' traces hold the batching rule's choice
        merit = merit_fn(args.preset, peaks, noise)
        vag = jax.value_and_grad(merit, argnums=(0, 1))
        row = dict(scenario=name, scale=scale, noise=noise, peaks=peaks, branch=label)
        batched_value = _common.time_compiled(jax.vmap(merit), (coefs, field),
                                              budget_s=args.budget)
        batched_vag = _common.time_compiled(jax.vmap(vag), (coefs, field),
                                            budget_s=args.budget)
        single = jax.jit(vag)
        row.update(
            vmap_value_ms=1e3 * batched_value["warm_s"] / args.designs,
            vmap_vag_ms=1e3 * batched_vag["warm_s"] / args.designs,
            loop_vag_ms=1e3 * time_loop(single, coefs, field, args.loop_repeats),
            compile_vmap_value_s=batched_value["compile_s"],
            compile_vmap_vag_s=batched_vag["compile_s"],
        )
        values[label] = np.asarray(batched_value["value"])
        rows.append(row)
        print(f"{name:6s} {label:10s} vmap value {row['vmap_value_ms']:7.2f} ms  "
              f"vmap vag {row['vmap_vag_ms']:7.2f} ms  loop vag {row['loop_vag_ms']:7.2f} ms "
              f"(per design)", flush=True)
    # How much the peaks move the values: which designs took the branch.
    change = np.abs(values["loop"] - values["off"]) / np.abs(values["off"])
    spread = np.abs(values["loop"] - values["vectorised"]) / np.abs(values["off"])
    for row in rows:
        row["designs_changed_by_peaks"] = int(np.sum(change > 1e-12))
        row["largest_relative_change"] = float(np.max(change))
        row["loop_vs_vectorised_largest_relative_difference"] = float(np.max(spread))
    return rows


def write(rows, info, args):
    _common.RESULTS.mkdir(parents=True, exist_ok=True)
    stem = "vmap_peaks" + (f"_{args.tag}" if args.tag else "")
    payload = dict(machine=info, preset=args.preset, designs=args.designs, seed=args.seed,
                   u=U, coefficients=COEFFICIENTS, rows=rows)
    (_common.RESULTS / f"{stem}.json").write_text(json.dumps(payload, indent=2) + "\n")
    lines = [
        f"# Closed-form peaks under vmap (`{args.preset}` preset, {args.designs} designs, "
        f"seed {args.seed}, u = {U})",
        "",
        f"Commit {info.get('commit')}, {info.get('cpu_model')}, cores in use: {info.get('nproc')}, "
        f"jax {info.get('jax_version')}, {info.get('dtype')}. Times per design, warm, ms. "
        "`changed` counts the designs whose value the peaks moved by more than 1e-12 "
        "relative (those that took the branch); `branch`: how the peaks' branch runs under vmap "
        "(`loop`: member by member, the CPU's default; `vectorised`: over the whole batch; "
        "`off`: peaks=False).",
        "",
        "| scenario | scale (waves) | noise | branch | vmap value | vmap value_and_grad | "
        "loop of single value_and_grad | changed | compile vmap vag (s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['scenario']} | {r['scale']} | {r['noise']:g} | {r['branch']} | "
            f"{r['vmap_value_ms']:.2f} | {r['vmap_vag_ms']:.2f} | {r['loop_vag_ms']:.2f} | "
            f"{r['designs_changed_by_peaks']}/{args.designs} | {r['compile_vmap_vag_s']:.1f} |")
    lines += ["", "Largest relative difference between the values of `loop` and `vectorised`: "
              + ", ".join(f"{r['scenario']} "
                          f"{r['loop_vs_vectorised_largest_relative_difference']:.1e}"
                          for r in rows if r["branch"] == "loop") + "."]
    (_common.RESULTS / f"{stem}.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {_common.RESULTS / stem}.json and .md")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", default="fast")
    parser.add_argument("--scenario", default="both", choices=("small", "large", "both"))
    parser.add_argument("--designs", type=int, default=32)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--budget", type=float, default=3.0,
                        help="seconds of warm repeats per timing (default 3)")
    parser.add_argument("--loop-repeats", type=int, default=3)
    parser.add_argument("--tag", default="")
    args = parser.parse_args(argv)
    if args.designs < 1:
        parser.error(f"--designs must be at least 1, got {args.designs}")
    info = _common.machine_info()
    names = ("small", "large") if args.scenario == "both" else (args.scenario,)
    rows = []
    for name in names:
        rows += run_scenario(name, **SCENARIOS[name], args=args)
    write(rows, info, args)


if __name__ == "__main__":
    main()

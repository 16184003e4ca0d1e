"""What a ``vmap`` batch of designs costs per design, against a loop of single calls.

On the backends of ``jmse_jax._merit.SEQUENTIAL_VMAP_BACKENDS`` (CPU) ``vmap`` of ``jmse``,
and of its first derivatives, runs the batch's designs one at a time (``lax.map`` of the
single-design program; form ``sequential``); elsewhere it is vectorised over the batch,
where the default's tiers run for a block of the batch only when one of its designs selects
them (``_merit._dispatch``) and the closed-form peaks (``peaks=True``, ``jmse_jax._ridges``)
only when one of its designs has a narrow minimum (``_numerics.batch_skipping_cond``, whose
branch again runs design by design on the backends of ``SEQUENTIAL_BRANCH_BACKENDS``).
This script measures each form on the machine it runs on (the module constants are set
and JAX's caches cleared before each), per design, warm, jitted, closed by
``block_until_ready``, with a loop of the jitted single-design call as the yardstick, and
checks that every form gives the loop's values.

Problem: ``--designs`` random designs (generator seed ``--seed``), the five Seidel
coefficients w020, w040, w131, w222, w220 uniform in ``[-scale, scale]`` waves, field uniform
in [0, 1], ``u = 0.3``, ``MarkovSignal(1, 5)``, ``WhiteNoise(noise)``, float64;
``value_and_grad`` with respect to the coefficients and the field. Scenarios: ``small``
(scale 0.7 waves, noise 1e-3: no design has narrow minima) and ``large`` (scale 3 waves,
noise 1e-4: about half of them do, and the default's designs spread over its tiers).

Forms (``vmap`` column): ``sequential`` (the CPU's default); ``vectorised`` (the other
backends' default), with the peaks' branch either ``loop`` (design by design, the CPU's
default) or ``vectorised``; ``loop`` rows are the Python loop of single calls.

Usage (from the repository root; about 10 min on one core)::

    taskset -c 1 .venv/bin/python benchmarks/vmap_batches.py [--presets fast,default]
        [--scenario small|large|both] [--designs 32] [--seed 7] [--no-peaks]

Writes ``benchmarks/results/vmap_batches.json`` and ``.md`` (``--tag`` adds a suffix).
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
from jmse_jax import _merit, _numerics  # noqa: E402

SCENARIOS = {"small": dict(scale=0.7, noise=1e-3), "large": dict(scale=3.0, noise=1e-4)}
COEFFICIENTS = ("w020", "w040", "w131", "w222", "w220")
U = 0.3
BACKEND = jax.default_backend()


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


def configure(sequential_vmap, sequential_branch):
    """Set the two module constants (read when ``jmse`` is traced) and drop every cached
    trace, whose batching holds the previous choice."""
    _merit.SEQUENTIAL_VMAP_BACKENDS = (BACKEND,) if sequential_vmap else ()
    _numerics.SEQUENTIAL_BRANCH_BACKENDS = (BACKEND,) if sequential_branch else ()
    jax.clear_caches()


def time_loop(fn, coefs, field, repeats):
    """Median over ``repeats`` of the time of a Python loop of single jitted calls, per
    design, and the values (compile excluded: one untimed call first)."""
    single = jax.jit(fn)
    start = time.perf_counter()
    jax.block_until_ready(single(coefs[0], field[0]))
    compile_s = time.perf_counter() - start
    times, out = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        out = [jax.block_until_ready(single(coefs[i], field[i])) for i in range(coefs.shape[0])]
        times.append((time.perf_counter() - start) / coefs.shape[0])
    return statistics.median(times), compile_s, out


def first_value(out):
    return np.asarray(out[0] if isinstance(out, tuple) else out)


def forms(peaks):
    """(vmap form, peaks' branch form, sequential vmap, sequential branch)."""
    yield "sequential", "-", True, True
    if not peaks:
        yield "vectorised", "-", False, True
    else:
        yield "vectorised", "loop", False, True
        yield "vectorised", "vectorised", False, False


def run(preset, peaks, name, scale, noise, args):
    coefs, field = designs(args.designs, scale, args.seed)
    merit = merit_fn(preset, peaks, noise)
    vag = jax.value_and_grad(merit, argnums=(0, 1))
    base = dict(preset=preset, peaks=peaks, scenario=name, scale=scale, noise=noise)
    configure(True, True)
    loop_value, compile_value, values = time_loop(merit, coefs, field, args.loop_repeats)
    loop_vag, compile_vag, values_vag = time_loop(vag, coefs, field, args.loop_repeats)
    # Each program against its own loop (the value of value_and_grad's program may differ
    # from the value program's by rounding).
    reference = np.array([float(v) for v in values])
    reference_vag = np.array([float(v[0]) for v in values_vag])
    rows = [dict(base, vmap="loop", branch="-", value_ms=1e3 * loop_value,
                 vag_ms=1e3 * loop_vag, compile_value_s=compile_value,
                 compile_vag_s=compile_vag, largest_difference_from_loop=0.0)]
    print(f"{preset:8s} peaks={peaks!s:5s} {name:6s} loop                   value "
          f"{rows[-1]['value_ms']:8.2f} ms  vag {rows[-1]['vag_ms']:8.2f} ms", flush=True)
    for form, branch, sequential_vmap, sequential_branch in forms(peaks):
        configure(sequential_vmap, sequential_branch)
        value = _common.time_compiled(jax.vmap(merit), (coefs, field), budget_s=args.budget)
        both = _common.time_compiled(jax.vmap(vag), (coefs, field), budget_s=args.budget)
        difference = max(np.max(np.abs(first_value(r["value"]) - ref) / ref)
                         for r, ref in ((value, reference), (both, reference_vag)))
        rows.append(dict(base, vmap=form, branch=branch,
                         value_ms=1e3 * value["warm_s"] / args.designs,
                         vag_ms=1e3 * both["warm_s"] / args.designs,
                         compile_value_s=value["compile_s"], compile_vag_s=both["compile_s"],
                         largest_difference_from_loop=float(difference)))
        print(f"{preset:8s} peaks={peaks!s:5s} {name:6s} {form:10s} {branch:10s}  value "
              f"{rows[-1]['value_ms']:8.2f} ms  vag {rows[-1]['vag_ms']:8.2f} ms  "
              f"(values vs loop {difference:.1e})", flush=True)
    configure(True, True)
    return rows


def write(rows, info, args):
    _common.RESULTS.mkdir(parents=True, exist_ok=True)
    stem = "vmap_batches" + (f"_{args.tag}" if args.tag else "")
    payload = dict(machine=info, designs=args.designs, seed=args.seed, u=U,
                   coefficients=COEFFICIENTS, scenarios=SCENARIOS, rows=rows)
    (_common.RESULTS / f"{stem}.json").write_text(json.dumps(payload, indent=2) + "\n")
    lines = [
        f"# vmap batches against a loop of single calls ({args.designs} designs, seed "
        f"{args.seed}, u = {U})",
        "",
        f"Commit {info.get('commit')} (dirty: {info.get('dirty')}), {info.get('cpu_model')}, "
        f"cores in use: {info.get('nproc')}, backend {info.get('backend')}, jax "
        f"{info.get('jax_version')}, {info.get('dtype')}. Times per design, warm, ms; "
        "compile of the vmapped value_and_grad (of one single call for `loop`). `vmap`: "
        "`sequential` runs the designs one at a time (the CPU's default), `vectorised` over "
        "the batch; `branch`: the same for the closed-form peaks' branch under a vectorised "
        "vmap. Scenarios: "
        + ", ".join(f"`{k}` coefficients within +-{v['scale']} waves, noise {v['noise']:g}"
                    for k, v in SCENARIOS.items()) + ".",
        "",
        "| preset | peaks | scenario | vmap | branch | value | value_and_grad | "
        "compile vag (s) | values vs loop |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['preset']} | {r['peaks']} | {r['scenario']} | {r['vmap']} | {r['branch']} | "
            f"{r['value_ms']:.2f} | {r['vag_ms']:.2f} | {r['compile_vag_s']:.1f} | "
            f"{r['largest_difference_from_loop']:.0e} |")
    (_common.RESULTS / f"{stem}.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {_common.RESULTS / stem}.json and .md")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--presets", default="fast,default")
    parser.add_argument("--scenario", default="both", choices=("small", "large", "both"))
    parser.add_argument("--designs", type=int, default=32)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--no-peaks", action="store_true",
                        help="skip the fast preset's runs with peaks=True")
    parser.add_argument("--budget", type=float, default=3.0,
                        help="seconds of warm repeats per timing (default 3)")
    parser.add_argument("--loop-repeats", type=int, default=3)
    parser.add_argument("--tag", default="")
    args = parser.parse_args(argv)
    if args.designs < 1:
        parser.error(f"--designs must be at least 1, got {args.designs}")
    presets = [p for p in args.presets.split(",") if p]
    for preset in presets:
        if preset not in jj.PRESETS:
            parser.error(f"unknown preset {preset!r}; presets are {', '.join(jj.PRESETS)}")
    info = _common.machine_info()
    names = ("small", "large") if args.scenario == "both" else (args.scenario,)
    rows = []
    for preset in presets:
        for peaks in (False, True) if preset == "fast" and not args.no_peaks else (False,):
            for name in names:
                rows += run(preset, peaks, name, **SCENARIOS[name], args=args)
    info["load_at_end"] = _common.load_average()
    write(rows, info, args)


if __name__ == "__main__":
    main()

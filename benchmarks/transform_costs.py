"""What each way of calling the default merit costs: first call and warm call, with and
without ``jit``, value, reverse mode and forward mode, at the paper's Fig. 1 point.

Every mode runs in a fresh Python process (compiled programs persist within a process, and
the persistent compilation cache is off), so "first call" includes tracing and compiling:

- ``eager value``: ``jj.jmse(ab, ...)`` on concrete inputs, no ``jit``;
- ``eager grad``: ``jax.grad(jj.jmse)(ab, ...)``, no ``jit``;
- ``eager hessian u``: ``jax.hessian`` in ``u`` (one variable), no ``jit``;
- ``eager grad, whole program`` and ``eager hessian u, whole program``: the same with the
  tiers' whole program differentiated, as before session 91 (derivatives taken without
  ``jit`` now differentiate the grid the design takes alone, ``_merit._eager_derivative``;
  here it is switched off);
- ``eager grad, on the axis`` (and ``, whole program``): ``jax.grad`` at the Fig. 1
  design moved to the axis (field 0), where it is rotationally symmetric: its one-ray
  plan alone is differentiated since session 92;
- ``eager otf``: ``jj.otf`` at one frequency, no ``jit``;
- ``jit value``, ``jit value_and_grad``, ``jit jvp`` (one tangent in every coefficient),
  ``jit hessian u`` (``jax.hessian`` in ``u``, forward over reverse through every tier):
  the first call is split into tracing (``lower``) and XLA compilation (``compile``).

Warm times are the fastest of 11 calls after the first. Usage (from the repository root;
~14 min on 2 cores, 9 of them the whole program's Hessian, eager and jitted)::

    .venv/bin/python benchmarks/transform_costs.py [--tag NAME] [--modes MODE ...]

Writes ``benchmarks/results/transform_costs[_NAME].json`` and ``.md``. To time an older
commit, run it with ``PYTHONPATH`` set to a worktree of that commit and ``JMSE_COMMIT``
naming it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import _common as common
import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

import jmse_jax as jj  # noqa: E402

MODES = ("eager value", "eager grad", "eager grad, whole program", "eager hessian u",
         "eager hessian u, whole program", "eager grad, on the axis",
         "eager grad, on the axis, whole program", "eager otf", "jit value",
         "jit value_and_grad", "jit jvp", "jit hessian u")
WARM_CALLS = 11


def _warm(fn, *args):
    best = float("inf")
    for _ in range(WARM_CALLS):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - start)
    return best


def _measure(mode: str) -> dict:
    ab = jj.Seidel(**common.FIG1)
    signal, noise = common.fig1_signal(), common.fig1_noise()
    field = common.FIG1_FIELD
    if mode.startswith("eager"):
        if mode.endswith(", whole program"):
            from jmse_jax import _merit

            _merit._eager_derivative = lambda *args: None
            mode = mode.removesuffix(", whole program")
        if mode.endswith(", on the axis"):
            field = 0.0
            mode = mode.removesuffix(", on the axis")

    def merit(a):
        return jj.jmse(a, field, common.FIG1_U, signal, noise)

    if mode.startswith("eager"):

        def in_u(u):
            return jj.jmse(ab, common.FIG1_FIELD, u, signal, noise)

        fn, arg = {"eager value": (merit, ab), "eager grad": (jax.grad(merit), ab),
                   "eager hessian u": (jax.hessian(in_u), jnp.asarray(common.FIG1_U)),
                   "eager otf": (lambda a: jj.otf(a, 0.1, 0.05, common.FIG1_FIELD), ab)}[mode]
        start = time.perf_counter()
        jax.block_until_ready(fn(arg))
        return dict(first_s=time.perf_counter() - start, warm_s=_warm(fn, arg))
    args = (ab,)
    if mode == "jit value":
        fn = jax.jit(merit)
    elif mode == "jit value_and_grad":
        fn = jax.jit(jax.value_and_grad(merit))
    elif mode == "jit hessian u":
        fn = jax.jit(jax.hessian(lambda u: jj.jmse(ab, common.FIG1_FIELD, u, signal, noise)))
        args = (jnp.asarray(common.FIG1_U),)
    else:
        fn = jax.jit(lambda a, t: jax.jvp(merit, (a,), (t,)))
        args = (ab, jax.tree_util.tree_map(jnp.ones_like, ab))
    start = time.perf_counter()
    lowered = fn.lower(*args)
    traced = time.perf_counter()
    compiled = lowered.compile()
    done = time.perf_counter()
    jax.block_until_ready(compiled(*args))
    return dict(trace_s=traced - start, compile_s=done - traced,
                first_s=done - start, warm_s=_warm(compiled, *args))


def main() -> None:
    if len(sys.argv) == 3 and sys.argv[1] == "--child":
        print(json.dumps(_measure(sys.argv[2])))
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tag", default="", help="suffix of the output file names")
    parser.add_argument("--modes", nargs="+", choices=MODES, default=MODES, metavar="MODE",
                        help="the modes to time (default: all)")
    args = parser.parse_args()
    tag = args.tag
    name = "transform_costs" + (f"_{tag}" if tag else "")
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    report = dict(description=__doc__.split("\n\n")[0], machine=common.machine_info(),
                  warm_calls=WARM_CALLS, modes={})
    for mode in args.modes:
        out = subprocess.run([sys.executable, __file__, "--child", mode], env=env,
                             capture_output=True, text=True, check=True).stdout
        report["modes"][mode] = json.loads(out.strip().splitlines()[-1])
        print(mode, report["modes"][mode], flush=True)
    common.write_json(common.RESULTS / f"{name}.json", report)

    def fmt(row, key, scale=1.0, unit="s"):
        return f"{row[key] * scale:.2f} {unit}" if key in row else "–"

    machine = report["machine"]
    lines = [
        "# What each way of calling the default costs (Fig. 1 point)", "",
        f"- machine: {machine['cpu_model']} ({machine['cpu_count']} CPUs), "
        f"jax {machine['jax_version']}, {machine['dtype']}, commit {machine.get('commit')}",
        f"- load at start: {machine['load_at_start']['uptime']}",
        "- one fresh process per mode, no persistent compilation cache; warm = fastest of "
        f"{WARM_CALLS} calls after the first", "",
        "| mode | first call | of it: trace | of it: compile | warm call |",
        "|---|---|---|---|---|",
    ]
    for mode, row in report["modes"].items():
        lines.append(f"| {mode} | {fmt(row, 'first_s')} | {fmt(row, 'trace_s')} | "
                     f"{fmt(row, 'compile_s')} | {fmt(row, 'warm_s', 1e3, 'ms')} |")
    (common.RESULTS / f"{name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()

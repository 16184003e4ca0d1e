"""The library on an accelerator computes what it computes on the CPU (float64).

Run from the repository root on a machine with a GPU (or TPU)::

    python benchmarks/device_check.py

For every case of the tests' problem bank and for the ``fast``, ``default`` and ``high``
presets and the square-grid baseline at B = 64, the value and the gradient with respect to
the Seidel coefficients are computed twice in the same process: on JAX's default device (the
accelerator) and on the host CPU (``jax.default_device(jax.devices("cpu")[0])``), whose
float64 path the test suite checks against analytic and brute-force oracles. It reports the
largest relative difference of the values and of the gradients (relative to the larger of
the gradient's largest component and the value, so that a gradient that vanishes by symmetry
is not compared with its own rounding noise), the accelerator's worst error against the
bank's references, and whether every output is finite. On a CPU-only machine both sides
are the CPU and the differences are zero.

Writes ``benchmarks/results/device_check{_TAG}.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import sys
import time

import _common as common
import jax
import numpy as np

import jmse_jax as jj

METHODS = {
    "preset fast": dict(preset="fast"),
    "preset default": dict(preset="default"),
    "preset high": dict(preset="high"),
    "baseline B=64": None,
}


def _function(settings):
    if settings is None:
        def fn(aberrations, field, u, signal, noise):
            return jj.baseline_jmse(aberrations, field, u, signal, noise, B=64)
    else:
        def fn(aberrations, field, u, signal, noise):
            return jj.jmse(aberrations, field, u, signal, noise, **settings)
    return jax.jit(jax.value_and_grad(fn, argnums=0))


def _evaluate(vag, arguments, device):
    with jax.default_device(device):
        placed = jax.device_put(arguments, device)
        value, grad = vag(*placed)
        value = float(value)
        grad = np.asarray(jax.tree_util.tree_leaves(grad), dtype=np.float64)
    return value, grad


def run(tag: str = "") -> dict:
    start = time.perf_counter()
    machine = common.machine_info()
    accelerator = jax.devices()[0]
    cpu = jax.devices("cpu")[0]
    cases = common.load_bank()
    rows = []
    for name, settings in METHODS.items():
        vag = _function(settings)
        per_case = {}
        for case in cases:
            value_a, grad_a = _evaluate(vag, case.arguments, accelerator)
            value_c, grad_c = _evaluate(vag, case.arguments, cpu)
            # A gradient that vanishes by symmetry (zero aberration) is compared on the
            # value's scale: d JMSE / d w is of the order of JMSE per wave.
            scale = max(float(np.max(np.abs(grad_c))), abs(value_c), 1e-300)
            per_case[case.name] = dict(
                value_rel_diff=abs(value_a / value_c - 1.0),
                grad_rel_diff=float(np.max(np.abs(grad_a - grad_c))) / scale,
                grad_scale=scale,
                finite=bool(np.isfinite(value_a) and np.all(np.isfinite(grad_a))),
                error=(common.relative_error(value_a, case.reference)
                       if case.converged else None))
        worst_value = max(per_case, key=lambda k: per_case[k]["value_rel_diff"])
        worst_grad = max(per_case, key=lambda k: per_case[k]["grad_rel_diff"])
        errors = [r["error"] for r in per_case.values() if r["error"] is not None]
        row = dict(method=name, cases=len(cases),
                   max_value_rel_diff=per_case[worst_value]["value_rel_diff"],
                   max_value_rel_diff_case=worst_value,
                   max_grad_rel_diff=per_case[worst_grad]["grad_rel_diff"],
                   max_grad_rel_diff_case=worst_grad,
                   accelerator_worst_error=max(errors, default=0.0),
                   all_finite=all(r["finite"] for r in per_case.values()),
                   per_case=per_case)
        rows.append(row)
        print(f"{name:16s} value diff {row['max_value_rel_diff']:.1e} ({worst_value})  "
              f"grad diff {row['max_grad_rel_diff']:.1e} ({worst_grad})  worst error on "
              f"{accelerator.platform} {row['accelerator_worst_error']:.1e}  "
              f"finite {row['all_finite']}", flush=True)
    report = dict(description=__doc__.splitlines()[0], machine=machine,
                  accelerator=str(accelerator), device_kind=accelerator.device_kind,
                  rows=rows, seconds=time.perf_counter() - start)
    stem = common.RESULTS / ("device_check" + (f"_{tag}" if tag else ""))
    common.write_json(stem.with_suffix(".json"), report)
    stem.with_suffix(".md").write_text(markdown(report))
    print(markdown(report))
    return report


def markdown(report) -> str:
    m = report["machine"]
    lines = [
        "# The library on an accelerator against the CPU (float64)", "",
        f"{report['device_kind']} ({report['accelerator']}) against the host CPU "
        f"({m['cpu_model']}), jax {m['jax_version']}, commit `{(m['commit'] or '?')[:10]}`, "
        f"{m['date']}. Every case of the tests' bank; value and gradient with respect to "
        "the Seidel coefficients; the gradient's difference is relative to the larger of its "
        "largest component and the value.", "",
        "| method | cases | max value rel. diff (case) | max gradient rel. diff (case) "
        "| worst error vs reference (accelerator) | all finite |",
        "|---|---|---|---|---|---|",
    ]
    for r in report["rows"]:
        lines.append(f"| {r['method']} | {r['cases']} | {r['max_value_rel_diff']:.1e} "
                     f"({r['max_value_rel_diff_case']}) | {r['max_grad_rel_diff']:.1e} "
                     f"({r['max_grad_rel_diff_case']}) | {r['accelerator_worst_error']:.1e} "
                     f"| {r['all_finite']} |")
    lines += ["", f"{report['seconds']:.0f} s.", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tag", default="", help="suffix of the output file names")
    args = parser.parse_args(argv)
    run(tag=args.tag)
    return 0


if __name__ == "__main__":
    sys.exit(main())

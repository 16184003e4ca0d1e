"""The library on an accelerator computes what it computes on the CPU (float64).

Run from the repository root on a machine with a GPU (or TPU)::

    python benchmarks/device_check.py

For every case of the tests' problem bank and for the ``fast``, ``default`` and ``high``
presets and the square-grid baseline at B = 64, the value and the gradient with respect to
the Seidel coefficients are computed twice in the same process: on JAX's default device (the
accelerator) and on the host CPU (``jax.default_device(jax.devices("cpu")[0])``), whose
float64 path the test suite checks against analytic and brute-force oracles. It reports the
largest relative difference of the values and of the gradients (relative to the gradient's
largest component), the accelerator's worst error against the bank's references, and
whether every output is finite. On a CPU-only machine both sides are the CPU and the
differences are zero.

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
        value_diff = grad_diff = 0.0
        worst_error = 0.0
        finite = True
        for case in cases:
            value_a, grad_a = _evaluate(vag, case.arguments, accelerator)
            value_c, grad_c = _evaluate(vag, case.arguments, cpu)
            finite &= bool(np.isfinite(value_a) and np.all(np.isfinite(grad_a)))
            value_diff = max(value_diff, abs(value_a / value_c - 1.0))
            scale = max(float(np.max(np.abs(grad_c))), 1e-300)
            grad_diff = max(grad_diff, float(np.max(np.abs(grad_a - grad_c))) / scale)
            if case.converged:
                worst_error = max(worst_error, common.relative_error(value_a, case.reference))
        row = dict(method=name, cases=len(cases), max_value_rel_diff=value_diff,
                   max_grad_rel_diff=grad_diff, accelerator_worst_error=worst_error,
                   all_finite=finite)
        rows.append(row)
        print(f"{name:16s} value diff {value_diff:.1e}  grad diff {grad_diff:.1e}  "
              f"worst error on {accelerator.platform} {worst_error:.1e}  finite {finite}",
              flush=True)
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
        "the Seidel coefficients; the gradient's difference is relative to its largest "
        "component.", "",
        "| method | cases | max value rel. diff | max gradient rel. diff "
        "| worst error vs reference (accelerator) | all finite |",
        "|---|---|---|---|---|---|",
    ]
    for r in report["rows"]:
        lines.append(f"| {r['method']} | {r['cases']} | {r['max_value_rel_diff']:.1e} "
                     f"| {r['max_grad_rel_diff']:.1e} | {r['accelerator_worst_error']:.1e} "
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

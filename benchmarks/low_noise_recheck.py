"""Re-evaluate one preset on the stored designs and references of ``low_noise.py``.

``low_noise.py`` takes about 14 minutes, most of it its references (a 1-D adaptive integral
on the axis, a polar grid with 22 400 fine radial nodes off it, and that grid's gradients).
After a change to one preset's grid, this script evaluates the preset again, value and
gradient (in ``w020``, ``w040``, ``w131``, ``w222``, ``w220`` and the field), on the rows
stored in ``results/low_noise.json`` and sets the new errors beside the stored ones (the
preset as it was when that file was written; its commit is in the file's ``machine``).

    .venv/bin/python benchmarks/low_noise_recheck.py [--preset fast]     # ~1 min on 2 cores

Writes ``results/low_noise_recheck_<preset>.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import json
import warnings

import _common as common  # turns on float64
import jax
import numpy as np

import jmse_jax as jj

TERMS = ("w020", "w040", "w131", "w222", "w220")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="fast", choices=tuple(jj.PRESETS))
    args = parser.parse_args(argv)
    stored = json.loads((common.RESULTS / "low_noise.json").read_text())
    machine = common.machine_info()
    signal = jj.MarkovSignal(1.0, 5.0)

    def merit(coefficients, field, u, noise):
        return jj.jmse(jj.Seidel(**coefficients), field, u, signal, jj.WhiteNoise(noise),
                       preset=args.preset)

    value = jax.jit(merit)
    gradient = jax.jit(jax.grad(merit, argnums=(0, 1)))

    def coefficients(row):
        return {k: float(row["coefficients"].get(k, 0.0)) for k in TERMS}

    rows, gradient_rows = [], []
    with warnings.catch_warnings():  # past the checked SNR, as the study means to be
        warnings.simplefilter("ignore")
        for r in stored["rows"]:
            v = float(value(coefficients(r), r["field"], r["u"], r["noise"]))
            rows.append(dict(case=r["case"], peak_snr=r["peak_snr"], value=v,
                             error=common.relative_error(v, r["reference"]),
                             stored_error=r["errors"][args.preset]))
        for r in stored["gradient_rows"]:
            g_c, g_h = gradient(coefficients(r), r["field"], r["u"], r["noise"])
            got = np.array([float(g_c[k]) for k in TERMS] + [float(g_h)])
            want = np.asarray(r["reference"])
            old = np.asarray(r["gradients"][args.preset])
            scale = np.max(np.abs(want))
            gradient_rows.append(dict(case=r["case"], peak_snr=r["peak_snr"],
                                      gradient=got.tolist(),
                                      error=float(np.max(np.abs(got - want)) / scale),
                                      stored_error=float(np.max(np.abs(old - want)) / scale)))
    then = stored["machine"].get("commit", "?")[:10]
    lines = [f"# `{args.preset}` again on the designs of `low_noise.py`", "",
             common.machine_line(machine, common.load_average()), "",
             f"Relative errors against the references stored in `results/low_noise.json` "
             f"(written at `{then}`, whose `{args.preset}` errors are the 'stored' columns). "
             "Gradients: the largest component's difference over the largest component of "
             "the reference gradient (w020, w040, w131, w222, w220, field).", "",
             "| design | peak S_x/S_n | value, stored | value, now |", "|---|---|---|---|"]
    lines += [f"| {r['case']} | {r['peak_snr']:.1e} | {r['stored_error']:.1e} | "
              f"{r['error']:.1e} |" for r in rows]
    lines += ["", "| design | peak S_x/S_n | gradient, stored | gradient, now |",
              "|---|---|---|---|"]
    lines += [f"| {r['case']} | {r['peak_snr']:.1e} | {r['stored_error']:.1e} | "
              f"{r['error']:.1e} |" for r in gradient_rows]
    report = dict(machine=machine, preset=args.preset, stored_commit=then, rows=rows,
                  gradient_rows=gradient_rows)
    common.write_report(f"low_noise_recheck_{args.preset}", report, lines)


if __name__ == "__main__":
    main()

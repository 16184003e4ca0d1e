"""How many angular fine S_e nodes ``"high"``'s gradient needs at low noise (``se_angular``).

Off the axis, under a signal spectrum flat to the cutoff, ``S_e`` turns from
``S_n / |H|^2`` to ``S_x`` along curves that the rays cross obliquely; the gradient's
integrand is a ridge along them, narrower as the peak ``S_x / S_n`` grows. Session 85's
climbs (``default_climb.py --preset high --gradient --noise -9.5 -6.5``) found two designs
where ``"high"``'s 960 angular fine nodes leave the gradient far off while the value holds:
one on its balanced grid (9.6e-2 at a peak ratio of 1.3e8) and one on its steep grid (5.8e-3
at 1.9e8). This script takes each, with the noise set to several peak ratios, and measures
the gradient's error (``default_climb.gradient_error``: sensitivities in the coefficients,
the field, ``u`` and the noise) of ``jmse(..., preset="high", se_angular=n)`` for several
``n``, against the grid that design takes in ``"high"`` with ``--reference`` angular fine
nodes (11520 by default; every other count as ``"high"``'s, which session 85 found not to
bind). That calibrated ``SE_ANGULAR_BY_SNR`` (session 86). ``--timing`` instead times
``"high"`` with each count at the paper's Fig. 1 point (value, ``value_and_grad`` in the
coefficients, and in the coefficients, ``u`` and the noise), warm and jitted, and with two
of the counts given as ``grad_se_angular`` (the gradient's alone; session 87).

Usage (from the repository root; about 25 min on 2 cores; the timing about 10 min, run it
on a quiet machine)::

    .venv/bin/python benchmarks/se_angular.py [--reference 11520]
    .venv/bin/python benchmarks/se_angular.py --timing

Writes ``results/se_angular.json`` and ``.md`` (``--timing``: ``se_angular_timing``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import default_climb as dc  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax._merit import _peak_snr, _route  # noqa: E402

#: Session 85's two designs (``results/default_climb_high_powerlaw_lownoise_gradient{,
#: _trial1920}.json``, each climb's worst) and the counts tried at each peak ratio.
DESIGNS = {
    "balanced": dict(
        row=dict(scale=8.0, coefficients=dict(
            w020=5.315262714212769, w040=4.0025627450400965, w131=2.404843876738526,
            w222=-6.2544309932938, w220=-9.576580493797533), field=1.0,
            u=0.9317604354509159, amplitude=0.00018132109196651908,
            exponent=2.7301513998965774, knee=0.06172842059333118,
            noise=2.836751222105705e-09),
        ratios={2e7: (960, 1920, 2880), 6e7: (1920, 2880, 3840),
                1.28e8: (960, 1920, 3840, 5760), 2e8: (960, 1920, 3840, 4800, 5760)}),
    "steep": dict(
        row=dict(scale=8.0, coefficients=dict(
            w020=6.644932297844935, w040=2.724906347815633, w131=3.085795717363572,
            w222=-5.3801335287493135, w220=-7.617778976339013), field=0.9469066664934074,
            u=0.85, amplitude=0.00018291638495696567, exponent=2.946692010240536,
            knee=0.06186467434113549, noise=3.533076788888267e-09),
        ratios={1.89e8: (960, 1920, 3840, 4800)}),
}


def _with_ratio(row, ratio):
    """``row`` with the noise that gives the peak ``S_x / S_n`` ``ratio``."""
    design = dc._design(row)
    snr = float(_peak_snr(*design[2:]))
    return dict(row, noise=row["noise"] * snr / ratio)


def _grid_taken(row):
    route = _route(*dc._design(row), preset="high")
    if route["balanced"]:
        return "balanced", dict(jj.HIGH_BALANCED_GRID)
    if route["steep"]:
        return "steep", dict(jj.HIGH_STEEP_GRID, peaks=True)
    grid = jj.PRESETS["high"]
    return "own", dict(nodes=grid["nodes"], se_nodes=grid["se_nodes"],
                       overlap_nodes=grid["overlap_nodes"],
                       overlap_floor=grid["overlap_floor"], peaks=True)


def calibrate(reference):
    rows = []
    for name, spec in DESIGNS.items():
        for ratio, counts in spec["ratios"].items():
            row = _with_ratio(spec["row"], ratio)
            plan, grid = _grid_taken(row)
            ref_grid = dict(grid, se_nodes=(grid["se_nodes"][0], reference))
            start = time.perf_counter()
            value_ref, s_ref = dc._sensitivities(row, ref_grid)
            for n in counts:
                value, s = dc._sensitivities(row, dict(preset="high", se_angular=n))
                rows.append(dict(design=name, plan=plan, ratio=ratio, se_angular=n,
                                 gradient_error=dc.gradient_error(s, s_ref),
                                 value_error=abs(value / value_ref - 1.0),
                                 table=jj.se_angular_for(*dc._design(row)[2:])))
                print(f"{name} ({plan}) ratio {ratio:.3g} se_angular {n}: gradient "
                      f"{rows[-1]['gradient_error']:.2e} value {rows[-1]['value_error']:.1e} "
                      f"[{time.perf_counter() - start:.0f} s]", flush=True)
    return rows


def timing(counts=(960, 1920, 3840, 5760), gradient_only=(1920, 5760)):
    """Warm jitted times of ``"high"`` with each count at the Fig. 1 point; for the counts
    ``gradient_only`` also with the count given as ``grad_se_angular`` (the gradient's
    alone, the value on ``"high"``'s own 960: what ``jmse`` takes by itself under
    differentiation at low noise, session 87)."""
    c0 = jnp.array([common.FIG1[k] for k in dc.TERMS])

    def merit(c, u, noise, n, option):
        return jj.jmse(jj.Seidel(*c), common.FIG1_FIELD, u, common.fig1_signal(),
                       jj.WhiteNoise(noise), preset="high", **{option: n})

    args = (c0, jnp.asarray(common.FIG1_U), jnp.asarray(1e-3))
    out = []
    runs = [(n, "se_angular") for n in counts] + [(n, "grad_se_angular")
                                                  for n in gradient_only]
    for n, option in runs:
        modes = (
            ("value", lambda c, u, s, n=n, o=option: merit(c, u, s, n, o)),
            ("value_and_grad (coefficients)",
             jax.value_and_grad(lambda c, u, s, n=n, o=option: merit(c, u, s, n, o))),
            ("value_and_grad (coefficients, u, noise)",
             jax.value_and_grad(lambda c, u, s, n=n, o=option: merit(c, u, s, n, o),
                                argnums=(0, 1, 2))))
        for mode, fn in modes[option == "grad_se_angular":]:
            timed = common.time_compiled(fn, args)
            seconds, compile_s = timed["warm_s"], timed["compile_s"]
            out.append(dict(option=option, se_angular=n, mode=mode, seconds=seconds,
                            compile_s=compile_s,
                            scratch_mb=(timed["temp_bytes"] or 0) / 1e6))
            print(f"{option} {n} {mode}: {seconds * 1e3:.1f} ms, compile {compile_s:.1f} s, "
                  f"scratch {out[-1]['scratch_mb']:.0f} MB", flush=True)
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--reference", type=int, default=11520,
                        help="angular fine nodes of the reference grid")
    parser.add_argument("--timing", action="store_true",
                        help="time 'high' with each count instead (results/se_angular_timing)")
    args = parser.parse_args(argv)
    machine = common.machine_info()
    if args.timing:
        times = timing()
        lines = ["# `high`'s cost against its angular fine nodes (`se_angular`)", "",
                 "`python benchmarks/se_angular.py --timing`", "",
                 common.machine_line(machine, common.load_average()), "",
                 "Fig. 1 point, `high`, warm and jitted (`_common.time_compiled`: median), "
                 "float64:", "",
                 "| option | count | call | time | compile | scratch |",
                 "|---|---|---|---|---|---|"]
        for t in times:
            lines.append(f"| {t['option']} | {t['se_angular']} | {t['mode']} | "
                         f"{t['seconds'] * 1e3:.1f} ms | {t['compile_s']:.1f} s | "
                         f"{t['scratch_mb']:.0f} MB |")
        print("\n".join(lines))
        common.write_report("se_angular_timing", dict(machine=machine, timing=times), lines)
        return
    rows = calibrate(args.reference)
    lines = ["# `high`'s gradient at low noise against its angular fine nodes (`se_angular`)",
             "", f"`python benchmarks/se_angular.py --reference {args.reference}`", "",
             common.machine_line(machine, common.load_average()), "",
             f"Reference: the grid the design takes in `high` with {args.reference} angular "
             f"fine nodes. `se_angular_for` is the count `optimise` takes "
             f"(`SE_ANGULAR_BY_SNR` = {jj.SE_ANGULAR_BY_SNR}).", "",
             "| design (plan) | peak S_x/S_n | se_angular | gradient's error | value's error | "
             "se_angular_for |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['design']} ({r['plan']}) | {r['ratio']:.3g} | {r['se_angular']} | "
                     f"{r['gradient_error']:.2e} | {r['value_error']:.1e} | {r['table']} |")
    print("\n".join(lines))
    common.write_report("se_angular", dict(machine=machine, reference=args.reference,
                                           rows=rows), lines)


if __name__ == "__main__":
    main()

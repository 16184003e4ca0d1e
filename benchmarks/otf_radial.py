"""How many radial OTF nodes ``"high"``'s grids need at low noise (``otf_radial``).

Session 87's climbs of ``"high"`` with ``se_angular_for``'s count
(``default_climb.py --preset high --gradient --se-angular --noise -9.5 -6.5``, seeds 3
and 4) found two designs where the count held nothing: their radial OTF nodes bound. Under
a flat signal spectrum at high SNR, ``S_e`` turns from ``S_n / |H|^2`` to ``S_x`` where
``|H|^2 S_x / S_n`` falls through 1; the fine S_e nodes interpolate ``H`` from the OTF
nodes, and an interpolation error ``dH`` moves ``S_e ~ S_n / |H|^2`` by ``2 dH / |H|``,
so the finer the turn (the larger ``S_x / S_n``, the smaller the ``|H|`` it sits at), the
more radial OTF nodes it needs, for the value as well as the gradient. This script takes
those two designs and session 86's two (``se_angular.py``), sets the noise to several peak
ratios, and measures the error of the value and of the gradient
(``default_climb.gradient_error``) of the grid each design takes in ``"high"``, with
``se_angular_for``'s angular count, against the radial OTF counts tried, with a reference
of ``--reference`` radial OTF nodes and finer counts elsewhere (``REFERENCE``).

Usage (from the repository root; about 45 min on 2 cores)::

    .venv/bin/python benchmarks/otf_radial.py [--reference 256]
    .venv/bin/python benchmarks/otf_radial.py --timing
    .venv/bin/python benchmarks/otf_radial.py --recheck   # about 5 min
    .venv/bin/python benchmarks/otf_radial.py --sweep     # about 5 min

Writes ``results/otf_radial.json`` and ``.md`` (``--timing``: ``otf_radial_timing``,
``"high"``'s cost with the counts at the Fig. 1 point; ``--recheck``: ``otf_radial_recheck``,
session 87's climbs' worst designs run again with the counts; ``--sweep``:
``otf_radial_sweep``, ``sweep_jmse(..., preset="high")``'s values at low noise, which choose
the counts from the sweep's ``u`` since session 89, against the own grid's).
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
import se_angular as sa  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax._merit import _peak_snr  # noqa: E402

#: Session 87's two designs (``results/default_climb_high_powerlaw_lownoise_se_angular_
#: gradient_seed{3,4}.json``, the worst of climb 1 and of climb 2), beside session 86's.
DESIGNS = {
    **{name: spec["row"] for name, spec in sa.DESIGNS.items()},
    "seed3": dict(scale=8.0, coefficients=dict(
        w020=2.026897570257605, w040=4.78166315946895, w131=-3.901791582308874,
        w222=-2.4631120182371133, w220=-4.198629083817106), field=0.1444528670747427,
        u=0.8421598724080679, amplitude=0.005549018796790858, exponent=2.04865410144773,
        knee=0.2167542987927513, noise=2.0363257009082733e-09),
    "seed4": dict(scale=4.0, coefficients=dict(
        w020=-1.5746692151060033, w040=-1.6933111332999435, w131=3.657237327590245,
        w222=2.33420283810366, w220=0.8216474483682494), field=0.619410278353009,
        u=0.7037803930463804, amplitude=0.0004522955935425895, exponent=1.7143066600902044,
        knee=0.28414584464841935, noise=3.1622776601683795e-10),
}
RATIOS = (2e6, 2e7, 6e7, 2e8)
COUNTS = (80, 120, 160, 192, 256)
#: Finer than every ``"high"`` grid and than every count tried except in the radial OTF
#: nodes, which ``--reference`` sets (the climbs' reference has 160).
REFERENCE = dict(nodes=(256, 64), se_nodes=(8000, 7680), overlap_nodes=(128, 128),
                 overlap_floor=128, peaks=True)


def calibrate(reference, counts=COUNTS, ratios=RATIOS, designs=DESIGNS):
    rows = []
    ref_grid = dict(REFERENCE, nodes=(reference, REFERENCE["nodes"][1]))
    for name, base in designs.items():
        plan, grid = sa._grid_taken(base)
        own = grid["nodes"][0]
        for ratio in ratios:
            row = sa._with_ratio(base, ratio)
            angular = max(grid["se_nodes"][1], jj.se_angular_for(*dc._design(row)[2:]))
            start = time.perf_counter()
            value_ref, s_ref = dc._sensitivities(row, ref_grid)
            for n in sorted({own, *(c for c in counts if c > own)}):
                options = dict(grid, nodes=(n, grid["nodes"][1]),
                               se_nodes=(grid["se_nodes"][0], angular))
                value, s = dc._sensitivities(row, options)
                rows.append(dict(design=name, plan=plan, ratio=ratio, se_angular=angular,
                                 otf_radial=n, own=own,
                                 gradient_error=dc.gradient_error(s, s_ref),
                                 value_error=abs(value / value_ref - 1.0)))
                print(f"{name} ({plan}, own {own}) ratio {ratio:.3g} angular {angular} "
                      f"radial {n}: gradient {rows[-1]['gradient_error']:.2e} value "
                      f"{rows[-1]['value_error']:.1e} [{time.perf_counter() - start:.0f} s]",
                      flush=True)
            # Each program keeps its constants (the fine stage's interpolation tables):
            # cached for the whole run they exhausted 24 GB after about 50.
            dc._gradient_program.cache_clear()
            jax.clear_caches()
    return rows


#: The option sets ``--timing`` runs: ``"high"``'s own grid, with ``otf_radial_for``'s count
#: alone (a value of ``jmse`` past ``CHECKED_SNR``), and ``se_angular_for``'s counts at two
#: ratios with and without ``otf_radial_for``'s, on values and gradients
#: (``se_angular``, ``otf_radial``: ``optimise``) or on the gradient alone (the ``grad_``
#: twins: ``jmse``'s and ``lens_merit``'s own choice).
TIMING_RUNS = ({}, dict(otf_radial=160), dict(se_angular=1920),
               dict(se_angular=1920, otf_radial=160),
               dict(grad_se_angular=1920, grad_otf_radial=160), dict(se_angular=5760),
               dict(se_angular=5760, otf_radial=160),
               dict(grad_se_angular=5760, grad_otf_radial=160))


def timing(runs=TIMING_RUNS):
    """Warm jitted times of ``"high"`` with each option set of ``runs`` at the Fig. 1
    point: the value, and ``value_and_grad`` in the coefficients (gradient-only sets: the
    latter alone, since their value is ``"high"``'s own)."""
    c0 = jnp.array([common.FIG1[k] for k in dc.TERMS])
    args = (c0, jnp.asarray(common.FIG1_U), jnp.asarray(1e-3))
    out = []
    for options in runs:
        def merit(c, u, noise, options=options):
            return jj.jmse(jj.Seidel(*c), common.FIG1_FIELD, u, common.fig1_signal(),
                           jj.WhiteNoise(noise), preset="high", **options)

        gradient_only = any(k.startswith("grad_") for k in options)
        modes = (("value", merit), ("value_and_grad (coefficients)", jax.value_and_grad(merit)))
        for mode, fn in modes[gradient_only:]:
            timed = common.time_compiled(fn, args)
            out.append(dict(options=options, mode=mode, seconds=timed["warm_s"],
                            compile_s=timed["compile_s"]))
            print(f"{options or 'high'} {mode}: {timed['warm_s'] * 1e3:.1f} ms, compile "
                  f"{timed['compile_s']:.1f} s", flush=True)
    return out


#: Session 87's climbs (``default_climb.py --preset high --gradient --se-angular --noise
#: -9.5 -6.5 --seed 3/4``): their results, whose worst designs ``--recheck`` runs again.
CLIMBS = tuple(f"default_climb_high_powerlaw_lownoise_se_angular_gradient_seed{seed}.json"
               for seed in (3, 4))


def recheck(reference, names=CLIMBS):
    """The worst design of each climb in ``names`` at its own noise, with what ``optimise``
    now gives ``"high"`` (``se_angular_for``'s and ``otf_radial_for``'s counts) against the
    reference (``REFERENCE`` with ``reference`` radial OTF nodes), beside the error the
    climb found; and the value of an eager ``jmse(..., preset="high")``, which takes the
    radial count by itself."""
    import json
    import warnings

    ref_grid = dict(REFERENCE, nodes=(reference, REFERENCE["nodes"][1]))
    rows = []
    for name in names:
        climbs = json.loads((HERE / "results" / name).read_text())["climbs"]
        for i, climb in enumerate(climbs):
            worst = climb.get("worst", climb)
            row = {k: worst[k] for k in ("scale", "coefficients", "field", "u", "amplitude",
                                         "exponent", "knee", "noise")}
            design = dc._design(row)
            options = dict(preset="high", se_angular=jj.se_angular_for(*design[2:]),
                           otf_radial=jj.otf_radial_for(*design[2:]))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # beyond CHECKED_SNR, as the climbs allowed
                value, s = dc._sensitivities(row, options)
                value_ref, s_ref = dc._sensitivities(row, ref_grid)
                eager = float(jj.jmse(*design, preset="high"))
            rows.append(dict(
                climbs=name, climb=i, peak_snr=float(_peak_snr(*design[2:])),
                strength=worst["strength"], u=row["u"], options=options,
                climb_error=worst["error"], climb_value_error=worst["value_error"],
                gradient_error=dc.gradient_error(s, s_ref),
                value_error=abs(value / value_ref - 1.0),
                eager_value_error=abs(eager / value_ref - 1.0)))
            print(rows[-1], flush=True)
            dc._gradient_program.cache_clear()
            jax.clear_caches()
    return rows


#: ``"high"``'s base radial OTF count: given, it raises nothing and turns the choice off.
PRESETS_HIGH_RADIAL = jj.PRESETS["high"]["nodes"][0]


def sweep_values(reference, ratios=(2e7, 2e8), names=("seed3", "seed4")):
    """``sweep_jmse(..., preset="high")``'s value of each design of ``names`` at the peak
    ratios ``ratios``: with the counts it now chooses from its concrete ``u``, with
    ``otf_radial=80`` given (``"high"``'s base count, which raises nothing and turns the
    choice off: what a sweep computed before session 89, with ``u`` traced), and the eager
    ``jmse``'s, each against the reference value (``REFERENCE`` with ``reference`` radial
    OTF nodes)."""
    import warnings

    import numpy as np

    ref_grid = dict(REFERENCE, nodes=(reference, REFERENCE["nodes"][1]))
    rows = []
    for name in names:
        for ratio in ratios:
            design = dc._design(sa._with_ratio(DESIGNS[name], ratio))
            aberrations, field, u, signal, noise = design
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # beyond CHECKED_SNR, as measured here
                now, before = (float(jj.sweep_jmse(
                    aberrations, field, np.array([u]), signal, noise, preset="high",
                    progress=False, **options).value[0])
                    for options in ({}, dict(otf_radial=PRESETS_HIGH_RADIAL)))
                eager = float(jj.jmse(aberrations, field, u, signal, noise, preset="high"))
                value_ref = float(jj.jmse(aberrations, field, u, signal, noise, **ref_grid))
            rows.append(dict(design=name, ratio=ratio, otf_radial=jj.otf_radial_for(
                u, signal, noise), sweep_error=abs(now / value_ref - 1.0),
                own_error=abs(before / value_ref - 1.0),
                eager_error=abs(eager / value_ref - 1.0), sweep_vs_eager=abs(now / eager - 1.0)))
            print(rows[-1], flush=True)
            jax.clear_caches()
    return rows


def ref_grid_text(reference):
    return str(dict(REFERENCE, nodes=(reference, REFERENCE["nodes"][1])))


def _heading(title, command, machine):
    """A report's first lines: its title, the command that made it and the machine."""
    return [f"# {title}", "", f"`python benchmarks/otf_radial.py{command}`", "",
            common.machine_line(machine, common.load_average()), ""]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--reference", type=int, default=256,
                        help="radial OTF nodes of the reference grid")
    parser.add_argument("--timing", action="store_true",
                        help="time 'high' with the counts instead (results/otf_radial_timing)")
    parser.add_argument("--recheck", action="store_true",
                        help="run session 87's climbs' worst designs again with the counts "
                             "(results/otf_radial_recheck)")
    parser.add_argument("--sweep", action="store_true",
                        help="sweep_jmse's values of 'high' at low noise against the own "
                             "grid's (results/otf_radial_sweep)")
    args = parser.parse_args(argv)
    machine = common.machine_info()
    if args.sweep:
        rows = sweep_values(args.reference)
        lines = _heading("`sweep_jmse(..., preset=\"high\")` at low noise, with the counts",
                         f" --sweep --reference {args.reference}", machine) + [
                 "Relative errors of the value against "
                 f"{ref_grid_text(args.reference)}: the sweep's (which chooses the counts "
                 "from its concrete `u` since session 89), the sweep's with `otf_radial=80` "
                 "given (the own grid's: what a sweep gave before, with `u` traced), and "
                 "the eager `jmse`'s.", "",
                 "| design | peak S_x/S_n | otf_radial_for | sweep | sweep before (own grid) "
                 "| eager jmse | sweep vs eager |", "|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r['design']} | {r['ratio']:.3g} | {r['otf_radial']} | "
                         f"{r['sweep_error']:.1e} | {r['own_error']:.1e} | "
                         f"{r['eager_error']:.1e} | {r['sweep_vs_eager']:.1e} |")
        print("\n".join(lines))
        common.write_report("otf_radial_sweep", dict(machine=machine, rows=rows), lines)
        return
    if args.recheck:
        rows = recheck(args.reference)
        lines = _heading("Session 87's worst low-noise designs of `high`, with the counts",
                         f" --recheck --reference {args.reference}", machine) + [
                 "Each climb's worst design at its own noise with `se_angular_for`'s and "
                 "`otf_radial_for`'s counts (what `optimise` gives `high`), against "
                 f"{ref_grid_text(args.reference)}; the "
                 "errors the climb found (with `se_angular` alone) beside them; the eager "
                 "value takes the radial count by itself.", "",
                 "| climbs | climb | peak S_x/S_n | strength | u | counts | gradient's error "
                 "(climb's) | value's error (climb's) | eager value's error |",
                 "|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(
                f"| {r['climbs']} | {r['climb']} | {r['peak_snr']:.3g} | {r['strength']:.1f} "
                f"| {r['u']:.2f} | {r['options']['se_angular']} / "
                f"{r['options']['otf_radial']} | {r['gradient_error']:.2e} "
                f"({r['climb_error']:.2e}) | {r['value_error']:.1e} "
                f"({r['climb_value_error']:.1e}) | {r['eager_value_error']:.1e} |")
        print("\n".join(lines))
        common.write_report("otf_radial_recheck", dict(machine=machine, rows=rows), lines)
        return
    if args.timing:
        times = timing()
        lines = _heading("`high`'s cost with the low-noise counts (`se_angular`, `otf_radial`)",
                         " --timing", machine) + [
                 "Fig. 1 point, `high`, warm and jitted (`_common.time_compiled`: median), "
                 "float64:", "", "| options | call | time | compile |", "|---|---|---|---|"]
        for t in times:
            lines.append(f"| {t['options'] or '(own grid)'} | {t['mode']} | "
                         f"{t['seconds'] * 1e3:.1f} ms | {t['compile_s']:.1f} s |")
        print("\n".join(lines))
        common.write_report("otf_radial_timing", dict(machine=machine, timing=times), lines)
        return
    rows = calibrate(args.reference)
    lines = _heading("`high`'s value and gradient at low noise against its radial OTF nodes",
                     f" --reference {args.reference}", machine) + [
             f"Reference: {ref_grid_text(args.reference)}. "
             "Each design on the grid it takes in `high`, with `se_angular_for`'s angular "
             "count and the radial OTF nodes given.", "",
             "| design (plan, own radial) | peak S_x/S_n | se_angular | radial OTF nodes | "
             "gradient's error | value's error |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['design']} ({r['plan']}, {r['own']}) | {r['ratio']:.3g} | "
                     f"{r['se_angular']} | {r['otf_radial']} | {r['gradient_error']:.2e} | "
                     f"{r['value_error']:.1e} |")
    print("\n".join(lines))
    common.write_report("otf_radial", dict(machine=machine, reference=args.reference,
                                           rows=rows), lines)


if __name__ == "__main__":
    main()

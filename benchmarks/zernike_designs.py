"""The default on random Zernike designs of higher order than Seidel's (Noll up to 22 or 37).

The default's tiers were calibrated on random Seidel designs (wavefronts of degree 4). A
Zernike design can hold secondary and tertiary terms (``Z12``-``Z37``: degree 5-8), whose
wavefront has more structure for the same slope. This script draws random such designs
(coefficients normal with standard deviation ``1 / n`` for radial order ``n``, scaled to an
``aberration_strength`` drawn from 2 to 20; u 0.2, 0.5 or 0.85; noise 1e-3 or 1e-4) and
measures, against a converged polar grid (two settings, whose difference is the
reference's own uncertainty):

- the default as a user calls it (its route and warnings too);
- the default's tiers by strength alone (the balanced grid turned off), which is how such a
  design was routed until session 66, when its terms were measured one Zernike polynomial
  at a time.

Usage (from the repository root; about 15 s a design on 2 cores)::

    .venv/bin/python benchmarks/zernike_designs.py [--designs 20] [--noll 22 37] [--seed 1]
        [--preset default|high]

Writes ``results/zernike_designs.json`` and ``.md`` (``zernike_designs_high`` for ``"high"``).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import numpy as np  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit  # noqa: E402
from jmse_jax._aberrations import noll_to_nm  # noqa: E402

SIGNAL = jj.MarkovSignal(1.0, 5.0)
FIELD = 0.5  # a Zernike design ignores the field
REFERENCES = (
    dict(nodes=(160, 80), se_nodes=(6400, 512), overlap_nodes=(128, 128), overlap_floor=128,
         peaks=True),
    dict(nodes=(224, 112), se_nodes=(9600, 768), overlap_nodes=(192, 192), overlap_floor=192,
         peaks=True),
)


def _default(ab, u, noise, balanced=True, preset="default"):
    """The preset's value, plan index and warnings for a concrete design (as ``jmse``
    calls it; ``balanced=False``: without the balanced grid, the tiers by strength alone,
    or ``"high"``'s own and steep grids)."""
    saved = jj.PRESETS[preset]["balanced"]
    if not balanced:
        jj.PRESETS[preset]["balanced"] = None
    try:
        static, inputs = _merit._prepare((ab, FIELD, u, SIGNAL, jj.WhiteNoise(noise)),
                                         jj.jmse_options(preset))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            value, index, _, _ = _merit._concrete_merit(static, inputs, warn=True)
    finally:
        jj.PRESETS[preset]["balanced"] = saved
    return float(value), int(index), [str(w.message)[:60] for w in caught]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--designs", type=int, default=20, help="designs per Noll range")
    parser.add_argument("--noll", type=int, nargs="+", default=[22, 37],
                        help="highest Noll index of each range (from 4)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--preset", default="default", choices=("default", "high"))
    parser.add_argument("--name", default=None, help="default: zernike_designs[_high]")
    args = parser.parse_args(argv)
    name = args.name or ("zernike_designs" if args.preset == "default"
                         else f"zernike_designs_{args.preset}")
    balanced_index = (len(jj.DEFAULT_TIERS) if args.preset == "default"
                      else _merit._n_strength_plans(_merit._prepare(
                          (jj.Zernike([1.0], noll=(16,)), FIELD, 0.5, SIGNAL, jj.WhiteNoise(1e-3)),
                          jj.jmse_options(args.preset))[0]))
    machine = common.machine_info()
    references = [jax.jit(lambda ab, u, noise, grid=grid: jj.jmse(
        ab, FIELD, u, SIGNAL, jj.WhiteNoise(noise), **grid)) for grid in REFERENCES]
    rng = np.random.default_rng(args.seed)
    rows = []
    start = time.perf_counter()
    for top in args.noll:
        noll = tuple(range(4, top + 1))
        orders = np.array([noll_to_nm(j)[0] for j in noll], float)
        for _ in range(args.designs):
            c = rng.normal(size=len(noll)) / orders
            u = float(rng.choice([0.2, 0.5, 0.85]))
            noise = float(rng.choice([1e-3, 1e-4]))
            target = float(rng.uniform(2.0, 20.0))
            scale = target / float(jj.aberration_strength(jj.Zernike(c, noll=noll), FIELD, u))
            ab = jj.Zernike(c * scale, noll=noll)
            strength = float(jj.aberration_strength(ab, FIELD, u))
            coarse, fine = (float(f(ab, u, noise)) for f in references)
            value, index, warned = _default(ab, u, noise, preset=args.preset)
            tiers, tier, _ = _default(ab, u, noise, balanced=False, preset=args.preset)
            row = dict(
                noll=top, coefficients=(c * scale).tolist(), u=u, noise=noise,
                strength=strength, slope=strength / min(math.sqrt(2.0) * u, 1.0),
                cancellation=float(_merit._cancellation_jit(ab, FIELD, u)),
                balanced=index == balanced_index, tier=tier, warned=warned,
                reference=fine, convergence=coarse / fine - 1.0,
                default=value / fine - 1.0, tiers=tiers / fine - 1.0)
            rows.append(row)
            print(f"Noll<={top} u={u} noise={noise:.0e} strength={strength:5.1f} "
                  f"slope={row['slope']:5.1f} cancellation={row['cancellation']:.2f} "
                  f"balanced={int(row['balanced'])} warned={len(warned)} "
                  f"default={row['default']:+.1e} tiers(t{tier})={row['tiers']:+.1e} "
                  f"reference~{row['convergence']:+.1e}", flush=True)
    seconds = time.perf_counter() - start
    lines = ["# The default on random Zernike designs of higher order", "",
             common.machine_line(machine, common.load_average()), "",
             f"{len(rows)} random designs (seed {args.seed}): Zernike coefficients of Noll 4 to "
             f"the highest index given, normal with deviation 1/n (n the radial order), scaled "
             "to an aberration_strength drawn from 2 to 20; u 0.2, 0.5 or 0.85; noise 1e-3 or "
             "1e-4; MarkovSignal(1, 5). Reference: the polar grid "
             f"{REFERENCES[1]}; `reference~`: its difference from {REFERENCES[0]}. "
             f"`default`: the preset `{args.preset}` as a user calls it; `tiers`: that preset "
             "with its balanced grid off (the default's tiers by strength alone; `high`'s own "
             f"and steep grids). {seconds:.0f} s in all.", "",
             "| Noll | designs | to the balanced grid | warned | default > 1e-4 | default "
             "worst | tiers > 1e-4 | tiers worst | reference~ worst |",
             "|---|---|---|---|---|---|---|---|---|"]
    for top in args.noll:
        group = [r for r in rows if r["noll"] == top]
        lines.append(
            f"| 4-{top} | {len(group)} | {sum(r['balanced'] for r in group)} | "
            f"{sum(bool(r['warned']) for r in group)} | "
            f"{sum(abs(r['default']) > 1e-4 for r in group)} | "
            f"{max(abs(r['default']) for r in group):.1e} | "
            f"{sum(abs(r['tiers']) > 1e-4 for r in group)} | "
            f"{max(abs(r['tiers']) for r in group):.1e} | "
            f"{max(abs(r['convergence']) for r in group):.1e} |")
    lines += ["", "Every design:", "", "| Noll | u | noise | strength | slope | cancellation | "
              "balanced | warned | default | tiers (tier) | reference~ |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| 4-{r['noll']} | {r['u']} | {r['noise']:.0e} | {r['strength']:.1f} | "
                     f"{r['slope']:.1f} | {r['cancellation']:.2f} | {r['balanced']} | "
                     f"{'; '.join(r['warned']) or '-'} | {r['default']:+.1e} | "
                     f"{r['tiers']:+.1e} ({r['tier']}) | {r['convergence']:+.1e} |")
    for line in lines[6:6 + len(args.noll)]:
        print(line)
    common.write_report(name, dict(machine=machine, preset=args.preset, designs=rows), lines)


if __name__ == "__main__":
    main()

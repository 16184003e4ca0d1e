"""Accuracy of the polar grid where the band's rays reach the cutoff at some angles only.

For ``1/sqrt(2) < u < 1`` a ray of the polar rule at angle ``alpha`` (triangle 1) ends at the
band's edge for ``alpha < arccos(u)`` and beyond the cutoff for larger angles, so the angular
integrand has a kink at ``arccos(u)`` and the angular Gauss rule converges slowly there. This
script measures it on random off-axis Seidel designs (coefficients up to +-3 waves, field
0.3..1, noise 1e-4..1e-2) at ``u = 0.6`` (no kink, the control) and ``u = 0.75, 0.85,
0.95``: the strict reference setting (``tests/problems.STRICT_OPTIONS``), the same with
twice the angular nodes (the comparison value), the default and the ``high`` preset.

Usage (from the repository root; ~5 min for 16 designs on 2 cores)::

    .venv/bin/python benchmarks/wide_band_check.py [--designs 16] [--seed 5]

Writes ``benchmarks/results/wide_band_check.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import _common as common
import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import jmse_jax as jj  # noqa: E402

sys.path.insert(0, str(common.TESTS))
import problems  # noqa: E402

U_VALUES = (0.6, 0.75, 0.85, 0.95)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--designs", type=int, default=16)
    parser.add_argument("--seed", type=int, default=5)
    args = parser.parse_args(argv)
    if args.designs < len(U_VALUES):  # designs go round the u values; each needs one
        parser.error(f"--designs must be at least {len(U_VALUES)} (one per u value in "
                     f"{U_VALUES}), got {args.designs}")

    strict = dict(problems.STRICT_OPTIONS)
    doubled = dict(strict, nodes=(strict["nodes"][0], 2 * strict["nodes"][1]),
                   se_nodes=(strict["se_nodes"][0], 2 * strict["se_nodes"][1]))
    fns = {
        "strict": jax.jit(lambda *a: jj.jmse(*a, **strict)),
        "doubled": jax.jit(lambda *a: jj.jmse(*a, **doubled)),
        "default": jax.jit(lambda *a: jj.jmse(*a)),
        "high": jax.jit(lambda *a: jj.jmse(*a, preset="high")),
    }
    rng = np.random.default_rng(args.seed)
    rows = []
    start = time.perf_counter()
    for i in range(args.designs):
        c = rng.uniform(-1, 1, 5) * rng.uniform(0.5, 3)
        ab = jj.Seidel(w020=c[0], w040=c[1], w131=c[2], w222=c[3], w220=c[4])
        field = float(rng.uniform(0.3, 1))
        u = U_VALUES[i % len(U_VALUES)]
        noise = float(10 ** rng.uniform(-4, -2))
        arguments = (ab, field, u, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(noise))
        values = {key: float(fn(*arguments)) for key, fn in fns.items()}
        ref = values["doubled"]
        row = dict(coefficients=[float(x) for x in c], field=field, u=u, noise=noise,
                   strength=float(jj.aberration_strength(ab, field, u)), values=values,
                   errors={k: abs(v - ref) / abs(ref) for k, v in values.items()
                           if k != "doubled"})
        rows.append(row)
        print(f"u {u:4.2f} strength {row['strength']:5.1f} noise {noise:.0e}: "
              + ", ".join(f"{k} {e:.1e}" for k, e in row["errors"].items()), flush=True)

    summary = {}
    for u in U_VALUES:
        sel = [r for r in rows if r["u"] == u]
        summary[str(u)] = {k: dict(median=statistics.median(r["errors"][k] for r in sel),
                                   worst=max(r["errors"][k] for r in sel))
                           for k in ("strict", "default", "high")}
    report = dict(description=__doc__.split("\n\n")[0], machine=common.machine_info(),
                  strict_options=strict, doubled_options=doubled, seed=args.seed,
                  designs=rows, summary=summary, seconds=time.perf_counter() - start)
    common.RESULTS.mkdir(parents=True, exist_ok=True)
    common.write_json(common.RESULTS / "wide_band_check.json", report)
    machine = report["machine"]
    lines = [
        "# The polar grid for 1/sqrt(2) < u < 1", "",
        f"{machine.get('cpu_model')}, jax {machine.get('jax_version')}, float64, commit "
        f"{machine.get('commit')}; {args.designs} random off-axis Seidel designs (seed "
        f"{args.seed}). Relative difference from the strict setting with twice the angular "
        f"nodes, `nodes={doubled['nodes']}, se_nodes={doubled['se_nodes']}`.", "",
        "| u | designs | strict: median / worst | default: median / worst "
        "| high: median / worst |",
        "|---|---|---|---|---|",
    ]
    for u, s in summary.items():
        count = sum(1 for r in rows if str(r["u"]) == u)
        lines.append(f"| {u} | {count} | " + " | ".join(
            f"{s[k]['median']:.1e} / {s[k]['worst']:.1e}" for k in ("strict", "default", "high"))
            + " |")
    (common.RESULTS / "wide_band_check.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())

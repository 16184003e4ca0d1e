"""The cheapest fixed polar grid for each error level at one design, against the baseline.

Issue 3 asks the default to be several times faster at the paper's Fig. 1 point than it is
(target 2: at most the time of ``baseline_jmse`` at B = 64). The default is adaptive: it
picks its grid from the design and verifies a cheap grid against a check grid. This script
asks what the best possible choice of grid could reach at one design, with nothing spent on
choosing or verifying it: it times many fixed polar grids (random draws from a family of node
counts, plus the default's own first and check grids), measures each one's error against the
design's converged reference, and reports the Pareto front of error against warm time. The
cheapest grid on the front below an error level is a lower bound (up to the sampling of the
family) on what any adaptive scheme over the polar overlap pipeline spends at that design.

The front, ``baseline_jmse`` at B = 32 ... 512 and the default preset are then timed again in
alternation (value and ``value_and_grad`` with respect to the Seidel coefficients), and the
ratios to the baselines are taken from those times. ``--dtype float32`` computes the grids in
float32 (and adds B = 64 and the default in float32 to the references). Usage (from the
repository root; about 10 min on one core)::

    taskset -c 1 .venv/bin/python benchmarks/grid_frontier.py [--problem fig1]
        [--samples 120] [--refine 2] [--seed 3] [--dtype float64] [--tag NAME]

Writes ``benchmarks/results/grid_frontier[_NAME].{json,md,png}``.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time

import _common as common
import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from accuracy_speed import _baseline, _in_float32, _jmse  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit  # noqa: E402
from jmse_jax._numerics import common_dtype  # noqa: E402

#: The family of fixed grids: each count drawn independently from its list.
FAMILY = dict(
    radial=(8, 10, 12, 14, 16, 20, 24, 28),
    angular=(3, 4, 5, 6, 8, 10),
    se_radial=(100, 150, 200, 300, 400),
    se_angular=(16, 24, 32, 40),
    overlap_phi=(10, 12, 14, 16, 18, 20, 24),
    overlap_t=(8, 10, 12, 14, 16),
    floor=(6, 8, 10, 12),
)
#: Error levels of the report.
LEVELS = (1e-3, 1e-4, 1e-5, 1e-6)
BASELINES = (32, 64, 128, 256, 512)


def _grid_options(nodes, se_nodes, overlap_nodes, floor):
    return dict(nodes=tuple(nodes), se_nodes=tuple(se_nodes),
                overlap_nodes=tuple(overlap_nodes), overlap_floor=int(floor))


def sample_grids(samples: int, seed: int) -> list[dict]:
    """``samples`` random grids of ``FAMILY`` and the default's first and check grids."""
    rng = np.random.default_rng(seed)
    grids = [dict(_merit._FIRST_GRID), dict(_merit._CHECK_GRID)]
    seen = {repr(sorted(g.items())) for g in grids}
    attempts = 0
    while len(grids) < samples + 2 and attempts < 100 * samples:
        attempts += 1
        grid = _from_counts({k: int(rng.choice(v)) for k, v in FAMILY.items()})
        key = repr(sorted(grid.items()))
        if key not in seen:
            seen.add(key)
            grids.append(grid)
    return grids


_KEYS = ("radial", "angular", "se_radial", "se_angular", "overlap_phi", "overlap_t", "floor")


def _counts(grid) -> dict:
    return dict(zip(_KEYS, (*grid["nodes"], *grid["se_nodes"], *grid["overlap_nodes"],
                            grid["overlap_floor"]), strict=True))


def _from_counts(c) -> dict:
    floor = min(c["floor"], c["overlap_phi"], c["overlap_t"])
    return _grid_options((c["radial"], c["angular"]), (c["se_radial"], c["se_angular"]),
                         (c["overlap_phi"], c["overlap_t"]), floor)


def neighbours(grid) -> list[dict]:
    """The grids one step cheaper in one count: that count replaced by the largest value of
    ``FAMILY`` below it (none where the family has no smaller value)."""
    out = []
    for key, c in _counts(grid).items():
        smaller = [v for v in FAMILY[key] if v < c]
        if smaller:
            out.append(_from_counts({**_counts(grid), key: max(smaller)}))
    return out


def _label(grid) -> str:
    return (f"{tuple(grid['nodes'])} / {tuple(grid['se_nodes'])} / "
            f"{tuple(grid['overlap_nodes'])} floor {grid['overlap_floor']}")


def _fn(dtype="float64", **options):
    """The merit with ``options``; in float32 its arguments are cast on entry and its value
    returned in float64 (errors are taken against the float64 reference)."""
    fn = _jmse(**options)
    return fn if dtype == "float64" else _in_float32(fn)


def pareto(rows) -> list[dict]:
    """Rows not beaten in both time and error by another row (ascending time)."""
    front, best = [], math.inf
    for row in sorted(rows, key=lambda r: r["value_s"]):
        if row["relative_error"] < best:
            front.append(row)
            best = row["relative_error"]
    return front


def alternate(entries, args, rounds: int, calls: int) -> None:
    """Time every entry's value and value_and_grad in alternation (``rounds`` rounds of
    ``calls`` calls each); store medians and minima in the entries."""
    compiled = []
    for entry in entries:
        value = jax.jit(entry["fn"]).lower(*args).compile()
        jax.block_until_ready(value(*args))
        fns = (value,)
        if not entry.get("value_only"):
            vag = jax.jit(jax.value_and_grad(entry["fn"], argnums=0)).lower(*args).compile()
            jax.block_until_ready(vag(*args))
            fns = (value, vag)
        compiled.append(fns)
    times = [([], []) for _ in entries]
    for _ in range(rounds):
        for fns, out in zip(compiled, times, strict=True):
            for fn, bucket in zip(fns, out[:len(fns)], strict=True):
                for _ in range(calls):
                    start = time.perf_counter()
                    jax.block_until_ready(fn(*args))
                    bucket.append(time.perf_counter() - start)
    for entry, (value_t, vag_t) in zip(entries, times, strict=True):
        entry.update(alt_value_s=statistics.median(value_t), alt_value_min_s=min(value_t))
        if vag_t:
            entry.update(alt_vag_s=statistics.median(vag_t), alt_vag_min_s=min(vag_t))


def _default_parts():
    """The adaptive default's parts at a design its shortcut serves (``jmse_jax._merit``
    internals, value only): the first grid, the first grid with its interpolation-error
    estimate, the float32 check grid and the strength that picks the tier."""
    # The shortcut of the Fig. 1 point's tier (1) as the default's plans hold it.
    _, shortcut = _merit._tier_plans(jj.jmse_options(), jj.DEFAULT_TIERS)[1]
    _, check, _, _, first, _ = shortcut

    def part(fn):
        def wrapped(aberrations, field, u, signal, noise):
            return fn((aberrations, field, u, signal, noise))

        return wrapped

    def dtype_of(ops):
        return common_dtype(*ops)

    return [
        dict(name="default: first grid",
             fn=part(lambda o: _merit._apply_merit(first, dtype_of(o), o))),
        dict(name="default: first grid and its estimate",
             fn=part(lambda o: _merit._apply_estimated(first, dtype_of(o), o)[0])),
        dict(name="default: check grid (float32)",
             fn=part(lambda o: _merit._check_value(check, dtype_of(o), o))),
        dict(name="default: strength", fn=part(lambda o: _merit._strength(*o[:3]))),
    ]


def components(problem: str, rounds: int, calls: int) -> dict:
    """The default and its parts, B = 64 and B = 512, timed in alternation."""
    case = {c.name: c for c in common.load_bank()}[problem]
    args = case.arguments
    info = common.machine_info()
    entries = [dict(name="baseline B=64", fn=_baseline(64)),
               dict(name="baseline B=512", fn=_baseline(512)),
               dict(name="preset default", fn=_fn())]
    entries += [dict(e, value_only=True) for e in _default_parts()]
    alternate(entries, args, rounds, calls)
    return dict(machine=info, problem=problem, rounds=rounds, calls=calls,
                parts={e["name"]: {k: v for k, v in e.items() if k not in ("fn",)}
                       for e in entries},
                load_at_end=common.load_average())


def components_markdown(report) -> str:
    m = report["machine"]
    lines = [
        f"# The default's parts at `{report['problem']}`",
        "",
        common.machine_line(m, report["load_at_end"])
        + f" Alternated, {report['rounds']} rounds of {report['calls']} calls: medians "
        "(fastest).",
        "",
        "| program | value | value_and_grad |",
        "|---|---|---|",
    ]
    for name, e in report["parts"].items():
        vag = ("–" if "alt_vag_s" not in e else f"{common.fmt_seconds(e['alt_vag_s'])} "
               f"({common.fmt_seconds(e['alt_vag_min_s'])})")
        lines.append(f"| {name} | {common.fmt_seconds(e['alt_value_s'])} "
                     f"({common.fmt_seconds(e['alt_value_min_s'])}) | {vag} |")
    return "\n".join(lines + [""])


def run(problem: str, samples: int, seed: int, refine: int, rounds: int, calls: int,
        dtype: str = "float64") -> dict:
    start = time.perf_counter()
    cases = {c.name: c for c in common.load_bank()}
    case = cases[problem]
    args = case.arguments
    info = common.machine_info()

    rows, seen = [], set()

    def measure(grid, origin):
        key = repr(sorted(grid.items()))
        if key in seen:
            return
        seen.add(key)
        timed = common.time_compiled(_fn(dtype, **grid), args, budget_s=0.3, max_repeats=25)
        row = dict(grid=grid, label=_label(grid), value=float(timed["value"]),
                   relative_error=common.relative_error(timed["value"], case.reference),
                   value_s=timed["warm_min_s"], compile_s=timed["compile_s"],
                   otf_nodes=2 * grid["nodes"][0] * grid["nodes"][1], origin=origin)
        rows.append(row)
        print(f"[{len(rows)}, {origin}] {row['label']}: error {row['relative_error']:.1e}, "
              f"{row['value_s'] * 1e6:.0f} us", flush=True)

    for grid in sample_grids(samples, seed):
        measure(grid, "sample")
    # Local refinement: every grid on the front (below the largest level) is tried one step
    # cheaper in each count, ``refine`` times over.
    for round_ in range(refine):
        for row in [r for r in pareto(rows) if r["relative_error"] <= LEVELS[0]]:
            for grid in neighbours(row["grid"]):
                measure(grid, f"refine {round_ + 1}")
    front = [r for r in pareto(rows) if r["relative_error"] <= LEVELS[0]]

    reference_entries = [dict(name=f"baseline B={B}", fn=_baseline(B)) for B in BASELINES]
    reference_entries.append(dict(name="preset default", fn=_fn()))
    if dtype != "float64":
        reference_entries += [dict(name="baseline B=64 float32", fn=_in_float32(_baseline(64))),
                              dict(name="preset default float32", fn=_fn(dtype))]
    for entry in reference_entries:
        entry["relative_error"] = common.relative_error(jax.jit(entry["fn"])(*args),
                                                        case.reference)
    front_entries = [dict(name=r["label"], fn=_fn(dtype, **r["grid"]), row=r) for r in front]
    print(f"alternated timing of {len(front_entries)} front grids, "
          f"{len(reference_entries)} references ...", flush=True)
    alternate(reference_entries + front_entries, args, rounds, calls)
    for entry in front_entries:
        entry["row"].update(alt_value_s=entry["alt_value_s"], alt_vag_s=entry["alt_vag_s"],
                            alt_value_min_s=entry["alt_value_min_s"],
                            alt_vag_min_s=entry["alt_vag_min_s"])
    references = {e["name"]: {k: v for k, v in e.items() if k != "fn"}
                  for e in reference_entries}
    b64 = references["baseline B=64"]
    b512 = references["baseline B=512"]

    levels = []
    for level in LEVELS:
        meeting = [r for r in front if r["relative_error"] <= level]
        if not meeting:
            levels.append(dict(level=level, grid=None))
            continue
        best_value = min(meeting, key=lambda r: r["alt_value_s"])
        best_vag = min(meeting, key=lambda r: r["alt_vag_s"])
        levels.append(dict(
            level=level,
            grid=best_value["label"], value_s=best_value["alt_value_s"],
            value_error=best_value["relative_error"],
            value_over_b64=best_value["alt_value_s"] / b64["alt_value_s"],
            b512_over_value=b512["alt_value_s"] / best_value["alt_value_s"],
            vag_grid=best_vag["label"], vag_s=best_vag["alt_vag_s"],
            vag_over_b64=best_vag["alt_vag_s"] / b64["alt_vag_s"]))
    return dict(
        machine=info, problem=problem, reference=case.reference,
        reference_convergence=case.convergence, samples=samples, seed=seed, refine=refine,
        grid_dtype=dtype,
        family=FAMILY, rounds=rounds, calls=calls, rows=rows,
        front=[r["label"] for r in front], references=references, levels=levels,
        load_at_end=common.load_average(), wall_s=time.perf_counter() - start,
    )


def _e(x):
    return "–" if x is None else f"{x:.1e}"


def markdown(report) -> str:
    m = report["machine"]
    refs = report["references"]
    b64 = refs["baseline B=64"]
    lines = [
        f"# The cheapest fixed grid per error level: `{report['problem']}`",
        "",
        f"{m['cpu_model']}, {m['nproc']} CPU(s) used, jax {m['jax_version']}, grids in "
        f"{report.get('grid_dtype', 'float64')} (the baselines and the default in float64 "
        f"unless named; errors against the float64 reference), "
        f"commit `{m['commit'][:10]}`, {m['date']}. Load average at start "
        f"{m['load_at_start']['load_1min']:.2f}, at end {report['load_at_end']['load_1min']:.2f}. "
        f"{len(report['rows'])} fixed polar grids ({report['samples']} random draws from the "
        f"family below, seed {report['seed']}, the default's first and check grids, and "
        f"{report['refine']} rounds of the front's neighbours one step cheaper in one count), "
        f"each timed alone (fastest of up to 25 warm calls); the front, the baselines and the "
        f"default were then timed in alternation ({report['rounds']} rounds of "
        f"{report['calls']} calls; medians), and the ratios use those times. Reference "
        f"{report['reference']:.10e} (convergence {report['reference_convergence']:.1e}).",
        "",
        "## Cheapest grid per error level (no cost for choosing or checking it)",
        "",
        "| error at most | grid (value) | error | value | / B=64 value | B=512 value / value "
        "| value_and_grad | / B=64 value_and_grad |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for lv in report["levels"]:
        if lv["grid"] is None:
            lines.append(f"| {lv['level']:.0e} | none in the sample | | | | | | |")
            continue
        lines.append(
            f"| {lv['level']:.0e} | {lv['grid']} | {_e(lv['value_error'])} | "
            f"{common.fmt_seconds(lv['value_s'])} | {lv['value_over_b64']:.2f} | "
            f"{lv['b512_over_value']:.0f}x | "
            f"{common.fmt_seconds(lv['vag_s'])} | {lv['vag_over_b64']:.2f} |")
    lines += ["", "## References, timed in the same alternation", "",
              "| method | error | value | value_and_grad | value / B=64 |", "|---|---|---|---|---|"]
    for name, r in refs.items():
        lines.append(f"| {name} | {_e(r['relative_error'])} | "
                     f"{common.fmt_seconds(r['alt_value_s'])} | "
                     f"{common.fmt_seconds(r['alt_vag_s'])} | "
                     f"{r['alt_value_s'] / b64['alt_value_s']:.2f} |")
    lines += ["", "## The front (error at most 1e-3)", "",
              "| grid: nodes / se_nodes / overlap_nodes | OTF nodes | error | value (alone) | "
              "value | value_and_grad |", "|---|---|---|---|---|---|"]
    for r in sorted((r for r in report["rows"] if "alt_value_s" in r),
                    key=lambda r: r["value_s"]):
        lines.append(f"| {r['label']} | {r['otf_nodes']} | {_e(r['relative_error'])} | "
                     f"{common.fmt_seconds(r['value_s'])} | "
                     f"{common.fmt_seconds(r['alt_value_s'])} | "
                     f"{common.fmt_seconds(r['alt_vag_s'])} |")
    lines += ["", "Family: " + ", ".join(f"{k} {list(v)}" for k, v in report["family"].items())
              + ".", ""]
    return "\n".join(lines)


def plot(report, path) -> None:
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, ax = plt.subplots(figsize=(8, 5.5))
    rows = report["rows"]
    floor = 1e-12
    ax.scatter([r["value_s"] for r in rows], [max(r["relative_error"], floor) for r in rows],
               s=12, color="C0", alpha=0.6, label="fixed polar grids (timed alone)")
    front = sorted((r for r in rows if "alt_value_s" in r), key=lambda r: r["value_s"])
    ax.step([r["value_s"] for r in front], [max(r["relative_error"], floor) for r in front],
            where="post", color="C0", linewidth=2, label="front")
    for name, r in report["references"].items():
        style = dict(color="k", marker="s") if name.startswith("baseline") else dict(
            color="C3", marker="*", markersize=14)
        ax.plot([r["alt_value_s"]], [max(r["relative_error"], floor)], linestyle="none",
                **style)
        ax.annotate(name, (r["alt_value_s"], max(r["relative_error"], floor)),
                    textcoords="offset points", xytext=(5, 4), fontsize=8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda x, _: f"{x * 1e3:g}"))
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("warm time of one JMSE value [ms]")
    ax.set_ylabel(f"relative error at {report['problem']}")
    ax.set_title("Fixed polar grids against the baseline at one design")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--problem", default="fig1", help="bank problem (tests/problems.py)")
    parser.add_argument("--samples", type=int, default=120, help="random grids")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--refine", type=int, default=2,
                        help="rounds of one-step-cheaper neighbours of the front")
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--calls", type=int, default=5)
    parser.add_argument("--dtype", default="float64", choices=("float64", "float32"),
                        help="dtype of the grids' computation (references stay float64)")
    parser.add_argument("--tag", default="")
    parser.add_argument("--components", action="store_true",
                        help="only time the default's parts against B = 64 and B = 512 "
                             "(grid_frontier_components[_NAME].{json,md})")
    parser.add_argument("--replot", action="store_true",
                        help="redraw the table and plot from the stored JSON only")
    a = parser.parse_args(argv)
    name = "grid_frontier" + (f"_{a.tag}" if a.tag else "")
    if a.components:
        report = components(a.problem, a.rounds, a.calls)
        stem = common.RESULTS / (name.replace("grid_frontier", "grid_frontier_components"))
        stem.with_suffix(".json").write_text(json.dumps(report, indent=1))
        stem.with_suffix(".md").write_text(components_markdown(report))
        print(components_markdown(report))
        return 0
    if a.replot:
        report = json.loads((common.RESULTS / f"{name}.json").read_text())
        (common.RESULTS / f"{name}.md").write_text(markdown(report))
        plot(report, common.RESULTS / f"{name}.png")
        return 0
    report = run(a.problem, a.samples, a.seed, a.refine, a.rounds, a.calls, a.dtype)
    common.RESULTS.mkdir(parents=True, exist_ok=True)
    (common.RESULTS / f"{name}.json").write_text(json.dumps(report, indent=1))
    (common.RESULTS / f"{name}.md").write_text(markdown(report))
    plot(report, common.RESULTS / f"{name}.png")
    print(markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())

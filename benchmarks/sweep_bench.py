"""Throughput and memory of ``jmse_jax.sweep`` on the paper's singlet space (issue 5).

The sweep: Berkner & Shroff's F/4.6 singlet space (``jmse_jax.lens.paper_singlet``), stop
distance 0..3 mm x front curvature -0.1..0.1 1/mm on a ``grid x grid`` lattice (25 x 25 in
the paper), times a few field heights (3 by default), ``u = 0.2``, ``MarkovSignal(1, 5)``,
``WhiteNoise(1e-3)``, in float64 (``--dtype float32``: in float32). Each design traces the
lens, converts its Seidel sums to waves and evaluates ``jmse``; ``value_and_grad``
differentiates with respect to stop distance, front curvature and field. Non-physical
lenses get ``SweepStatus.INVALID`` through ``lens_status``.

Every configuration (device count x mode) runs in its own process, so that JAX can be
given the device count (``--xla_force_host_platform_device_count``) and so that its memory
peak (``ru_maxrss``) is its own. Fake CPU devices share the same cores: on a CPU they show
that the sharded code path works and what it costs, not a speed-up.

Usage (from the repository root)::

    python benchmarks/sweep_bench.py                       # default preset, 25 x 25 x 3
    python benchmarks/sweep_bench.py --preset fast --grid 10 --devices 1,2,4
    python benchmarks/sweep_bench.py --option nodes=[12,8] --option overlap_nodes=[24,24]
    python benchmarks/sweep_bench.py --preset fast --dtype float32 --tag fast_float32
    python benchmarks/sweep_bench.py --preset fast --devices 1 --workers 1,2 --tag workers

Writes ``benchmarks/results/sweep_bench.json`` and ``sweep_bench.md`` (``--tag`` adds a
suffix to both names).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"


def _parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", default="default", help="jmse preset (default: default)")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=JSON",
                        help="jmse option override, e.g. nodes=[12,8] (repeatable)")
    parser.add_argument("--grid", type=int, default=25, help="lattice points per lens axis")
    parser.add_argument("--fields", default="0.0,0.7,0.95", help="field heights, comma separated")
    parser.add_argument("--devices", default="1,2,4", help="device counts, comma separated")
    parser.add_argument("--modes", default="value,grad", help="value and/or grad")
    parser.add_argument("--batch-size", type=int, default=None,
                        help="designs per device per vmap (default: sweep's, 1 on CPU)")
    parser.add_argument("--chunks-per-call", type=int, default=None,
                        help="chunks each device works through per call (default: sweep's, "
                             "up to 8 on CPU)")
    parser.add_argument("--workers", default=None,
                        help="host threads issuing calls, comma separated (default: sweep's, "
                             "cores per device on CPU)")
    parser.add_argument("--repeats", type=int, default=1,
                        help="sweeps per configuration; the fastest run is reported")
    parser.add_argument("--timeout", type=float, default=1800.0,
                        help="seconds allowed per configuration")
    parser.add_argument("--dtype", default="float64", choices=("float64", "float32"),
                        help="dtype of the designs, hence of the whole computation; float32 "
                             "runs also report their largest relative difference from "
                             "float64 on one device")
    parser.add_argument("--tag", default="", help="suffix of the output file names")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--mode", help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def _options(args) -> dict:
    options = {}
    for item in args.option:
        key, _, value = item.partition("=")
        if not value:
            raise SystemExit(f"--option must look like KEY=JSON, got {item!r}")
        value = json.loads(value)
        options[key] = tuple(value) if isinstance(value, list) else value
    return options


def _worker(args) -> dict:
    """One configuration, in this process: its device count is fixed by XLA_FLAGS."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    import jmse_jax as jj
    from jmse_jax import lens

    options = _options(args)
    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)
    space = lens.PAPER_SINGLET
    fields = [float(f) for f in args.fields.split(",")]
    designs = jj.hypercube(
        stop_distance=np.linspace(*space["stop_distance_range"], args.grid),
        front_curvature=np.linspace(*space["front_curvature_range"], args.grid),
        field=np.asarray(fields),
    )
    designs = {key: value.astype(args.dtype) for key, value in designs.items()}

    def merit(design):
        singlet = lens.paper_singlet(design["stop_distance"], design["front_curvature"])
        return jj.jmse(lens.seidel_waves(singlet), design["field"], 0.2, signal, noise,
                       preset=args.preset, **options)

    def physical(design):
        singlet = lens.paper_singlet(design["stop_distance"], design["front_curvature"])
        return lens.lens_status(singlet).ok

    workers = None if args.workers is None else int(args.workers)
    runs = []
    for _ in range(max(1, args.repeats)):
        result = jj.sweep(merit, designs, grad=args.mode == "grad", valid=physical,
                          batch_size=args.batch_size, chunks_per_call=args.chunks_per_call,
                          workers=workers, progress=False)
        runs.append(result.metadata)
    best = min(runs, key=lambda m: m["run_s"])
    float64_difference = grad_difference = None
    if args.dtype != "float64" and jax.device_count() == 1:  # accuracy of the cheaper dtype
        reference = jj.sweep(merit, {k: v.astype(np.float64) for k, v in designs.items()},
                             grad=args.mode == "grad", valid=physical,
                             batch_size=args.batch_size, chunks_per_call=args.chunks_per_call,
                             workers=workers, progress=False)
        ok = result.ok & reference.ok
        float64_difference = float(np.max(np.abs(
            result.value[ok].astype(np.float64) / reference.value[ok] - 1.0)))
        if args.mode == "grad":
            # Per design: the largest difference of a gradient component from float64,
            # relative to the largest component of that design's float64 gradient (the
            # lens variables differ in scale; the field's derivative is 0 on the axis).
            keys = ("stop_distance", "front_curvature")
            got = np.stack([result.grad[k][ok].astype(np.float64) for k in keys], -1)
            want = np.stack([reference.grad[k][ok] for k in keys], -1)
            scale = np.max(np.abs(want), axis=-1)
            relative = np.max(np.abs(got - want), axis=-1) / scale
            grad_difference = [float(np.median(relative)), float(np.percentile(relative, 99)),
                               float(np.max(relative))]
    n = best["n_designs"]
    memory = best["memory"] or {}
    return {
        "mode": args.mode,
        "n_devices": best["n_devices"],
        "device_kind": best["device_kind"],
        "platform": best["platform"],
        "n_designs": n,
        "padded_designs": best["padded_designs"],
        "batch_size": best["batch_size"],
        "chunks_per_call": best.get("chunks_per_call"),
        "workers": best["workers"],
        "compile_s": [m["compile_s"] for m in runs],
        "run_s": [m["run_s"] for m in runs],
        "designs_per_second": n / best["run_s"],
        "status_counts": result.status_counts(),
        "dtype": args.dtype,
        "max_rel_diff_from_float64": float64_difference,
        "grad_rel_diff_from_float64": grad_difference,
        "xla_temp_bytes_per_device": memory.get("temp_bytes"),
        "xla_temp_bytes_per_design": (memory["temp_bytes"] / best["batch_size"]
                                      if memory.get("temp_bytes") is not None else None),
        "peak_rss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
    }


def _run_configuration(args, n_devices: int, mode: str, workers: int | None) -> dict:
    env = dict(os.environ)
    flags = [f for f in env.get("XLA_FLAGS", "").split() if "device_count" not in f]
    if n_devices > 1:
        flags.append(f"--xla_force_host_platform_device_count={n_devices}")
    env["XLA_FLAGS"] = " ".join(flags)
    command = [sys.executable, str(Path(__file__).resolve()), "--worker", "--mode", mode,
               "--preset", args.preset, "--grid", str(args.grid), "--fields", args.fields,
               "--repeats", str(args.repeats), "--dtype", args.dtype]
    if args.batch_size is not None:
        command += ["--batch-size", str(args.batch_size)]
    if args.chunks_per_call is not None:
        command += ["--chunks-per-call", str(args.chunks_per_call)]
    if workers is not None:
        command += ["--workers", str(workers)]
    for item in args.option:
        command += ["--option", item]
    started = time.perf_counter()
    try:
        completed = subprocess.run(command, env=env, capture_output=True, text=True,
                                   timeout=args.timeout)
    except subprocess.TimeoutExpired:
        return {"mode": mode, "n_devices": n_devices, "workers": workers,
                "error": f"timeout after {args.timeout} s"}
    if completed.returncode != 0:
        return {"mode": mode, "n_devices": n_devices, "workers": workers,
                "error": completed.stderr[-2000:]}
    row = json.loads(completed.stdout.strip().splitlines()[-1])
    row["process_wall_s"] = time.perf_counter() - started
    return row


def _distinct(rows, key) -> str:
    return ", ".join(sorted({str(row[key]) for row in rows if key in row}))


def _markdown(report: dict) -> str:
    machine = report["machine"]
    lines = [
        "# Sweep throughput: the paper's singlet space",
        "",
        f"{report['description']}",
        "",
        f"- machine: {machine.get('cpu_model')} ({machine.get('cpu_count')} CPUs), "
        f"{machine.get('platform')}",
        f"- devices: {_distinct(report['rows'], 'device_kind')} "
        f"({_distinct(report['rows'], 'platform')})",
        f"- jax {machine.get('jax_version')}, dtype {report.get('dtype', 'float64')}, "
        f"commit {machine.get('commit')}"
        f"{' (with uncommitted changes)' if machine.get('dirty') else ''}",
        f"- load average at start: {machine.get('load_at_start', {}).get('uptime')}",
        f"- jmse preset {report['preset']!r}, options {report['options']}, "
        f"batch_size {report['batch_size']} per device, "
        f"chunks_per_call {report.get('chunks_per_call')}",
    ]
    if all(row.get("platform", "cpu") == "cpu" for row in report["rows"]):
        lines.append("- fake CPU devices share the same cores: more devices do not add "
                     "compute here.")
    lines += [
        "",
        "| mode | devices | workers | designs | designs/s | run s | compile s "
        "| XLA temp MB/design | peak RSS MB | statuses |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in report["rows"]:
        if "error" in row:
            lines.append(f"| {row['mode']} | {row['n_devices']} | {row.get('workers') or ''} "
                         f"| | failed: {row['error'].splitlines()[-1] if row['error'] else ''} "
                         f"| | | | | |")
            continue
        per_design = row["xla_temp_bytes_per_design"]
        lines.append(
            f"| {row['mode']} | {row['n_devices']} | {row.get('workers', '')} "
            f"| {row['n_designs']} "
            f"| {row['designs_per_second']:.1f} | {min(row['run_s']):.2f} "
            f"| {min(row['compile_s']):.1f} "
            f"| {'' if per_design is None else f'{per_design / 1e6:.1f}'} "
            f"| {row['peak_rss_bytes'] / 1e6:.0f} | {row['status_counts']} |"
        )
    for row in report["rows"]:
        if row.get("max_rel_diff_from_float64") is not None:
            lines.append(f"\n{row['mode']}, {row['n_devices']} device: largest relative "
                         f"difference of the {row['dtype']} values from float64 "
                         f"{row['max_rel_diff_from_float64']:.1e}.")
            if row.get("grad_rel_diff_from_float64") is not None:
                median, p99, worst = row["grad_rel_diff_from_float64"]
                lines.append(f"Gradients (stop distance, front curvature): per design, the "
                             f"largest difference of a component from float64 relative to "
                             f"the design's largest float64 component: median {median:.1e}, "
                             f"99th percentile {p99:.1e}, largest {worst:.1e} (the largest "
                             f"where a gradient nearly vanishes, near a design's optimum).")
    lines += ["", "`run s` excludes compilation (the executable is compiled ahead of time; "
              "`compile s` is that step). XLA temp MB/design is XLA's temporary-buffer size "
              "of the compiled sweep per device divided by `batch_size`: the memory to budget "
              "per design in flight (times `workers` calls in flight). `workers`: host "
              "threads issuing calls at the same time.", ""]
    return "\n".join(lines)


def main(argv=None) -> None:
    args = _parse_args(argv)
    if args.worker:
        print(json.dumps(_worker(args)))
        return
    sys.path.insert(0, str(HERE))
    from _common import machine_info  # noqa: E402 - turns on float64; the driver computes nothing

    machine = machine_info()
    rows = []
    for mode in args.modes.split(","):
        for n_devices in (int(d) for d in args.devices.split(",")):
            for workers in ([None] if args.workers is None
                            else [int(w) for w in args.workers.split(",")]):
                row = _run_configuration(args, n_devices, mode, workers)
                print(json.dumps(row), flush=True)
                rows.append(row)
    n_fields = len(args.fields.split(","))
    report = {
        "description": (
            f"{args.grid} x {args.grid} x {n_fields}-field singlet sweep "
            f"({args.grid * args.grid * n_fields} designs): stop distance x front curvature "
            f"x field {args.fields}, u = 0.2, MarkovSignal(1, 5), WhiteNoise(1e-3)."
        ),
        "preset": args.preset,
        "dtype": args.dtype,
        "options": _options(args),
        "batch_size": (args.batch_size if args.batch_size is not None
                       else next((r["batch_size"] for r in rows if "batch_size" in r), None)),
        "chunks_per_call": (args.chunks_per_call if args.chunks_per_call is not None
                            else next((r.get("chunks_per_call") for r in rows
                                       if "batch_size" in r), None)),
        "machine": machine,
        "rows": rows,
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    stem = "sweep_bench" + (f"_{args.tag}" if args.tag else "")
    (RESULTS / f"{stem}.json").write_text(json.dumps(report, indent=2, default=str) + "\n")
    (RESULTS / f"{stem}.md").write_text(_markdown(report))
    print(_markdown(report))


if __name__ == "__main__":
    main()

"""Where one warm call's time goes, by pipeline stage, from XLA's own per-thunk trace.

XLA's CPU runtime runs a compiled program as a sequence of *thunks* (one per fusion, dot,
FFT, ...). ``jax.profiler`` records each thunk's start and duration. This script traces
``--calls`` warm calls of each program, keeps the leaf thunks (not the conditionals and
loops that contain them), and attributes wall time by a sweep over the timeline: where
thunks overlap (XLA's runtime may run independent thunks on two pool threads, even on one
core), each instant is shared equally among those running, so the attributed times add up
to the busy time, which a plain sum of durations does not. Each thunk is then named by the
library's named scopes in its HLO metadata (``coarse_otf``, ``fine_se``, inside
``check_grid`` or ``interpolation_estimate`` or neither, and ``strength``; ``backward`` when
it belongs to reverse mode's transpose), and by its kind (XLA loop fusion, YNNPACK fusion,
dot, FFT, ...).

The untraced warm time (fastest of ``--calls`` calls) is given beside the traced busy time:
the profiler's own overhead is the difference.

Usage (from the repository root; ~1 min, one core)::

    taskset -c 1 .venv/bin/python benchmarks/thunk_profile.py

Writes ``results/thunk_profile.{json,md}``.
"""

from __future__ import annotations

import argparse
import collections
import gzip
import json
import math
import re
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402

import jmse_jax as jj  # noqa: E402

#: HLO opcodes whose thunks contain others (their time is their children's).
CONTAINERS = ("conditional", "while", "call")
_INSTRUCTION = re.compile(r"\s*(?:ROOT )?%([\w.\-]+) = .*? ([a-z][\w-]*)\(")


def _programs(baseline_b: int):
    """``{label: (function of the aberrations, aberrations)}`` at the Fig. 1 point."""
    ab = jj.Seidel(**common.FIG1)
    signal, noise = common.fig1_signal(), common.fig1_noise()

    def default(a):
        return jj.jmse(a, common.FIG1_FIELD, common.FIG1_U, signal, noise)

    def baseline(a):
        return jj.baseline_jmse(a, common.FIG1_FIELD, common.FIG1_U, signal, noise,
                                B=baseline_b)

    return {
        "default value": (default, ab),
        "default value_and_grad": (jax.value_and_grad(default), ab),
        f"B = {baseline_b} value": (baseline, ab),
        f"B = {baseline_b} value_and_grad": (jax.value_and_grad(baseline), ab),
    }


def _instructions(hlo_text: str) -> dict[str, tuple[str, str]]:
    """``{instruction name: (opcode, its op_name metadata)}`` from compiled HLO text.

    Instructions that XLA's passes created without metadata (the dots it forms from
    contractions, for one) take their first operand's, up to a few producers back."""
    found, operands = {}, {}
    for line in hlo_text.splitlines():
        match = _INSTRUCTION.match(line)
        if match and match.group(1) not in found:
            meta = re.search(r'op_name="([^"]*)"', line)
            found[match.group(1)] = (match.group(2), meta.group(1) if meta else "")
            arguments = line[match.end():].split(")", 1)[0]
            operands[match.group(1)] = re.findall(r"%([\w.\-]+)", arguments)

    def op_name(name, depth=4):
        if found[name][1] or depth == 0:
            return found[name][1]
        for operand in operands[name]:
            if operand in found and (inherited := op_name(operand, depth - 1)):
                return inherited
        return ""

    return {name: (opcode, op_name(name)) for name, (opcode, _) in found.items()}


def _stage(op_name: str) -> str:
    """``[backward] [check grid: | estimate: | strength] coarse OTF | fine S_e | other``."""
    if "strength" in op_name:
        return "strength"
    part = ("coarse OTF" if "coarse_otf" in op_name
            else "fine S_e" if "fine_se" in op_name else "other")
    if "check_grid" in op_name:
        part = "check grid: " + part
    elif "interpolation_estimate" in op_name:
        part = "estimate: " + part
    return ("backward " if "transpose(" in op_name else "") + part


def _kind(name: str, opcode: str) -> str:
    if name.startswith("ynn_fusion"):
        return "YNNPACK fusion"
    if opcode == "fusion":
        return "XLA loop fusion"
    return opcode


def _exclusive_times(events) -> list[float]:
    """Each event's share of the wall clock: overlapping events split each instant."""
    edges = sorted({t for e in events for t in (e[0], e[0] + e[1])})
    share = [0.0] * len(events)
    order = sorted(range(len(events)), key=lambda i: events[i][0])
    active, k = [], 0
    for left, right in zip(edges, edges[1:], strict=False):
        while k < len(order) and events[order[k]][0] <= left:
            active.append(order[k])
            k += 1
        active = [i for i in active if events[i][0] + events[i][1] > left]
        if active:
            part = (right - left) / len(active)
            for i in active:
                share[i] += part
    return share


def profile(fn, args, calls: int, with_stages: bool) -> dict:
    timing = common.time_compiled(fn, args, budget_s=math.inf, max_repeats=calls,
                                  min_repeats=calls)
    compiled = timing["compiled"]
    instructions = _instructions(compiled.as_text())
    stages = {_stage(op_name) for _, op_name in instructions.values()}
    if with_stages and "coarse OTF" not in stages:
        raise RuntimeError("no thunk carries the library's `coarse_otf` scope: have the named "
                           "scopes in jmse_jax/_merit.py changed? Update _stage to match.")
    with tempfile.TemporaryDirectory() as folder:
        jax.profiler.start_trace(folder)
        for _ in range(calls):
            jax.block_until_ready(compiled(*args))
        jax.profiler.stop_trace()
        trace = next(Path(folder).rglob("*.trace.json.gz"))
        events = json.loads(gzip.decompress(trace.read_bytes()))["traceEvents"]
    leaves = [(e["ts"], e["dur"], e["name"]) for e in events
              if e.get("ph") == "X" and e["name"] in instructions
              and instructions[e["name"]][0] not in CONTAINERS]
    shares = _exclusive_times(leaves)
    by_stage, by_kind = collections.Counter(), collections.Counter()
    count_stage = collections.Counter()
    for (_, _, name), share in zip(leaves, shares, strict=True):
        opcode, op_name = instructions[name]
        by_stage[_stage(op_name)] += share / calls
        count_stage[_stage(op_name)] += 1 / calls
        by_kind[_kind(name, opcode)] += share / calls
    return dict(
        untraced_min_us=timing["warm_min_s"] * 1e6,
        busy_us=sum(shares) / calls,
        thunks_per_call=len(leaves) / calls,
        leaf_thunks_in_program=sum(1 for op, _ in instructions.values()
                                   if op not in CONTAINERS),
        stages={k: dict(us=v, thunks=count_stage[k]) for k, v in by_stage.most_common()},
        kinds=dict(by_kind.most_common()),
    )


def _lines(report: dict) -> list[str]:
    lines = ["# Where one warm call's time goes (XLA thunk trace)", "",
             "Fig. 1 point, " + common.machine_line(report["machine"], report["load_at_end"]),
             f"{report['calls']} traced calls per program (`benchmarks/thunk_profile.py`); "
             "overlapping thunks share each instant, so the stage times add up to the busy "
             "time. The untraced time is the fastest of as many calls without the profiler.",
             ""]
    for label, p in report["programs"].items():
        lines += [f"## {label}", "",
                  f"Untraced {p['untraced_min_us']:.0f} µs; traced busy {p['busy_us']:.0f} µs "
                  f"in {p['thunks_per_call']:.0f} thunk runs per call.", "",
                  "| stage | µs | share | thunk runs |", "|---|---:|---:|---:|"]
        for stage, s in p["stages"].items():
            lines.append(f"| {stage} | {s['us']:.0f} | {s['us'] / p['busy_us']:.0%} | "
                         f"{s['thunks']:.0f} |")
        lines += ["", "| kind | µs |", "|---|---:|"]
        lines += [f"| {kind} | {us:.0f} |" for kind, us in p["kinds"].items()]
        lines.append("")
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=200)
    parser.add_argument("--baseline-b", type=int, default=64)
    args = parser.parse_args(argv)
    report = dict(machine=common.machine_info(), calls=args.calls, programs={})
    for label, (fn, ab) in _programs(args.baseline_b).items():
        report["programs"][label] = profile(fn, (ab,), args.calls, label.startswith("default"))
        print(label, f"{report['programs'][label]['untraced_min_us']:.0f} us", flush=True)
    report["load_at_end"] = common.load_average()
    common.write_report("thunk_profile", report, _lines(report))


if __name__ == "__main__":
    main()

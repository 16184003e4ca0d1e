"""Where the test suite's time goes: JAX tracing, lowering and XLA compilation per test.

The suite is compile-bound. This file is both a pytest plugin that records every trace,
lowering and backend compilation (``jax.monitoring`` duration events) with the test that
caused it, and each test's wall time and end (the workers' timelines), one JSON-lines file
per xdist worker, and the script that summarises them.

Run the suite with it as ``make test`` runs it (from the repository root)::

    PYTHONPATH=benchmarks .venv/bin/python -m pytest -q -n auto --dist loadfile \\
        -p no:cacheprovider -p suite_compile_probe
    .venv/bin/python benchmarks/suite_compile_probe.py      # summary (markdown on stdout)

The events go to ``$JMSE_JAX_COMPILE_PROBE_DIR`` (default ``benchmarks/results/
suite_compile``); each run of the plugin replaces its worker's file. A program served from
the persistent compilation cache still records a compile event, with the (short) time it
took to load it.
"""

from __future__ import annotations

import collections
import glob
import json
import os
import pathlib
import time

_DIR = pathlib.Path(os.environ.get(
    "JMSE_JAX_COMPILE_PROBE_DIR",
    pathlib.Path(__file__).resolve().parent / "results" / "suite_compile"))
_EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
    "/jax/core/compile/backend_compile_duration": "compile",
}
_state = {"test": "<collection>", "out": None, "start": None}


def _listener(event, duration, **kwargs):
    kind = _EVENTS.get(event)
    if kind is not None and _state["out"] is not None:
        record = {"test": _state["test"], "kind": kind, "s": duration,
                  "fun": str(kwargs.get("fun_name", ""))}
        _state["out"].write(json.dumps(record) + "\n")
        _state["out"].flush()


def pytest_configure(config):
    import jax.monitoring

    _DIR.mkdir(parents=True, exist_ok=True)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    _state["out"] = open(_DIR / f"events_{worker}.jsonl", "w")  # noqa: SIM115
    jax.monitoring.register_event_duration_secs_listener(_listener)


def pytest_runtest_logstart(nodeid, location):
    _state["test"] = nodeid
    _state["start"] = time.time()


def pytest_runtest_logfinish(nodeid, location):
    """The test's wall time (setup, call and teardown) and when it ended, for the workers'
    timelines (``kind`` "test")."""
    if _state["out"] is not None and _state["start"] is not None:
        end = time.time()
        _state["out"].write(json.dumps({"test": nodeid, "kind": "test", "s": end - _state["start"],
                                        "end": end, "fun": ""}) + "\n")
        _state["out"].flush()


def pytest_unconfigure(config):
    if _state["out"] is not None:
        _state["out"].close()
        _state["out"] = None


def summarise(directory=_DIR, top=25) -> str:
    """Markdown summary of the recorded events: totals, the programs compiled most, the
    tests and files that spend most on compilation (with the files' wall time), and each
    worker's timeline."""
    events = []
    for path in sorted(glob.glob(str(pathlib.Path(directory) / "events_*.jsonl"))):
        worker = pathlib.Path(path).stem.removeprefix("events_")
        with open(path) as f:
            events.extend({**json.loads(line), "worker": worker} for line in f if line.strip())
    if not events:
        raise SystemExit(f"no events in {directory}: run the suite with -p suite_compile_probe")
    tests = [e for e in events if e["kind"] == "test"]
    if any(e["worker"].startswith("gw") for e in tests):  # xdist's controller sees them all
        tests = [e for e in tests if e["worker"].startswith("gw")]
    events = [e for e in events if e["kind"] != "test"]
    totals = collections.Counter()
    for e in events:
        totals[e["kind"]] += e["s"]
    lines = ["# Test suite: trace, lowering and compilation time", "",
             "| kind | seconds | events |", "|---|---:|---:|"]
    for kind in ("trace", "lower", "compile"):
        n = sum(1 for e in events if e["kind"] == kind)
        lines.append(f"| {kind} | {totals[kind]:.0f} | {n} |")
    by_fun = collections.defaultdict(list)
    by_test = collections.Counter()
    by_file = collections.Counter()
    for e in events:
        by_test[e["test"]] += e["s"]
        by_file[e["test"].split("::")[0]] += e["s"]
        if e["kind"] == "compile":
            by_fun[e["fun"]].append(e["s"])
    lines += ["", "## Programs by compile time", "", "| program | compiles | seconds | largest |",
              "|---|---:|---:|---:|"]
    for fun, times in sorted(by_fun.items(), key=lambda kv: -sum(kv[1]))[:top]:
        lines.append(f"| `{fun}` | {len(times)} | {sum(times):.1f} | {max(times):.1f} |")
    wall = collections.Counter()
    for e in tests:
        wall[e["test"].split("::")[0]] += e["s"]
    lines += ["", "## Files (trace + lower + compile; wall time of their tests)", "",
              "| file | compile-side seconds | wall seconds |", "|---|---:|---:|"]
    files = sorted(set(by_file) | set(wall), key=lambda k: -max(by_file[k], wall[k]))
    lines += [f"| {k} | {by_file[k]:.0f} | {wall[k]:.0f} |" for k in files[:top]]
    if tests:
        lines += _timelines(tests)
    lines += ["", "## Tests (trace + lower + compile)", "", "| test | seconds |", "|---|---:|"]
    lines += [f"| {k} | {v:.1f} |" for k, v in by_test.most_common(top)]
    return "\n".join(lines) + "\n"


def _timelines(tests) -> list[str]:
    """Per worker: the files in the order it ran them, its busy time and when it finished,
    counted from the first test's start on any worker."""
    origin = min(e["end"] - e["s"] for e in tests)
    last = max(e["end"] for e in tests)
    by_worker = collections.defaultdict(list)
    for e in tests:
        by_worker[e.get("worker", "?")].append(e)
    lines = ["", "## Workers", "",
             f"All tests ran in {last - origin:.0f} s of wall time (first start to last end).",
             "", "| worker | busy seconds | finished at | files, in order |", "|---|---:|---:|---|"]
    for worker, items in sorted(by_worker.items()):
        items.sort(key=lambda e: e["end"])
        files = list(dict.fromkeys(e["test"].split("::")[0].split("/")[-1] for e in items))
        lines.append(f"| {worker} | {sum(e['s'] for e in items):.0f} | "
                     f"{max(e['end'] for e in items) - origin:.0f} | {', '.join(files)} |")
    return lines


if __name__ == "__main__":
    print(summarise(), end="")

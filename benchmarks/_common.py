"""Shared pieces of the benchmark scripts: machine description, timing, the problem bank.

Imported by ``accuracy_speed.py``, ``paper_figures.py`` and ``run_all.py`` (run from the
repository root; see ``benchmarks/README.md``). Importing this module turns on float64 (the
library never does; benchmarks and tests do).
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import math
import os
import pathlib
import platform
import statistics
import subprocess
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")

import numpy as np  # noqa: E402

import jmse_jax as jj  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
TESTS = ROOT / "tests"

#: The paper's Fig. 1 point (Berkner & Shroff, Fig. 1; SPEC section 5).
FIG1 = dict(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
FIG1_FIELD = 0.95
FIG1_U = 0.2


#: A polar grid with every count past the presets' (nodes, fine S_e nodes, overlap rule,
#: closed-form peaks): the audits' reference (``shape_routes.py``, ``shortcut_margin.py``,
#: ``default_climb.py``); session 79 found it and one a step finer to agree within 1e-9 on
#: every design it checked.
CONVERGED_POLAR = dict(nodes=(160, 64), se_nodes=(6400, 960), overlap_nodes=(128, 128),
                       overlap_floor=128, peaks=True)


def fig1_signal():
    return jj.MarkovSignal(1.0, 5.0)


def fig1_noise():
    return jj.WhiteNoise(1e-3)


# --------------------------------------------------------------------------------------
# Machine description
# --------------------------------------------------------------------------------------


def _cpu_model() -> str | None:
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None


def _commit() -> dict:
    def git(*args):
        try:
            return subprocess.run(["git", *args], capture_output=True, text=True, check=True,
                                  cwd=ROOT).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return None

    if os.environ.get("JMSE_COMMIT"):
        # A copy of the tree whose .git is missing or stale (the lent GPU machine's): the
        # caller names the commit.
        return dict(commit=os.environ["JMSE_COMMIT"],
                    dirty=os.environ.get("JMSE_DIRTY", "0") not in ("", "0"))
    # --no-optional-locks: read only, never refresh the index (another process may commit).
    status = git("--no-optional-locks", "status", "--porcelain", "--untracked-files=no")
    return dict(commit=git("rev-parse", "HEAD"), dirty=None if status is None else bool(status))


def load_average() -> dict:
    """The 1/5/15-minute load averages and ``uptime``'s line (the timings' noise level)."""
    try:
        one, five, fifteen = os.getloadavg()
    except OSError:
        one = five = fifteen = None
    try:
        line = subprocess.run(["uptime"], capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        line = None
    return dict(load_1min=one, load_5min=five, load_15min=fifteen,
                uptime=line.strip() if line else None)


def machine_info() -> dict:
    """Platform, CPU model, CPU count, versions, dtype, git commit, date and load."""
    import scipy

    return dict(
        platform=platform.platform(),
        cpu_model=_cpu_model(),
        cpu_count=os.cpu_count(),
        nproc=len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        python=sys.version.split()[0],
        jax_version=jax.__version__,
        jaxlib_version=getattr(jax.lib, "__version__", None) or _jaxlib_version(),
        numpy_version=np.__version__,
        scipy_version=scipy.__version__,
        jmse_jax_version=jj.__version__,
        devices=[str(d) for d in jax.devices()],
        backend=jax.default_backend(),
        device_kind=jax.devices()[0].device_kind,
        dtype="float64" if jax.config.jax_enable_x64 else "float32",
        **_commit(),
        date=datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        load_at_start=load_average(),
    )


def machine_line(machine: dict, load_at_end: dict) -> str:
    """One sentence for a report's heading: CPU, CPUs used, jax, dtype, commit, date, load."""
    m = machine
    return (f"{m['cpu_model']}, {m['nproc']} CPU(s) used, jax {m['jax_version']}, "
            f"{m['dtype']}, commit `{m['commit'][:10]}`, {m['date']}. Load average at start "
            f"{m['load_at_start']['load_1min']:.2f}, at end {load_at_end['load_1min']:.2f}.")


def _jaxlib_version():
    try:
        import jaxlib

        return jaxlib.__version__
    except ImportError:
        return None


# --------------------------------------------------------------------------------------
# Timing
# --------------------------------------------------------------------------------------


def time_compiled(fn, args, *, budget_s: float = 2.0, max_repeats: int = 7,
                  min_repeats: int = 1, warmup: bool = True) -> dict:
    """Compile ``fn`` for ``args`` ahead of time, then time warm calls of the executable.

    The compile time is that of ``jax.jit(fn).lower(*args).compile()`` (tracing included).
    One untimed call then warms the executable (unless ``warmup`` is False: for long runs,
    where the first execution's overhead is negligible), and repeats run until ``max_repeats``
    or until ``budget_s`` seconds are spent (at least ``min_repeats``); the warm time is their
    median. Every call is closed by ``jax.block_until_ready``.

    Returns a dict with ``compiled`` (the executable), ``compile_s``, ``warm_s`` (median),
    ``warm_min_s``, ``repeats``, ``temp_bytes`` (XLA's scratch memory estimate) and
    ``value`` (the output, on the host).
    """
    start = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_s = time.perf_counter() - start
    times = []
    spent = 0.0
    if warmup:
        value = jax.block_until_ready(compiled(*args))
    else:
        start = time.perf_counter()
        value = jax.block_until_ready(compiled(*args))
        times.append(time.perf_counter() - start)
        spent += times[-1]
    while len(times) < max_repeats and (len(times) < min_repeats or spent < budget_s):
        start = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        times.append(time.perf_counter() - start)
        spent += times[-1]
    try:
        temp_bytes = int(compiled.memory_analysis().temp_size_in_bytes)
    except (AttributeError, TypeError):
        temp_bytes = None
    return dict(compiled=compiled, compile_s=compile_s, warm_s=statistics.median(times),
                warm_min_s=min(times), repeats=len(times), temp_bytes=temp_bytes,
                value=jax.tree_util.tree_map(np.asarray, value))


# --------------------------------------------------------------------------------------
# The problem bank (tests/problems.py)
# --------------------------------------------------------------------------------------


class Case:
    """One bank problem as the benchmarks use it: arguments of ``jmse`` and its reference."""

    def __init__(self, name, arguments, reference=None, convergence=None, source=None):
        self.name = name
        self.arguments = arguments  # (aberrations, field, u, signal, noise)
        self.reference = reference
        self.convergence = convergence  # estimated relative error of the reference
        self.reference_source = source

    @property
    def converged(self) -> bool:
        """Enters the worst-case error: the reference is converged, or its error unknown."""
        if self.reference is None:
            return False
        return self.convergence is None or self.convergence <= CONVERGED_RTOL

    def describe(self) -> dict:
        ab, field, u, signal, noise = self.arguments
        return dict(
            name=self.name,
            aberrations={f.name: float(getattr(ab, f.name)) for f in dataclasses.fields(ab)
                         if np.ndim(getattr(ab, f.name)) == 0 and float(getattr(ab, f.name))},
            field=float(field), u=float(u), signal=repr(signal), noise=repr(noise),
            reference=self.reference, reference_convergence=self.convergence,
            reference_source=self.reference_source, converged=self.converged,
        )


#: A reference counts as converged (and its case enters the worst-case error) at most this
#: estimated relative error; replaced by ``problems.CONVERGED_RTOL`` when the bank has one.
CONVERGED_RTOL = 1e-6

_REFERENCE_CACHE = RESULTS / "reference_cache.json"


def _import_problems():
    if str(TESTS) not in sys.path:
        sys.path.insert(0, str(TESTS))
    import problems

    return problems


def _as_arguments(item):
    """``(aberrations, field, u, signal, noise)`` from a bank entry (object or dict)."""
    if hasattr(item, "arguments"):
        return tuple(item.arguments())
    get = item.get if isinstance(item, dict) else lambda key: getattr(item, key)
    aberrations = get("aberrations")
    if callable(aberrations) and not isinstance(aberrations, jj.AbstractAberrations):
        aberrations = aberrations()
    if isinstance(aberrations, dict):
        aberrations = jj.Seidel(**aberrations)
    signal, noise = get("signal"), get("noise")
    return aberrations, float(get("field")), float(get("u")), signal, noise


def _strict_options(problems):
    return dict(getattr(problems, "STRICT_OPTIONS", None) or dict(preset="high"))


def load_bank(*, limit: int | None = None, reference_fallback: str = "strict") -> list[Case]:
    """The tests' problem bank with references.

    Reads ``tests/problems.py`` (``PROBLEMS``, or a ``BANK`` list of objects/dicts with
    ``name, aberrations, field, u, signal, noise, reference``). Cases whose reference is not
    filled in yet get one computed here (``reference_fallback``: ``"strict"`` uses the bank's
    ``STRICT_OPTIONS`` and estimates its convergence against ``preset="high"``; ``"high"``
    uses the high preset alone, convergence unknown), cached in
    ``benchmarks/results/reference_cache.json`` keyed by the case's arguments.
    """
    global CONVERGED_RTOL
    problems = _import_problems()
    CONVERGED_RTOL = getattr(problems, "CONVERGED_RTOL", CONVERGED_RTOL)
    items = list(getattr(problems, "PROBLEMS", None) or problems.BANK)
    if limit is not None:
        items = items[:limit]
    cache = json.loads(_REFERENCE_CACHE.read_text()) if _REFERENCE_CACHE.exists() else {}
    cases, missing = [], []
    for item in items:
        name = item["name"] if isinstance(item, dict) else item.name
        arguments = _as_arguments(item)
        reference = convergence = None
        source = None
        try:
            if isinstance(item, dict):
                reference = item.get("reference")
            else:
                reference = item.reference
                convergence = getattr(item, "convergence", None)
            source = "tests/problems.py"
        except (KeyError, AttributeError):
            reference = None
        if reference is not None:
            reference = float(reference)
            convergence = 0.0 if convergence is None else float(convergence)
        case = Case(name, arguments, reference, convergence, source)
        if reference is None:
            missing.append(case)
        cases.append(case)
    if missing:
        strict = _strict_options(problems)
        fns = {"strict": jax.jit(lambda *a: jj.jmse(*a, **strict)),
               "high": jax.jit(lambda *a: jj.jmse(*a, preset="high"))}
        changed = False
        for case in missing:
            key = case.name + "|" + repr(case.arguments)
            entry = cache.get(key)
            if entry is None or (reference_fallback == "strict" and "strict" not in entry):
                entry = dict(entry or {})
                start = time.perf_counter()
                entry["high"] = float(fns["high"](*case.arguments))
                if reference_fallback == "strict":
                    entry["strict"] = float(fns["strict"](*case.arguments))
                    entry["strict_options"] = repr(strict)
                print(f"  reference {case.name}: {entry} ({time.perf_counter() - start:.1f} s)",
                      flush=True)
                cache[key] = entry
                changed = True
            if "strict" in entry:
                case.reference = entry["strict"]
                case.convergence = abs(entry["high"] - entry["strict"]) / abs(entry["strict"])
                case.reference_source = "computed (STRICT_OPTIONS; problems.py had none)"
            else:
                case.reference = entry["high"]
                case.convergence = None
                case.reference_source = "computed (preset high; problems.py had none)"
        if changed:
            RESULTS.mkdir(parents=True, exist_ok=True)
            _REFERENCE_CACHE.write_text(json.dumps(cache, indent=1))
    return cases


def relative_error(value, reference) -> float:
    return abs(float(value) - reference) / abs(reference)


def fmt_seconds(seconds: float | None) -> str:
    if seconds is None or not math.isfinite(seconds):
        return "–"
    if seconds < 1e-3:
        return f"{seconds * 1e6:.0f} µs"
    if seconds < 1.0:
        return f"{seconds * 1e3:.2f} ms"
    return f"{seconds:.2f} s"


def write_json(path: pathlib.Path, data) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2, default=_json_default))


def write_report(name: str, report: dict, lines: list[str]) -> None:
    """Print a study's markdown ``lines`` and write ``results/<name>.json`` (``report``, with
    the load average at the end added to its ``machine`` entry) and ``results/<name>.md``."""
    report["machine"]["load_at_end"] = load_average()
    print("\n".join(lines))
    write_json(RESULTS / f"{name}.json", report)
    (RESULTS / f"{name}.md").write_text("\n".join(lines) + "\n")


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (tuple, set)):
        return list(value)
    return repr(value)

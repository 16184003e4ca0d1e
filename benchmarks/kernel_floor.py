"""How far XLA's code for the overlap engine's inner loop is from a hand-written kernel.

The default's time at the Fig. 1 point is mostly the overlap engine's chord sums: for each
chord, the phase at ``J`` Gauss nodes from its values at ``Q = 4`` collocation points (a
``J x Q`` interpolation), ``cos(2 pi x)`` and ``sin(2 pi x)`` by one polynomial each
(``_numerics.cos_sin_2pi_stacked``) and the sums with the Gauss and chord weights. This
study times that loop as the library runs it (``_otf._phase_integral``'s value, under
``jax.jit``) against the same arithmetic written in C (the same degree-17 polynomial for
``sin(pi r)``, the same exact range reduction), compiled by gcc with ``-O3 -march=native``,
one thread and two (OpenMP), on the first grid's shape: 384 nodes x 36 chords x 14 Gauss
nodes (193 536 points). Inputs are random phases of up to 4 waves; the three results are
compared with NumPy's ``cos``/``sin`` in float64.

Run from the repository root (needs gcc; about 1 minute):

    .venv/bin/python benchmarks/kernel_floor.py

It times the one-thread pair in a child process pinned to one CPU (``taskset -c 1``), then
everything again unpinned (XLA may use its thread pool; OpenMP takes two threads), in
alternated rounds, and writes ``results/kernel_floor.{json,md}``. Not part of the library:
a measurement of what a custom kernel (``jax.ffi``) could gain.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import pathlib
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import _common as common
import jax
import jax.numpy as jnp
import numpy as np

from jmse_jax import _numerics, _otf

#: The first grid's shape: nodes, chords per node (2 halves x 18), Gauss nodes per chord,
#: collocation points per chord (the C kernel is written for Q = 4, as the engine's Seidel
#: phases use).
NODES, CHORDS, J, Q = 384, 36, 14, 4

_C_SOURCE = r"""
#include <stddef.h>
#include <omp.h>
/* out[c] = wc[c] sum_j w[j] cos(2 pi D_cj), out[nc + c] = the same with sin, where
   D_cj = sum_q M[j][q] phi[q][c] (phases stored collocation-point-major, so that the loop
   runs along the chords and vectorises). sin(pi r) = r sum_k P[k] r^(2k), r the phase minus
   its nearest integer (exact), and cos(2 pi y) = 1 - 2 sin(pi r)^2. */
static void sums(const double *restrict phi, size_t nc, size_t stride,
                 const double *restrict wc, const double *restrict M,
                 const double *restrict w, int nt, const double *restrict P,
                 double *restrict oc, double *restrict os) {
  const double magic = 6755399441055744.0; /* 1.5 * 2^52: round to nearest */
  const double *p0 = phi, *p1 = phi + stride, *p2 = phi + 2 * stride, *p3 = phi + 3 * stride;
  for (size_t c = 0; c < nc; c++) { oc[c] = 0.0; os[c] = 0.0; }
  for (int j = 0; j < nt; j++) {
    const double m0 = M[4 * j], m1 = M[4 * j + 1], m2 = M[4 * j + 2], m3 = M[4 * j + 3];
    const double wj = w[j];
#pragma GCC ivdep
    for (size_t c = 0; c < nc; c++) {
      double d = m0 * p0[c] + m1 * p1[c] + m2 * p2[c] + m3 * p3[c];
      double y = d - 0.25;
      double r1 = d - ((d + magic) - magic), r2 = y - ((y + magic) - magic);
      double z1 = r1 * r1, z2 = r2 * r2;
      double a1 = P[8], a2 = P[8];
      for (int k = 7; k >= 0; k--) { a1 = a1 * z1 + P[k]; a2 = a2 * z2 + P[k]; }
      double s1 = a1 * r1, s2 = a2 * r2;
      oc[c] += wj * (1.0 - 2.0 * s1 * s1);
      os[c] += wj * (1.0 - 2.0 * s2 * s2);
    }
  }
  for (size_t c = 0; c < nc; c++) { oc[c] *= wc[c]; os[c] *= wc[c]; }
}

void chord_sums(const double *phi, size_t nc, const double *wc, const double *M,
                const double *w, int nt, const double *P, double *out, int threads) {
#pragma omp parallel num_threads(threads)
  {
    int t = omp_get_thread_num(), n = omp_get_num_threads();
    size_t lo = nc * t / n, hi = nc * (t + 1) / n;
    sums(phi + lo, hi - lo, nc, wc + lo, M, w, nt, P, out + lo, out + nc + lo);
  }
}
"""


def _build(directory: pathlib.Path) -> ctypes.CDLL:
    source, library = directory / "kernel.c", directory / "kernel.so"
    source.write_text(_C_SOURCE)
    subprocess.run(["gcc", "-O3", "-march=native", "-fno-math-errno", "-ffp-contract=fast",
                    "-fopenmp", "-shared", "-fPIC", "-o", str(library), str(source)],
                   check=True)
    lib = ctypes.CDLL(str(library))
    pointer = ctypes.POINTER(ctypes.c_double)
    lib.chord_sums.argtypes = [pointer, ctypes.c_size_t, pointer, pointer, pointer,
                               ctypes.c_int, pointer, pointer, ctypes.c_int]
    return lib


def _problem():
    """Random phases and chord weights, the engine's own rule along the chords (the
    Lagrange matrix from its Q Chebyshev points to its J Gauss nodes, the moments and the
    Gauss weights they sum to) and the sine polynomial's coefficients."""
    rng = np.random.default_rng(0)
    phase = rng.uniform(-4.0, 4.0, (NODES, CHORDS, Q))
    chord_w = rng.uniform(0.0, 0.1, (NODES, CHORDS))
    *_, interp, moment = _otf._overlap_rule(CHORDS // 2, J, Q)
    w = moment.sum(axis=1)
    coefficients = np.asarray(_numerics._SIN_PI_R, np.float64)
    return phase, chord_w, interp, moment, w, coefficients


def _oracle(phase, chord_w, interp, w):
    d = np.einsum("ncq,jq->ncj", phase, interp)
    cos = np.einsum("ncj,j->nc", np.cos(2 * np.pi * d), w) * chord_w
    sin = np.einsum("ncj,j->nc", np.sin(2 * np.pi * d), w) * chord_w
    return cos.sum(axis=1), sin.sum(axis=1)


def _best_of(fn, calls: int) -> float:
    best = math.inf
    for _ in range(calls):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def _measure(rounds: int, calls: int, threads: list[int]) -> dict:
    phase, chord_w, interp, moment, w, coefficients = _problem()
    if coefficients.shape != (9,):
        raise SystemExit(f"expected 9 coefficients of sin(pi r), got {coefficients.shape}")
    exact_cos, exact_sin = _oracle(phase, chord_w, interp, w)

    xla = jax.jit(lambda ph, cw: _otf._phase_integral(ph, cw, jnp.asarray(interp),
                                                       jnp.asarray(moment)))
    ph, cw = jnp.asarray(phase), jnp.asarray(chord_w)
    re, im = xla(ph, cw)

    def run_xla():
        jax.block_until_ready(xla(ph, cw))

    with tempfile.TemporaryDirectory() as directory:
        lib = _build(pathlib.Path(directory))
        nc = NODES * CHORDS
        soa = np.ascontiguousarray(phase.reshape(nc, Q).T)
        flat_w = np.ascontiguousarray(chord_w.reshape(nc))
        m = np.ascontiguousarray(interp)
        out = np.zeros(2 * nc)
        ptr = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731

        def run_c(n):
            lib.chord_sums(ptr(soa), nc, ptr(flat_w), ptr(m), ptr(w), J, ptr(coefficients),
                           ptr(out), n)

        errors = dict(xla=max(np.abs(np.asarray(re) - exact_cos).max(),
                              np.abs(np.asarray(im) - exact_sin).max()))
        for n in threads:
            run_c(n)
            c_cos = out[:nc].reshape(NODES, CHORDS).sum(axis=1)
            c_sin = out[nc:].reshape(NODES, CHORDS).sum(axis=1)
            errors[f"c_{n}"] = max(np.abs(c_cos - exact_cos).max(),
                                   np.abs(c_sin - exact_sin).max())
        runs = {"xla": run_xla, **{f"c_{n}": (lambda n=n: run_c(n)) for n in threads}}
        times = {name: [] for name in runs}
        for _ in range(rounds):
            for name, fn in runs.items():
                times[name].append(_best_of(fn, calls))
    points = NODES * CHORDS * J
    return dict(points=points, errors=errors,
                median_s={k: statistics.median(v) for k, v in times.items()},
                min_s={k: min(v) for k, v in times.items()}, rounds=rounds, calls=calls)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--calls", type=int, default=60, help="calls per round (best taken)")
    parser.add_argument("--child", choices=["pinned", "unpinned"], help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if shutil.which("gcc") is None:
        raise SystemExit("kernel_floor.py needs gcc to build the C kernel")
    if args.child:
        threads = [1] if args.child == "pinned" else [1, 2]
        print(json.dumps(_measure(args.rounds, args.calls, threads)))
        return

    machine = common.machine_info()
    results = {}
    for mode in ("pinned", "unpinned"):
        command = [sys.executable, __file__, "--child", mode, "--rounds", str(args.rounds),
                   "--calls", str(args.calls)]
        if mode == "pinned":
            if shutil.which("taskset") is None or len(os.sched_getaffinity(0)) < 2:
                continue
            command = ["taskset", "-c", "1", *command]
        done = subprocess.run(command, capture_output=True, text=True, check=True)
        results[mode] = json.loads(done.stdout.strip().splitlines()[-1])

    lines = ["# The overlap engine's inner loop: XLA against a hand-written kernel", "",
             common.machine_line(machine, common.load_average()), "",
             f"{NODES} nodes x {CHORDS} chords x {J} Gauss nodes = {NODES * CHORDS * J} "
             "points, random phases up to 4 waves, float64. Times: median over the rounds "
             "of the best of each round's calls; rounds alternate the methods.", "",
             "| CPUs | method | time | per point | vs XLA | largest error vs NumPy |",
             "|---|---|---|---|---|---|"]
    labels = dict(xla="XLA (`_otf._phase_integral`, value)", c_1="C, one thread",
                  c_2="C, two threads (OpenMP)")
    for mode, result in results.items():
        base = result["median_s"]["xla"]
        for name, seconds in result["median_s"].items():
            lines.append(
                f"| {'one (taskset -c 1)' if mode == 'pinned' else 'all'} | {labels[name]} | "
                f"{common.fmt_seconds(seconds)} | {seconds * 1e9 / result['points']:.2f} ns | "
                f"{base / seconds:.2f}x | {result['errors'][name]:.1e} |")
    common.write_report("kernel_floor", dict(machine=machine, results=results), lines)


if __name__ == "__main__":
    main()

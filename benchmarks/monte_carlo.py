"""Does the JMSE predict the error Wiener restoration really leaves? A Monte-Carlo study.

Run from the repository root::

    .venv/bin/python benchmarks/monte_carlo.py            # full study (~10 min on 2 cores)
    .venv/bin/python benchmarks/monte_carlo.py --quick    # small sizes, a smoke run

Writes ``benchmarks/results/monte_carlo.json``, ``monte_carlo.md`` (tables) and the figures
``monte_carlo_restoration.png`` (scene / capture / restoration for a good and a bad design)
and ``monte_carlo_ratios.png``.

What is simulated (``jmse_jax.monte_carlo_mse``; derivation in ``jmse_jax/_simulate.py``):
scenes drawn from the signal model on a periodic ``n x n`` sensor grid of pitch
``1 / (2 u)`` (``lambda N`` units), blurred by the OTF from ``jmse_jax.otf`` at the grid's DFT
frequencies, white noise of per-pixel variance ``S_n (2 u)**2`` added, Wiener-restored with
``jmse_jax.wiener_filter``. The per-pixel MSE is compared with

- the *discrete* prediction ``(2u/n)**2 sum_k S_e(nu_k)``: its exact expectation (the odd
  ``n`` makes the DFT cells tile the band ``[-u, u]**2``; no aliasing, no pixel MTF, same
  OTF normalisation ``H(0) = 1``);
- the *continuous* prediction ``2 pi JMSE`` (``jmse``, preset "high"): the ``n -> infinity``
  limit; the gap is the midpoint-rule error of the grid, tabulated against ``n``.

Then the merit's assumptions are broken on purpose: the scene is drawn on a 5x finer grid
covering the optics' support (``5 u = 1`` cutoff), blurred there and sampled by point
decimation (aliasing) or by square pixels (aliasing + pixel MTF), and restored with the
filter that ignores both.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jmse_jax as jj  # noqa: E402

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")

FIG1 = dict(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
U = 0.2
NOISE = jj.WhiteNoise(1e-3)
MARKOV = jj.MarkovSignal(1.0, 5.0)
POWERLAW = jj.PowerLawSignal(1e-3, 2.0, 0.01)

#: (name, Seidel coefficients, field, signal): from focus to far from focus.
DESIGNS = [
    ("diffraction_limited", {}, 0.0, MARKOV),
    ("defocus_m0.5", {"w020": -0.5}, 0.0, MARKOV),
    ("defocus_m1", {"w020": -1.0}, 0.0, MARKOV),
    ("defocus_m2", {"w020": -2.0}, 0.0, MARKOV),
    ("fig1", FIG1, 0.95, MARKOV),
    ("defocus_m4", {"w020": -4.0}, 0.0, MARKOV),
    ("defocus_m6", {"w020": -6.0}, 0.0, MARKOV),
    ("fig1_defocus_m6", {**FIG1, "w020": -6.0}, 0.95, MARKOV),
    ("powerlaw_fig1", FIG1, 0.95, POWERLAW),
]

BROKEN_DESIGNS = ("diffraction_limited", "fig1", "defocus_m6")

#: Designs whose S_e has sharp ridges along OTF zeros (far from focus): the grid-size study
#: goes one size further for them.
RIDGE_DESIGNS = ("defocus_m2", "defocus_m4", "defocus_m6")


def _signal_description(signal):
    if isinstance(signal, jj.MarkovSignal):
        return f"MarkovSignal({signal.variance}, {signal.correlation_length})"
    return f"PowerLawSignal({signal.amplitude}, {signal.exponent}, {signal.knee})"


def _commit():
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                              check=True, cwd=os.path.dirname(RESULTS)).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def _summary(res, prediction):
    ratio = float(res.mse / prediction)
    rel_se = float(res.standard_error / prediction)
    return dict(ratio=ratio, ratio_standard_error=rel_se,
                z=(ratio - 1.0) / rel_se, within_3_se=bool(abs(ratio - 1.0) <= 3.0 * rel_se))


def agreement_study(size, trials, batch, discretisation_sizes, extra_size, seed):
    rows = []
    for index, (name, coefficients, field, signal) in enumerate(DESIGNS):
        ab = jj.Seidel(**coefficients)
        start = time.perf_counter()
        res = jj.monte_carlo_mse(ab, field, U, signal, NOISE, jax.random.key(seed + index),
                                 size=size, trials=trials, batch=batch, jmse_preset="high")
        elapsed = time.perf_counter() - start
        jmse_value = float(res.continuous_prediction) / jj.PIXEL_MSE_PER_JMSE
        discretisation = {}
        sizes = list(discretisation_sizes)
        if name in RIDGE_DESIGNS and extra_size:
            sizes.append(extra_size)
        for n in sizes:
            value = (float(res.discrete_prediction) if n == size else
                     float(jj.predicted_pixel_mse(ab, field, U, signal, NOISE, size=n)))
            discretisation[str(n)] = dict(
                discrete_prediction=value,
                relative_gap=value / float(res.continuous_prediction) - 1.0,
            )
        row = dict(
            name=name, seidel=coefficients, field=field, u=U, signal=_signal_description(signal),
            noise_variance=float(NOISE.variance), size=size, trials=res.trials,
            jmse=jmse_value,
            continuous_prediction=float(res.continuous_prediction),
            discrete_prediction=float(res.discrete_prediction),
            measured_mse=float(res.mse), standard_error=float(res.standard_error),
            predicted_standard_error=float(res.predicted_standard_error),
            vs_discrete=_summary(res, res.discrete_prediction),
            vs_continuous=_summary(res, res.continuous_prediction),
            discretisation_gap=float(res.discrete_prediction / res.continuous_prediction) - 1.0,
            discretisation=discretisation,
            seconds=elapsed,
        )
        rows.append(row)
        print(f"{name:22s} JMSE={jmse_value:.6e} "
              f"measured/discrete={row['vs_discrete']['ratio']:.4f}"
              f" +- {row['vs_discrete']['ratio_standard_error']:.4f}  measured/2piJMSE="
              f"{row['vs_continuous']['ratio']:.4f}  gap={row['discretisation_gap']:+.2e}"
              f"  ({elapsed:.0f} s)", flush=True)
    return rows


def large_grid_study(size, trials, batch, seed):
    """Far from focus ``S_e`` has ridges of width ~1e-3 along the OTF zeros: at n = 257 the
    DFT cells (2u/n = 1.6e-3) do not resolve them and the finite sensor's MSE differs from
    2 pi JMSE by the midpoint-rule error. Repeat the ridge designs on a finer frequency grid."""
    rows = []
    designs = {name: (c, f, s) for name, c, f, s in DESIGNS}
    for index, name in enumerate(("defocus_m4", "defocus_m6")):
        coefficients, field, signal = designs[name]
        start = time.perf_counter()
        res = jj.monte_carlo_mse(jj.Seidel(**coefficients), field, U, signal, NOISE,
                                 jax.random.key(seed + index), size=size, trials=trials,
                                 batch=batch, jmse_preset="high")
        row = dict(name=name, size=size, trials=res.trials, measured_mse=float(res.mse),
                   standard_error=float(res.standard_error),
                   discrete_prediction=float(res.discrete_prediction),
                   continuous_prediction=float(res.continuous_prediction),
                   vs_discrete=_summary(res, res.discrete_prediction),
                   vs_continuous=_summary(res, res.continuous_prediction),
                   discretisation_gap=float(res.discrete_prediction / res.continuous_prediction)
                   - 1.0,
                   seconds=time.perf_counter() - start)
        rows.append(row)
        print(f"{name:22s} n={size} measured/discrete={row['vs_discrete']['ratio']:.4f} +- "
              f"{row['vs_discrete']['ratio_standard_error']:.4f}  measured/2piJMSE="
              f"{row['vs_continuous']['ratio']:.4f}  gap={row['discretisation_gap']:+.2e}",
              flush=True)
    return rows


def broken_study(size, trials, batch, oversample, seed):
    rows = []
    designs = {name: (c, f, s) for name, c, f, s in DESIGNS}
    for index, name in enumerate(BROKEN_DESIGNS):
        coefficients, field, signal = designs[name]
        ab = jj.Seidel(**coefficients)
        for sampling in jj._simulate.SAMPLINGS:
            start = time.perf_counter()
            res = jj.monte_carlo_mse(ab, field, U, signal, NOISE, jax.random.key(seed + index),
                                     size=size, trials=trials, batch=batch,
                                     oversample=oversample, sampling=sampling,
                                     jmse_preset="high")
            row = dict(
                name=name, sampling=sampling, oversample=oversample, size=size,
                trials=res.trials,
                measured_mse=float(res.mse), standard_error=float(res.standard_error),
                discrete_prediction=float(res.discrete_prediction),
                continuous_prediction=float(res.continuous_prediction),
                alias_aware_prediction=float(res.model_prediction),
                vs_discrete=_summary(res, res.discrete_prediction),
                vs_continuous=_summary(res, res.continuous_prediction),
                vs_alias_aware=_summary(res, res.model_prediction),
                seconds=time.perf_counter() - start,
            )
            rows.append(row)
            print(f"{name:20s} {sampling:6s} measured/merit={row['vs_discrete']['ratio']:.4f} +- "
                  f"{row['vs_discrete']['ratio_standard_error']:.4f}  measured/alias-aware="
                  f"{row['vs_alias_aware']['ratio']:.4f}  ({row['seconds']:.0f} s)", flush=True)
    return rows


def restoration_figure(size, seed, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    key_scene, key_noise = jax.random.split(jax.random.key(seed))
    scene = jj.random_scene(MARKOV, (size, size), U, key_scene)
    designs = [("fig1 (good: the paper's optimum)", jj.Seidel(**FIG1), 0.95),
               ("fig1 with w020 = -6 (bad: far from focus)",
                jj.Seidel(**{**FIG1, "w020": -6.0}), 0.95)]
    fig, axes = plt.subplots(len(designs), 3, figsize=(11, 7.4), constrained_layout=True)
    limits = np.percentile(np.asarray(scene), [0.5, 99.5])
    panels = {}
    for row, (title, ab, field) in enumerate(designs):
        capture = jj.simulate_capture(scene, ab, field, U, NOISE, key_noise)
        restored = jj.restore(capture, ab, field, U, MARKOV, NOISE)
        mse_capture = float(jnp.mean((capture - scene) ** 2))
        mse_restored = float(jnp.mean((restored - scene) ** 2))
        predicted = float(jj.predicted_pixel_mse(ab, field, U, MARKOV, NOISE, size=size))
        panels[title] = dict(mse_capture=mse_capture, mse_restored=mse_restored,
                             predicted_discrete=predicted)
        for col, (image, label) in enumerate([
            (scene, "scene (MarkovSignal(1, 5))"),
            (capture, f"capture: blur + noise, MSE {mse_capture:.4f}"),
            (restored, f"Wiener restoration, MSE {mse_restored:.4f}\n"
                       f"(expected {predicted:.4f})"),
        ]):
            ax = axes[row, col]
            ax.imshow(np.asarray(image), cmap="gray", vmin=limits[0], vmax=limits[1],
                      interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(label, fontsize=9)
        axes[row, 0].set_ylabel(title, fontsize=9)
    fig.suptitle(f"u = {U}, WhiteNoise({NOISE.variance}), {size} x {size} pixels", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return panels


def ratio_figure(rows, broken, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.2), constrained_layout=True,
                                 gridspec_kw=dict(width_ratios=(3, 2)))
    x = np.arange(len(rows))
    for offset, key, label in ((-0.12, "vs_discrete", "measured / discrete prediction"),
                               (0.12, "vs_continuous", "measured / 2 pi JMSE")):
        ratios = [r[key]["ratio"] for r in rows]
        errors = [3 * r[key]["ratio_standard_error"] for r in rows]
        ax.errorbar(x + offset, ratios, yerr=errors, fmt="o", capsize=3, label=label)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(x, [r["name"] for r in rows], rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("ratio (error bars: 3 standard errors)")
    ax.set_title("Assumptions held: Monte-Carlo MSE / merit")
    ax.legend(fontsize=8)
    labels = [f"{r['name']}\n{r['sampling']}" for r in broken]
    xb = np.arange(len(broken))
    bx.errorbar(xb - 0.12, [r["vs_discrete"]["ratio"] for r in broken],
                yerr=[3 * r["vs_discrete"]["ratio_standard_error"] for r in broken], fmt="o",
                capsize=3, label="measured / merit (discrete)")
    bx.errorbar(xb + 0.12, [r["vs_alias_aware"]["ratio"] for r in broken],
                yerr=[3 * r["vs_alias_aware"]["ratio_standard_error"] for r in broken], fmt="s",
                capsize=3, label="measured / alias- and pixel-aware model")
    bx.axhline(1.0, color="k", lw=0.8)
    bx.set_yscale("log")
    bx.set_xticks(xb, labels, rotation=45, ha="right", fontsize=7)
    bx.set_title("Assumptions broken (5x finer scene)")
    bx.legend(fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(report):
    lines = ["# Monte-Carlo check of the JMSE", "",
             f"u = {U}, WhiteNoise({NOISE.variance}); per-pixel MSE = 2 pi JMSE "
             f"(+ midpoint-rule error of the {report['settings']['size']}-pixel grid). "
             f"{report['settings']['trials']} trials per design.", "",
             "| design | JMSE | 2 pi JMSE | discrete pred. | measured MSE | meas./discrete "
             "| meas./2piJMSE | grid gap |",
             "|---|---|---|---|---|---|---|---|"]
    for r in report["agreement"]:
        d, c = r["vs_discrete"], r["vs_continuous"]
        lines.append(
            f"| {r['name']} | {r['jmse']:.6e} | {r['continuous_prediction']:.6e} | "
            f"{r['discrete_prediction']:.6e} | {r['measured_mse']:.6e} | "
            f"{d['ratio']:.4f} ± {d['ratio_standard_error']:.4f} | "
            f"{c['ratio']:.4f} ± {c['ratio_standard_error']:.4f} | "
            f"{r['discretisation_gap']:+.1e} |")
    sizes = sorted({n for r in report["agreement"] for n in r["discretisation"]}, key=int)
    lines += ["", "Discrete prediction / 2 pi JMSE - 1 against grid size n:", "",
              "| design | " + " | ".join(f"n = {n}" for n in sizes) + " |",
              "|---|" + "---|" * len(sizes)]
    for r in report["agreement"]:
        gaps = " | ".join(f"{r['discretisation'][n]['relative_gap']:+.1e}"
                          if n in r["discretisation"] else "" for n in sizes)
        lines.append(f"| {r['name']} | {gaps} |")
    lines += ["", "Ridge designs on a finer sensor grid (the midpoint-rule gap closes):", "",
              "| design | n | trials | meas./discrete | meas./2piJMSE | grid gap |",
              "|---|---|---|---|---|---|"]
    for r in report["large_grid"]:
        d, c = r["vs_discrete"], r["vs_continuous"]
        lines.append(f"| {r['name']} | {r['size']} | {r['trials']} | "
                     f"{d['ratio']:.4f} ± {d['ratio_standard_error']:.4f} | "
                     f"{c['ratio']:.4f} ± {c['ratio_standard_error']:.4f} | "
                     f"{r['discretisation_gap']:+.1e} |")
    lines += ["", "Assumptions broken (scene on a 5x finer grid):", "",
              "| design | sampling | measured MSE | meas./merit | meas./alias-aware model |",
              "|---|---|---|---|---|"]
    for r in report["broken"]:
        lines.append(
            f"| {r['name']} | {r['sampling']} | {r['measured_mse']:.6e} | "
            f"{r['vs_discrete']['ratio']:.4f} ± {r['vs_discrete']['ratio_standard_error']:.4f} | "
            f"{r['vs_alias_aware']['ratio']:.4f} ± "
            f"{r['vs_alias_aware']['ratio_standard_error']:.4f} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes (smoke run)")
    parser.add_argument("--seed", type=int, default=20240607)
    args = parser.parse_args(argv)
    if args.quick:
        settings = dict(size=65, trials=32, batch=8, discretisation_sizes=(33, 65),
                        extra_size=129, large_size=129, large_trials=8,
                        broken_size=33, broken_trials=16, figure_size=65)
    else:
        settings = dict(size=257, trials=64, batch=8, discretisation_sizes=(65, 129, 257, 513),
                        extra_size=1025, large_size=1025, large_trials=16,
                        broken_size=97, broken_trials=32, figure_size=257)
    oversample = 5  # 5 u = 1: the fine grid covers the optics' whole support
    os.makedirs(RESULTS, exist_ok=True)
    start = time.perf_counter()
    rows = agreement_study(settings["size"], settings["trials"], settings["batch"],
                           settings["discretisation_sizes"], settings["extra_size"], args.seed)
    large = large_grid_study(settings["large_size"], settings["large_trials"], 2,
                             args.seed + 300)
    broken = broken_study(settings["broken_size"], settings["broken_trials"], 4, oversample,
                          args.seed + 100)
    panels = restoration_figure(settings["figure_size"], args.seed + 200,
                                os.path.join(RESULTS, "monte_carlo_restoration.png"))
    ratio_figure(rows, broken, os.path.join(RESULTS, "monte_carlo_ratios.png"))
    report = dict(
        description="Monte-Carlo per-pixel MSE of Wiener restoration vs the JMSE merit",
        normalisation=("per-pixel MSE = (2u/n)^2 sum_k S_e(nu_k) on an odd n x n periodic "
                       "sensor grid (exact expectation) -> iint_band S_e d^2nu = 2 pi JMSE"),
        pixel_mse_per_jmse=jj.PIXEL_MSE_PER_JMSE,
        machine=dict(platform=platform.platform(), processor=platform.processor(),
                     cpu_count=os.cpu_count(), python=sys.version.split()[0]),
        jax_version=jax.__version__, numpy_version=np.__version__,
        devices=[str(d) for d in jax.devices()],
        dtype="float64", commit=_commit(),
        date=datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        settings=dict(settings, u=U, noise_variance=float(NOISE.variance), seed=args.seed,
                      broken_oversample=oversample,
                      otf_nodes=list(jj._simulate.DEFAULT_OTF_NODES),
                      jmse_preset="high", quick=args.quick),
        agreement=rows,
        all_within_3_se_of_discrete=all(r["vs_discrete"]["within_3_se"] for r in rows),
        all_within_3_se_of_continuous=all(r["vs_continuous"]["within_3_se"] for r in rows),
        max_standard_error=max(r["vs_discrete"]["ratio_standard_error"] for r in rows),
        large_grid=large,
        broken=broken,
        restoration_figure=panels,
        seconds=time.perf_counter() - start,
    )
    with open(os.path.join(RESULTS, "monte_carlo.json"), "w") as handle:
        json.dump(report, handle, indent=2)
    with open(os.path.join(RESULTS, "monte_carlo.md"), "w") as handle:
        handle.write(markdown(report))
    print(markdown(report))
    print(f"total {report['seconds']:.0f} s")
    return 0 if report["all_within_3_se_of_discrete"] else 1


if __name__ == "__main__":
    raise SystemExit(main())

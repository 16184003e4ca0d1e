"""The paper's singlet design space (Berkner & Shroff Fig. 2): aberration hypercube + JMSE map.

F/4.6 singlet; "thickness of surface 1" (the stop-to-lens distance) 0..3 mm x "curvature of
surface 2" (the lens front) -0.1..0.1 1/mm, 25 x 25 samples; field 0.95. The open choices
are fixed in ``jmse_jax.lens.PAPER_SINGLET`` (N-BK7, EFL 9 mm, centre thickness 1.5 mm,
10 degree full field, d line, back curvature from an F/4.6 solve). For the JMSE map the image
plane sits at the RMS-best focus of field 0.95 (``w020 = -(w040 + (w220 + w222/2) h^2)``),
signal ``MarkovSignal(1, 5)``, noise ``WhiteNoise(1e-3)``, u = 0.2 (SPEC §5's Fig. 1 setting).

Writes ``benchmarks/results/singlet_space.{json,png}``.

Usage: python benchmarks/singlet_space.py [--preset default] [--samples 25]
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import subprocess
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import jmse_jax  # noqa: E402
from jmse_jax import lens as jl  # noqa: E402

RESULTS = pathlib.Path(__file__).resolve().parent / "results"


def machine_info():
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                                cwd=pathlib.Path(__file__).resolve().parent,
                                check=False).stdout.strip()
    except OSError:
        commit = "unknown"
    return {
        "machine": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "jax_version": jax.__version__,
        "backend": jax.default_backend(),
        "devices": [str(d) for d in jax.devices()],
        "dtype": str(jnp.zeros(()).dtype),
        "load_average_1_5_15min": list(os.getloadavg()),
        "commit": commit,
    }


def field_coefficients(stop_distance, front_curvature, field):
    """Wavefront coefficients at ``field`` [waves] of one design (h powers applied)."""
    lens = jl.paper_singlet(stop_distance, front_curvature)
    w = jl.seidel_waves(lens, check=False)
    status = jl.lens_status(lens)
    h = field
    return {
        "astigmatism": w.w222 * h * h,
        "coma": w.w131 * h,
        "spherical": w.w040,
        "field_curvature": w.w220 * h * h,
        "best_focus_defocus": -(w.w040 + (w.w220 + 0.5 * w.w222) * h * h),
        "ok": status.ok,
        "back_curvature": lens.curvatures[1],
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="default", choices=tuple(jmse_jax.PRESETS))
    parser.add_argument("--samples", type=int, default=25)
    parser.add_argument("--batch", type=int, default=25, help="designs per vmap batch")
    args = parser.parse_args()
    p = jl.PAPER_SINGLET
    field, u = p["field"], 0.2
    signal, noise = jmse_jax.MarkovSignal(1.0, 5.0), jmse_jax.WhiteNoise(1e-3)
    stops = jnp.linspace(*p["stop_distance_range"], args.samples)
    curvatures = jnp.linspace(*p["front_curvature_range"], args.samples)
    grid_stop, grid_curv = jnp.meshgrid(stops, curvatures, indexing="ij")

    t0 = time.perf_counter()
    cube = jax.jit(jax.vmap(jax.vmap(lambda s, c: field_coefficients(s, c, field))))(
        grid_stop, grid_curv)
    cube = jax.tree_util.tree_map(np.asarray, cube)
    cube_time = time.perf_counter() - t0

    def jmse_of(design):
        s, c = design
        lens = jl.paper_singlet(s, c)
        w = jl.seidel_waves(lens, check=False)
        best = -(w.w040 + (w.w220 + 0.5 * w.w222) * field * field)
        w = jmse_jax.Seidel(best, w.w040, w.w131, w.w222, w.w220, w.w311, 0.0)
        value = jmse_jax.jmse(w, field, u, signal, noise, preset=args.preset)
        return jnp.where(jl.lens_status(lens).ok, value, jnp.inf)

    designs = (grid_stop.ravel(), grid_curv.ravel())
    sweep = jax.jit(lambda d: jax.lax.map(jmse_of, d, batch_size=args.batch))
    t0 = time.perf_counter()
    compiled = sweep.lower(designs).compile()
    compile_time = time.perf_counter() - t0
    t0 = time.perf_counter()
    jmse_map = np.asarray(jax.block_until_ready(compiled(designs))).reshape(grid_stop.shape)
    sweep_time = time.perf_counter() - t0

    RESULTS.mkdir(parents=True, exist_ok=True)
    extent = [float(curvatures[0]), float(curvatures[-1]), float(stops[0]), float(stops[-1])]
    fig, axes = plt.subplots(2, 3, figsize=(15, 9), constrained_layout=True)
    panels = [("astigmatism", "astigmatism w222 h² [waves]"), ("coma", "coma w131 h [waves]"),
              ("spherical", "spherical w040 [waves]"),
              ("field_curvature", "field curvature w220 h² [waves]"),
              ("best_focus_defocus", "RMS-best defocus w020 [waves]")]
    for ax, (key, title) in zip(axes.ravel(), panels, strict=False):
        im = ax.imshow(cube[key], origin="lower", extent=extent, aspect="auto", cmap="viridis")
        ax.set_title(title)
        ax.set_xlabel("front curvature c (surface 2) [1/mm]")
        ax.set_ylabel("stop distance (thickness of surface 1) [mm]")
        ax.locator_params(axis="x", nbins=5)
        fig.colorbar(im, ax=ax)
    ax = axes.ravel()[-1]
    im = ax.imshow(np.log10(jmse_map), origin="lower", extent=extent, aspect="auto",
                   cmap="magma")
    ax.set_title(f"log10 JMSE, field {field}, u = {u} (RMS-best focus)")
    ax.set_xlabel("front curvature c (surface 2) [1/mm]")
    ax.set_ylabel("stop distance (thickness of surface 1) [mm]")
    ax.locator_params(axis="x", nbins=5)
    fig.colorbar(im, ax=ax)
    fig.suptitle("F/4.6 N-BK7 singlet, EFL 9 mm, 10° full field, d line: aberrations at "
                 f"field {field}")
    png = RESULTS / "singlet_space.png"
    fig.savefig(png, dpi=110)

    best = np.unravel_index(np.argmin(jmse_map), jmse_map.shape)
    report = {
        "description": __doc__.splitlines()[0],
        "choices": {**{k: v for k, v in p.items()}, "glass": "N-BK7 (AbbeGlass 1.5168, 64.17)",
                    "focus": "RMS-best focus at field 0.95",
                    "signal": "MarkovSignal(1, 5)", "noise": "WhiteNoise(1e-3)", "u": u,
                    "jmse_preset": args.preset},
        "samples": args.samples,
        "ranges_waves": {k: [float(np.min(cube[k])), float(np.max(cube[k]))]
                         for k in ("astigmatism", "coma", "spherical", "field_curvature",
                                   "best_focus_defocus")},
        "all_designs_physical": bool(np.all(cube["ok"])),
        "back_curvature_range": [float(np.min(cube["back_curvature"])),
                                 float(np.max(cube["back_curvature"]))],
        "jmse_range": [float(np.min(jmse_map)), float(np.max(jmse_map))],
        "jmse_best_design": {"stop_distance": float(stops[best[0]]),
                             "front_curvature": float(curvatures[best[1]]),
                             "jmse": float(jmse_map[best])},
        "timing_s": {"aberration_cube_incl_compile": cube_time,
                     "jmse_map_compile": compile_time, "jmse_map_run": sweep_time,
                     "per_design_ms": 1e3 * sweep_time / jmse_map.size},
        "jmse_map": jmse_map.tolist(),
        "stop_distances": np.asarray(stops).tolist(),
        "front_curvatures": np.asarray(curvatures).tolist(),
        "environment": machine_info(),
        "png": str(png.relative_to(RESULTS.parent.parent)),
    }
    with open(RESULTS / "singlet_space.json", "w") as f:
        json.dump(report, f, indent=1)
    print(json.dumps({k: v for k, v in report.items() if k not in ("jmse_map",)}, indent=1))


if __name__ == "__main__":
    main()

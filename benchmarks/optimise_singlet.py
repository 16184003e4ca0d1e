"""JMSE-driven optimisation of the paper's F/4.6 singlet: 5 starts, and JMSE vs RMS designs.

Variables: front curvature, stop position and focus (image-plane shift); the back curvature
is solved for F/4.6 at every step. Objective: JMSE averaged over fields 0, 0.7, 1.0
(``MarkovSignal(1, 5)``, ``WhiteNoise(1e-3)``, u = 0.2). Reports, per JMSE preset: the
5-start spread of the optimum, iterations and wall time (first call = with compilation);
the RMS-wavefront-optimal design from the same start and both merits of both designs; a
polychromatic (F, d, C) optimisation; and a bounded one (jaxopt L-BFGS-B).

Writes ``benchmarks/results/optimise_singlet.json``.

Usage: python benchmarks/optimise_singlet.py [--presets fast default]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import jax

jax.config.update("jax_enable_x64", True)

from jmse_jax import lens as jl  # noqa: E402
from jmse_jax._optimise import optimise  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from singlet_space import RESULTS, machine_info  # noqa: E402

VARIABLES = ("curvatures[0]", "stop_position", "image_shift")
#: (stop distance [mm], front curvature [1/mm], image shift [mm]) of the 5 starting designs.
STARTS = ((1.0, 0.05, 0.0), (0.5, -0.08, 0.0), (2.5, -0.02, -0.1), (2.0, 0.07, -0.2),
          (1.5, 0.0, -0.3))
#: A start at the corner of the space (strong positive bending, stop 3 mm in front) that
#: BFGS takes to a different, 8x worse local minimum (front curvature 0.088, stop 3.8 mm in
#: front): the design landscape is multimodal, as lens-design landscapes are. Reported apart.
OTHER_BASIN_START = (3.0, 0.09, -0.2)


def describe(result):
    return {
        "parameters": result.parameters,
        "back_curvature": float(result.lens.curvatures[1]),
        "jmse": result.jmse,
        "jmse_per_field": result.jmse_per_field,
        "rms_wavefront_waves": result.rms_wavefront,
        "start_jmse": result.start_jmse,
        "start_rms_wavefront_waves": result.start_rms_wavefront,
        "iterations": result.iterations,
        "wall_time_s": result.wall_time,
        "result": result.result,
        "solver": result.solver,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", nargs="+", default=["fast", "default"])
    args = parser.parse_args()
    report = {"description": __doc__.splitlines()[0], "variables": VARIABLES,
              "fields": (0.0, 0.7, 1.0), "f_number": 4.6, "u": 0.2,
              "signal": "MarkovSignal(1, 5)", "noise": "WhiteNoise(1e-3)",
              "design_choices": {k: v for k, v in jl.PAPER_SINGLET.items()},
              "environment": machine_info(), "presets": {}}
    for preset in args.presets:
        options = {"preset": preset}
        runs = []
        for stop, curvature, shift in STARTS:
            start = jl.paper_singlet(stop, curvature, image_shift=shift)
            result = optimise(start, VARIABLES, f_number=4.6, jmse_options=options)
            runs.append({"start": {"stop_distance": stop, "front_curvature": curvature,
                                   "image_shift": shift}, **describe(result)})
            print(f"[{preset}] start {stop, curvature, shift}: JMSE {result.jmse:.8e} "
                  f"({result.iterations} it, {result.wall_time:.2f} s, {result.result})",
                  flush=True)
        best = [r["jmse"] for r in runs]
        spread = (max(best) - min(best)) / min(best)
        rerun = optimise(jl.paper_singlet(*STARTS[0][:2], image_shift=STARTS[0][2]),
                         VARIABLES, f_number=4.6, jmse_options=options)
        jmse_design = rerun
        rms_design = optimise(jl.paper_singlet(*STARTS[0][:2], image_shift=STARTS[0][2]),
                              VARIABLES, f_number=4.6, merit="rms", jmse_options=options)
        print(jmse_design.summary())
        print(rms_design.summary(), flush=True)
        entry = {
            "starts": runs,
            "relative_spread_of_best_jmse": spread,
            "first_call_wall_time_s": runs[0]["wall_time_s"],
            "steady_state_wall_time_s": rerun.wall_time,
            "iterations": [r["iterations"] for r in runs],
            "wall_times_s": [r["wall_time_s"] for r in runs],
            "jmse_optimal": describe(jmse_design),
            "rms_optimal": describe(rms_design),
            "jmse_ratio_rms_over_jmse_design": rms_design.jmse / jmse_design.jmse,
            "rms_ratio_jmse_over_rms_design": (jmse_design.rms_wavefront
                                               / rms_design.rms_wavefront),
        }
        if preset == args.presets[0]:
            other = optimise(jl.paper_singlet(*OTHER_BASIN_START[:2],
                                              image_shift=OTHER_BASIN_START[2]),
                             VARIABLES, f_number=4.6, jmse_options=options)
            entry["other_local_minimum"] = {"start": OTHER_BASIN_START, **describe(other)}
            print(f"[{preset}] start {OTHER_BASIN_START}: JMSE {other.jmse:.8e} (other basin)",
                  flush=True)
            poly = optimise(jl.paper_singlet(*STARTS[0][:2], image_shift=STARTS[0][2]),
                            VARIABLES, f_number=4.6, jmse_options=options,
                            wavelengths=(jl.FRAUNHOFER_F, jl.FRAUNHOFER_D, jl.FRAUNHOFER_C))
            print(poly.summary(), flush=True)
            entry["polychromatic_FdC"] = describe(poly)
            bounded = optimise(jl.paper_singlet(*STARTS[0][:2], image_shift=STARTS[0][2]),
                               VARIABLES, f_number=4.6, jmse_options=options,
                               bounds={"stop_position": (-3.0, 0.0),
                                       "curvatures[0]": (-0.1, 0.1)})
            print(bounded.summary(), flush=True)
            entry["bounded_lbfgsb"] = describe(bounded)
        report["presets"][preset] = entry
        print(f"[{preset}] 5-start spread {spread:.2e}; JMSE design {jmse_design.jmse:.6e} "
              f"(RMS {jmse_design.rms_wavefront:.4f} waves) vs RMS design "
              f"{rms_design.jmse:.6e} (RMS {rms_design.rms_wavefront:.4f} waves)", flush=True)
    RESULTS.mkdir(parents=True, exist_ok=True)
    with open(RESULTS / "optimise_singlet.json", "w") as f:
        json.dump(report, f, indent=1, default=float)


if __name__ == "__main__":
    main()

"""Compact reproduction of Berkner & Shroff's Fig. 1 and Fig. 4 for ``jmse-jax reproduce``.

The full experiments (finer grids, machine records) live in
``benchmarks/paper_figures.py``; this module only needs the installed package, so the console
script works without the repository. Plots use matplotlib's Agg backend (no display needed).
Callers switch on float64 (the library never does).
"""

from __future__ import annotations

import functools
import json
import math
import os
import time
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._aberrations import Seidel, Zernike, noll_to_nm, wavefront
from ._merit import baseline_jmse, jmse, jmse_options, run_time_checks
from ._otf import otf
from ._pupil import PolarGrid, SquareGrid, zernike_fit
from ._quadrature import frequency_quadrature
from ._spectra import MarkovSignal, WhiteNoise, error_spectral_density

__all__ = ["FIG1", "FIG1_FIELD", "FIG1_U", "FIG1_REFERENCE", "run"]

#: The paper's Fig. 1 operating point: Seidel coefficients [waves], field, u (SPEC §5).
FIG1 = dict(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
FIG1_FIELD = 0.95
FIG1_U = 0.2
#: Converged float64 JMSE of the Fig. 1 point (SPEC §5).
FIG1_REFERENCE = 2.6539432e-3

PAPER_RULES = ("rectangle", "trapezoid", "gauss", "gauss_polar")
RULE_LABELS = {"rectangle": "rectangle", "trapezoid": "trapezoid", "gauss": "Gauss ⊗ Gauss",
               "gauss_polar": "Gauss radial × trapezoid angular",
               "polar": "polar Gauss panels (ours)"}
THRESHOLDS = (1e-3, 1e-6)


def fig1_spectra():
    """``MarkovSignal(1, 5)`` and ``WhiteNoise(1e-3)``, the paper's signal and noise."""
    return MarkovSignal(1.0, 5.0), WhiteNoise(1e-3)


def _warm_times(methods, args: tuple, rounds: int, calls: int = 5) -> dict:
    """JMSE and warm times of each method (``(name, function)`` pairs) at ``args``: a row
    ``jmse``, ``time_value_s``, ``time_value_and_grad_s`` per name.

    The jitted value and ``value_and_grad`` of every method are compiled by their first call;
    then ``rounds`` rounds run the programs in turn, each ``calls`` times, and a program's
    time is its fastest call (the least disturbed by other work on the host). Taking the
    programs in alternation spreads the host's drift over them alike: on a shared 2-core
    host, in three fresh processes each, the default's value over B = 64's at the Fig. 1
    point read 2.96-5.41 with each program timed in one run of 11 calls, and 2.52-2.94 with
    11 rounds of 5 calls in alternation.

    The programs are traced without ``jmse``'s run-time checks (``run_time_checks(False)``):
    the points timed are the package's own, inside the checked range, and a program with
    the checks' host callback is not kept in the console script's compile cache (a second
    ``jmse-jax reproduce`` took 105 s with them against 61 s without, session 106). At the
    Fig. 1 point the checks cost the default's value about 3 % and its ``value_and_grad``
    about 1 % (session 105)."""
    programs = {}
    for name, fn in methods:
        programs[name, "value_and_grad"] = jax.jit(jax.value_and_grad(fn))
        programs[name, "value"] = jax.jit(fn)
    with run_time_checks(False):  # read when the programs are traced: by their first call
        results = {key: jax.block_until_ready(fn(*args)) for key, fn in programs.items()}
    best = dict.fromkeys(programs, math.inf)
    for _ in range(rounds):
        for key, fn in programs.items():
            for _ in range(calls):
                start = time.perf_counter()
                jax.block_until_ready(fn(*args))
                best[key] = min(best[key], time.perf_counter() - start)
    return {name: dict(jmse=float(results[name, "value_and_grad"][0]),
                       time_value_s=best[name, "value"],
                       time_value_and_grad_s=best[name, "value_and_grad"])
            for name, _ in methods}


def fig1_comparison(rounds: int = 5, log: Callable = print) -> dict:
    """JMSE and timings of the baseline (B = 64) and the default preset at the Fig. 1 point:
    each time is the fastest of ``5 * rounds`` warm calls, the four programs (value and
    ``value_and_grad`` of each method) taken in turn, 5 calls at a time (``_warm_times``)."""
    # Every input is an argument of the compiled programs, as in an optimiser's loop and in
    # benchmarks/accuracy_speed.py. Closed over, XLA folds the spectra and the nodes into
    # constants: at this point the default's warm times were then about 2 % lower and the
    # baseline's 6 % (one process, 15 alternated rounds).
    args = (Seidel(**FIG1), FIG1_FIELD, FIG1_U, *fig1_spectra())
    calls = 5
    rows = _warm_times((("baseline B=64", functools.partial(baseline_jmse, B=64)),
                        ("jmse default", jmse)), args, rounds, calls)
    log("Fig. 1 operating point of Berkner & Shroff (field 0.95, u = 0.2,"
        " MarkovSignal(1, 5), WhiteNoise(1e-3)); float64")
    log(f"{'method':<16}{'JMSE':>14}{'rel. err':>11}{'value':>11}{'value+grad':>13}")
    for name, row in rows.items():
        row["relative_error"] = row["jmse"] / FIG1_REFERENCE - 1.0
        log(f"{name:<16}{row['jmse']:>14.7e}{row['relative_error']:>+11.2e}"
            f"{row['time_value_s'] * 1e3:>9.2f}ms{row['time_value_and_grad_s'] * 1e3:>11.2f}ms")
    base, ours = rows["baseline B=64"]["jmse"], rows["jmse default"]["jmse"]
    log(f"baseline vs default: {base / ours - 1.0:+.2%}")
    return dict(reference=FIG1_REFERENCE, methods=rows, device=str(jax.devices()[0]),
                repeats=calls * rounds, rounds=rounds, calls_per_round=calls,
                run_time_checks=False)


# --------------------------------------------------------------------------------------
# Fig. 1: OPD and log10 S_e
# --------------------------------------------------------------------------------------


def fig1_maps(path, n_pupil: int = 128, n_freq: int = 121, wide: float = 0.6,
              preset: str = "default") -> dict:
    """Plot the OPD [waves] and ``log10 S_e`` (over the band and over ``|nu| < wide``).

    The title's JMSE is ``jmse(preset=preset)``, returned as ``jmse_<preset>``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    aberrations = Seidel(**FIG1)
    field, u = FIG1_FIELD, FIG1_U
    signal, noise = fig1_spectra()
    coords = np.linspace(-1.0, 1.0, n_pupil)
    px, py = np.meshgrid(coords, coords, indexing="xy")
    opd = np.asarray(wavefront(aberrations, px, py, field))
    opd = np.where(px**2 + py**2 <= 1.0, opd, np.nan)
    overlap = jmse_options("high")["overlap_nodes"]
    # The tilt only multiplies H by a phase ramp: |H| and S_e are unchanged (as in jmse).
    otf_at = jax.jit(lambda a, x, y: otf(a.without_tilt(), x, y, field, nodes=overlap))

    def error_density(half_width):
        freqs = np.linspace(-half_width, half_width, n_freq)
        fx, fy = np.meshgrid(freqs, freqs, indexing="xy")
        h = otf_at(aberrations, jnp.asarray(fx), jnp.asarray(fy))
        return np.asarray(error_spectral_density(h, signal(fx, fy), noise(fx, fy)))

    s_e_band, s_e_wide = error_density(u), error_density(wide)
    value = float(jmse(aberrations, field, u, signal, noise, preset=preset))
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    im = axes[0].imshow(opd, origin="lower", extent=(-1, 1, -1, 1), cmap="RdBu_r")
    axes[0].set_title("OPD [waves]")
    axes[0].set_xlabel("x (pupil)")
    axes[0].set_ylabel("y (pupil; field along +y)")
    fig.colorbar(im, ax=axes[0])
    im = axes[1].imshow(np.log10(s_e_band), origin="lower", extent=(-u, u, -u, u), cmap="gray")
    axes[1].set_title("log10 S_e over the sensor band |ν_x|, |ν_y| < u")
    axes[1].set_xlabel("ν_x [cutoff units 1/(λN)]")
    axes[1].set_ylabel("ν_y")
    fig.colorbar(im, ax=axes[1])
    im = axes[2].imshow(np.log10(s_e_wide), origin="lower", extent=(-wide, wide, -wide, wide),
                        cmap="gray")
    axes[2].add_patch(Rectangle((-u, -u), 2 * u, 2 * u, fill=False, edgecolor="r"))
    axes[2].set_title("log10 S_e beyond the band (red: the band)\nridges = OTF zeros",
                      fontsize=9)
    axes[2].set_xlabel("ν_x [cutoff units 1/(λN)]")
    fig.colorbar(im, ax=axes[2])
    fig.suptitle(f"Berkner & Shroff Fig. 1 point: field {field}, u = {u}, "
                 f"JMSE ({preset}) = {value:.6e}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    finite = opd[np.isfinite(opd)]
    return dict(seidel=FIG1, field=field, u=u, signal=repr(signal), noise=repr(noise),
                **{f"jmse_{preset}": value},
                opd_min=float(finite.min()), opd_max=float(finite.max()),
                opd_rms=float(np.sqrt(np.mean((finite - finite.mean()) ** 2))),
                log10_s_e_band_min=float(np.log10(s_e_band.min())),
                log10_s_e_band_max=float(np.log10(s_e_band.max())),
                pupil_grid=n_pupil, frequency_grid=n_freq, wide_half_width=wide)


# --------------------------------------------------------------------------------------
# Fig. 4 right: JMSE versus the number of frequency nodes
# --------------------------------------------------------------------------------------


def _rule_nodes(rule, u, p):
    """Nodes and weights of ``rule`` with ``p**2`` OTF nodes per quadrant (flat, host)."""
    if rule == "polar":
        nu_x, nu_y, w = frequency_quadrature("polar", u, (p, max(p // 2, 1)))
    else:
        nu_x, nu_y, w = frequency_quadrature(rule, u, p)
    return np.asarray(nu_x), np.asarray(nu_y), np.asarray(w)


def jmse_versus_nodes(aberrations, field, u, signal, noise, rules, ps, overlap_nodes):
    """JMSE of each rule at each ``p``, from one OTF evaluation over all their nodes.

    ``JMSE = sum(w S_e) / (2 pi)`` over the folded quadrant (the Seidel wavefront is even in
    x); the OTF is that of the de-tilted wavefront, as in ``jmse``.
    """
    segments, xs, ys, ws = [], [], [], []
    offset = 0
    for rule in rules:
        for p in ps:
            x, y, w = _rule_nodes(rule, u, p)
            segments.append((rule, p, offset, offset + x.size))
            offset += x.size
            xs.append(x)
            ys.append(y)
            ws.append(w)
    nu_x, nu_y = jnp.asarray(np.concatenate(xs)), jnp.asarray(np.concatenate(ys))
    w = np.concatenate(ws)

    @jax.jit
    def error_density(aberrations, nu_x, nu_y):
        h = otf(aberrations.without_tilt(), nu_x, nu_y, field, nodes=overlap_nodes)
        return error_spectral_density(h, signal(nu_x, nu_y), noise(nu_x, nu_y))

    s_e = np.asarray(error_density(aberrations, nu_x, nu_y))
    values = {rule: {} for rule in rules}
    for rule, p, start, stop in segments:
        values[rule][p] = float(np.sum(w[start:stop] * s_e[start:stop]) / (2.0 * math.pi))
    return values, int(nu_x.size)


def first_stays_below(ps, errors, threshold):
    """Smallest tested ``p`` from which every tested ``p' >= p`` has error < threshold."""
    answer = None
    for p in sorted(ps, reverse=True):
        if errors[p] < threshold:
            answer = p
        else:
            break
    return answer


def rule_rows(values, reference, ps) -> dict:
    """Per rule: the JMSE and relative error at each ``p`` (keys as strings, for JSON) and
    the ``p`` from which the error stays below each of ``THRESHOLDS``."""
    rows = {}
    for rule, by_p in values.items():
        errors = {p: abs(by_p[p] - reference) / abs(reference) for p in ps}
        rows[rule] = dict(
            jmse={str(p): by_p[p] for p in ps},
            relative_error={str(p): errors[p] for p in ps},
            first_stays_below={f"{t:g}": first_stays_below(ps, errors, t) for t in THRESHOLDS},
        )
    return rows


def fig4_right(ps: Sequence[int], defocus_values=(-6.0, -2.75), reference_preset="high",
               log: Callable = print) -> dict:
    """JMSE versus ``p`` for the paper's four rules and ours, at each defocus [waves].

    The converged value is ``jmse(preset=reference_preset)`` (at -2.75 the SPEC's value).
    """
    rules = PAPER_RULES + ("polar",)
    overlap = jmse_options("high")["overlap_nodes"]
    signal, noise = fig1_spectra()
    out: dict[str, Any] = dict(
        u=FIG1_U, field=FIG1_FIELD, ps=list(ps), overlap_nodes=list(overlap),
        signal=repr(signal), noise=repr(noise), rules=list(rules), defocus={})
    for defocus in defocus_values:
        aberrations = Seidel(**{**FIG1, "w020": defocus})
        start = time.perf_counter()
        if defocus == FIG1["w020"]:
            reference, source = FIG1_REFERENCE, "SPEC §5 (converged float64)"
        else:
            reference = float(jmse(aberrations, FIG1_FIELD, FIG1_U, signal, noise,
                                   preset=reference_preset))
            source = f"jmse(preset={reference_preset!r})"
        values, n_nodes = jmse_versus_nodes(aberrations, FIG1_FIELD, FIG1_U, signal, noise,
                                            rules, ps, overlap)
        rows = rule_rows(values, reference, ps)
        out["defocus"][str(defocus)] = dict(reference=reference, reference_source=source,
                                            otf_evaluations=n_nodes, rules=rows,
                                            seconds=time.perf_counter() - start)
        log(f"      defocus {defocus:+.2f}: reference {reference:.9e}, {n_nodes} OTF nodes, "
            f"{time.perf_counter() - start:.1f} s")
    return out


def plot_fig4_right(data, path, dpi: int = 110):
    """Two columns (one per defocus): JMSE versus p on top, relative error below.

    A defocus block with ``"presets"`` (``{name: {"jmse", "relative_error",
    "otf_nodes_per_quadrant"}}``) also gets a star per preset, at the ``p`` whose ``p**2``
    equals the preset's OTF nodes per quadrant."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ps = data["ps"]
    fig, axes = plt.subplots(2, len(data["defocus"]), figsize=(11, 7.5), sharex=True,
                             squeeze=False)
    for column, (defocus, block) in enumerate(data["defocus"].items()):
        top, bottom = axes[0, column], axes[1, column]
        for i, rule in enumerate(data["rules"]):
            style = dict(color=f"C{i}", marker="os^Dv"[i % 5], markersize=4,
                         linewidth=2.0 if rule == "polar" else 1.2)
            row = block["rules"][rule]
            top.plot(ps, [row["jmse"][str(p)] for p in ps], label=RULE_LABELS[rule], **style)
            bottom.plot(ps, [max(row["relative_error"][str(p)], 1e-16) for p in ps], **style)
        reference = block["reference"]
        top.axhline(reference, color="k", linestyle="--", linewidth=1, label="converged value")
        for j, (preset, entry) in enumerate(block.get("presets", {}).items()):
            if entry.get("otf_nodes_per_quadrant"):
                p_equiv = math.sqrt(entry["otf_nodes_per_quadrant"])
                style = dict(marker="*", markersize=13, color=f"C{6 + j}", linestyle="none",
                             markeredgecolor="k",
                             label=f"preset {preset} (polar + OTF interpolation)")
                top.plot([p_equiv], [entry["jmse"]], **style)
                bottom.plot([p_equiv], [max(entry["relative_error"], 1e-16)], **style)
        spread = [block["rules"][r]["jmse"][str(p)] for r in data["rules"] for p in ps
                  if p >= 8] or [reference]
        low, high = min(spread + [reference]), max(spread + [reference])
        margin = 0.1 * (high - low) + 1e-3 * abs(reference)
        top.set_ylim(low - margin, high + margin)
        top.set_title(f"defocus w020 = {float(defocus):g} waves (Fig. 1 aberrations, u = 0.2)")
        top.set_ylabel("JMSE")
        top.grid(alpha=0.3)
        for t in THRESHOLDS:
            bottom.axhline(t, color="0.5", linestyle=":", linewidth=1)
        bottom.set_yscale("log")
        bottom.set_xscale("log", base=2)
        bottom.set_xlabel("p (nodes per axis per quadrant; p² OTF nodes per quadrant)")
        bottom.set_ylabel("relative error")
        bottom.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Berkner & Shroff Fig. 4 (right): JMSE versus frequency nodes")
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


# --------------------------------------------------------------------------------------
# Fig. 4 left: OPD error d_Omega[K, L]
# --------------------------------------------------------------------------------------

#: The paper's accuracy goal for the rebuilt wavefront [waves RMS].
WAVE_TENTH = 0.1


def _hypercube_sample(n, seed, dims=5, half_width=6.0):
    """Latin hypercube sample of ``n`` points in ``[-half_width, half_width]**dims``: each axis
    is cut into ``n`` equal strata and every stratum holds exactly one point."""
    rng = np.random.default_rng(seed)
    strata = np.stack([rng.permutation(n) for _ in range(dims)], axis=1)
    unit = (strata + rng.random((n, dims))) / n
    return half_width * (2.0 * unit - 1.0)  # (n, dims): w020, w040, w131, w222, w220


def _resolvable_noll(rings, arms):
    """Noll indices 1 ... 15 (radial order <= 4) that a rings x arms polar grid resolves."""
    keep = []
    for j in range(1, 16):
        n, m = noll_to_nm(j)
        if n <= 2 * rings - 1 and 2 * abs(m) < arms:
            keep.append(j)
    return tuple(keep)


def opd_error(n_designs: int = 64, rings_list: Sequence[int] = tuple(range(2, 11)),
              arms_list: Sequence[int] = tuple(range(4, 12)) + tuple(range(12, 41, 2)),
              seed: int = 20240607, field: float = FIG1_FIELD, log: Callable = print) -> dict:
    """The paper's Fig. 4 (left): OPD error ``d_Omega[K, L]`` of rebuilding the wavefront from
    ``L`` rings x ``K`` arms of polar samples, by piecewise-cubic interpolation (as the
    paper's bicubic) and by our Zernike quadrature projection.

    ``d_Omega`` is the mean over ``n_designs`` Latin-hypercube Seidel designs (w020, w040,
    w131, w222, w220 in [-6, 6] waves, at ``field``) of the RMS difference [waves] from the
    exact wavefront at the centres of the 64 x 64 grid's cells inside the disc. Needs scipy
    (Clough-Tocher interpolation).
    """
    from scipy.interpolate import CloughTocher2DInterpolator, NearestNDInterpolator

    rings_list, arms_list = tuple(rings_list), tuple(arms_list)
    coefficients = _hypercube_sample(n_designs, seed)
    keys = ("w020", "w040", "w131", "w222", "w220")
    # NumPy coefficient columns: the Seidel polynomial then evaluates in NumPy (fast on host).
    aberrations = Seidel(**{k: coefficients[:, i, None] for i, k in enumerate(keys)})
    reference_grid = SquareGrid(64)
    inside = reference_grid.weights > 0
    x_ref, y_ref = reference_grid.x[inside], reference_grid.y[inside]
    opd_ref = np.asarray(aberrations(x_ref[None, :], y_ref[None, :], field))

    def rms(approx):  # (n_designs, points) -> mean over designs of the RMS over the disc
        return float(np.mean(np.sqrt(np.mean((approx - opd_ref) ** 2, axis=1))))

    # Zernike projection c_j = (1/pi) sum_i w_i W_i Z_j(x_i, y_i), zernike_fit's quadrature,
    # as one matrix per grid; the 15 polynomials (n <= 4) are evaluated once, through the
    # public Zernike model, at the union of every grid's points and at the reference cells.
    grids = {(r, a): PolarGrid(r, a) for r in rings_list for a in arms_list}
    all_x = np.concatenate([x_ref] + [g.x.ravel() for g in grids.values()])
    all_y = np.concatenate([y_ref] + [g.y.ravel() for g in grids.values()])
    basis_all = np.stack([np.asarray(wavefront(Zernike(np.eye(15)[q]), all_x, all_y))
                          for q in range(15)])  # (15, points), Noll 1 .. 15
    basis_ref = basis_all[:, : x_ref.size]
    offsets = np.cumsum([x_ref.size] + [g.size for g in grids.values()])
    basis_at = {key: basis_all[:, start:stop]
                for key, start, stop in zip(grids, offsets[:-1], offsets[1:], strict=True)}
    checks = {}

    d_cubic = np.full((len(rings_list), len(arms_list)), np.nan)
    d_zernike = np.full_like(d_cubic, np.nan)
    start = time.perf_counter()
    for i, rings in enumerate(rings_list):
        for k, arms in enumerate(arms_list):
            grid = grids[rings, arms]
            xs, ys = grid.x.ravel(), grid.y.ravel()
            samples = np.asarray(aberrations(xs[None, :], ys[None, :], field))  # (n, L K)
            points = np.column_stack([xs, ys])
            # tol 1e-4 on the gradient estimate: 3-10x faster, d_Omega unchanged to 1e-7.
            cubic = CloughTocher2DInterpolator(points, samples.T, tol=1e-4)(x_ref, y_ref)
            outside = np.isnan(cubic[:, 0])
            if np.any(outside):
                cubic[outside] = NearestNDInterpolator(points, samples.T)(x_ref[outside],
                                                                          y_ref[outside])
            d_cubic[i, k] = rms(cubic.T)
            rows = [j - 1 for j in _resolvable_noll(rings, arms)]
            projection = (basis_at[rings, arms][rows] * grid.weights.ravel()).T / math.pi
            fitted = samples @ projection  # (n, terms)
            d_zernike[i, k] = rms(fitted @ basis_ref[rows])
            if (rings, arms) in ((6, 40), (3, 10), (10, 40)):
                # Same numbers as the public zernike_fit (first design)?
                api = zernike_fit(samples[0].reshape(rings, arms), grid,
                                     tuple(j + 1 for j in rows)).coefficients
                checks[f"L={rings},K={arms}"] = float(np.max(np.abs(np.asarray(api)
                                                                    - fitted[0])))
    seconds = time.perf_counter() - start
    def findings(d):
        ok = d <= WAVE_TENTH
        fewest = None
        for i, rings in enumerate(rings_list):
            for k, arms in enumerate(arms_list):
                if ok[i, k] and (fewest is None or rings * arms < fewest[0] * fewest[1]):
                    fewest = (rings, arms)
        min_arms = {str(r): next((a for k, a in enumerate(arms_list)
                                  if np.all(ok[i, k:])), None)
                    for i, r in enumerate(rings_list)}
        paper = None
        if 6 in rings_list and 40 in arms_list:
            paper = float(d[rings_list.index(6), arms_list.index(40)])
        return dict(fewest_samples=None if fewest is None else dict(
                        rings=fewest[0], arms=fewest[1], samples=fewest[0] * fewest[1]),
                    min_arms_per_rings=min_arms, d_at_paper_choice_L6_K40=paper)

    out = dict(n_designs=n_designs, seed=seed, field=field, coefficient_range=[-6.0, 6.0],
               coefficients=list(keys), reference_grid="64 x 64 cell centres inside the disc",
               rings=list(rings_list), arms=list(arms_list), units="waves RMS",
               d_cubic=d_cubic.tolist(), d_zernike=d_zernike.tolist(),
               zernike_fit_agreement=checks,
               cubic=findings(d_cubic), zernike=findings(d_zernike), seconds=seconds)
    log(f"fig4 left ({seconds:.1f} s): cubic needs {out['cubic']['fewest_samples']}, "
          f"Zernike needs {out['zernike']['fewest_samples']}; at (6, 40): cubic "
          f"{out['cubic']['d_at_paper_choice_L6_K40']}, Zernike "
          f"{out['zernike']['d_at_paper_choice_L6_K40']}")
    return out


def plot_fig4_left(data, path, dpi: int = 110):
    """Two panels (cubic, Zernike): d_Omega over (K arms, L rings), the lambda/10 contour in
    red, the paper's (L, K) = (6, 40) as a star and the fewest samples below lambda/10 as a
    circle."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    rings, arms = np.array(data["rings"]), np.array(data["arms"])
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6), sharey=True)
    panels = (("d_cubic", "piecewise-cubic interpolation (as the paper's bicubic)"),
              ("d_zernike", "Zernike quadrature projection (ours)"))
    norm = LogNorm(vmin=1e-16, vmax=10.0)
    for ax, (key, title) in zip(axes, panels, strict=True):
        d = np.clip(np.array(data[key]), 1e-16, None)
        mesh = ax.pcolormesh(arms, rings, d, norm=norm, cmap="viridis", shading="nearest")
        ax.contour(arms, rings, d, levels=[WAVE_TENTH], colors="r", linewidths=2)
        ax.plot([40], [6], marker="*", color="w", markersize=12, markeredgecolor="k")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("K (arms)")
        found = data["cubic" if key == "d_cubic" else "zernike"]["fewest_samples"]
        if found:
            ax.plot([found["arms"]], [found["rings"]], marker="o", color="r", markersize=8,
                    markerfacecolor="none")
    axes[0].set_ylabel("L (rings)")
    fig.colorbar(mesh, ax=axes, label="d_Ω [waves RMS]  (red: λ/10; ★ paper's L=6, K=40; "
                 "○ fewest samples)")
    fig.suptitle("Berkner & Shroff Fig. 4 (left): OPD error over the aberration hypercube")
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    plt.close(fig)


# --------------------------------------------------------------------------------------


def _p(x):
    return "not within the tested p" if x is None else f"p = {x} ({x * x} nodes/quadrant)"


def markdown(report) -> str:
    """A short report of ``run``'s numbers."""
    comparison = report["fig1_comparison"]["methods"]
    lines = ["# Berkner & Shroff, reproduced by `jmse-jax reproduce`"
             + (" (quick)" if report["quick"] else ""), "",
             f"jax {jax.__version__}, {report['device']}, float64, {report['seconds']:.0f} s.",
             "", "## Fig. 1 operating point", "",
             "Seidel " + ", ".join(f"{k} = {v}" for k, v in FIG1.items())
             + f" waves, field {FIG1_FIELD}, u = {FIG1_U} (Nyquist / cutoff), MarkovSignal(1, 5),"
             " WhiteNoise(1e-3).", "",
             "| method | JMSE | relative error | value [ms] | value + grad [ms] |",
             "|---|---|---|---|---|"]
    for name, row in comparison.items():
        lines.append(f"| {name} | {row['jmse']:.7e} | {row['relative_error']:+.2e} | "
                     f"{row['time_value_s'] * 1e3:.2f} | "
                     f"{row['time_value_and_grad_s'] * 1e3:.2f} |")
    f1 = report["fig1"]
    timing = report["fig1_comparison"]
    lines += ["", f"Times: the fastest of {timing['repeats']} warm calls of each jitted "
              f"function, the four taken in turn ({timing['rounds']} rounds of "
              f"{timing['calls_per_round']} calls each), traced without jmse's run-time "
              f"design checks (`run_time_checks(False)`, so that the compile cache keeps "
              f"them; at this point they cost the default's value about 3 %). "
              f"Reference {FIG1_REFERENCE:.7e} (SPEC §5). OPD from "
              f"{f1['opd_min']:.2f} to {f1['opd_max']:.2f} waves (RMS {f1['opd_rms']:.2f}); "
              f"log10 S_e over the band from {f1['log10_s_e_band_min']:.2f} to "
              f"{f1['log10_s_e_band_max']:.2f}. Maps: `fig1.png`.", "",
              "## Fig. 4 right: JMSE versus frequency nodes (u = 0.2)", "",
              "OTF evaluated directly at each rule's nodes; *stays below* = the smallest tested "
              "p from which every larger tested p stays below the threshold. Plot: "
              "`fig4_right.png`.", "",
              "| defocus [waves] | rule | stays < 1e-3 from | stays < 1e-6 from | "
              "error at largest p |", "|---|---|---|---|---|"]
    f4 = report["fig4_right"]
    last = str(f4["ps"][-1])
    for defocus, block in f4["defocus"].items():
        for rule in f4["rules"]:
            row = block["rules"][rule]
            lines.append(f"| {defocus} | {RULE_LABELS[rule]} | "
                         f"{_p(row['first_stays_below']['0.001'])} | "
                         f"{_p(row['first_stays_below']['1e-06'])} | "
                         f"{row['relative_error'][last]:.1e} |")
    lines += ["", "References: " + "; ".join(
        f"defocus {d}: {b['reference']:.9e} ({b['reference_source']})"
        for d, b in f4["defocus"].items()), ""]
    left = report.get("fig4_left")
    lines += ["## Fig. 4 left: OPD rebuilt from L rings x K arms of polar samples", ""]
    if left is None:
        lines += [f"Skipped: {report.get('fig4_left_skipped')}", ""]
    else:
        lines += [f"d_Omega = mean over {left['n_designs']} Latin-hypercube Seidel designs "
                  "(coefficients in [-6, 6] waves) of the RMS error of the rebuilt wavefront "
                  "[waves]. Plot: `fig4_left.png` (red: the lambda/10 contour).", "",
                  "| method | fewest samples below lambda/10 | d_Omega at the paper's "
                  "L = 6, K = 40 |", "|---|---|---|"]
        for key, name in (("cubic", "piecewise-cubic interpolation (the paper's)"),
                          ("zernike", "Zernike quadrature projection (ours)")):
            fewest = left[key]["fewest_samples"]
            where = ("none" if fewest is None else
                     f"L = {fewest['rings']}, K = {fewest['arms']} ({fewest['samples']})")
            lines.append(f"| {name} | {where} | {_e(left[key]['d_at_paper_choice_L6_K40'])} |")
        lines.append("")
    return "\n".join(lines) + "\n"


def _e(x):
    return "n/a" if x is None else f"{x:.2g}"


def run(out_dir, quick: bool = False, log: Callable = print) -> dict:
    """Write ``fig1_comparison.json``, ``fig1.png``, ``fig4_right.png``, ``fig4_left.png``
    (when scipy is installed), ``reproduce.json`` and ``reproduce.md`` into ``out_dir``;
    progress goes to ``log``."""
    start = time.perf_counter()
    os.makedirs(out_dir, exist_ok=True)
    steps = 5
    log(f"[1/{steps}] Fig. 1 point: baseline B=64 vs jmse default (compiling, then timing)")
    # Even the quick run takes the fastest of many warm calls: a single warm call read the
    # default at 3-5 ms against about 1.3 ms for the fastest of 11.
    comparison = fig1_comparison(rounds=5 if quick else 11, log=log)
    with open(os.path.join(out_dir, "fig1_comparison.json"), "w") as f:
        json.dump(comparison, f, indent=2)
    log(f"[2/{steps}] Fig. 1 maps: OPD and log10 S_e")
    figure1 = fig1_maps(os.path.join(out_dir, "fig1.png"),
                        *((48, 41) if quick else (128, 121)))
    log(f"[3/{steps}] Fig. 4 right: JMSE versus p for 5 quadrature rules, defocus -6 and -2.75")
    ps = (4, 8, 16) if quick else (4, 6, 8, 12, 16, 24, 32, 48, 64)
    right = fig4_right(ps, reference_preset="default" if quick else "high", log=log)
    plot_fig4_right(right, os.path.join(out_dir, "fig4_right.png"))
    log(f"[4/{steps}] Fig. 4 left: OPD error of cubic interpolation and Zernike projection")
    left, skipped = None, None
    try:
        import scipy  # noqa: F401 - the cubic interpolation of the paper's method
    except ImportError:
        skipped = "needs scipy (pip install scipy) for the paper's cubic interpolation"
        log(f"  skipped: {skipped}")
    else:
        left = (opd_error(8, (2, 3, 4, 6, 8), (4, 6, 8, 10, 16, 24, 40), log=log) if quick
                else opd_error(log=log))
        plot_fig4_left(left, os.path.join(out_dir, "fig4_left.png"))
    log(f"[5/{steps}] writing the report")
    report = dict(description="Berkner & Shroff Fig. 1 and Fig. 4, jmse-jax reproduce",
                  quick=quick, device=str(jax.devices()[0]), jax_version=jax.__version__,
                  fig1_comparison=comparison, fig1=figure1, fig4_right=right, fig4_left=left,
                  fig4_left_skipped=skipped, seconds=time.perf_counter() - start)
    with open(os.path.join(out_dir, "reproduce.json"), "w") as f:
        json.dump(report, f, indent=2)
    with open(os.path.join(out_dir, "reproduce.md"), "w") as f:
        f.write(markdown(report))
    log(f"wrote {out_dir}/: fig1_comparison.json, fig1.png, fig4_right.png"
        f"{'' if left is None else ', fig4_left.png'}, reproduce.json, reproduce.md "
        f"({report['seconds']:.0f} s)")
    return report

"""The JMSE merit (Berkner & Shroff Eq. 7) and the paper's square-grid baseline.

``JMSE(u) = (1/2 pi) \\iint_{|nu_x| < u, |nu_y| < u} S_e(nu) d^2 nu`` with
``S_e = S_x S_n / (|H|^2 S_x + S_n)`` (Stork & Robinson, Appl. Opt. 47(10), 2008).
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import math
import os
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero
from jax.flatten_util import ravel_pytree

from ._aberrations import AbstractAberrations, Seidel, Zernike
from ._numerics import (
    EXACT,
    AccuracyWarning,
    all_finite,
    batch_skipping_cond,
    check_choice,
    check_count,
    check_finite_tree,
    check_range,
    common_dtype,
    concrete_primal,
    is_concrete,
    is_single_precision,
    one_at_a_time,
    refuse_reverse_over,
    reverse_over_derivative,
    select_batch,
    spread_batch,
    with_batching_rule,
)
from ._otf import OTF_METHODS, _otf_fft, _otf_nudft, _otf_overlap, check_scalars, otf_fft_grid
from ._quadrature import (
    FINE_SUB_PANEL,
    OUTER_NODES,
    QUADRATURES,
    AngularTables,
    angular_interpolation_block,
    angular_rule,
    angular_split,
    fine_sub_panels,
    frequency_quadrature,
    polar_interpolation_matrices,
    polar_panels,
    radial_panel_sizes,
)
from ._radial import radial_band_integral
from ._ridges import ridge_peaks
from ._spectra import AbstractNoise, AbstractSignal, error_spectral_density, x_mirrored

__all__ = [
    "DEFAULT_TIERS",
    "OVERLAP_FLOOR",
    "PRESETS",
    "SE_ANGULAR_BY_SNR",
    "TierShortcut",
    "CHECKED_SNR",
    "CHECKED_SNR_PEAKS",
    "BALANCED_CANCELLATION",
    "BALANCED_GRID",
    "CANCELLING_STRENGTH",
    "CHECKED_CANCELLATION",
    "CHECKED_SLOPE",
    "CHECKED_STRENGTH",
    "DEGREE_NODES",
    "DEGREE_OVERLAP",
    "DEGREE_SE_NODES",
    "DEGREE_STEEP_SLOPE",
    "HIGH_BALANCED_GRID",
    "HIGH_DEGREE_NODES",
    "HIGH_RAY_GRID",
    "HIGH_STEEP_GRID",
    "HIGH_STRONG_STRENGTH",
    "SEQUENTIAL_VMAP_BACKENDS",
    "STEEP_SLOPE",
    "U_MAX",
    "aberration_strength",
    "baseline_jmse",
    "jmse",
    "jmse_options",
    "se_angular_for",
    "otf_radial_for",
    "OTF_RADIAL_BY_SNR",
]

#: Largest Nyquist ratio accepted: at u = 1.5 the band's corners lie past the cutoff.
U_MAX = 1.5

#: The largest ``aberration_strength`` at which the default's tiers (and ``"high"``) were
#: checked (docs/accuracy.md, "The adaptive default"). A concrete design beyond it gets a
#: ``AccuracyWarning`` from ``jmse``. ``"fast"`` has no bound of its own: it is percent-level off
#: on some designs well inside this (docs/accuracy.md, "The `fast` preset").
CHECKED_STRENGTH = 25.0
#: The same for rotationally symmetric designs, which take the one-ray plans (docs/accuracy.md).
CHECKED_STRENGTH_ONE_RAY = 45.0
#: The largest wavefront slope ``max |grad W|`` (tilt removed) [waves per pupil radius] at
#: which the default's tiers and one-ray plans were checked: ``aberration_strength`` is the
#: slope times ``min(sqrt(2) u, 1)``, so at small ``u`` a design of moderate strength can be
#: one of many waves, and there the overlap rule's orders bind. Designs steeper than
#: ``STEEP_SLOPE`` take the last tier (and the strong one-ray plan, which takes that tier's
#: overlap rule): on designs of slope up to 67 at u 0.1-0.3 the worst error was 7.2e-5
#: (``benchmarks/small_u_single_terms.py`` and STEEP_SLOPE's note); beyond, single terms
#: were far off (74 waves of coma at u = 0.1, slope 173, 1.6e-1; 43 waves of defocus at
#: u = 0.2, slope 87, 7e-3). A concrete design beyond it gets an ``AccuracyWarning`` from ``jmse``.
CHECKED_SLOPE = 65.0
#: Terms that cancel each other's slope: a design off the axis whose ``cancellation`` (the
#: ``aberration_strength`` of each of its terms alone, summed, over the design's own) is at
#: least this, at a strength of at least ``CANCELLING_STRENGTH``, takes the default's
#: balanced tier (``BALANCED_GRID``; ``"high"`` its ``HIGH_BALANCED_GRID``), and with the
#: preset that has none (``"fast"``) gets an ``AccuracyWarning`` from a concrete ``jmse`` call
#: (and from ``eval`` and ``sweep``). The tiers were calibrated on random designs, whose
#: terms seldom cancel (median 1.3); defocus set against spherical aberration, as a
#: designer balances them (``W = c (rho^2 + r rho^4)``, cancellation 2-7 for r in
#: -1.5..-0.3), a hair off the axis
#: was measured up to 8e-2 off in those tiers at strength 15 and 3.5e-3 at strength 4
#: (``benchmarks/balanced_polar.py``): 64 of 398 such designs more than 1e-4 off, all of
#: cancellation 3.2 or more and strength 3 or more (none of r = -1, whose cancellation is
#: 3.0, nor -1.5); so was astigmatism at the medial focus, ``w020 = -w222 h^2 / 2``
#: (cancellation 3.0), 8.7e-3 at strength 14 (u = 0.5). The bound, below 3 for that reason,
#: also sends 33 of the calibration's 426 random designs to the balanced tier. On the axis
#: the one-ray plans hold such designs (``_RAY_GRIDS``).
BALANCED_CANCELLATION = 2.5
#: The strength from which ``BALANCED_CANCELLATION`` applies.
CANCELLING_STRENGTH = 2.5
#: The largest ``cancellation`` at which the balanced tier was checked: a design beyond it
#: (off the axis, of strength at least ``CANCELLING_STRENGTH``) gets an ``AccuracyWarning`` from
#: a concrete default or ``"high"`` ``jmse`` call (and from ``eval`` and ``sweep``). Defocus against
#: spherical aberration reaches 7.0 at ``r = -2/3``, the most for those two terms (3000
#: random designs of defocus, spherical aberration, coma and astigmatism within +-10 waves
#: reached 6.3); see ``BALANCED_GRID``.
CHECKED_CANCELLATION = 7.0
#: The largest peak signal-to-noise ratio ``max S_x / S_n`` over the band at which the
#: polar grids of ``"fast"`` and the default were checked (a noise variance of about 8e-5
#: under ``MarkovSignal(1, 5)``, whose ``S_x(0)`` is 157; the bank's lowest noise, 1e-4, is
#: 1.6e6). Beyond it narrow features of ``S_e`` outgrow the fine grids: its peaks where the
#: OTF nearly vanishes on a ring (designs near rotational symmetry), of width
#: ``~ sqrt(S_n / S_x)`` (docs/accuracy.md, "Accuracy at low noise"), and, under flat
#: signal spectra, its turn from ``S_n / |H|^2`` to ``S_x`` along curves that the rays cross
#: obliquely. Session 85's climbs at peak ratios 2e6-2e8 (``default_climb.py --noise``)
#: found the default's steep tier 4.7e-4 off in the value and 1e-1 in the gradient under
#: power-law spectra (under Markov spectra 1.3e-5 and 6.3e-4; near the axis its strong
#: tiers' peaks hold it within 1e-6), with ``peaks=True`` too, since that tier has them
#: already. A concrete call that takes a polar grid of a preset gets an ``AccuracyWarning``.
#: ``"high"`` is held to ``CHECKED_SNR_PEAKS`` instead, and so are rotationally symmetric
#: designs: their one-ray plans integrate those peaks in closed form (single terms checked
#: to a peak ratio of 1.6e16; defocus balanced against spherical aberration within 7e-5 up
#: to 1.6e8 but 1.4e-2 off at 1.6e10, ``balanced_one_ray.py``).
CHECKED_SNR = 2e6
#: ``CHECKED_SNR`` for calls whose polar grids integrate those peaks in closed form
#: (``jmse_jax._ridges``) without the default's tiers (``peaks=True``: the ``"high"``
#: preset), and for rotationally symmetric designs (one-ray plans, ``CHECKED_SNR``'s note).
#: Checked near the axis to a peak ratio of 1.6e8 (``benchmarks/low_noise.py``: values
#: within 3e-9 up to 1.6e9, gradients within 4e-7 at 1.6e7 and 3e-6 at 1.6e8) and off it by
#: session 85's climbs of ``"high"`` under power-law spectra at peak ratios 2e6-2e8
#: (``default_climb.py --preset high --noise``): values within 7.6e-6 (session 87's seed 3
#: found 2.6e-5, gradient 1.4e-4, on a design of strength 24.2 at u 0.84 and 6.2e7 on
#: ``HIGH_STEEP_GRID``, whose 128 radial OTF nodes bind there: 256 hold 2e-8, and at 2e6
#: the 128 hold 1.4e-7; its seed 4 a gradient 3.0e-4 off, value 4.3e-7, at 1.2e7 on the
#: own grid, whose 80 radial OTF nodes bind: 160 hold 5.2e-6; on that design at 2e8 the
#: own grid's value is 3.2e-5 off, its gradient 6.9e-4, and 120 hold 8.4e-7 and 1.6e-5:
#: benchmarks/README.md; since session 88 ``"high"`` takes 160 radial OTF nodes past
#: ``CHECKED_SNR``, for values and gradients: ``OTF_RADIAL_BY_SNR``). Its gradients there
#: were not held: up to 9.7e-2 off (value 9e-7) on a strong design near the cutoff (its
#: balanced grid), where ``S_e`` turns from ``S_n / |H|^2`` to ``S_x`` along curves
#: narrower than its 960 angular fine nodes (``HIGH_STEEP_GRID``'s counts there: 2.0e-2;
#: with 1920 angular nodes 8.7e-3, 3840 1.9e-5; the count needed grows with the ratio, and
#: doubling it costs every ``"high"`` design half its time again). Since session 86
#: ``optimise``, which follows the gradient, gives ``"high"`` the count the ratio needs
#: (``se_angular``, ``SE_ANGULAR_BY_SNR``), and warns past ``CHECKED_SNR`` when told to
#: take fewer. Since session 87 so does ``jmse`` under differentiation, for the gradient
#: alone, where ``u`` and the spectra are concrete (``grad_se_angular``), and it warns at
#: run time where they are traced.
CHECKED_SNR_PEAKS = 2e8
#: Largest ``S_x / S_n`` on the innermost ring where the OTF can vanish (``_ring_snr``) at
#: which the default's two weakest tiers are used: a design above the first bound skips
#: tier 0, above the second tier 1 too (``_tier_index``). Their grids have no closed-form
#: peaks and 800 and 2400 fine radial nodes, and near the axis, where the OTF nearly
#: vanishes on rings inside the band, the ridges of ``S_e`` there (width
#: ``~ sqrt(S_n / S_x)``) outgrow them well inside ``CHECKED_SNR`` when the signal spectrum
#: is flat enough that the SNR on the ring is near the peak's: session 80's adversarial
#: climb (``benchmarks/default_climb.py``) found tier 0 1.3e-2 off at a peak SNR of 1.9e6
#: (2.5 waves of defocus, field 0.07, u = 0.1, correlation length 1.35; ring SNR 1.6e6) and
#: tier 1 1.4e-4 there. Scanning the noise on that design, tier 0 holds 1.2e-7 up to a ring
#: SNR of 2.6e4 (7.7e-6 at 8.7e4) and tier 1 1.1e-8 up to 2.6e5 (1.3e-5 at 8.7e5); tier 2
#: (4800 fine radial nodes) 2.1e-8 at 1.6e6. The paper's Fig. 1 point (ring SNR 9.9e4)
#: keeps tier 1, and so does the same design at noise 1e-4 (9.9e5).
WEAK_TIER_SNR = (3e4, 1e6)
#: Largest ``S_x / S_n`` at the band's edge (``_edge_snr``: at its corner ``sqrt(2) u``, or
#: at the cutoff for a band that reaches it) at which the default's tiers 1 to 3 are used; a
#: design above it takes the steep tier (``_STEEP_GRID``), and in ``"high"`` a band that
#: reaches the cutoff takes ``HIGH_STEEP_GRID``. Under a flat signal spectrum at high SNR,
#: ``S_e`` turns from ``S_n / |H|^2`` to ``S_x`` where ``|H|^2 S_x / S_n`` falls through 1,
#: sharply where ``H`` is small: near the cutoff, where ``H`` falls as ``(1 - r)^{3/2}``,
#: the radial interpolation of the OTF has to follow the turn (tier 1's 40 radial OTF nodes
#: fall short on bands that reach it), and where the curve of the turn crosses the rays
#: obliquely (the band's corner just inside the cutoff, the low rings of an astigmatic
#: OTF) the fine angular rule has to resolve it (tier 2's 128 angular nodes, tier 3's 256).
#: The tiers were calibrated under ``MarkovSignal`` spectra of correlation length 2-10,
#: whose ``S_x / S_n`` at the band's edge stays low except at small ``u`` (the Fig. 1 point:
#: 220; ``MarkovSignal(1, 5)`` at noise 1e-4 and u = 0.1: 1.7e4). Session 81's adversarial
#: climbs under power-law spectra (``benchmarks/default_climb.py --signal powerlaw``) found
#: tier 1 2.6e-4 off at u = 0.905 (``PowerLawSignal(2.11, 2.5, 1)``, noise 2.3e-6, SNR 3.8e5
#: at the cutoff), tier 2 1.1e-3 at u = 0.703 (``PowerLawSignal(0.88, 2.64, 0.64)``, noise
#: 2e-6, 2.9e5 at the corner) and 4.2e-4 at u = 0.454 (strength 5.4, SNR 2.8e5 at the
#: corner), and tier 1 8.5e-5 at u = 0.11 (strength 4.9, slope 31, 1.8e5); the steep tier's
#: grid holds each within 6e-7. On random designs under flat spectra
#: (``benchmarks/edge_snr_tiers.py``) bands that reach the cutoff have tier 1 within 1.7e-5
#: up to 3e4 and 9.8e-5 at 3e4-1e5, 7e-4 beyond, and ``"high"``'s own grid 3.9e-5 at 6e4;
#: narrower bands show no error above 4.6e-6 at any SNR up to the checked peak (the climbs'
#: designs are rare), and each of the climbs' failures lies above 5.9e4.
EDGE_TIER_SNR = 3e4
#: ``_ring_snr``'s innermost ring, as a multiple of ``u / aberration_strength``: the OTF's
#: first zero where the phase difference across the overlap lens reaches about half a wave,
#: ``nu ~ 1 / (4 max |grad W|)``, with the strength ``max |grad W| sqrt(2) u``: about
#: ``0.35 u / strength``, taken a little inside.
_RING_FRACTION = 0.3


class TierShortcut(NamedTuple):
    """Cheaper grids a tier tries first: a value is kept when a coarse ``check`` agrees.

    For ``u <= u_max`` the tier computes the merit on ``check`` and on ``trial`` (both
    cheaper than the tier's own grid); when ``|trial - check| <= rtol |trial|`` it returns
    the ``trial`` value, otherwise it computes its own grid. The two grids differ in every
    node count, so their errors are largely unrelated and their difference tracks the
    ``trial`` grid's error: on the calibration designs near the threshold the error was at
    most 5.6 times the difference, and a check closer to the trial failed together with it
    (benchmarks/README.md, "Adaptive default"). Above ``u_max`` the tier goes straight to
    its own grid. The check is computed in float32 whatever the merit's dtype
    (``_check_value``); the trial and the tier's grid in the merit's own.

    ``first`` (optional) is a still cheaper grid tried before ``trial``, with the same
    check. A coarse grid and the check can miss the same feature of the OTF alike (both
    interpolants smooth over a steep fall-off they do not resolve) and agree on a value
    that is off, so ``first`` is kept only when, besides agreeing with the check, its own
    interpolation-error estimate is at most ``first_tol``: the relative change of its value
    when its OTF interpolants lose one polynomial degree, radially or angularly
    (``_estimated_merit_value``). When ``first`` is refused, ``trial`` is tried as above;
    ``trial=None`` goes straight to the tier's own grid.
    """

    trial: dict | None
    check: dict
    rtol: float
    u_max: float = math.inf
    first: dict | None = None
    first_tol: float = 0.0


#: Smallest overlap order on the inner radial panels of the grids of the default's two
#: weakest tiers (and of the shortcut's grids), which serve designs of strength <= 5: their
#: full order is sized for that bound, so the inner panels, whose phase variation across
#: the overlap lens is at most ``t_max`` times the outer panel's, need proportionally fewer
#: nodes (``_polar_otf``). On the stored calibration designs (``benchmarks/recheck_tiers.py
#: --floor``) tiers 0 and 1 keep their worst errors (2.0e-6 and 2.1e-5) and no design's
#: error moves by more than 2.7e-6 (10 moved some by 1.5e-5); on the unbounded tiers 2 and
#: 3 a floor of 12 would not hold (tier 3: 3.0e-4 instead of 8.4e-5), so they keep the
#: presets' ``OVERLAP_FLOOR``. About a quarter less overlap work for the tiers that use it.
_WEAK_FLOOR = 12
#: The presets' ``overlap_floor`` (see ``_polar_otf``).
OVERLAP_FLOOR = 24
_TIER0_GRID = dict(nodes=(24, 12), se_nodes=(800, 96), overlap_nodes=(20, 20),
                   overlap_floor=_WEAK_FLOOR)
#: Above ``u = 1/sqrt(2)`` rays of the band reach the cutoff, where H has its
#: ``(1 - r)^{3/2}`` edge, or end just short of it, and polynomial interpolation along the
#: rays needs more radial OTF nodes. There the middle tier's shortcut is not tried (its
#: trial and check grids missed the edge alike: at u = 0.85 both were 2.1e-4 off and agreed
#: to 6e-6), and designs of strength 5-15 skip the third tier (56 radial nodes: 5.4e-4 off
#: at u = 0.8; the fourth's 80: 2e-6). Calibrated in ``benchmarks/results/
#: calibrate_tiers_kink.md`` (406 designs with u in 0.75-0.95).
_REACHES_CUTOFF_U = 1.0 / math.sqrt(2.0)

#: The shortcuts' check grid, computed in float32 (``TierShortcut``). Its angular OTF count
#: (10) differs from the first grid's (8), so that it sees the first grid's angular
#: interpolation error independently of that grid's own estimate (which drops one Legendre
#: degree, and under-reads a slowly decaying series). With 8 angular nodes in both, a hill
#: climb over tier-1 designs found kept first grids up to 4.5e-5 off (estimate 2.9e-6, check
#: agreement 2e-7; u = 0.70, field 0.26), and 1.15e-5 near w222 = 1.6 at field 1;
#: with 10 the check refuses all of them, the same climb finds 1.15e-5 at worst (the check's
#: own rtol); the calibration designs keep the same first grids and 1000 random weak
#: designs one more (779 of 920; ``benchmarks/shortcut_margin.py``,
#: ``benchmarks/recheck_shortcut.py``, session 80). It costs about 6 % of the Fig. 1
#: point's value time.
_CHECK_GRID = dict(nodes=(20, 10), se_nodes=(200, 32), overlap_nodes=(16, 16),
                   overlap_floor=_WEAK_FLOOR)
#: The shortcuts' first grid and its error-estimate tolerance (``TierShortcut.first``): it
#: differs from the check in every count (the angular one since session 80), and costs
#: about 40 % of tier 0's grid. On the stored calibration designs and
#: bank cases that the shortcuts serve it was kept for 71 of 79 designs of tier 0 (worst
#: error 1.0e-6) and 108 of 214 of tier 1 (worst 1.8e-6); the check alone would have kept
#: 116 of the latter, one of them 1.6e-4 off (``benchmarks/recheck_shortcut.py``). Tier 0's
#: grid, tried next as a trial, was kept for 5 more designs of tier 1 and is no longer tried.
_FIRST_GRID = dict(nodes=(24, 8), se_nodes=(300, 40), overlap_nodes=(18, 14), overlap_floor=10)
_FIRST_TOL = 1e-5
#: The shortcut of the default's two weak tiers.
_SHORTCUT = TierShortcut(trial=None, check=_CHECK_GRID, rtol=1e-5, u_max=_REACHES_CUTOFF_U,
                         first=_FIRST_GRID, first_tol=_FIRST_TOL)

#: The fourth tier's grid; the steep tier's (``_STEEP_GRID``) differs in its overlap rule
#: and its fine angular count.
_TIER3_GRID = dict(nodes=(96, 48), se_nodes=(4800, 256), overlap_nodes=(56, 40), peaks=True)
#: The steep tier's grid: tier 3's with the overlap rule (64, 64) (``STEEP_SLOPE``) and, since
#: session 81, 512 angular fine ``S_e`` nodes, for the designs that ``EDGE_TIER_SNR`` sends
#: here: under a flat spectrum at high SNR ``S_e`` turns from ``S_n / |H|^2`` to ``S_x``
#: along curves that the rays cross obliquely (the band's corner near the cutoff, the OTF's
#: low rings of an astigmatic design), and tier 3's 256 angular nodes left 5.2e-5 (u = 0.703,
#: ``PowerLawSignal(0.88, 2.64, 0.64)``, noise 2e-6) where 512 leave 6e-7. In tier 3 itself
#: they cost 28 % of its time (``hypercube_2``: value 143 -> 183 ms, ``ab_compare.py``, one
#: core), which its designs under ``MarkovSignal`` do not need.
_STEEP_GRID = dict(_TIER3_GRID, se_nodes=(4800, 512), overlap_nodes=(64, 64), overlap_floor=64)

#: Grids of the ``"default"`` preset by difficulty: ``(largest aberration_strength, largest
#: u, grid options, shortcut)``; the first tier whose two bounds hold is used, and a design
#: steeper than ``STEEP_SLOPE`` takes the last (the steep tier). The coarse
#: first tier is kept away from bands that reach the cutoff, where ``H`` has its
#: ``(1 - r)^{3/2}`` edge. Calibrated on 426 random Seidel designs (coefficients to +-8
#: waves, field 0-1, u 0.1-1, noise 1e-4 to 1e-2, strength up to 25) against a converged
#: reference (benchmarks/README.md, "Adaptive default"): worst relative error 2e-6, 2e-5,
#: 5e-5 and 1e-5 in the four tiers. At high SNR the S_e ridges along the OTF's zeros set the
#: fine radial count (2400); the OTF grids are the smallest that hold the bound. The second
#: tier first tries the first tier's grid (``TierShortcut``): of the 218 calibration designs
#: in that tier it kept 119 (55 %), with a worst error of 4.3e-6 among them; it is skipped
#: for ``u > 1/sqrt(2)`` (``_REACHES_CUTOFF_U``), where the third tier is skipped too. With
#: those bounds, 406 random designs with u in 0.75-0.95 (``calibrate_tiers.py --u ...``)
#: give a worst error of 3e-5 up to strength 15 and 8e-5 in 15-25 (the fourth tier). The
#: fine angular counts of the third and fourth tiers were then lowered (256 -> 128 and
#: 384 -> 256) where the stored references of both calibrations show no loss: the largest
#: change in a design's error 2e-11 and 2e-8 (``benchmarks/recheck_tiers.py``); so was the
#: overlap rule's order along the chords (the second entry of ``overlap_nodes``: 28 -> 24,
#: 40 -> 24, 56 -> 32 in tiers 1-3; largest change 1.5e-9, 1.7e-8 and 1.9e-9), and on
#: 2026-11-25 tier 3's again, 32 -> 24 (worst error 8.4e-5 unchanged, largest change
#: 5.8e-7; 16 failed in tiers 1 and 2: 6.2e-5 and 8.2e-4). Across the chords (the first
#: entry) the order binds and stays.
#: Those random designs never put the whole strength into one term. On 2026-11-29 designs of
#: a single strong term (outside the calibration's +-8-wave box, inside the checked strength)
#: found tiers 2 and 3 far short (``benchmarks/single_term_tiers.py``): pure coma, whose
#: phase difference varies along the overlap chords (defocus's does not), 3.3e-3 off at
#: strength 14.5 and 6e-2 at 24.5 (u = 0.3), for want of order along the chords; strong
#: astigmatism up to 7e-4, for want of fine radial S_e nodes and angular OTF nodes; and
#: defocus on the axis 1.3e-2 off at strength 44, whose one-ray plan takes its coarse count
#: from tier 3's radial count. Tiers 2 and 3 became (64, 40) / (4800, 128) / (40, 32) and
#: (96, 48) / (4800, 256) / (56, 40): worst 3e-4 on those 32 designs (24.7 waves of coma at
#: u = 0.3; 9.4e-5 for the rest, the astigmatic ones at the 4800 radial nodes' own error),
#: 3.5e-5 on the axis up to strength 44, and 9.8e-7 and 2.8e-8 (were 1.3e-5 and 8.4e-5) on
#: the stored calibration designs of the two tiers, at 1.8x and 2.6x their grids' time
#: alone and 2.3-5.3x in the default (benchmarks/README.md, optimisation log, session 54).
#: Later the same day the steep designs (``STEEP_SLOPE``) were found short of tier 3's
#: overlap rule; they take a fifth tier of their own, tier 3's grid with the overlap rule
#: (64, 64) on every panel (floor 64), which costs about 1.8x tier 3's value time (session
#: 56: a fifth grid adds about 7 % to the default's compile, where giving tier 3 itself that
#: rule cost every strong design the 1.8x).
#: Since session 84 the own grids of tiers 2, 3 and steep (``_TIER3_GRID``) integrate the
#: narrow peaks of ``S_e`` in closed form (``peaks``, ``jmse_jax._ridges``). Their values did
#: not need it, but their gradients did: where a near-axis design's OTF nearly vanishes on
#: rings, the peaks move across the fine nodes as a coefficient or ``u`` moves, and the fine
#: rule's small error oscillates with the node spacing, which the derivative amplifies. A
#: climb on the gradient's error (``benchmarks/default_climb.py --gradient --signal
#: powerlaw``) found a tier-3 design 1.3e-6 off in its value and 3.1e-2 in its gradient
#: (2.4e-5 with the peaks), and 6 waves of defocus with 0.5 of astigmatism at field 0.1, u
#: 0.3, noise 1e-4 (tier 2) was 4.5e-2 off (3.5e-7). Cost: about 3 % of those tiers' time
#: where no minimum is narrow (``hypercube_0`` 37.4 -> 39.4 ms a value, ``hypercube_2``
#: 95.7 -> 99.3 ms, one core), 30-45 % where one is, and about 10 % of the default's
#: compile (one core: value 20.9 -> 22.9 s, value_and_grad 47.9 -> 52.7 s); the weak tiers,
#: whose designs' gradients were within 3.5e-5 on the same climbs, keep their grids.
DEFAULT_TIERS: tuple[tuple[float, float, dict, TierShortcut | None], ...] = (
    (1.0, 0.5, _TIER0_GRID, _SHORTCUT),
    (5.0, math.inf, dict(nodes=(40, 20), se_nodes=(2400, 160), overlap_nodes=(28, 24),
                         overlap_floor=_WEAK_FLOOR),
     _SHORTCUT),
    (15.0, _REACHES_CUTOFF_U, dict(nodes=(64, 40), se_nodes=(4800, 128), overlap_nodes=(40, 32),
                                   peaks=True),
     None),
    (math.inf, math.inf, _TIER3_GRID, None),
    # The steep tier: reached only through STEEP_SLOPE and EDGE_TIER_SNR (the tier before it
    # has no bound of its own).
    (math.inf, math.inf, _STEEP_GRID, None),
)
#: Designs whose wavefront slope ``max |grad W|`` (tilt removed) [waves per pupil radius]
#: exceeds this take the last tier (the steep one) whatever their strength. The strength
#: scales the slope by ``min(sqrt(2) u, 1)``, so at small ``u`` a design of moderate
#: strength holds many waves, and the phase difference across the overlap lens, which grows
#: with the slope, outgrows the weaker tiers' overlap rules: on 48 designs of one term at u
#: 0.1-0.3 (``benchmarks/small_u_single_terms.py``, session 55) 22 were more than 1e-4 off
#: (8.5e-3 for 22 waves of coma at u = 0.2, strength 14.5), each with a slope above 35; the
#: calibration designs reach 35-42. They take a last tier whose overlap rule is raised from
#: tier 3's (56, 40) with the presets' floor 24 to (64, 64) on every panel: on 55 designs of
#: slope 45-67 at u 0.1-0.3 (single terms and mixtures) it is within 6.9e-5 of converged
#: references, where (56, 56) with floor 56 left 2.3e-3 and (64, 64) with floor 40 1.6e-4 on
#: a mixture at u = 0.3 (slope 55), and the 288 stored calibration designs of tier 3 keep
#: their worst error (2.5e-8 with that rule), at about 1.8x the tier's value time.
STEEP_SLOPE = 35.0

#: The grid of the default's balanced tier, taken by designs off the axis whose terms
#: cancel (``BALANCED_CANCELLATION``), whatever their strength or slope. The tiers by
#: strength fall short on them for want of several counts at once (on four designs,
#: doubling one count at a time helped one each): the OTF ripples more finely along the
#: rays than the slope says (radial OTF nodes), the phase difference varies along the
#: overlap chords (the overlap rule), and where such a design's OTF nearly vanishes on rings
#: the peaks of ``S_e`` need the closed-form integration of ``jmse_jax._ridges``
#: (``peaks``). Chosen on the 64 designs of ``benchmarks/balanced_polar.py`` that the tiers
#: had more than 1e-4 off (``benchmarks/balanced_tier.py``, session 64): (128, 64) / (9600,
#: 256) / (96, 96) floor 96 left 8 of them off without peaks and 2 with them (9.5e-4 at u =
#: 0.2, slope 53; 1.2e-4 at u = 1) whatever the overlap rule ((128, 128)) or the fine
#: counts ((14400, 256), (9600, 384)); 160 radial OTF nodes brought all 64 within 2.6e-5
#: (192: 4.6e-5; 192 with the overlap rule (80, 80) or (64, 64): 1.2e-3 and 5.7e-2 off), and
#: so did 48 angular OTF nodes and 4800 fine radial ones, which keep the reverse pass's
#: scratch at the other tiers' (23.4 MB; with (160, 64) / (9600, 256) it was 60 MB and the
#: Fig. 1 point's value_and_grad 2.2x slower, as every design pays for the largest branch's
#: scratch, ``_tier_plans``); without peaks that grid left 21 off (4.6e-3). The overlap
#: rule's floor on the inner panels (``_polar_otf``) was then lowered from 96 to 64: on the
#: 64 the same errors at 0.18-0.21 s a design instead of 0.30 s (floor 48 held them too but
#: left one design of r = -2/3 9.4e-5 off, where 64 and 96 give 3e-6; floor 24 left one of
#: the 64 2.2e-4 off; (96, 80) floor 32 one 2.4e-3; (96, 64) floor 64 one 2.8e-3; 32
#: angular OTF nodes one 1.5e-4). On every stored design that cancels (334 of the balanced
#: family and the tier calibrations), 36 of astigmatism at the medial focus, 36 three-term
#: mixtures and 82 more of the balanced family up to its largest cancellation (7.0 at
#: r = -2/3), 488 in all, the default (as a user calls it) is within 4.9e-5 of
#: converged references (``results/balanced_tier.md``; the tiers by strength left 66 of the
#: 370 stored and medial-focus ones more than 1e-4 off, worst 8.1e-2). A value takes about
#: 0.2 s (2 cores; median over those 64 designs), and the closed-form peaks add a few
#: seconds to the compile of the default's jitted value and value_and_grad (2 cores, fresh
#: processes: 10-13 -> 13-16 s and 22-29 -> 29-35 s). The bound also sends designs that
#: the tiers by strength held to this grid: 33 of the calibration's 426 random designs and
#: two of the bank's off-axis cases
#: (``kink_u0.85_shortcut``, 4.5e-7 off in tier 1, and ``kink_u0.8_strong``, 7.9e-8 in tier
#: 3), which now cost 0.43 s instead of 9 and 42 ms (a value, concrete call). Its angular
#: fine count is 512 since session 81 (was 256): under flat power-law spectra at high SNR
#: the turn of ``S_e`` from ``S_n / |H|^2`` to ``S_x`` crosses the rays obliquely
#: (``EDGE_TIER_SNR``), and a climb there found a design that cancels 2.4e-4 off with 256
#: (u = 0.195, strength 2.6, ``PowerLawSignal(0.65, 2.78, 0.18)``, noise 9.4e-5; 5.6e-6 with
#: 512), at 9 % more of the grid's time (489 -> 530 ms, jitted value).
BALANCED_GRID = dict(nodes=(160, 48), se_nodes=(4800, 512), overlap_nodes=(96, 96),
                     overlap_floor=64, peaks=True)
#: The balanced grid of the ``"high"`` preset, taken (as ``BALANCED_GRID`` in the default) by
#: designs off the axis whose terms cancel (``BALANCED_CANCELLATION``). On the 488 designs
#: of ``benchmarks/balanced_tier.py`` (session 65, ``results/balanced_high.md``) ``"high"``'s
#: own grid left 91 more than 1e-4 off, worst 3.7e-1; this grid leaves none, worst 2.6e-5
#: (3 more than 1e-5, 18 more than 1e-6: the balanced family at u = 1 and u = 0.2 at
#: strength 15-25, where the own grid was far worse), and no design where the own grid was
#: within 1e-6 is now more than 3 times its error; median 0.28 s a design (2 cores). It is
#: ``BALANCED_GRID`` with ``"high"``'s 960 angular fine nodes: that grid's 256 left
#: three-term mixtures 4.9e-5 off; (192, 64) / (9600, 512) / (128, 128) floor 96 left one
#: design 4.6e-5 off at 0.79 s. Jitted ``"high"`` programs compile it as a second branch:
#: at the Fig. 1 point the value's compile took 4.3-4.7 -> 7.1-8.6 s and value_and_grad's
#: 8.1-9.7 -> 15.3-17.3 s, scratch 7.5 -> 15.1 MB (value; value_and_grad 47.7 MB either
#: way), run time unchanged (about 34 / 75 ms).
HIGH_BALANCED_GRID = dict(nodes=(160, 48), se_nodes=(4800, 960), overlap_nodes=(96, 96),
                          overlap_floor=64, peaks=True)

#: The steep grid of the ``"high"`` preset, taken (as the default's steep tier) by designs
#: off the axis steeper than ``STEEP_SLOPE``. ``"high"``'s own grid was 1.7e-2 off on 25
#: waves of coma at u = 0.3 (slope 58) and 2.8e-2 on 29 at u = 0.2 (slope 67), where the
#: default's steep tier holds 1e-4: on the 69 designs of ``benchmarks/high_steep.py``
#: (session 65; single terms and mixtures of slope 21-67 at u 0.1-0.3, within
#: ``CHECKED_SLOPE``) it left 12 more than 1e-4 off. Its own grid with the overlap rule
#: (64, 64) to (96, 96) still left astigmatism 2.3e-3 off (its 80 radial OTF nodes); (96,
#: 48) / (4800, 960) with (64, 64) floor 64, the default's steep counts, 6.9e-5; (128, 64) /
#: (6400, 960) with (64, 64) 6.5e-5 (a mixture, the overlap rule); this grid 1.2e-6
#: (``results/high_steep.md``).
HIGH_STEEP_GRID = dict(nodes=(128, 64), se_nodes=(6400, 960), overlap_nodes=(80, 80),
                       overlap_floor=80)
#: ``"high"`` also takes ``HIGH_STEEP_GRID`` for designs stronger than this (the default's
#: fourth tier starts here). Its own grid (overlap rule (48, 48), 80 radial OTF nodes) is
#: coarser than the default's fourth tier ((56, 40), 96), and on random Seidel designs of
#: strength 21-25 at u 1.1-1.2 it was 2.8e-5 and 2.9e-6 off where the default held 2.5e-7
#: and 1.0e-6; with this grid 5.4e-10 and 3.0e-11 (session 79's audit;
#: ``benchmarks/shape_routes.py``).
HIGH_STRONG_STRENGTH = 15.0
#: Designs beyond Seidel's shapes (``beyond_seidel_degree``) steeper than this take the
#: balanced plan (``DEGREE_OVERLAP``) instead of the default's steep tier, whose overlap rule
#: (64, 64) binds on single terms of high angular order: at u = 0.3 with 0.5 waves of
#: defocus, ``Z28`` (``m = 6``) at slope 30 was 1.3e-4 off, ``Z14`` 5.0e-5, and ``Z15``
#: 4.5e-4 at slope 34.7, against 1.4e-6, 1.1e-8 and 1.5e-6 in the balanced plan; at slope
#: 25 the steep tier held 2.6e-6, 8.0e-8 and 9.0e-6 (session 79,
#: ``benchmarks/shape_routes.py``). Session 67's random
#: designs of Noll 4-22 to 4-45, which spread their slope over many terms, had set the
#: bound at ``STEEP_SLOPE``.
DEGREE_STEEP_SLOPE = 25.0

#: The counts of the ``"high"`` preset's one-ray plan (``_radial_plans``), over its own grid:
#: the default's strong one-ray plan (``_RAY_GRIDS``) with ``"high"``'s fine counts. With
#: ``"high"``'s own counts along the ray (overlap rule (48, 48)) the preset was far off on
#: designs on the axis of many waves: on the 1500 designs of ``balanced_one_ray.py`` at
#: noise 1e-3 to 1e-6 (defocus, and defocus balanced against spherical aberration, strength
#: 1-45) 197 more than 1e-4 off, up to 6.5e-1 (45 of strength at u = 0.5, slope 64; pure
#: defocus there 5.1e-1); with these counts none, worst 7.0e-5, the default's errors on
#: every one of them (session 65). About 60 ms a design on 2 cores (was about 15).
HIGH_RAY_GRID = dict(nodes=(256, 48), se_nodes=(4800, 960), overlap_nodes=(128, 96))
#: The overlap rule that replaces the balanced grid's (``BALANCED_GRID``,
#: ``HIGH_BALANCED_GRID``) in programs for designs of higher degree than Seidel's
#: (``beyond_seidel_degree``): their balanced plan. On defocus with ``Z28`` (``rho^6 cos 6
#: theta``) at u = 0.3, slope 46, which cancels nothing, the balanced grid's rule (96, 96)
#: floor 64 was 3.1e-3 off and the steep tier's (64, 64) 1.1e-3, where more radial or
#: angular OTF nodes or fine nodes did not help; the order across the chords binds (96:
#: 6.0e-4, 112: 5.5e-6, 128: 3.4e-6), the order along them and the floor hardly do ((128,
#: 96) floor 96: 4.0e-6; floor 64: 1.4e-5). On the 77 random Zernike designs of
#: ``benchmarks/zernike_routes.py`` (session 67) that take the balanced plan up to
#: ``CHECKED_SLOPE`` this rule, (128, 128) floor 128 and (128, 96) floor 128 all leave the
#: same worst error (1.4e-5, a design whose references differ by 1.1e-6; session 68 found
#: it bound by the grid's angular counts, 8.8e-6 with 64 angular OTF nodes); it costs about
#: 0.7x the first of those (0.87 against 1.2 s a value, Noll 4-45, 2 cores). Since session
#: 82 the order along the chords is 128 again (``DEGREE_NODES`` has the story): a climb
#: found a Noll 4-22 design at slope 63 1.5e-4 off with (128, 96), floor 96 or 128, and
#: 4.9e-7 with (128, 128) at either floor ((112, 112) floor 112: 4.5e-7; (160, 128): 4.9e-7).
DEGREE_OVERLAP = dict(overlap_nodes=(128, 128), overlap_floor=96)
#: The OTF nodes (radial, angular) of the balanced plan in programs for designs of higher
#: degree than Seidel's (with ``DEGREE_OVERLAP``), in the default and ``"high"``: the
#: balanced grids' 48 angular nodes bind on such designs. On the 175 random Zernike designs
#: of ``benchmarks/zernike_high_routes.py`` (session 68), up to ``CHECKED_SLOPE``,
#: ``"high"``'s grid with ``DEGREE_OVERLAP`` was up to 2.3e-5 off (a Noll 4-22 design at u =
#: 0.2, slope 55, whose two references differ by 1.1e-6), with 64 angular nodes 3.9e-6
#: (two more than 1e-6, where the references are not resolved), at about 1.3x the time
#: (``HIGH_STEEP_GRID`` with ``DEGREE_OVERLAP``, about as costly, 4.3e-6); the default kept
#: 48 (its worst there 1.4e-5). Session 82's adversarial climbs over Noll 4-22 designs under
#: power-law spectra (``benchmarks/default_climb.py --family zernike --signal powerlaw``)
#: found the plan short on random designs' tails: one with 0.57 and 0.27 waves of
#: quadrafoil (``Z14``, ``Z15``; strength 23, u = 0.29, slope 56) 3.0e-4 off with 48
#: angular nodes (56, 64, 80: 2.8e-5, 2.4e-7, 1.5e-11; ``MarkovSignal(1, 5)`` at noise
#: 1e-4: 1.5e-4 with 48); once it had 64, one with 2.2 waves of astigmatism and quadrafoil
#: (u = 0.29, slope 60) 7.4e-3 off (80: 2.5e-5, 96: 8.3e-7), and one at slope 63 short of
#: the overlap rule (above). Seidel's shapes, on which the balanced grid's counts were set,
#: have angular order at most 2; terms of higher order make the OTF turn faster with the
#: frequency's angle at a given strength. With these nodes and ``DEGREE_OVERLAP`` the three
#: designs are within 1e-6, and the 72 stored designs of ``zernike_routes.py`` that take the
#: plan within the checked slope within 1.1e-6 (were 1.4e-5). Cost: such a design about
#: 2.4x its time before session 82 (4.3 s a value, one core); the Zernike value program's
#: scratch went 29.8 -> 44.7 MB, past the size at which XLA remaps it on every call
#: (``_tier_plans``), until session 83 took the fine stage's copies out (18.3 MB).
DEGREE_NODES = (160, 96)
#: ``"high"``'s name for ``DEGREE_NODES`` (the two presets differed until session 82).
HIGH_DEGREE_NODES = DEGREE_NODES
#: The fine S_e nodes (radial, angular) of the balanced plan in programs for designs of
#: higher degree than Seidel's, in the default and ``"high"`` (whose balanced grid,
#: ``HIGH_BALANCED_GRID``, has them already). Under flat spectra S_e stays large out to
#: the cutoff, where such designs' OTFs turn fast with the frequency's angle: a climb from
#: the quadrafoil design of session 82 (``default_climb.py --family zernike --signal
#: powerlaw --start``) reached a Noll 4-22 design at u = 0.118, strength 9.1, peak S_x / S_n
#: at the band's edge 9.3e4, that ``BALANCED_GRID``'s 512 angular fine nodes left 4.5e-5 off
#: (768: 1.4e-5, 1024: 1.5e-6, 960: 2.2e-7 from a reference finer in every count, which is
#: the reference's own difference from the next; 6400 radial nodes with 512: no change).
#: A few % of such a design's time (the overlap OTF dominates; one core, the plan's grid
#: alone at 1024: value 4.30 -> 4.47 s, value_and_grad 10.2 -> 10.6 s; the default's Zernike
#: program with 960: 4.24 -> 4.37 s and 14.0 -> 14.7 s, ``ab_zernike.py``). Session 83.
DEGREE_SE_NODES = (4800, 960)

#: Options that fix the grid: overriding any of them turns the default's tiers off.
_GRID_OPTIONS = ("quadrature", "nodes", "se_nodes", "otf_method", "overlap_nodes",
                 "overlap_floor")
#: Options that raise a count in every polar grid a call may take (``_with_floors``), as
#: ``(option, grid entry, index in its pair)``: the angular fine S_e nodes and the radial
#: OTF nodes, which low noise needs (``SE_ANGULAR_BY_SNR``, ``OTF_RADIAL_BY_SNR``). Each
#: has a twin for the derivatives alone (``grad_`` + the name: ``_raised``).
_FLOORS = (("se_angular", "se_nodes", 1), ("otf_radial", "nodes", 0))
_FLOOR_WORDS = dict(se_angular="angular fine S_e nodes", otf_radial="radial OTF nodes")
#: The floors that hold values as well as gradients: ``jmse`` takes these for both
#: (``_auto_counts``), the others for the gradient alone.
_VALUE_FLOORS = ("otf_radial",)
_FLOOR_OPTIONS = tuple(name for floor, _, _ in _FLOORS for name in (floor, "grad_" + floor))
#: Preset entries that are not ``jmse`` keywords.
_PRESET_ONLY = ("tiers", "radial", "balanced", "steep", "ray")

#: Named accuracy/speed settings of ``jmse``. ``nodes`` are OTF nodes per polar triangle
#: (radial, angular), ``se_nodes`` the finer nodes on which the OTF is interpolated and
#: ``S_e`` integrated, ``overlap_nodes`` the per-frequency autocorrelation rule (chords
#: across the overlap lens, Gauss nodes along each chord).
#: ``tiers`` (``"default"`` only) adapts the grid to the aberration strength; the fixed grid
#: listed with it is the second tier's (that of the paper's Fig. 1 point), used when a grid
#: option is overridden. ``radial``: a rotationally symmetric design (any design on the axis)
#: with isotropic spectra is integrated along one ray (``jmse_jax._radial``), with counts
#: along the ray derived from the grid (``radial_counts``); overriding a grid option turns it
#: off too. ``peaks``: the polar grids' fine stage integrates the narrow peaks of ``S_e``
#: at the minima of ``|H|^2`` along its rays in closed form (``jmse_jax._ridges``); on in
#: ``"high"``, and in the default only in the own grids of its strong tiers (2, 3 and
#: steep: ``DEFAULT_TIERS``), as it costs every program that holds a grid about 1.5 s of
#: compile (3 s with a gradient) and doubles the time of a design that has such peaks.
#: ``balanced``: the grid taken by designs off the axis whose terms cancel
#: (``BALANCED_CANCELLATION``; ``BALANCED_GRID``, ``HIGH_BALANCED_GRID``); None in ``"fast"``
#: and when a grid option is overridden.
PRESETS: dict[str, dict] = {
    # 16 overlap nodes along the chords (20 until 2026-11-25): the same worst error on the
    # bank (3.1e-2) and on 40 random designs of the paper's singlet space against ``high``
    # (2.7e-5); its one-ray plan keeps 24 (``_radial._MIN_ALONG``). Fine S_e nodes (800, 48)
    # instead of (400, 120) since 2026-12-03: fewer fine nodes, in the same time, resolve the
    # S_e ridges at high SNR better (``benchmarks/fast_grids.py``: on the stored calibration
    # designs 4.1e-4 -> 2.0e-6 up to strength 1, 1.8e-3 -> 1.1e-3 at 1-3, 1.4e-2 -> 3.5e-3
    # at 3-5, the same beyond; bank case fig1_defocus_m6_u_0.1_noise_1e-4 6.7e-4 -> 1.8e-4).
    # No accuracy bound: beyond strength 5 its OTF grid binds (4.8e-2 at 5-8;
    # docs/accuracy.md); for an optimiser's steps and a sweep's survey.
    "fast": dict(
        quadrature="polar", nodes=(24, 16), se_nodes=(800, 48), otf_method="overlap",
        overlap_nodes=(28, 16), tiers=None, radial=True,
        overlap_floor=OVERLAP_FLOOR, peaks=False, balanced=None, steep=None, ray=None,
        se_angular=None, grad_se_angular=None, otf_radial=None, grad_otf_radial=None,
    ),
    "default": dict(
        quadrature="polar", nodes=(40, 20), se_nodes=(2400, 160), otf_method="overlap",
        overlap_nodes=(28, 24), tiers=DEFAULT_TIERS, radial=True,
        overlap_floor=OVERLAP_FLOOR, peaks=False, balanced=BALANCED_GRID, steep=None, ray=None,
        se_angular=None, grad_se_angular=None, otf_radial=None, grad_otf_radial=None,
    ),
    # 80 radial OTF nodes for H's (1 - r)^(3/2) edge on bands that reach the cutoff, 2800
    # radial S_e nodes for the ridges along the OTF's zeros at high SNR; each count differs
    # from the tests' strict reference setting, so the two estimate each other's error
    # (benchmarks/README.md: worst 7.2e-7 on the bank's hardest cases, was 2.7e-5).
    "high": dict(
        quadrature="polar", nodes=(80, 40), se_nodes=(2800, 960), otf_method="overlap",
        overlap_nodes=(48, 48), tiers=None, radial=True,
        overlap_floor=OVERLAP_FLOOR, peaks=True, balanced=HIGH_BALANCED_GRID,
        steep=HIGH_STEEP_GRID, ray=HIGH_RAY_GRID, se_angular=None,
        grad_se_angular=None, otf_radial=None, grad_otf_radial=None,
    ),
}


def jmse_options(preset: str = "default", **overrides) -> dict:
    """The full option set of ``jmse`` for ``preset`` with ``overrides`` applied, validated."""
    check_choice("preset", preset, tuple(PRESETS))
    options = dict(PRESETS[preset])
    options.setdefault("B", 64)
    for key, value in overrides.items():
        if key not in options or key in _PRESET_ONLY:
            allowed = ", ".join(sorted(k for k in options if k not in _PRESET_ONLY))
            raise ValueError(f"unknown jmse option {key!r}; options are: {allowed}")
        if value is not None:
            options[key] = value
            if key in _GRID_OPTIONS:
                options["tiers"] = None
                options["radial"] = False
                options["balanced"] = None
                options["steep"] = None
                options["ray"] = None
    check_choice("quadrature", options["quadrature"], QUADRATURES)
    check_choice("otf_method", options["otf_method"], OTF_METHODS)
    check_count("B", options["B"])
    options["overlap_nodes"] = _pair("overlap_nodes", options["overlap_nodes"])
    check_count("overlap_floor", options["overlap_floor"])
    options["overlap_floor"] = int(options["overlap_floor"])
    if not isinstance(options["peaks"], (bool, np.bool_)):
        raise ValueError(f"peaks must be True or False, got {options['peaks']!r}")
    options["peaks"] = bool(options["peaks"])
    if options["quadrature"] == "polar":
        options["nodes"] = _pair("nodes", options["nodes"])
        # One node at least on each of the three radial panels (``_quadrature``).
        check_count("nodes[0] (radial nodes of the polar rule)", options["nodes"][0], 3)
        if options["se_nodes"] is not None:
            options["se_nodes"] = _pair("se_nodes", options["se_nodes"])
            check_count("se_nodes[0] (radial nodes of the polar rule)",
                        options["se_nodes"][0], 3)
            if any(f < c for f, c in zip(options["se_nodes"], options["nodes"], strict=True)):
                raise ValueError(
                    f"se_nodes must be at least nodes in each direction (the OTF is "
                    f"interpolated from nodes to the finer se_nodes), got se_nodes="
                    f"{options['se_nodes']} with nodes={options['nodes']}")
    else:
        nodes = options["nodes"]
        if isinstance(nodes, (tuple, list)):
            nodes = nodes[0]
        check_count("nodes", nodes)
        options["nodes"] = int(nodes)
        options["se_nodes"] = None
    for name in _FLOOR_OPTIONS:
        if options[name] is None:
            continue
        check_count(name, options[name])
        options[name] = int(options[name])
        if options["tiers"] is not None:
            raise ValueError(
                f"{name} applies to fixed grids and their branches (preset='high' or "
                f"'fast', or grid options of your own), not to the default's tiers, whose "
                f"counts are calibrated together with their shortcuts; got "
                f"{name}={options[name]} with preset={preset!r}")
        if options["se_nodes"] is None:
            raise ValueError(
                f"{name} needs the polar rule's fine S_e nodes (quadrature='polar' with "
                f"se_nodes), got quadrature={options['quadrature']!r}")
        if name.endswith("otf_radial") and options[name] > options["se_nodes"][0]:
            raise ValueError(
                f"{name} must be at most se_nodes[0] = {options['se_nodes'][0]} (the OTF "
                f"is interpolated from its nodes to the finer fine S_e nodes), got "
                f"{name}={options[name]}")
    return options


def _pair(name, value):
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        value = (value, value)
    if isinstance(value, np.ndarray) and value.shape == (2,):  # as frequency_quadrature takes
        value = tuple(value.tolist())
    if not (isinstance(value, (tuple, list)) and len(value) == 2):
        raise ValueError(f"{name} must be an int or a pair of ints, got {value!r}")
    check_count(f"{name}[0]", value[0])
    check_count(f"{name}[1]", value[1])
    return (int(value[0]), int(value[1]))


def _validate_geometry(aberrations, field, u):
    if not isinstance(aberrations, AbstractAberrations):
        raise TypeError(
            f"aberrations must be a jmse_jax.Seidel or jmse_jax.Zernike, got {type(aberrations)}"
        )
    check_finite_tree("aberrations", aberrations)
    check_range("field", field, 0.0, 1.0)
    check_range("u", u, 0.0, U_MAX, low_inclusive=False)
    _check_one_design(aberrations, field, u)


def _check_one_design(aberrations, field, u):
    """``ValueError`` unless ``field``, ``u`` and Seidel coefficients are scalars (one design;
    batches go through ``sweep_jmse`` or ``jax.vmap``)."""
    check_scalars(aberrations, [("field", field), ("u", u)],
                  "for many designs use jmse_jax.sweep_jmse or jax.vmap")


def _check_spectrum_types(signal, noise):
    if not isinstance(signal, AbstractSignal):
        raise TypeError(f"signal must be a jmse_jax signal model, got {type(signal)}")
    if not isinstance(noise, AbstractNoise):
        raise TypeError(f"noise must be a jmse_jax noise model, got {type(noise)}")


def _validate(aberrations, field, u, signal, noise):
    _validate_geometry(aberrations, field, u)
    _check_spectrum_types(signal, noise)
    for name, spectrum in (("signal", signal), ("noise", noise)):
        for path, leaf in jax.tree_util.tree_flatten_with_path(spectrum)[0]:
            if np.ndim(leaf) != 0:
                raise ValueError(
                    f"{name}{jax.tree_util.keystr(path)} must be a scalar (one design; "
                    f"vmap over designs), got shape {np.shape(leaf)}")
        _check_symmetries(name, spectrum, u)


#: Where ``_check_symmetries`` compares a spectrum of one's own with its reflections, as
#: fractions of ``u`` (fixed, so that a check does not vary from call to call).
_SYMMETRY_POINTS = np.array([[0.13, 0.71], [0.52, -0.28], [0.91, 0.37], [-0.64, 0.88],
                             [0.35, 0.04], [0.77, -0.93], [0.06, 0.49], [-0.42, -0.17]])


def _check_symmetries(name, spectrum, u):
    """``ValueError`` unless a concrete spectrum of one's own (not isotropic) is even,
    ``S(-nu) = S(nu)`` (the merit integrates half the band and doubles it), and, where it
    says it is ``x_symmetric``, mirror symmetric in ``nu_x`` (the merit then folds the band
    onto one quadrant): compared at eight points inside the band to 1e-9 (1e-4 in float32).
    Isotropic models are both; under ``jit`` (a traced spectrum or ``u``) nothing is
    checked."""
    if spectrum.isotropic or not is_concrete((spectrum, u)):
        return
    points = _SYMMETRY_POINTS * float(np.max(u))
    nu_x, nu_y = (jnp.asarray(points[:, i]) for i in (0, 1))
    values = spectrum(nu_x, nu_y)
    # Reflections are exact, so an even formula gives the same value to rounding.
    tolerance = 1e-4 if is_single_precision(jnp.result_type(values)) else 1e-9
    values = np.asarray(values, dtype=np.float64)
    checks = [("even, S(-nu) = S(nu), as the spectrum of every real field is",
               spectrum(-nu_x, -nu_y), "-nu")]
    if spectrum.x_symmetric:
        checks.append(("mirror symmetric, S(-nu_x, nu_y) = S(nu_x, nu_y), as its "
                       "x_symmetric says", spectrum(-nu_x, nu_y), "(-nu_x, nu_y)"))
    for what, reflected, where in checks:
        reflected = np.asarray(reflected, dtype=np.float64)
        gap = np.abs(reflected - values) > tolerance * np.maximum(np.abs(values),
                                                                  np.abs(reflected))
        if np.any(gap):
            i = int(np.argmax(gap))
            raise ValueError(
                f"{name} must be {what}; {type(spectrum).__name__} gives "
                f"{float(values[i])!r} at nu = ({points[i, 0]:.4g}, {points[i, 1]:.4g}) and "
                f"{float(reflected[i])!r} at {where}")


def _sanitise(inputs):
    """``(inputs, ok)``: ``ok`` when every leaf is finite and ``field``, ``u`` and the
    spectra's parameters are in range; where not, the inputs are replaced by a harmless
    stand-in design (no aberrations, ``field`` 0, ``u`` 0.5, every spectrum parameter 1).

    Used when values are traced (no ValueError possible): the merit then returns ``+inf``
    with zero gradient instead of NaN or a plausible-looking wrong number.
    """
    aberrations, field, u, signal, noise = inputs
    ok = all_finite(inputs)
    # No upper bound on u here: the merit is defined for any band, and lens_merit passes
    # bands past U_MAX (u scaled to other wavelengths); concrete calls are checked.
    ok = (ok & (field >= 0) & (field <= 1) & (u > 0)
          & jnp.asarray(signal.valid(), bool) & jnp.asarray(noise.valid(), bool))
    stand_in = (
        jax.tree_util.tree_map(jnp.zeros_like, aberrations),
        jnp.zeros_like(field),
        jnp.full_like(u, 0.5),
        jax.tree_util.tree_map(jnp.ones_like, signal),
        jax.tree_util.tree_map(jnp.ones_like, noise),
    )
    safe = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), inputs, stand_in)
    return safe, ok


def _otf_at(aberrations, nu_x, nu_y, field, options):
    method = options["otf_method"]
    if method == "overlap":
        return _otf_overlap(aberrations, nu_x, nu_y, field, options["overlap_nodes"])
    if method == "nudft":
        return _otf_nudft(aberrations, nu_x, nu_y, field, options["B"])
    return _otf_fft(aberrations, nu_x, nu_y, field, options["B"])


def _panel_overlap_orders(options, n_radial: int) -> list[tuple[int, float, tuple[int, int]]]:
    """``(nodes, t_max, overlap order)`` of each radial panel of a polar grid with
    ``n_radial`` radial OTF nodes: ``n = floor + (n_full - floor) t_max`` per axis, at most
    ``n_full`` (``_polar_otf``)."""
    floor = options["overlap_floor"]
    return [(count, t_max, tuple(min(n, math.ceil(floor + (n - floor) * t_max))
                                 for n in options["overlap_nodes"]))
            for count, t_max in radial_panel_sizes(n_radial)]


@jax.named_scope("coarse_otf")
def _polar_otf(aberrations, nu_x, nu_y, field, options):
    """OTF on the coarse polar nodes ``(2, n_angular, n_radial)``, panel by radial panel.

    The phase difference across the overlap lens grows with ``|nu|``, so the overlap rule's
    order is reduced on the inner radial panels in proportion to their outer radius
    ``t_max``: ``n = floor + (n_full - floor) t_max`` per axis, at most ``n_full`` (the full
    order on the outer panel), with ``floor`` the option ``overlap_floor``.
    With the private option ``_remat_otf`` (see ``_tier_plans``) reverse mode recomputes the
    inner panels' blocks instead of storing their chord moments.
    """
    if options["otf_method"] != "overlap":
        return _otf_at(aberrations, nu_x, nu_y, field, options)
    parts, start = [], 0
    for count, t_max, order in _panel_overlap_orders(options, nu_x.shape[-1]):
        stop = start + count
        remat = options.get("_remat_otf", False)
        parts.append(_otf_overlap(aberrations, nu_x[..., start:stop], nu_y[..., start:stop],
                                  field, order,
                                  remat=remat == "all" or (bool(remat) and t_max < 1)))
        start = stop
    return jnp.concatenate(parts, axis=-1)


#: Fine S_e nodes per block of angular rows (see ``_fine_blocks``).
_FINE_BLOCK_POINTS = 1 << 16


def _fine_blocks(n_r, n_a):
    """``(n_blocks, size)``: equal blocks of angular rows of the fine S_e grid, each under
    ``_FINE_BLOCK_POINTS`` nodes (the last padded with ``n_blocks * size - n_a`` rows).

    XLA's CPU runtime allocates a call's scratch afresh; above about 32 MB the pages come
    freshly mapped and every first touch faults (about 1 us per 4 kB page), which cost the
    strongly aberrated tiers up to a third of their time. Blocks keep each temporary small.
    """
    per_block = max(1, _FINE_BLOCK_POINTS // (2 * n_r))
    n_blocks = -(-n_a // per_block)
    return n_blocks, -(-n_a // n_blocks)


def _signal_at(signal, panels, outer):
    """``S_x`` at the inner (or ``outer``) nodes; isotropic signals from the stored radii."""
    if type(signal).__call__ is AbstractSignal.__call__:  # S_x(nu) = radial(|nu|)
        return signal.radial(panels.outer_radius if outer else panels.radius)
    if outer:
        return signal(panels.outer_nu_x, panels.outer_nu_y)
    return signal(panels.nu_x, panels.nu_y)


def _fine_parts(h, l_a, l_a_t, u, signal, noise, n_r, n_a, angles, dtype, adjoint, ridges):
    """``sum w S_e`` over a block of angular rows of the fine grid (``angles``: their angle
    fractions and weights; ``l_a``: their rows of the angular interpolation matrix) and their
    outer nodes, with the closed-form peaks of ``jmse_jax._ridges`` if ``ridges`` (on the
    fine rule with sub-panels, ``FINE_SUB_PANEL``); with ``adjoint``, also ``L_a^T g`` where
    ``g = w dS_e/dRe(H) + i w dS_e/dIm(H)``.

    ``h`` holds the radially interpolated OTF as real numbers, ``(n_coarse, 2, 2, n_r)``:
    coarse angular rows first, then real and imaginary parts, then the two triangles. The
    real matrix ``l_a`` then takes one real product (half the flops of a complex one) in the
    plain row-major layout YNNPACK takes, and the adjoint comes back in the same layout.
    These products contract over at most a few dozen rows, so their summation order is
    fixed.
    """
    fine = polar_panels(u, n_r, n_a, dtype, n_outer=OUTER_NODES, angles=angles,
                        sub_panel=FINE_SUB_PANEL if ridges else None)
    size = l_a.shape[0]
    h = jnp.matmul(l_a, h.reshape(h.shape[0], -1), precision=EXACT).reshape(size, 2, 2, n_r)
    h_re, h_im = h[:, 0], h[:, 1]  # (rows, triangles, n_r)
    # The fine grid's arrays, (triangles, rows, n_r), to this layout: isotropic spectra come
    # as (rows, n_r) and broadcast; the weights factor as row x radial.
    s_x = _signal_at(signal, fine, outer=False)
    s_x = jnp.swapaxes(s_x, 0, 1) if s_x.ndim == 3 else s_x[:, None, :]
    s_n = noise(fine.nu_x, fine.nu_y)
    s_n = jnp.swapaxes(s_n, 0, 1) if jnp.ndim(s_n) == 3 else s_n
    denominator = (h_re * h_re + h_im * h_im) * s_x + s_n
    s_e = s_x * s_n / denominator  # error_spectral_density, with its denominator kept
    s_x_out = _signal_at(signal, fine, outer=True)  # H = 0 beyond the cutoff
    # The radial sums as a product with the radial weights: a reduction would take S_e's
    # element-wise chain into a YNNPACK fusion, which evaluates it several times slower
    # than XLA's own loop; a product leaves the chain to that loop.
    rows = jnp.matmul(s_e, fine.radial_weights, precision=EXACT)  # (rows, triangles)
    value = (jnp.sum(fine.row_weights[:, None] * rows)
             + jnp.sum(fine.outer_weights * s_x_out))
    peaks = None
    if ridges:
        t, starts, edges = fine_sub_panels(n_r)
        peaks = functools.partial(ridge_peaks, h, denominator, s_x, s_n, t,
                                  fine.radial_weights, fine.row_weights, starts, edges)
    if not adjoint:
        if peaks is not None:
            value = value + peaks()
        return value
    # dS_e/dRe(H) + i dS_e/dIm(H) = -2 S_x^2 S_n H / D^2 = -2 (S_e S_x / D) H.
    weights = fine.row_weights[:, None, None] * fine.radial_weights
    coefficient = -2.0 * weights * s_e * s_x / denominator
    # l_a_t: l_a transposed in memory, so that the product has the layout YNNPACK takes.
    # One product per part, each taking its own same-shape product ``c * H``: one product
    # of ``c`` broadcast over both parts cost a separate loop as long as a product
    # (benchmarks/README.md, optimisation log).
    parts = [coefficient * h_re, coefficient * h_im]
    if peaks is not None:  # the peaks' derivatives join the rule's at their nodes
        correction, *parts = peaks(parts)
        value = value + correction
    back = [jnp.matmul(l_a_t, part.reshape(size, -1), precision=EXACT) for part in parts]
    return value, jnp.stack(back, axis=1).reshape(l_a_t.shape[0], 2, 2, n_r)


@jax.named_scope("fine_se")
def _fine_total(h_coarse, u, signal, noise, coarse, fine, dtype, adjoint, drop=(0, 0),
                ridges=False):
    """``\\iint S_e`` on the ``fine`` polar grid, ``H`` interpolated from the ``coarse`` one;
    with ``ridges``, on the fine rule with sub-panels and with the closed-form peaks of
    ``jmse_jax._ridges``.

    Blocks of angular rows (``_fine_blocks``) run one after another. With ``adjoint``, also
    returns ``G = L_r^T (sum_blocks L_a^T g)``: the coarse-sized gradient of the total with
    respect to ``Re(H_coarse)`` + i ``Im(H_coarse)``. ``drop`` lowers the interpolants'
    degree (``polar_interpolation_matrices``; for ``_interpolation_estimate``).
    """
    l_r, l_a_rows = polar_interpolation_matrices(coarse, fine, drop,
                                                 FINE_SUB_PANEL if ridges else None)
    n_r, n_a = fine
    # The angular rules may be split at arccos(u) (``angular_split``): the coarse rule's
    # template row picks the fine rule's row and the block-diagonal interpolation matrix.
    split = angular_split(u, coarse[1], dtype)
    # Above BUILT_ANGULAR_BYTES the matrices are built block by block from host tables.
    built = isinstance(l_a_rows, AngularTables)
    if built:
        coarse_row = tuple(jnp.asarray(a)[split[0]].astype(dtype)
                           for a in l_a_rows[:3])
        l_a = jnp.stack([jnp.asarray(a)[split[0]].astype(dtype) for a in l_a_rows[3:]], -1)
    else:
        l_a = jnp.asarray(l_a_rows, dtype)[split[0]]
    frac, w_frac = angular_rule(u, coarse[1], dtype, split=split, fine=n_a)
    # Separable interpolation, radial axis first (the cheaper order). Every product is real
    # (real and imaginary parts stacked on a leading axis) with its matrix stored in the
    # layout YNNPACK takes (``l_r.T`` transposed on the host): complex products, and real
    # ones with a transposed operand, went to XLA's own dot at 3-6x the time. An earlier
    # attempt at real radial products (a concatenated layout that XLA's threaded GEMM took)
    # summed in an order that depended on the program and broke the bit-for-bit equality of
    # sweeps across device counts; these pass it (``tests/test_sweep.py``). The coarse OTF
    # goes to the layout below before the product (coarse-sized, about 1 MB), so that the
    # product writes the fine-sized result in place: two products, stacked and transposed
    # after, held three fine-sized copies at once (44.7 MB of scratch in the Zernike value
    # program, past the ~32 MB at which every call pays page faults; now about 18 MB).
    l_r_t = jnp.asarray(np.ascontiguousarray(l_r.T), dtype)
    parts = jnp.stack([jnp.real(h_coarse), jnp.imag(h_coarse)])  # (re/im, tri, rows, c_r)
    parts = jnp.transpose(parts, (2, 0, 1, 3))  # (coarse rows, re/im, triangles, c_r)
    h = jnp.matmul(parts.reshape(-1, parts.shape[-1]), l_r_t,
                   precision=EXACT).reshape(*parts.shape[:3], n_r)
    # The blocks run one after another in a loop, so the program holds one block, not one
    # copy per block: an unrolled version took 21 s to trace and compile the default's
    # value_and_grad against 13 s, at the same run time (benchmarks/README.md). Padded rows
    # carry zero weight and zero interpolation rows, so they add exact zeros.
    n_blocks, size = _fine_blocks(n_r, n_a)
    pad = n_blocks * size - n_a
    # Padded rows get zero rows (built: a part that is neither, -1).
    l_a = jnp.concatenate([l_a, jnp.full((pad, l_a.shape[1]), -1.0 if built else 0.0,
                                         dtype)]).reshape(n_blocks, size, -1)
    rows = (
        l_a,
        l_a if built else jnp.swapaxes(l_a, 1, 2),
        jnp.concatenate([frac, jnp.full(pad, 0.5, dtype)]).reshape(n_blocks, size),
        jnp.concatenate([w_frac, jnp.zeros(pad, dtype)]).reshape(n_blocks, size),
    )

    def block(carry, rows):
        total, back = carry
        rows_l, rows_l_t, frac, w_frac = rows
        if built:
            rows_l = angular_interpolation_block(coarse_row, rows_l[:, 0], rows_l[:, 1])
            rows_l_t = rows_l.T
        part = _fine_parts(h, rows_l, rows_l_t, u, signal, noise, n_r, n_a, (frac, w_frac),
                           dtype, adjoint, ridges)
        if adjoint:
            part, block_back = part
            back = back + block_back
        return (total + part, back), None

    # The adjoint's zeros made from this ``h`` (``_after``): one shared zero array, formed
    # before the first of two quadrants' loops, stayed live through both (2 x 15 MB).
    carry = (jnp.zeros((), dtype),
             _after(jnp.zeros(h.shape, h.dtype), h) if adjoint else jnp.zeros((), h.dtype))
    rows = tuple(jnp.asarray(a, dtype) for a in rows)
    if n_blocks == 1:
        (total, back), _ = block(carry, tuple(a[0] for a in rows))
    else:
        # Without the adjoint this total may be differentiated by ordinary means (``u`` and
        # the spectra): its blocks are rematerialised then (``_FINE_REMAT``).
        (total, back), _ = jax.lax.scan(block if adjoint else _FINE_REMAT(block), carry, rows)
    if not adjoint:
        return total
    l_r = jnp.asarray(l_r, dtype)
    back = jnp.transpose(back, (1, 2, 0, 3))  # (re/im, triangles, coarse rows, n_r)
    return total, jax.lax.complex(jnp.matmul(back[0], l_r, precision=EXACT),
                                  jnp.matmul(back[1], l_r, precision=EXACT))


#: How the fine stage's blocks run when the total is differentiated by ordinary means (the
#: tangents of ``u`` and the spectra, ``_fine_stage_jvp``): rematerialised, so that reverse
#: mode stores each block's inputs and recomputes the block in the backward pass, instead
#: of keeping every block's fine-grid intermediates. Before session 86 a ``value_and_grad``
#: in ``u`` and the noise held them all: at the Fig. 1 point (one core) the default's
#: scratch was 455 MB and it took 6.4 ms, ``"high"``'s 1065 MB and 689 ms; now 27 MB and
#: 4.3 ms, 72 MB and 347 ms (XLA's CPU runtime maps scratch above about 32 MB afresh on
#: every call and pays a page fault per 4 kB), and the scratch no longer grows with the
#: fine nodes (``"high"``'s balanced grid with 3840 angular ones: 3.1 GB -> 0.3 GB). The
#: gradient is the same to the last bit. A gradient in the coefficients alone never came
#: here (``_fine_stage``'s adjoint).
_FINE_REMAT = jax.checkpoint


@functools.partial(jax.custom_jvp, nondiff_argnums=(4, 5, 6, 7))
def _fine_stage(h_coarse, u, signal, noise, coarse, fine, dtype, ridges):
    """``_fine_total``'s value, with a derivative rule that needs no fine-grid residuals.

    The total depends on ``h_coarse`` through linear interpolation and an element-wise
    ``S_e``, so its derivative is ``Re <G, dh_coarse>`` with the coarse-sized ``G`` formed
    in the forward pass (one extra product per block). Reverse mode then stores ``G`` only
    (the coarse grid's size, under 100 kB), instead of every fine-grid intermediate (tens
    of MB; XLA's CPU runtime maps scratch above about 32 MB afresh on every call and pays a
    page fault per 4 kB), and its backward pass is a product with ``G``. Tangents of ``u``
    and the spectra go through an ordinary forward-mode derivative, only when they are not
    symbolic zeros, with the blocks rematerialised in reverse mode (``_FINE_REMAT``).
    """
    return _fine_total(h_coarse, u, signal, noise, coarse, fine, dtype, False, ridges=ridges)


def _is_zero(tangent) -> bool:
    return all(isinstance(leaf, SymbolicZero) for leaf in jax.tree_util.tree_leaves(
        tangent, is_leaf=lambda x: isinstance(x, SymbolicZero)))


def _instantiate(tangent):
    return jax.tree_util.tree_map(
        lambda t: jnp.zeros(t.shape, t.dtype) if isinstance(t, SymbolicZero) else t,
        tangent, is_leaf=lambda x: isinstance(x, SymbolicZero))


def _after(x, done):
    """``x`` unchanged, but computed after ``done`` (an array) in XLA's schedule.

    A data dependency orders the two: XLA's CPU pipeline drops optimisation barriers before
    it schedules, and it does not fold ``y * 0`` in floating point. Only ``done``'s first
    element is read (its finite part, so that ``x`` never turns into NaN), without a
    gradient."""
    first = jax.lax.stop_gradient(jnp.real(jnp.ravel(done)[0]))
    return x * (1.0 + 0.0 * jnp.where(jnp.isfinite(first), first, 0.0)).astype(x.dtype)


def _fine_stage_jvp(coarse, fine, dtype, ridges, primals, tangents):
    h_coarse, u, signal, noise = primals
    d_h, d_u, d_signal, d_noise = tangents
    value, adjoint = _fine_total(h_coarse, u, signal, noise, coarse, fine, dtype, True,
                                 ridges=ridges)
    tangent = jnp.zeros_like(value)
    if not _is_zero(d_h):
        tangent = tangent + jnp.sum(jnp.real(jnp.conj(adjoint) * d_h))
    others = (u, signal, noise)
    d_others = (d_u, d_signal, d_noise)
    if not _is_zero(d_others):
        def total(u, signal, noise):
            return _fine_total(h_coarse, u, signal, noise, coarse, fine, dtype, False,
                               ridges=ridges)
        tangent = tangent + jax.jvp(total, others, _instantiate(d_others))[1]
    return value, tangent


_fine_stage.defjvp(_fine_stage_jvp, symbolic_zeros=True)


def _band_integrals(aberrations, field, u, signal, noise, options, dtype, mirrored,
                    estimate=False):
    """``\\iint_band S_e`` over the folded first quadrant, and with ``mirrored`` over the
    x-mirrored one too (a list of one or two); with ``estimate``, each with its
    ``_interpolation_estimate``.

    The mirrored quadrant takes the OTF at ``(-nu_x, nu_y)`` and the spectra there
    (``x_mirrored``): a wavefront even in x has the same OTF in both, which is then computed
    once, and spectra that are not mirror symmetric differ. The polar rule computes the OTF
    of both quadrants in one call of the overlap engine (the nodes of the two stacked): a
    wavefront that is not even in x then traces and compiles one OTF stage per panel
    instead of two, with the same values node by node."""
    signs = (1.0, -1.0) if mirrored else (1.0,)
    spectra = [(signal, noise), x_mirrored(signal, noise)] if mirrored else [(signal, noise)]
    if options["quadrature"] != "polar":
        nu_x, nu_y, w = frequency_quadrature(options["quadrature"], u, options["nodes"], dtype)
        return [jnp.sum(w * error_spectral_density(
            _otf_at(aberrations, sign * nu_x, nu_y, field, options), s(nu_x, nu_y),
            n(nu_x, nu_y))) for sign, (s, n) in zip(signs, spectra, strict=True)]
    coarse = polar_panels(u, *options["nodes"], dtype)
    if mirrored and not aberrations.x_symmetric:
        nu_x = jnp.stack([coarse.nu_x, -coarse.nu_x])
        h_all = _polar_otf(aberrations, nu_x, jnp.broadcast_to(coarse.nu_y, nu_x.shape), field,
                           options)
    else:  # the nodes as they are (an even wavefront's one quadrant, or both alike)
        h_all = [_polar_otf(aberrations, coarse.nu_x, coarse.nu_y, field, options)]
        h_all = h_all * len(signs)
    out = []
    for h, (signal, noise) in zip(h_all, spectra, strict=True):
        if options["se_nodes"] is None:
            s_e = error_spectral_density(h, signal(coarse.nu_x, coarse.nu_y),
                                         noise(coarse.nu_x, coarse.nu_y))
            s_x_out = signal(coarse.outer_nu_x, coarse.outer_nu_y)  # H = 0 past the cutoff
            out.append(jnp.sum(coarse.weights * s_e) + jnp.sum(coarse.outer_weights * s_x_out))
            continue
        ridges = bool(options.get("peaks", False))
        if out:
            # The quadrants' fine stages one after the other: XLA's scheduler otherwise
            # forms both radially interpolated OTFs (15 MB each on the balanced grid) before
            # either loop, and scratch above about 32 MB costs every call of the program
            # its page faults (``_fine_blocks``).
            h = _after(h, out[-1][0] if estimate else out[-1])
        total = _fine_stage(h, u, signal, noise, options["nodes"], options["se_nodes"], dtype,
                            ridges)
        if estimate:
            total = total, _interpolation_estimate(h, u, signal, noise, total, options, dtype,
                                                   ridges)
        out.append(total)
    return out


@jax.named_scope("interpolation_estimate")
def _interpolation_estimate(h, u, signal, noise, total, options, dtype, ridges):
    """Estimate of the fine S_e stage's interpolation error, relative to its ``total``: the
    largest change of the total when the OTF's interpolants from the coarse nodes ``h`` lose
    their top Legendre coefficient, radially or angularly (``_ESTIMATE_DROP``; no
    gradient), each with the closed-form peaks (``ridges``) if the total has them."""
    nodes, se_nodes = options["nodes"], options["se_nodes"]
    h, u, signal, noise, total = jax.lax.stop_gradient((h, u, signal, noise, total))
    change = [jnp.abs(_fine_total(h, u, signal, noise, nodes, se_nodes, dtype, False, drop,
                                  ridges) - total) for drop in _ESTIMATE_DROP]
    return functools.reduce(jnp.maximum, change) / jnp.abs(total)


#: The lowered interpolants of ``_interpolation_estimate``: one Legendre degree fewer in
#: the radial, then in the angular direction. On the calibration designs a drop of 2
#: overestimated the error about 100-fold (the paper's Fig. 1 point: 5e-5 against 2.4e-7)
#: and refused most trials (benchmarks/README.md, optimisation log).
_ESTIMATE_DROP = ((1, 0), (0, 1))


def _estimated_merit_value(options, dtype, aberrations, field, u, signal, noise):
    """``(merit, estimate)``: ``_merit_value`` with its interpolation-error estimate."""
    return _merit_value(options, dtype, aberrations, field, u, signal, noise, estimate=True)


#: Pupil points (radii x angles) on which ``aberration_strength`` samples the wavefront slope.
_SLOPE_RADII = np.linspace(0.05, 1.0, 12)
_SLOPE_ANGLES = np.linspace(0.0, 2.0 * math.pi, 24, endpoint=False)


@jax.named_scope("strength")
def _strength(aberrations, field, u):
    """``aberration_strength`` without validation (traceable; no gradient flows)."""
    aberrations, field, u = jax.lax.stop_gradient((aberrations.without_tilt(), field, u))
    dtype = common_dtype(aberrations, field, u)
    return _max_slope(lambda x, y: aberrations(x, y, field), dtype) * _band_reach(u)


def _max_slope(wavefront, dtype):
    """``max |grad W|`` of ``wavefront(x, y)`` over the strength's sample points."""
    rho, theta = np.meshgrid(_SLOPE_RADII, _SLOPE_ANGLES)
    x = jnp.asarray((rho * np.sin(theta)).ravel(), dtype)
    y = jnp.asarray((rho * np.cos(theta)).ravel(), dtype)
    # W is pointwise in (x, y), so the gradient of the sum is the pointwise gradient.
    gx, gy = jax.grad(lambda x, y: jnp.sum(wavefront(x, y)), argnums=(0, 1))(x, y)
    return jnp.max(jnp.sqrt(gx * gx + gy * gy))


def _cancellation(aberrations, field, u):
    """The ``aberration_strength`` of each term of ``aberrations`` alone (each coefficient,
    tilt removed), summed, over the design's own (traceable; 1 for a single term; no
    gradient). Seidel's field curvature is defocus at a given field point, so ``w220 h^2``
    is folded into ``w020`` first (one shape, one term). A ``Zernike`` design is split into
    terms of Seidel's shapes (``Zernike.seidel_like_terms``), not into its polynomials:
    ``Z4`` and ``Z11`` set against each other cancel as much as the same defocus and
    spherical aberration given as Seidel coefficients, where their Zernike terms alone
    showed about half of it. A design of zero strength gives 1."""
    aberrations = jax.lax.stop_gradient(aberrations.without_tilt())
    if isinstance(aberrations, Seidel):
        a, h2 = aberrations, jnp.square(field)
        aberrations = Seidel(w020=a.w020 + a.w220 * h2, w040=a.w040, w131=a.w131,
                             w222=a.w222, w220=0.0, w311=a.w311, w111=a.w111)
    total = _strength(aberrations, field, u)
    if isinstance(aberrations, Zernike):
        dtype = common_dtype(aberrations, field, u)
        slopes = [_max_slope(term, dtype) for term in aberrations.seidel_like_terms()]
        parts = sum(slopes, jnp.zeros((), dtype)) * _band_reach(jax.lax.stop_gradient(u))
    else:
        flat, unravel = ravel_pytree(aberrations)
        eye = jnp.eye(flat.shape[0], dtype=flat.dtype)
        parts = jax.vmap(lambda e: _strength(unravel(e * flat), field, u))(eye)
    return jnp.where(total > 0, jnp.sum(parts) / jnp.where(total > 0, total, 1.0), 1.0)


_cancellation_jit = jax.jit(_cancellation)


def _band_reach(u):
    """``min(sqrt(2) u, 1)``: the largest frequency the band reaches [cutoff units], the
    factor between a design's slope ``max |grad W|`` and its ``aberration_strength``."""
    return jnp.minimum(math.sqrt(2.0) * u, 1.0)


def aberration_strength(aberrations: AbstractAberrations, field, u):
    """How hard a design is for ``jmse``: the default preset picks its grid from this.

    ``max |grad W|`` over the pupil (tilt removed; waves per pupil radius, sampled at 12 radii
    x 24 angles) times ``min(sqrt(2) u, 1)``, the largest frequency the band reaches (cutoff
    units). The OTF's ripples along a ray and the phase spread across the overlap both grow
    with it. See ``DEFAULT_TIERS`` for the thresholds.

    Parameters
    ----------
    aberrations : Seidel or Zernike [waves]
    field : float in [0, 1]
    u : float in (0, 1.5]

    Returns
    -------
    scalar [waves]; not differentiable (its gradient is zero). Under ``jit`` or ``vmap``
    (values unchecked) a non-finite input, ``field`` outside [0, 1] or ``u`` outside
    (0, 1.5] gives ``+inf`` (``jmse`` itself computes a traced band past 1.5, which
    ``lens_merit``'s bands scaled to other wavelengths need).

    Examples
    --------
    >>> import jmse_jax as jj
    >>> round(float(jj.aberration_strength(jj.Seidel(w020=1.0), 0.0, 0.5)), 6)  # 2 * 1 * 0.707
    1.414214
    """
    _validate_geometry(aberrations, field, u)
    dtype = common_dtype(aberrations, field, u)
    field, u = jnp.asarray(field, dtype), jnp.asarray(u, dtype)
    # Traced input is not checked above: out of range or non-finite gives +inf, as jmse
    # (no stand-in needed: _strength passes no gradient).
    ok = (all_finite((aberrations, field, u)) & (field >= 0) & (field <= 1) & (u > 0)
          & (u <= U_MAX))
    return jnp.where(ok, _strength(aberrations, field, u), jnp.inf)


def _ring_snr(strength, u, signal, noise):
    """``S_x / S_n`` on the innermost ring where the OTF of a design of this strength can
    vanish, ``_RING_FRACTION u / strength`` from the origin (at most the band's corner,
    ``sqrt(2) u``; ``_snr_on_ring``); traceable."""
    return _snr_on_ring(jnp.minimum(_RING_FRACTION * u / jnp.maximum(strength, 1e-30),
                                    jnp.sqrt(2.0) * u), u, signal, noise)


def _edge_snr(u, signal, noise):
    """``S_x / S_n`` at the band's edge, ``min(sqrt(2) u, 1)`` from the origin
    (``_snr_on_ring``); traceable."""
    return _snr_on_ring(jnp.minimum(jnp.sqrt(2.0) * u, 1.0), u, signal, noise)


#: Points per quadrant on which ``_snr_on_ring`` takes the largest ``S_x / S_n`` of spectra
#: that are not isotropic.
_RING_POINTS = 17


def _snr_on_ring(r, u, signal, noise):
    """The largest ``S_x / S_n`` on the ring ``|nu| = r`` inside the band ``[-u, u]^2``:
    for isotropic spectra its value at ``(r, 0)``; for others the largest at
    ``_RING_POINTS`` angles on the ring's arc in the first quadrant, and in the second too
    unless both are ``x_symmetric`` (``_max_snr``). The point ``(r, 0)`` can lie outside
    the band (``r > u``), where such spectra need not resemble the band's. Traceable; no
    derivative flows through it (the tiers' choice)."""
    if signal.isotropic and noise.isotropic:
        return _snr_at(r, signal, noise)
    r, u = jax.lax.stop_gradient(r), jax.lax.stop_gradient(u)
    # The arc inside the square: nu_x = r cos(theta) <= u and nu_y = r sin(theta) <= u.
    ratio = jnp.clip(u / r, 0.0, 1.0)
    low, high = jnp.arccos(ratio), jnp.arcsin(ratio)
    theta = low + (high - low) * jnp.linspace(0.0, 1.0, _RING_POINTS, dtype=r.dtype)
    return _max_snr(r * jnp.cos(theta), r * jnp.sin(theta), signal, noise)


def _max_snr(nu_x, nu_y, signal, noise):
    """``max S_x / S_n`` over the points ``(nu_x, nu_y)`` of the band's first quadrant and,
    for spectra that are not both ``x_symmetric``, over their mirror images
    ``(-nu_x, nu_y)`` too (``S(-nu) = S(nu)`` gives the other two quadrants)."""
    if not (signal.x_symmetric and noise.x_symmetric):
        nu_x, nu_y = jnp.concatenate([nu_x, -nu_x]), jnp.concatenate([nu_y, nu_y])
    return jnp.max(signal(nu_x, nu_y) / noise(nu_x, nu_y))


def _snr_at(nu, signal, noise):
    """``S_x / S_n`` at ``(nu, 0)``."""
    zero = jnp.zeros_like(nu)
    return signal(nu, zero) / noise(nu, zero)


def _tier_index(strength, u, tiers, snr=None, edge_snr=None):
    """Index of the first tier whose bounds hold (traceable; the last tier has none); a
    design steeper than ``STEEP_SLOPE`` takes the last tier. With the ring SNR ``snr``
    (``_ring_snr``) and the default's tiers, a tier ``i`` of ``WEAK_TIER_SNR``'s is skipped
    above its bound there (``_snr_bounds``); with the SNR at the band's edge ``edge_snr``
    (``_edge_snr``), tiers 1 to 3 above ``EDGE_TIER_SNR`` (``_edge_bounds``)."""
    snr_bounds = () if snr is None else _snr_bounds(tiers)
    edge_bounds = () if edge_snr is None else _edge_bounds(tiers)
    index = jnp.zeros((), jnp.int32)
    past = jnp.asarray(True)
    for i, (bound, u_bound, *_) in enumerate(tiers[:-1]):
        skip = (strength > bound) | (u > u_bound)
        if i < len(snr_bounds):
            skip = skip | (snr > snr_bounds[i])
        if i < len(edge_bounds):
            skip = skip | (edge_snr > edge_bounds[i])
        past = past & skip
        index = index + past.astype(jnp.int32)
    return jnp.where(_steep(strength, u), len(tiers) - 1, index).astype(jnp.int32)


def _snr_bounds(tiers):
    """``WEAK_TIER_SNR`` for the default's tiers (calibrated on their grids), else none: a
    caller's own tiers are chosen by strength and ``u`` alone."""
    return WEAK_TIER_SNR if tiers == DEFAULT_TIERS else ()


def _edge_bounds(tiers):
    """The bounds on ``_edge_snr`` of the default's tiers (``EDGE_TIER_SNR`` on tiers 1
    to 3, so that such a design takes the steep tier), else none."""
    b = EDGE_TIER_SNR
    return (math.inf, b, b, b) if tiers == DEFAULT_TIERS else ()


def _steep(strength, u, slope=STEEP_SLOPE):
    """Whether a design is steeper than ``slope`` (``STEEP_SLOPE``; traceable)."""
    return strength > slope * _band_reach(u)


def _plain_one_ray_merit(options, dtype, operands):
    # The one ray integrates the wavefront's radial part (``symmetric_part``): the same
    # wavefront where the design is symmetric, and the right first derivatives wherever
    # ``first_order_symmetric`` holds.
    aberrations, field, *rest = operands
    return radial_band_integral(aberrations.symmetric_part(field), field, *rest, options,
                                dtype) / (2.0 * math.pi)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _one_ray_merit(static, operands):
    """The merit along one ray (``options`` with ``_radial``; ``static.value`` is
    ``(options, dtype)``), whose first derivatives are the one ray's own and whose second
    derivatives are the polar grid's (the same options less ``_radial``).

    Along one ray a first derivative is exact wherever the design stays symmetric to first
    order (``_switched_merit_jvp`` sends the other designs to the polar grid), but a second
    derivative is not: a perturbation that breaks the symmetry (the field on the axis moves
    coma in) changes the merit at second order in ways the one ray cannot see (on the axis
    of the Fig. 1 design ``d^2 J / d field^2`` came out +7.6e-3 against -4.9e-2).
    """
    options, dtype = static.value
    return _plain_one_ray_merit(options, dtype, operands)


def _live_tangents(d_operands):
    """``(wrt, live)``: which leaves of ``d_operands`` carry a tangent, and those tangents."""
    leaves = jax.tree_util.tree_leaves(d_operands, is_leaf=lambda x: isinstance(x, SymbolicZero))
    wrt = tuple(not isinstance(t, SymbolicZero) for t in leaves)
    return wrt, [t for t, w in zip(leaves, wrt, strict=True) if w]


def _tangent(value, gradient, live):
    """``sum_i <gradient_i, live_i>`` in ``value``'s dtype (operands wider than the
    computation, a float64 signal in a float32 merit, contribute in their own dtype)."""
    terms = [jnp.sum(g * t).astype(value.dtype) for g, t in zip(gradient, live, strict=True)]
    return sum(terms, jnp.zeros_like(value))


def _one_ray_merit_jvp(static, primals, tangents):
    (operands,), (d_operands,) = primals, tangents
    wrt, live = _live_tangents(d_operands)
    value, gradient = _one_ray_value_and_gradient(static, wrt, operands)
    return value, _tangent(value, gradient, live)


_one_ray_merit.defjvp(_one_ray_merit_jvp, symbolic_zeros=True)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1))
def _one_ray_value_and_gradient(static, wrt, operands):
    """The one ray's value and its gradient in the leaves ``wrt`` of ``operands`` (a list),
    from one pass (until 2026-12-06 the value was computed a second time beside the
    gradient's own: about 0.3 ms of a 1.6 ms ``value_and_grad`` on the axis). Derivatives:
    the value's are the one ray's (``_one_ray_merit``), the gradient's the polar grid's."""
    options, dtype = static.value
    return _value_and_grad(functools.partial(_plain_one_ray_merit, options, dtype),
                           wrt)(operands)


@_one_ray_value_and_gradient.defjvp
def _one_ray_value_and_gradient_jvp(static, wrt, primals, tangents):
    (operands,), (d_operands,) = primals, tangents
    options, dtype = static.value
    plane = {k: v for k, v in options.items() if k != "_radial"}

    def plane_gradient(ops):
        return _value_and_grad(lambda o: _merit_value(plane, dtype, *o), wrt)(ops)[1]

    _, d_gradient = jax.jvp(plane_gradient, (operands,), (d_operands,))
    value, d_value = jax.jvp(functools.partial(_one_ray_merit, static), (operands,),
                             (d_operands,))
    gradient = _one_ray_value_and_gradient(static, wrt, operands)[1]
    return (value, gradient), (d_value, d_gradient)


def _mirror_symmetric(aberrations, signal, noise) -> bool:
    """Whether ``S_e(-nu_x, nu_y) = S_e(nu_x, nu_y)`` by the models' static properties, so
    that one of the band's x-mirrored quadrants serves for both."""
    return aberrations.x_symmetric and signal.x_symmetric and noise.x_symmetric


def _merit_value(options, dtype, aberrations, field, u, signal, noise, estimate=False):
    """The merit on the grid of ``options``; with ``estimate``, ``(merit, estimate)`` with
    the relative interpolation-error estimate of ``_interpolation_estimate`` (the larger of
    the two halves' for a wavefront that is not even in x; a polar grid with a fine S_e
    stage only)."""
    if estimate and (options.get("_radial") or options["quadrature"] != "polar"
                     or options["se_nodes"] is None):
        raise ValueError("an estimated grid needs the polar rule with se_nodes")
    if options.get("_radial"):  # a plan for rotationally symmetric designs (see jmse)
        return _one_ray_merit(_Static((options, dtype)), (aberrations, field, u, signal, noise))
    halves = _band_integrals(aberrations, field, u, signal, noise, options, dtype,
                             not _mirror_symmetric(aberrations, signal, noise),
                             estimate=estimate)
    total = halves[0]
    if len(halves) == 2:  # a wavefront or spectra not even in x: the mirrored quadrant too
        mirrored = halves[1]
        if estimate:
            return (0.5 * (total[0] + mirrored[0]) / (2.0 * math.pi),
                    jnp.maximum(total[1], mirrored[1]))
        total = 0.5 * (total + mirrored)
    if estimate:
        return total[0] / (2.0 * math.pi), total[1]
    return total / (2.0 * math.pi)


class _Static:
    """Static arguments (the tiers' plans and the dtype) of ``_switched_merit``, hashable by
    value."""

    def __init__(self, value):
        self.value = value
        self._key = repr(value)

    def __hash__(self):
        return hash(self._key)

    def __eq__(self, other):
        return isinstance(other, _Static) and self._key == other._key


#: How the strong tiers' reverse passes treat their overlap blocks (``_remat_otf``):
#: ``"all"`` recomputes every radial panel's blocks, ``True`` the inner panels' only.
#: Blocks whose chords are integrated in closed form (the steep and balanced grids) are
#: recomputed too: stored, as in session 100, they took the shared scratch to 177 MB.
_REMAT_OTF = "all"
#: The default's weak tiers: the first one-ray plan serves at most this many plans, and
#: the tiers after them recompute their overlap blocks in the reverse pass.
_WEAK_PLANS = 2
#: The grids of the default's two one-ray plans (weak, strong), over the last tier of each
#: group (``_radial_plans``). Until 2026-12-01 each plan took its group's last grid as it
#: stands, which holds on single terms but not on defocus balanced against spherical
#: aberration (``W = c (rho^2 + r rho^4)``, r in -1.5..-0.3), the designs a lens designer
#: makes on purpose: they hold far more spherical aberration than their slope says, so the
#: phase difference varies more along the overlap chords (the order along them binds) and
#: the OTF ripples more finely along the ray (the coarse count binds). On 2000 such designs
#: and single terms, strength 1-45, slope up to 65, u 0.05-1.2, noise 1e-3 to 1e-8
#: (``benchmarks/balanced_one_ray.py``, ``results/balanced_one_ray.md``), the plans as they
#: were left 49 of 1160 weak designs and 183 of 840 strong ones more than 1e-4 off (at
#: noise 1e-4 alone: 9 and 34, worst 2.4e-2 and 1.5e-1). With these grids every design is
#: within 7e-5 up to noise 1e-6 (peak S_x / S_n 1.6e8) and the weak ones within 8e-6 at
#: 1e-8, while 29 strong ones are 1e-4 to 1.4e-2 off there (so designs on the axis are held
#: to ``CHECKED_SNR_PEAKS``). Each grid is about the smallest that held: a weak plan of 48
#: nodes with (40, 40) or (48, 48) left 1e-3 at 1e-8; a strong one of 192 nodes with
#: (128, 96) 1.6e-3 at 1e-6, of 144 nodes 2.4e-4 at 1e-4, (120, 96) or (128, 80) 1.3e-4 and
#: 3.9e-4 at 1e-4 (session 63). Since session 99 the chords of Seidel designs (and of radial
#: Zernike terms up to Z11) are integrated in closed form (``_chords.even_chord_integral``),
#: so the order along them (the second entry of ``overlap_nodes``) serves only radial terms
#: of higher degree; the errors on those 2000 designs are unchanged or smaller.
_RAY_GRIDS = (dict(nodes=(56, 20), overlap_nodes=(48, 48)),
              dict(nodes=(256, 48), overlap_nodes=(128, 96)))


def _tier_plans(options, tiers):
    """Each tier's full option set and its shortcut's ``(trial, check, rtol, u_max, first,
    first_tol)`` (or None; a grid not given is None).

    The strong tiers' reverse passes (every tier after the two weak ones; with fewer tiers,
    the two strongest) recompute their overlap blocks (``_remat_otf``, ``_REMAT_OTF``)
    instead of storing their chord moments. All tiers share one executable
    whose scratch is sized for the largest branch, and above about 32 MB XLA's CPU runtime
    maps scratch afresh on every call and pays a page fault per 4 kB, which every design
    then pays, the Fig. 1 point's shortcut included. With the last tier's inner panels
    recomputed the value_and_grad scratch was 26 MB until tiers 2 and 3 grew on
    2026-11-29 (``DEFAULT_TIERS``); then it was 53 MB and the Fig. 1 point's value_and_grad
    went from 3.1 to 5.6 ms (Intel VM, ``ab_compare.py``). Recomputing every panel of both
    tiers brings it to 23 MB and the Fig. 1 point back to 3.1 ms, at about 3x the time of
    those tiers' value_and_grad (benchmarks/README.md, optimisation log).
    """
    plans = []
    for i, (_, _, grid, shortcut) in enumerate(tiers):
        short = None
        if shortcut is not None:
            if shortcut.trial is None and shortcut.first is None:
                raise ValueError("a TierShortcut needs a trial or a first grid")
            # The first and check grids keep their calibrated form, without the closed-form
            # peaks of jmse_jax._ridges (option ``peaks``): each grid's peaks add about 3 s
            # to the compile of every program that holds it, and where the peaks matter the
            # two coarse grids miss them differently and disagree, which sends the design
            # to its tier's own grid (with the peaks).
            short = (None if shortcut.trial is None else {**options, **shortcut.trial},
                     {**options, **shortcut.check, "peaks": False}, float(shortcut.rtol),
                     float(shortcut.u_max),
                     None if shortcut.first is None
                     else {**options, **shortcut.first, "peaks": False},
                     float(shortcut.first_tol))
        full = {**options, **grid}
        if i >= min(len(tiers) - 2, _WEAK_PLANS):
            full["_remat_otf"] = _REMAT_OTF
        plans.append((full, short))
    return tuple(plans)


def _radial_applies(options, signal, noise) -> bool:
    """Whether the one-ray integral (``jmse_jax._radial``) can stand in for the polar grid of
    ``options``: the polar rule with the overlap engine and a fine S_e grid, and spectra
    that depend on ``|nu|`` only."""
    return (options["quadrature"] == "polar" and options["otf_method"] == "overlap"
            and options["se_nodes"] is not None and signal.isotropic and noise.isotropic)


def _radial_plans(plans, ray=None):
    """The one-ray plans standing in for ``plans`` on rotationally symmetric designs, and the
    first plan index of the second group.

    ``ray`` (a preset's ``ray`` entry, ``HIGH_RAY_GRID``): one plan over the first plan's grid
    with these counts, whatever the plans.

    The plans are split in two groups, each served by its last (finest) plan's grid counts
    along the ray, with ``_RAY_GRIDS`` over them when there are two groups: the first half
    of the plans, at most ``_WEAK_PLANS`` of them, and the rest. One-ray plans cost a few
    ms at most, and they add to the compile time of the default (two plans: about 10-15 %
    more CPU time to compile its value_and_grad), so two cover its five tiers.
    """
    if ray is not None:
        first = {k: v for k, v in plans[0][0].items() if k != "_remat_otf"}
        return (({**first, **ray, "_radial": True}, None),), 1
    split = min(_WEAK_PLANS, -(-len(plans) // 2))
    groups = (plans[:split], plans[split:]) if len(plans) > 1 else (plans,)
    overrides = _RAY_GRIDS if len(groups) == len(_RAY_GRIDS) else ({},) * len(groups)
    radial = tuple(
        ({**{k: v for k, v in group[-1][0].items() if k != "_remat_otf"}, **grid,
          "_radial": True}, None)
        for group, grid in zip(groups, overrides, strict=True))
    return radial, split


def _accepts(trial, check, rtol):
    """Whether a shortcut's ``trial`` value stands (False for non-finite values)."""
    return jnp.abs(trial - check) <= rtol * jnp.abs(trial)


def _first_kept(first, estimate, check, rtol, first_tol):
    """Whether a shortcut's ``first`` value stands: the check agrees with it (``_accepts``)
    and its error ``estimate`` is at most ``first_tol``."""
    return _accepts(first, check, rtol) & (estimate <= first_tol)


#: The dtype in which a shortcut's check grid is computed, whatever the merit's dtype.
_CHECK_DTYPE = jnp.dtype(jnp.float32)


def _in_check_dtype(operands):
    """``operands`` with every floating leaf cast to ``_CHECK_DTYPE``, without a gradient."""
    def cast(x):
        x = jnp.asarray(x)
        return x.astype(_CHECK_DTYPE) if jnp.issubdtype(x.dtype, jnp.floating) else x

    return jax.tree_util.tree_map(cast, jax.lax.stop_gradient(operands))


@jax.named_scope("check_grid")
def _check_value(check_grid, dtype, operands):
    """A shortcut's check value, computed in float32 and returned in ``dtype``.

    The check only decides whether the trial's value stands (``_accepts``, relative
    tolerance 1e-5), and float32 moves it by far less than that: on the 212 calibration and
    bank designs the shortcut serves, a median 3e-7 and no decision changed
    (benchmarks/README.md, optimisation log). In float32 the check takes about 60 % of
    its float64 time. It is never differentiated: only the trial's or the tier's own value
    and gradient are returned. Spectra outside float32's range (``S_x S_n`` beyond about
    1e38 or below 1e-45) make the check non-finite, which refuses the trial: the tier's own
    grid, in the merit's dtype, then gives the value.
    """
    return _apply_merit(check_grid, _CHECK_DTYPE, _in_check_dtype(operands)).astype(dtype)


def _eligible(operands, u_max):
    """Whether a shortcut is tried for these operands (``u <= u_max``; batched if ``u`` is)."""
    return jax.lax.stop_gradient(operands[2]) <= u_max


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _switched_merit(static, index, operands):
    """The merit of plan ``index[0]`` of ``static.value[0]``: one plan runs (``lax.switch``).
    ``index[1]`` is the design's tier among the plans before the one-ray ones
    (``static.value[2]`` of them; None when there are no one-ray plans or only those).

    A tier with a shortcut computes its trial and check values and keeps the trial's when
    they agree, else computes its own grid (``lax.cond``: only one of the two runs under
    ``jit``).

    The derivative rule is written by hand: differentiating through ``lax.switch`` makes JAX
    carry the residuals of every branch (many times the cost of the selected one). Here the
    selected branch computes its value and gradient together, and the tangent is their
    inner product with the input tangents, outside the switch (forward and reverse mode).
    The gradient is that of the grid whose value is returned. A one-ray plan taken because
    the values happen to be symmetric integrates the wavefront's radial part
    (``symmetric_part``), whose first derivatives are the merit's wherever every change
    that breaks the symmetry acts at first order as its radial part
    (``first_order_symmetric``: every Seidel design, and Zernike sets without a term
    ``cos m theta`` of m a positive multiple of 4); for the other designs, the value and
    gradient under differentiation are the design's tier's (polar grid). The one-ray plans'
    second derivatives are always the polar grid's (``_one_ray_merit``).

    Under ``vmap`` (``_dispatch``) each tier runs, for the whole batch, only when one of
    the batch's designs selects it, and a shortcut's own grid only when one of them refuses
    the trial.
    """
    plans, dtype, _ = static.value
    return _dispatch(plans, dtype, with_grad=None)(index[0], operands)


def _dispatch(plans, dtype, with_grad):
    """``lax.switch`` over the tiers (their value, or value and gradient), with a batching
    rule that skips the tiers a batch does not use.

    ``with_grad`` is None for the value alone, else a tuple of booleans, one per leaf of the
    operands: the gradient (a list) is taken in the leaves marked True (``_value_and_grad``).

    ``vmap`` of a ``lax.switch`` or ``lax.cond`` whose index is batched evaluates every
    branch for every design and selects. The rule instead runs each tier, vectorised over
    the whole batch, inside a ``lax.cond`` on whether any design selects it (an unbatched
    predicate, so the other tiers are skipped), and selects each design's result from its
    own tier. In a tier with a shortcut the trial and check run for the batch, and the own
    grid only if a design of the tier refuses its trial. Each design gets exactly what it
    gets alone; a batch of designs from one tier costs one tier.
    """
    if with_grad is None:
        branches = [functools.partial(_tier_value, plan, dtype) for plan in plans]
    else:
        branches = [functools.partial(_tier_value_and_grad, plan, dtype, with_grad)
                    for plan in plans]

    def switch(index, operands):
        return jax.lax.switch(index, branches, operands)

    # Derivatives of the dispatch itself (second derivatives of ``jmse``, e.g. a Hessian)
    # differentiate the plain switch (``with_batching_rule``).
    def run_batched(axis_size, in_batched, index, operands):
        index, operands = spread_batch(axis_size, (index, operands), in_batched)
        shape = jax.eval_shape(jax.vmap(branches[0]), operands)
        zeros = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shape)
        out = zeros
        for tier, plan in enumerate(plans):
            mask = index == tier
            result = _batched_tier(plan, dtype, with_grad, mask, operands, zeros)
            out = jax.tree_util.tree_map(functools.partial(select_batch, mask), result, out)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return with_batching_rule(switch, run_batched)


def _batched_tier(plan, dtype, with_grad, mask, operands, zeros):
    """One tier for a whole batch, skipped (zeros) unless a design in ``mask`` needs it."""
    grid, shortcut = plan

    def merit(options):
        fn = functools.partial(_apply_merit, options, dtype)
        return jax.vmap(fn if with_grad is None else _value_and_grad(fn, with_grad))

    def skip(ops):
        return zeros

    if shortcut is None:
        return jax.lax.cond(jnp.any(mask), merit(grid), skip, operands)
    trial_grid, check_grid, rtol, u_max, first_grid, first_tol = shortcut
    refused = jnp.zeros_like(mask)

    def with_shortcut(ops):
        eligible = _eligible(ops, u_max)

        def attempt(ops):
            check = jax.vmap(functools.partial(_check_value, check_grid, dtype))(ops)

            def second(ops):
                trial = merit(trial_grid)(ops)
                return trial, eligible & _accepts(_value_of(trial, with_grad), check, rtol)

            if first_grid is None:
                return second(ops)
            result, estimate = jax.vmap(_first_fn(first_grid, dtype, with_grad))(ops)
            accepted = eligible & _first_kept(_value_of(result, with_grad), estimate, check,
                                              rtol, first_tol)
            if trial_grid is None:
                return result, accepted
            trial, kept = jax.lax.cond(jnp.any(mask & eligible & ~accepted), second,
                                       lambda ops: (zeros, refused), ops)
            result = jax.tree_util.tree_map(functools.partial(select_batch, accepted), result,
                                            trial)
            return result, accepted | kept

        trial, accepted = jax.lax.cond(jnp.any(mask & eligible), attempt,
                                       lambda ops: (zeros, refused), ops)
        own = jax.lax.cond(jnp.any(mask & ~accepted), merit(grid), skip, ops)
        return jax.tree_util.tree_map(functools.partial(select_batch, accepted), trial, own)

    return jax.lax.cond(jnp.any(mask), with_shortcut, skip, operands)


def _value_of(result, with_grad):
    """The value of a merit's result (the value, or ``(value, gradient)``)."""
    return result if with_grad is None else result[0]


def _first_fn(grid, dtype, with_grad):
    """``ops -> (result, estimate)`` on a shortcut's ``first`` grid: its value (or value and
    gradient, as ``_value_and_grad`` gives them) and its error estimate."""
    fn = functools.partial(_apply_estimated, grid, dtype)
    if with_grad is None:
        return fn
    value_and_grad = _value_and_grad(fn, with_grad, has_aux=True)

    def first(ops):
        (value, estimate), gradient = value_and_grad(ops)
        return (value, gradient), estimate

    return first


def _apply_merit(grid, dtype, operands):
    return _grid_merit(_Static(grid), dtype, operands)


def _apply_estimated(grid, dtype, operands):
    return _estimated_grid_merit(_Static(grid), dtype, operands)


@functools.partial(jax.jit, static_argnums=(0, 1))
def _estimated_grid_merit(grid, dtype, operands):
    """``_estimated_merit_value`` on ``grid.value`` (see ``_grid_merit``)."""
    return _estimated_merit_value(grid.value, dtype, *operands)


@functools.partial(jax.jit, static_argnums=(0, 1))
def _grid_merit(grid, dtype, operands):
    """``_merit_value`` on ``grid.value``: a jitted call, so that a grid used by several
    plans (the first tier's, which is also the second's trial) is traced once per program."""
    return _merit_value(grid.value, dtype, *operands)


def _value_and_grad(fn, wrt, has_aux=False):
    """``value_and_grad`` of ``fn(operands)`` in the leaves of ``operands`` marked True in
    ``wrt``; the gradient is the list of those leaves' gradients. ``has_aux``: ``fn``
    returns ``(value, aux)``, as for ``jax.value_and_grad``."""

    def value_and_grad(operands):
        leaves, treedef = jax.tree_util.tree_flatten(operands)

        def of_live(live):
            it = iter(live)
            full = [next(it) if w else leaf for leaf, w in zip(leaves, wrt, strict=True)]
            return fn(jax.tree_util.tree_unflatten(treedef, full))

        return jax.value_and_grad(of_live, has_aux=has_aux)(
            [leaf for leaf, w in zip(leaves, wrt, strict=True) if w])

    return value_and_grad


def _shortcut_attempt(shortcut, dtype, operands, with_grad):
    """A shortcut's result (value, or value and gradient) and whether it is kept: its
    ``first`` grid's when that is kept, else its trial's when that is.

    The grids run only when the shortcut is eligible (``lax.cond``), and the trial only
    when the first grid is refused; otherwise the result is zeros and not kept. The tier's
    own grid then runs in one ``lax.cond`` of the caller, so the program holds one copy of
    it.
    """
    trial_grid, check_grid, rtol, u_max, first_grid, first_tol = shortcut
    trial_fn = None
    if trial_grid is not None:
        trial_fn = functools.partial(_apply_merit, trial_grid, dtype)
        if with_grad is not None:
            # The trial's gradient is formed with its value: it is the answer more often
            # than not, and its value alone would cost a second pass when it is.
            trial_fn = _value_and_grad(trial_fn, with_grad)
    first_fn = None if first_grid is None else _first_fn(first_grid, dtype, with_grad)

    def attempt_trial(ops, check):
        trial = trial_fn(ops)
        return trial, _accepts(_value_of(trial, with_grad), check, rtol)

    def attempt(ops):
        check = _check_value(check_grid, dtype, ops)
        if first_fn is None:
            return attempt_trial(ops, check)
        first, estimate = first_fn(ops)
        kept = _first_kept(_value_of(first, with_grad), estimate, check, rtol, first_tol)
        if trial_fn is None:
            return first, kept
        return jax.lax.cond(kept, lambda ops, check: (first, kept), attempt_trial, ops, check)

    def skip(ops):
        zeros = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype),
                                       jax.eval_shape(attempt, ops)[0])
        return zeros, jnp.asarray(False)

    return jax.lax.cond(_eligible(operands, u_max), attempt, skip, operands)


def _tier_value(plan, dtype, operands):
    grid, shortcut = plan
    if shortcut is None:
        return _apply_merit(grid, dtype, operands)
    trial, accepted = _shortcut_attempt(shortcut, dtype, operands, with_grad=None)
    return jax.lax.cond(accepted, lambda ops: trial,
                        functools.partial(_apply_merit, grid, dtype), operands)


def _tier_value_and_grad(plan, dtype, wrt, operands):
    grid, shortcut = plan
    full = _value_and_grad(functools.partial(_apply_merit, grid, dtype), wrt)
    if shortcut is None:
        return full(operands)
    trial, accepted = _shortcut_attempt(shortcut, dtype, operands, with_grad=wrt)
    return jax.lax.cond(accepted, lambda ops: trial, full, operands)


def _eager_tier_choice(plan, dtype, operands):
    """``_tier_value`` for concrete inputs, where only the grids needed are compiled and
    run, as ``(value, path)``: ``path`` names the grid that gave the value, ``"first"`` or
    ``"trial"`` (a shortcut's grid kept) or ``"grid"`` (the plan's own)."""
    grid, shortcut = plan
    if shortcut is not None:
        trial_grid, check_grid, rtol, u_max, first_grid, first_tol = shortcut
        if bool(_eligible(operands, u_max)):
            check = _compiled_check(_Static(check_grid), dtype, operands)
            if first_grid is not None:
                first, estimate = _compiled_estimated(_Static(first_grid), dtype, operands)
                if bool(_first_kept(first, estimate, check, rtol, first_tol)):
                    return first, "first"
            if trial_grid is not None:
                trial = _compiled_merit(_Static(trial_grid), dtype, operands)
                if bool(_accepts(trial, check, rtol)):
                    return trial, "trial"
    return _compiled_merit(_Static(grid), dtype, operands), "grid"


@functools.partial(jax.jit, static_argnums=(0, 1))
def _compiled_merit(grid, dtype, operands):
    """``_apply_merit`` on the grid ``grid.value`` after removing the tilt, compiled once per
    grid, dtype and input structure (on concrete inputs the merit would otherwise run
    primitive by primitive)."""
    aberrations, *rest = operands
    return _apply_merit(grid.value, dtype, (aberrations.without_tilt(), *rest))


@functools.partial(jax.jit, static_argnums=(0, 1))
def _compiled_estimated(grid, dtype, operands):
    """``_apply_estimated`` after removing the tilt (see ``_compiled_merit``)."""
    aberrations, *rest = operands
    return _apply_estimated(grid.value, dtype, (aberrations.without_tilt(), *rest))


@functools.partial(jax.jit, static_argnums=(0, 1))
def _compiled_check(grid, dtype, operands):
    """``_check_value`` on the grid ``grid.value`` after removing the tilt (in ``dtype``,
    before the cast, as under ``jit``), compiled once per grid, dtype and input structure."""
    aberrations, *rest = operands
    return _check_value(grid.value, dtype, (aberrations.without_tilt(), *rest))


def _switched_merit_jvp(static, primals, tangents):
    plans, dtype, n_base = static.value
    (index, tier), operands = primals
    _, d_operands = tangents
    # Only the operands that carry a tangent are differentiated: forward mode (``jvp``,
    # ``jacfwd``) and un-jitted reverse mode would otherwise form the gradient in ``u``, the
    # field and the spectra too (through every node's position), which only a jitted
    # ``value_and_grad`` lets XLA drop.
    # (JAX calls this rule only when some tangent is nonzero.)
    wrt, live = _live_tangents(d_operands)
    if n_base is None:
        value, gradient = _dispatch(plans, dtype, with_grad=wrt)(index, operands)
    else:
        # A one-ray plan taken because the values happen to be symmetric: its first
        # derivatives hold only where every first-order change acts as its radial part
        # (``first_order_symmetric``; every Seidel design). Elsewhere (a Zernike set with a
        # term cos 4k theta) the value and gradient are the design's tier's (polar grid):
        # the value then differs from the one ray's by no more than that grid's error.
        # (Taking the value from the one ray there too, by a second switch, cost 0.15 ms of
        # every design's value_and_grad at the Fig. 1 point, one core: 1.37 -> 1.52 ms.)
        aberrations, field = operands[0], operands[1]
        first_order = aberrations.first_order_symmetric(field)
        if first_order is not True:
            index = jnp.where((index >= n_base) & jnp.asarray(first_order, bool), index, tier)
        value, gradient = _dispatch(plans, dtype, with_grad=wrt)(index, operands)
    return value, _tangent(value, gradient, live)


_switched_merit.defjvp(_switched_merit_jvp, symbolic_zeros=True)


def jmse(
    aberrations: AbstractAberrations,
    field,
    u,
    signal: AbstractSignal,
    noise: AbstractNoise,
    *,
    preset: str = "default",
    quadrature: str | None = None,
    nodes=None,
    se_nodes=None,
    otf_method: str | None = None,
    overlap_nodes=None,
    overlap_floor: int | None = None,
    B: int | None = None,
    peaks: bool | None = None,
    se_angular: int | None = None,
    grad_se_angular: int | None = None,
    otf_radial: int | None = None,
    grad_otf_radial: int | None = None,
):
    """Predicted mean-squared error after Wiener restoration (JMSE), Berkner & Shroff Eq. (7).

    .. math::

        \\mathrm{JMSE}(u) = \\frac{1}{2\\pi} \\iint_{|\\nu_x|<u, |\\nu_y|<u}
            \\frac{S_x S_n}{|H|^2 S_x + S_n} \\, d^2\\nu

    Parameters
    ----------
    aberrations : Seidel or Zernike [waves]
    field : float in [0, 1] [fraction of the full field]
    u : float in (0, 1.5] [sensor Nyquist / optical cutoff, ``lambda N / (2 p)``]
    signal : MarkovSignal, PowerLawSignal or WhiteSignal (``S_x``)
    noise : WhiteNoise (``S_n > 0``)
    preset : {"fast", "default", "high"}
        Named option sets (``PRESETS``); ``"default"`` is the recommended trade-off
        (relative error <= 1e-4 on the package's aberration bank, see the README). It is
        adaptive: the grid is chosen from ``aberration_strength`` (``DEFAULT_TIERS``), coarse
        for nearly diffraction-limited designs and finer for strongly aberrated ones, with
        ``lax.switch`` under ``jit`` (one tier runs); a design off the axis whose terms
        cancel each other's slope (defocus set against spherical aberration, say;
        ``BALANCED_CANCELLATION``) takes a balanced tier of its own (``BALANCED_GRID``,
        about 0.2 s a value; ``"high"`` has one too, ``HIGH_BALANCED_GRID``, about
        0.3 s, and a steep grid past ``STEEP_SLOPE`` or ``HIGH_STRONG_STRENGTH``,
        ``HIGH_STEEP_GRID``, and finer counts along its one ray, ``HIGH_RAY_GRID``). A
        design beyond Seidel's shapes (``beyond_seidel_degree``: a Zernike term of radial
        order 5 or more, or of angular order 3 or more) takes the steep tier, or if its
        terms cancel or it is steeper than ``DEGREE_STEEP_SLOPE`` the balanced plan with
        the overlap rule ``DEGREE_OVERLAP``, the OTF nodes ``DEGREE_NODES`` and the fine
        S_e nodes ``DEGREE_SE_NODES`` (``"high"``: its balanced plan, likewise). The two weakest
        tiers first try a cheaper grid and keep its value when a coarse check grid
        (computed in float32, on other angular nodes) agrees with it to 1e-5 and its own
        interpolation-error estimate is below 1e-5
        (``TierShortcut``; only for ``u <= 1/sqrt(2)``, where no ray of the band reaches
        the cutoff): about half of the middle tier's designs and nine in ten of the first's,
        the paper's Fig. 1 point among them, then cost that grid, its estimate and the check
        (at Fig. 1 about 2.5-3.5 times ``baseline_jmse`` at ``B = 64`` for the value and
        about twice for ``value_and_grad``), and the others pay the two cheap grids on top
        of their own. Under ``vmap`` a tier runs, for the whole batch, only
        if one of the batch's designs selects it (and a tier's own grid only if one refuses
        its shortcut), so a batch of similar designs costs one tier; each design gets
        what it gets alone. (That is the vectorised ``vmap`` of GPUs; on CPU ``vmap``
        runs the designs one at a time, ``SEQUENTIAL_VMAP_BACKENDS``, which costs a
        loop's time.) The value can jump, within the tolerance, where a
        design crosses a tier bound or the shortcut's threshold; an optimiser wants a fixed
        grid (``"fast"``, ``optimise``'s default). Every preset integrates a rotationally
        symmetric design (any design on the axis; ``radially_symmetric``) with isotropic
        spectra along one ray instead (``jmse_jax._radial``: 10-20 times faster than the
        polar grid, and more accurate). Setting any grid option (``quadrature``,
        ``nodes``, ``se_nodes``, ``otf_method``, ``overlap_nodes``, ``overlap_floor``) fixes
        the grid (no tiers, no one-ray path): the unset ones take the second tier's values,
        but for ``overlap_floor``, which stays at ``OVERLAP_FLOOR``.
    quadrature : {"polar", "gauss", "gauss_polar", "trapezoid", "rectangle"}
        Frequency rule over the band (``jmse_jax._quadrature``).
    nodes : int or (int, int)
        OTF nodes: per axis for tensor rules, ``(radial, angular)`` per triangle for
        ``"polar"``.
    se_nodes : (int, int) or None
        ``"polar"`` only: the OTF is interpolated (per panel, polynomially) from ``nodes`` to
        these finer nodes, on which ``S_e`` is integrated. ``S_e`` has sharp ridges along the
        OTF's zeros at high SNR while ``H`` stays smooth, and OTF evaluations dominate the
        cost, so this buys accuracy almost for free.
    otf_method : {"overlap", "nudft", "fft"}
    overlap_nodes : int or (int, int)
        ``(n_phi, n_t)`` of the overlap engine. In float32 the engine rounds ``n_t`` (and
        each inner panel's, see ``overlap_floor``) up to a multiple of 8, which its CPU
        loops run fastest at (``_otf.along_chord_order``); float64 takes it as given.
    overlap_floor : int
        ``"polar"`` with ``"overlap"`` only: the overlap order on the inner radial panels of
        the band, where the phase varies less across the overlap lens, is
        ``overlap_floor + (n - overlap_floor) t_max`` per axis (``t_max``: the panel's outer
        end as a fraction of the ray; at most ``n``). 24 in every preset's fixed grid
        (``OVERLAP_FLOOR``); the default's tiers for designs of strength <= 5 and the
        shortcut's check grid use 12, its first grid 10.
    B : int
        Pupil grid of the ``"nudft"``/``"fft"`` engines.
    peaks : bool
        ``"polar"`` with ``se_nodes`` only: where ``|H|^2`` has a minimum along a ray of the
        fine grid whose peak of ``S_e`` is too narrow for the fine nodes (designs near the
        axis at high SNR), integrate that peak in closed form (``jmse_jax._ridges``). On in
        the ``"high"`` preset; off in ``"fast"``, and in the ``"default"`` preset's weak
        tiers (0 and 1), where it would add to the compile time of every program (the
        strong tiers' peaks added about 10 %) and double the time of a design that has
        such peaks. The default's tiers 2, 3 and steep have it in their own grids
        (``DEFAULT_TIERS``, since session 84: without it a near-axis design's gradient was
        up to 4.5e-2 off where its value was right to 2e-6). Not a grid option:
        ``peaks=True`` keeps the default's tiers (their own grids take it, the shortcuts'
        first and check grids do not), and their noise bound ``CHECKED_SNR``: off the axis
        under flat spectra the steep tier, which has the peaks, was 4.7e-4 off beyond it.
    se_angular : int or None
        At least this many angular fine S_e nodes in every polar grid the call may take
        (``"high"``'s own, balanced and steep grids; a grid of your own), without fixing
        the grid: the preset's branches and one-ray plans stay. For gradients at high SNR
        under flat signal spectra, where ``S_e`` turns from ``S_n / |H|^2`` to ``S_x``
        along curves that the rays cross obliquely: at peak ratios 2e6-2e8 ``"high"``'s
        960 were up to 1e-1 off in the gradient while its value held 1e-6
        (``se_angular_for`` gives a count checked there; ``optimise`` takes it by
        itself). Time grows with it (``"high"`` at the Fig. 1 point with 5760: value
        and gradient about 3 times its own), memory hardly (the fine stage runs in
        blocks). Not with the default's tiers (``ValueError``).
    grad_se_angular : int or None
        ``se_angular`` for derivatives alone: differentiated (``jax.grad``, ``jvp``),
        ``jmse`` returns the gradient of the grid with at least this many angular fine
        S_e nodes and the value of its own grid, so the value does not change with
        differentiation (the gradient costs the finer grid's ``value_and_grad`` plus
        the value). ``"high"`` takes ``se_angular_for``'s count by itself when ``u`` and
        the spectra are concrete at a peak ``S_x / S_n`` beyond ``CHECKED_SNR`` (a
        gradient in the coefficients, the field or a lens's parameters, ``lens_merit``
        included; ``u`` and the spectra differentiated without ``jit`` count as concrete,
        since their tracers carry the values), unless ``se_angular`` or grid options are
        given. With ``u`` or the spectra traced by your ``jit`` or ``vmap`` it cannot see
        the ratio: each gradient then checks it at run time and warns beyond
        ``CHECKED_SNR``, naming the count to give. Not with the default's tiers
        (``ValueError``); concrete calls, which return values only, ignore it.
    otf_radial : int or None
        At least this many radial OTF nodes in every polar grid the call may take, as
        ``se_angular`` does for the angular fine S_e nodes (at most ``se_nodes[0]``). At
        low noise under flat signal spectra the fine nodes' interpolation of ``H``
        binds where ``S_e`` turns at small ``|H|``: ``"high"``'s own 80 left a gradient
        3.0e-4 off at a peak ratio of 1.2e7 and a value 3.2e-5 at 2e8, its steep grid's
        128 a gradient 3.3e-4 and a value 6.2e-5 at 2e8; 160 held them within 4e-7
        (``otf_radial_for`` gives the count, ``OTF_RADIAL_BY_SNR``). ``"high"`` takes it
        by itself, for the value and the gradient, where ``u`` and the spectra are
        concrete at a peak ratio beyond ``CHECKED_SNR``, unless grid options or any of
        the four counts are given. With them traced (a noise level swept under ``vmap``,
        or an argument of your ``jit``) the value is its own grid's and warns at run
        time beyond ``CHECKED_SNR``, naming the count to give, as a gradient does
        (``grad_se_angular``). Time: at the Fig. 1 point 160 radial OTF
        nodes add about 50 ms to ``"high"``'s 82 ms value, and 64 ms to its 234 ms
        ``value_and_grad`` with 1920 angular fine nodes (docs/accuracy.md).
    grad_otf_radial : int or None
        ``otf_radial`` for derivatives alone, as ``grad_se_angular`` is. Giving any of
        ``se_angular``, ``grad_se_angular``, ``otf_radial`` or ``grad_otf_radial`` turns
        ``"high"``'s own choice of both counts off.

    Returns
    -------
    scalar, in the units of ``S_x`` (a variance). Differentiable in every float: the
    coefficients, ``field``, ``u``, and the signal and noise parameters.

    Notes
    -----
    A concrete design whose ``aberration_strength`` exceeds what the presets were checked
    at (``CHECKED_STRENGTH``, 25; 45 for rotationally symmetric designs), or whose wavefront
    slope ``max |grad W|`` does (``CHECKED_SLOPE``, 65 waves per pupil radius: at small
    ``u`` a design of moderate strength can hold many waves), gets a
    ``AccuracyWarning`` unless grid options are given, and so does a peak ``max S_x / S_n``
    above ``CHECKED_SNR`` (2e6; ``CHECKED_SNR_PEAKS``, 2e8, with ``peaks`` outside the
    default's tiers, as in ``"high"``, or for a rotationally symmetric design, whose one-ray
    plan integrates them in closed form): narrow features of ``S_e`` then outgrow the grids
    (docs/accuracy.md, "Accuracy at low noise"). With the design traced (your ``jit`` or
    ``vmap``) and ``u`` and the spectra concrete, the ratio's warning is given when the
    call is traced, past ``CHECKED_SNR`` for any design with ``"fast"`` and the default.
    The design's own warnings (and the ratio's, with the spectra traced) are then given
    when the program runs, in words that name the bound rather than the design's values,
    so that Python's filters show each once: the program computes the strength, slope,
    cancellation and ratio as a concrete call does and calls the host only for a design
    beyond them (once per ``vmap`` batch). JAX's persistent compilation cache keeps no
    program that calls the host: trace inside ``run_time_checks(False)`` to leave the
    checks out (the same numbers, no run-time warnings).
    Discrete options are static (Python values). Bad concrete input raises ``ValueError``;
    under ``jit``/``vmap`` non-finite or out-of-range inputs (``field``, ``u <= 0``, the
    spectra's parameters) give ``+inf`` (never NaN) with zero gradient. A traced ``u`` above
    ``U_MAX`` is computed, not refused: ``lens_merit`` scales the band to other wavelengths
    and may pass 1.5 (the band beyond the cutoff adds ``S_x`` alone, integrated as for
    ``u <= 1.5``).
    Works in float32 and float64; the result follows the inputs' dtype.

    Outside ``jit`` nothing runs primitive by primitive: a call on concrete inputs
    compiles only the grids its design needs, each once per process (the default: about
    2 s for the first design on a 2-core CPU, milliseconds per call after that). So does a
    derivative taken without ``jit`` (``jax.grad(jmse)(...)``, ``jax.hessian``; not under
    ``vmap``), whose tracers carry the concrete design: the grid is chosen on it, and only
    that grid's derivative is compiled (about 4 s for the default's gradient at the Fig. 1
    point, 44 s for the whole program), with the derivatives the traced program has; a
    rotationally symmetric design compiles its one-ray plan alone. Under an outer ``jit``
    these inner programs are inlined.

    Examples
    --------
    >>> import jax
    >>> jax.config.update("jax_enable_x64", True)
    >>> import jmse_jax as jj
    >>> ab = jj.Seidel(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
    >>> value = jj.jmse(ab, 0.95, 0.2, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3))
    >>> round(float(value), 9)  # the converged value is 2.6539432e-3
    0.002653942
    """
    static, inputs = _prepare(
        (aberrations, field, u, signal, noise),
        jmse_options(preset, quadrature=quadrature, nodes=nodes, se_nodes=se_nodes,
                     otf_method=otf_method, overlap_nodes=overlap_nodes,
                     overlap_floor=overlap_floor, B=B, peaks=peaks, se_angular=se_angular,
                     grad_se_angular=grad_se_angular, otf_radial=otf_radial,
                     grad_otf_radial=grad_otf_radial))
    # A preset's grids (the grid options, when given, are the user's own sizing).
    preset_grid = all(v is None for v in (quadrature, nodes, se_nodes, otf_method,
                                          overlap_nodes, overlap_floor))
    given = dict(se_angular=se_angular, grad_se_angular=grad_se_angular,
                 otf_radial=otf_radial, grad_otf_radial=grad_otf_radial)
    static, gradient_static, watch = _low_noise_statics(
        static, (u, signal, noise), given, auto=preset_grid)
    if is_concrete(inputs):
        # On a design stronger than they were checked at: a warning.
        return _concrete_merit(static, inputs, warn=preset_grid)[0]
    primal = concrete_primal(inputs) if preset_grid else None
    if primal is not None:
        # Differentiated outside jit (an eager jax.grad, jax.jvp): the same warnings.
        choice = tuple(x.item() for x in _concrete_choice(static, *primal))
        _warn_design(static, primal, choice, stacklevel=3)
    elif preset_grid and is_concrete((u, signal, noise)):
        # Under jit or vmap with u and the spectra concrete: the peak ratio's warning, once
        # when the call is traced (the design's own warnings need its values).
        _warn_snr_of_traced_design(static, u, signal, noise, stacklevel=3)
    # Otherwise the design (and, with u or the spectra traced, the peak ratio unless
    # "high"'s low-noise check watches it) is checked when the program runs.
    # With run_time_checks(False) neither check is compiled in (no host callback: the
    # program can be stored in JAX's persistent compilation cache); values are unchanged.
    checks = _run_time_checks_on()
    check = (not watch and not is_concrete((u, signal, noise))
             if checks and preset_grid and primal is None and not _CHECKED_ALREADY.get()
             else None)
    try:
        if primal is not None and gradient_static is None and not watch:
            # Only the grid this design takes is compiled and differentiated.
            eager = _eager_derivative(static, inputs, primal, choice)
            if eager is not None:
                return eager
        if _batching_program(static):
            # Reverse mode over a derivative of this program fails inside JAX, in places
            # (in the outer backward pass, with an AssertionError, for one-ray plans with
            # the peaks) and under forms (a jit between the two derivatives) that jmse
            # cannot see: the program's inputs carry a refusal that the outer derivative
            # meets first, as soon as it linearizes.
            inputs = refuse_reverse_over(inputs, _REVERSE_OVER_DERIVATIVE)
        return _traced_entry(static, inputs, gradient_static, watch and checks, check)
    except ValueError as error:  # raised while tracing: costs nothing at run time
        if _SECOND_REVERSE not in str(error):
            raise
        raise ValueError(_REVERSE_OVER_DERIVATIVE) from error


#: ``jmse``'s error for reverse mode over one of its own derivatives where JAX cannot take
#: it (``_batching_program``).
_REVERSE_OVER_DERIVATIVE = (
    "jmse cannot be differentiated in reverse mode through one of its own derivatives "
    "(jax.grad of jax.grad, jax.jacrev of jax.jacrev, jax.grad of a jax.jvp) with the "
    "default's tiers or the closed-form peaks (preset='high', peaks=True): JAX cannot "
    "linearize their derivative rules a second time. Take second derivatives forward "
    "over reverse instead: jax.hessian(f), jax.jacfwd(jax.grad(f)), or jax.jvp of "
    "jax.grad(f) for one direction (docs/conventions.md, 'Second derivatives')")


def _batching_program(static) -> bool:
    """Whether the traced program of ``static`` holds a batching rule that reverse mode
    cannot linearize a second time (``with_batching_rule``'s ``custom_vmap``): the switch
    between several plans (the default's tiers, ``"high"``'s steep and balanced grids) or
    the closed-form peaks' branch (``batch_skipping_cond``). A single plan without the
    peaks (``"fast"``, grids given) has neither, and reverse over reverse works there.
    The design does not change which plans there are (only the balanced plan's counts)."""
    plans = _base_plans(static)
    return len(plans) > 1 or any(plan.get("peaks") for plan, _ in plans)


#: Why ``_eager_derivative``, whose programs carry no ``refuse_reverse_over``, refuses
#: reverse mode over a derivative of a one-ray plan with the peaks itself: JAX fails there
#: only in the outer derivative's backward pass, outside ``jmse``, with an
#: ``AssertionError`` (``fancy_bilinear_transpose``), and a process's memory then grew
#: until it was killed (session 92).
_ONE_RAY_REVERSE = "reverse mode over a derivative of a one-ray plan with the closed-form peaks"


#: The start of JAX's error when reverse mode linearizes the derivative rule of the tier
#: switch or of the peaks' branch a second time (``jax.grad(jax.grad(jmse))``), which
#: ``jmse`` turns into an error that says what to do instead. ``refuse_reverse_over``
#: refuses such calls before JAX meets it; this stays for a JAX whose partial-evaluation
#: tracer is not named ``JaxprTracer``, which the sentinel reads.
_SECOND_REVERSE = "Linearization failed to produce known values"


#: Backends on which ``vmap`` of ``jmse`` (and of its derivatives) runs the batch's designs
#: one at a time (``lax.map``) rather than vectorised. On CPU a vectorised batch cost
#: 2.5-8 times a loop per design (32 random designs within +-3 waves, u = 0.3, one core,
#: value_and_grad: ``fast`` 11.0 against 3.8 ms, the default 109 against 13.5 ms): XLA's
#: CPU loops, tuned for one design's arrays, gain nothing from the batch axis, and the
#: default's tiers and shortcuts run for every design of a block that one design needs.
SEQUENTIAL_VMAP_BACKENDS = ("cpu",)


def _traced_entry(static, inputs, gradient_static=None, watch=False, check=None):
    """``_traced_merit``, run design by design under ``vmap`` on the backends of
    ``SEQUENTIAL_VMAP_BACKENDS`` (the default backend's, at trace time), with the gradient
    of ``gradient_static`` and the run-time checks ``watch`` and ``check`` when ``jmse`` asks
    for them (``_merit_with_rule``)."""
    sequential = jax.default_backend() in SEQUENTIAL_VMAP_BACKENDS
    if not sequential and gradient_static is None and not watch and check is None:
        return _traced_merit(static, inputs)
    return _merit_with_rule(static, gradient_static, watch, sequential, check, inputs)


@functools.partial(jax.jit, static_argnums=(0, 1, 2, 3, 4))
def _merit_with_rule(static, gradient_static, watch, sequential, check, inputs):
    """``_traced_merit(static, inputs)`` under a derivative rule of its own: with
    ``sequential`` its ``vmap`` runs design by design, for the value and for first
    derivatives alike; with ``gradient_static`` (``_raised``: more angular fine S_e
    nodes) its derivatives are that program's while the value stays ``static``'s, so it
    does not change with differentiation (the gradient costs the finer program's
    ``value_and_grad`` plus this value); with ``watch`` every value and every gradient
    checks the peak ``S_x / S_n`` and warns beyond ``CHECKED_SNR`` (``_warn_traced_snr``;
    a host callback, about 0.1 ms; a value alone warns only where the radial OTF nodes,
    which hold values, fall short); with ``check`` (None, or whether the peak ratio is
    checked too) every value and gradient checks its designs (``_design_check``; the host
    is called only for designs beyond the checked range).

    Jitted, as ``_traced_merit`` is: a transformation applied without ``jit`` then traces
    the wrappers once and reuses the program (an eager ``jax.grad`` of the Fig. 1 point
    took 7.5 ms per call with them traced anew each call, against 3.1 ms before them).

    A batching rule alone (``custom_vmap``) is not consulted under differentiation, so the
    derivative rule forms the value and the gradient in the leaves that carry a tangent
    together, by one call whose ``vmap`` also runs design by design; ``vmap`` of
    ``jax.grad`` or ``value_and_grad`` batches that call. (That is what ``_switched_merit``'s
    rule computes for a tangent anyway: a reverse-mode gradient.) Second derivatives go
    through that call's plain form (``with_batching_rule``): a Hessian is what it was.
    """
    by_design = one_at_a_time if sequential else (lambda fn: fn)
    merit = by_design(functools.partial(_traced_merit, static))
    finer = functools.partial(_traced_merit, gradient_static or static)

    own = tuple(_own_counts(static.value[0]).items()) if watch else None

    def checked(inputs, value, gradient=None):
        """``value`` (and ``gradient``, a list of arrays) once the checks have run."""
        if not watch and check is None:
            return value, gradient
        zero = jnp.zeros((), value.dtype)
        if watch:
            zero = zero + _run_time_zero(
                functools.partial(_warn_traced_snr, own, gradient is not None),
                _peak_snr(*inputs[2:])).astype(value.dtype)
        if check is not None:
            zero = zero + _design_check(static, check, inputs).astype(value.dtype)
        # The zero goes into every output, so the check runs whichever is used (a jax.grad
        # drops the value, and a pure callback whose result is unused is dropped with it);
        # into the gradient as a factor 1 + 0, so that its derivatives (a jax.hessian) use
        # it too.
        return value + zero.astype(value.dtype), (
            None if gradient is None else [g * (1 + zero.astype(g.dtype)) for g in gradient])

    def value_and_grad(wrt):
        def run(inputs):
            value, gradient = by_design(_value_and_grad(finer, wrt))(inputs)
            if gradient_static is not None:
                value = merit(inputs)
            return checked(inputs, value, list(gradient))

        return run

    return _gradient_rule(lambda inputs: checked(inputs, merit(inputs))[0],
                          value_and_grad)(inputs)


def _gradient_rule(value, value_and_grad):
    """``value`` (a function of one pytree of operands) whose tangent is the inner product
    of ``value_and_grad(wrt)(operands)``'s gradient (a list, one array per leaf marked True
    in ``wrt``) with the tangents of the leaves that carry one (``_live_tangents``): the
    derivative rule of the tiers' switch, so that forward mode forms a reverse-mode
    gradient and a Hessian (forward over reverse) keeps only that gradient."""

    @jax.custom_jvp
    def call(operands):
        return value(operands)

    def call_jvp(primals, tangents):
        (operands,), (d_operands,) = primals, tangents
        wrt, live = _live_tangents(d_operands)
        out, gradient = value_and_grad(wrt)(operands)
        return out, _tangent(out, list(gradient), live)

    call.defjvp(call_jvp, symbolic_zeros=True)
    return call


def _run_time_zero(check, snr):
    """A zero of ``snr``'s shape and dtype, computed once ``check`` has seen ``snr`` on the
    host when the program runs (a ``pure_callback``: add the zero to every output that
    must wait for the check, or the callback is dropped as unused). Under ``vmap``
    ``check`` runs once per batch with the batch's ratios (``jax.debug.callback`` unrolls
    a batch into one callback per design: a ``vmap`` of 5000 traced calls took 59 s more
    to compile), and it takes no derivative (its input is a constant to them)."""
    snr = jax.lax.stop_gradient(snr)

    def host(ratios):
        check(ratios)
        return np.zeros(np.shape(ratios), snr.dtype)

    return jax.pure_callback(host, jax.ShapeDtypeStruct(snr.shape, snr.dtype), snr,
                             vmap_method="expand_dims")


#: The columns of ``_design_check``'s statistics, one row per design.
_CHECK_STATS = ("in_range", "symmetric", "strength", "cancellation", "u", "snr")


def _design_check(static, snr, inputs):
    """A zero that carries the run-time check of a traced ``jmse`` call with a preset's
    grids (``jmse``'s ``check``): the warnings a concrete call gives its design
    (``_warn_design``: strength, wavefront slope, cancelling terms) and, with ``snr``, the
    peak ``S_x / S_n`` (past ``CHECKED_SNR``, or ``CHECKED_SNR_PEAKS`` for a one-ray plan or
    the peaks), computed in the program from the design as the concrete call computes them.
    Only a design beyond one of those bounds calls the host (``batch_skipping_cond``: under
    ``vmap`` one call per batch, and none where no design is beyond), so a call inside the
    checked range pays the statistics (``_strength``, and ``_cancellation`` from
    ``CANCELLING_STRENGTH``, which the default's tiers compute as well) and one branch.
    Out-of-range inputs (``+inf`` values) are left out, and no derivative flows."""
    safe, ok = _sanitise(jax.lax.stop_gradient(inputs))
    aberrations, field, u, signal, noise = safe
    aberrations = aberrations.without_tilt()
    symmetric = aberrations.radially_symmetric(field) if static.value[2] else False
    strength = _strength(aberrations, field, u)
    dtype = strength.dtype
    cancellation = _cancellation_from(strength, aberrations, field, u)
    balanced = static.value[4] is not None
    snr_peaks = _snr_peaks(static.value[0]["peaks"], static.value[1])
    strong, steep, cancelling, _ = _beyond_checked(strength, u.astype(dtype), symmetric,
                                                   cancellation, balanced=balanced, xp=jnp)
    beyond = strong | steep | cancelling
    peak = jnp.zeros((), dtype)
    if snr:
        peak = _peak_snr(u, signal, noise).astype(dtype)
        peaks = jnp.asarray(symmetric) | snr_peaks
        beyond = beyond | (peak > jnp.where(peaks, CHECKED_SNR_PEAKS, CHECKED_SNR))
    stats = jnp.stack([jnp.asarray(x, dtype) for x in (
        ok, symmetric, strength, cancellation, u, peak)])
    host = functools.partial(_warn_traced_designs, balanced, snr_peaks, snr)
    zero = batch_skipping_cond(ok & beyond, lambda s: _run_time_zero(host, s),
                               jnp.zeros_like, stats, sequential=False)
    return jnp.sum(zero)


def _warn_traced_designs(balanced, snr_peaks, snr, stats):
    """The host's part of ``_design_check``: ``stats`` (``_CHECK_STATS``, one row per
    design of the call or its ``vmap`` batch) -> the warnings ``_warn_design`` gives, one
    per kind. ``balanced``: the preset has the balanced grid; ``snr_peaks``: its grids have
    the peaks (``_snr_peaks``); ``snr``: the peak ratio was checked. The texts name the
    bound, not the design's values, so that Python's warning filters (by default: each text
    once) keep an optimiser's loop or a sweep from repeating them call after call."""
    stats = np.asarray(stats, float).reshape(-1, len(_CHECK_STATS))
    stats = stats[stats[:, 0] > 0]  # out-of-range designs: +inf, no warning
    if stats.shape[0] == 0:
        return
    symmetric, strength, cancellation, u, peak = stats[:, 1:].T
    symmetric = symmetric > 0
    strong, steep, cancelling, _ = _beyond_checked(strength, u, symmetric, cancellation,
                                                   balanced=balanced)
    for beyond, message in (
            (strong, _strength_message(_TRACED_DESIGN)),
            (steep, _slope_message(_TRACED_DESIGN[3:])),
            (cancelling, _cancellation_message(
                f"more than {CHECKED_CANCELLATION if balanced else BALANCED_CANCELLATION:g}",
                balanced))):
        if beyond.any():
            warnings.warn(message + _TRACED_SUFFIX, AccuracyWarning, stacklevel=2)
    if snr:
        peaks = symmetric | snr_peaks
        beyond = peak > np.where(peaks, CHECKED_SNR_PEAKS, CHECKED_SNR)
        if beyond.any():
            _warn_snr(float(peak[beyond].max()), 3, peaks=bool(peaks[beyond].all()),
                      shown=_TRACED_DESIGN, suffix=_TRACED_SUFFIX)


#: How ``_warn_traced_designs`` names the design, in place of its values.
_TRACED_DESIGN = "of a design in a traced call"
_TRACED_SUFFIX = (" (jmse under jit, vmap or grad checks its designs when the program runs; "
                  "aberration_strength and the spectra, called on the design itself, give "
                  "the values)")


def _low_noise_statics(static, spectra, given, auto):
    """``(static, gradient_static, watch)`` of ``jmse``: ``static`` with the counts that
    hold values raised, the static whose gradient ``jmse`` returns when it is not that
    one's (None otherwise), and whether each gradient checks the peak ratio at run time.
    ``given``: the four count options as given (``_FLOOR_OPTIONS``); with none of them and
    ``auto`` (a preset's grids) the counts are ``_auto_counts``' (``otf_radial`` for
    both, ``se_angular`` for the gradient), otherwise the ``grad_`` counts given raise the
    gradient's (the others are in ``static`` already, ``_base_plans``)."""
    auto = auto and all(n is None for n in given.values())
    counts, watch = (_auto_counts(*static.value[:2], spectra) if auto else (None, False))
    # The radial OTF nodes hold the value as well as the gradient (OTF_RADIAL_BY_SNR).
    static = _raised(static, {k: n for k, n in (counts or {}).items()
                              if k in _VALUE_FLOORS}) or static
    grads = counts if auto else {k: given["grad_" + k] for k, _, _ in _FLOORS}
    return static, _raised(static, grads or {}), watch


def _auto_counts(options, tiers, spectra):
    """``(counts, watch)``: the counts ``jmse`` takes by itself for a call with a preset's
    grids and none of the counts given, as the ``{floor: count}`` of ``options``'s
    (resolved ``jmse`` options; ``tiers`` theirs) that ``_counts_for_snr`` raises
    (``otf_radial`` for the value and the gradient, ``se_angular`` for the gradient).
    Only where ``options`` hold the peaks without the default's tiers (``"high"``, whose
    own counts hold its gradients only to ``CHECKED_SNR``) and ``spectra``, the arguments
    ``(u, signal, noise)`` as given, are concrete: ``{}`` there at a peak ``S_x / S_n``
    within ``CHECKED_SNR`` (the own counts hold), None where the choice does not apply.
    Spectra differentiated without ``jit`` count as concrete (``concrete_primal``).
    ``watch``: the same case with ``spectra`` traced, where the counts cannot be chosen
    (grid sizes are static); a gradient then warns at run time beyond ``CHECKED_SNR``,
    and a value where its radial OTF nodes fall short (``_warn_traced_snr``). ``jmse``,
    ``lens_merit`` and ``optimise`` use it."""
    if not _chooses_counts(options, tiers):
        return None, False  # no fine polar grid, or the default's tiers
    # Differentiated without jit (an eager jax.grad in u or the noise), the tracers carry
    # the concrete spectra.
    spectra = spectra if is_concrete(spectra) else concrete_primal(spectra)
    if spectra is None:
        return None, True
    # Concrete even inside a caller's jit, where the call would be staged out.
    with jax.ensure_compile_time_eval():
        snr = float(_peak_snr(*spectra))
    return (_above_own(options, _counts_for_snr(snr)) if snr > CHECKED_SNR else {}), False


def _chooses_counts(options, tiers) -> bool:
    """Whether calls with the resolved ``jmse`` options ``options`` (``tiers`` theirs) take
    the low-noise counts by themselves (``_auto_counts``): a fine polar grid with the peaks
    and without the default's tiers (``"high"``)."""
    return options["se_nodes"] is not None and _snr_peaks(options["peaks"], tiers)


def _raised(static, counts):
    """``static`` with its floors (``_FLOORS``) raised to ``counts`` (``{floor: count or
    None}``), or None when that raises no count of its own grid (``_above_own``). With the
    default's tiers, which refuse the floors, or without a fine polar grid: None."""
    options, tiers = static.value[0], static.value[1]
    if options["se_nodes"] is None or tiers is not None:
        return None
    raised = _above_own(options, counts)
    if not raised:
        return None
    return _Static(({**options, **raised},) + tuple(static.value[1:]))


def _above_own(options, counts):
    """The counts of ``counts`` (``{floor: count or None}``) above those of ``options``'s
    own grid (``_own_counts``; the branches of ``"high"`` have as many or more)."""
    own = _own_counts(options)
    return {k: n for k, n in counts.items() if n is not None and n > own[k]}


def _own_counts(options):
    """``{floor: count}``: the counts of ``options``'s own grid that ``_FLOORS`` raise, with
    its floors applied (the branches of ``"high"`` have as many or more)."""
    return {floor: max(options[entry][index], options[floor] or 0)
            for floor, entry, index in _FLOORS}


def _warn_traced_snr(own, gradient, snr):
    """The run-time warning of a call of ``"high"`` (the peaks without the default's tiers)
    whose ``u`` or spectra were traced (``_auto_counts``'s ``watch``), at the peak ratios
    ``snr`` (one per design): for a gradient (``gradient``) beyond ``CHECKED_SNR``, for a
    value alone where ``OTF_RADIAL_BY_SNR`` asks for more radial OTF nodes than the grid's
    (the value's count, ``_VALUE_FLOORS``; without them a value was up to 6.2e-5 off at
    2e8); beyond ``CHECKED_SNR_PEAKS``, where no count was checked, it says so, as the
    concrete call's warning does (``_warn_beyond_checked_snr``). ``own``: ``_own_counts``
    of the grid, as ``((floor, count), ...)``."""
    snr = np.asarray(snr)
    snr = snr[np.isfinite(snr)]  # out-of-range inputs give +inf values and zero gradients
    if snr.size == 0 or snr.max() <= CHECKED_SNR:
        return
    counts = _counts_for_snr(float(snr.max()))
    own = dict(own)
    floors = [floor for floor, _, _ in _FLOORS if gradient or floor in _VALUE_FLOORS]
    short = [floor for floor in floors if counts[floor] > own[floor]]
    if not gradient and not short:
        return
    prefix = "grad_" if gradient else ""
    give = ", ".join(f"{prefix}{floor}={counts[floor]}" for floor in short) or "nothing more"
    have = ", ".join(f"{own[floor]} {_FLOOR_WORDS[floor]}" for floor in floors)
    tables = ", ".join(f"{floor.upper()}_BY_SNR" for floor in floors)
    helpers = ", ".join(f"jmse_jax.{floor}_for" for floor in floors)
    also = ", or se_angular and otf_radial," if gradient else ""
    what = "gradient" if gradient else "value"
    beyond = (f"; beyond {CHECKED_SNR_PEAKS:.0e} (CHECKED_SNR_PEAKS) no counts were checked, "
              f"and the {what} may be off by more than 1e-4 with these: give finer grids "
              f"and compare two of them" if snr.max() > CHECKED_SNR_PEAKS else "")
    warnings.warn(
        f"jmse's {what} at a peak S_x / S_n of {snr.max():.2g}, beyond {CHECKED_SNR:.0e}, "
        f"with {have}: with u or the spectra traced jmse cannot choose the counts that hold "
        f"it ({tables}), and preset='high''s own hold its {what} only to "
        f"{CHECKED_SNR:.0e}; pass {give} ({helpers} of (u, signal, noise)){also} to jmse"
        f"{beyond}",
        AccuracyWarning, stacklevel=2)


def _prepare(arguments, options):
    """``(static, inputs)`` of ``jmse`` for validated ``arguments`` and resolved options
    (the ``grad_`` counts are ``jmse``'s own business, not part of the static)."""
    _validate(*arguments)
    aberrations, field, u, signal, noise = arguments
    dtype = common_dtype(*arguments)
    inputs = (aberrations, jnp.asarray(field, dtype), jnp.asarray(u, dtype), signal, noise)
    options = dict(options)
    for floor, _, _ in _FLOORS:
        options.pop("grad_" + floor, None)
    tiers = options.pop("tiers")
    radial = options.pop("radial") and _radial_applies(options, signal, noise)
    balanced = options.pop("balanced")  # None with a fixed grid (``jmse_options``)
    steep, ray = options.pop("steep"), options.pop("ray")
    return _Static((options, tiers, radial, dtype, balanced, steep, ray)), inputs


def _route(aberrations, field, u, signal, noise, **options):
    """Which plan ``jmse`` (with these options) takes for a concrete design, as a dict:
    ``tier`` (index into the tiers, ``len(DEFAULT_TIERS)`` for the balanced tier, the tier
    by strength when a one-ray plan runs; None without tiers), ``balanced`` (the preset's
    balanced grid runs: ``BALANCED_GRID``, ``HIGH_BALANCED_GRID``), ``steep`` (the steep
    grid of a preset without tiers runs: ``HIGH_STEEP_GRID``), ``one_ray`` (a one-ray
    plan runs, ``jmse_jax._radial``) and ``path`` (the shortcut's ``"first"`` or ``"trial"``
    grid, or the plan's own ``"grid"``); and the ``value`` it returns. For the benchmarks."""
    static, inputs = _prepare((aberrations, field, u, signal, noise), jmse_options(**options))
    # The counts jmse takes by itself at low noise (the plans' indices do not change).
    static, _, _ = _low_noise_statics(
        static, (u, signal, noise), {k: options.get(k) for k in _FLOOR_OPTIONS},
        auto=not any(options.get(k) is not None for k in _GRID_OPTIONS))
    value, index, symmetric, path = _concrete_merit(static, inputs)
    tiers, balanced, steep = static.value[1], static.value[4], static.value[5]
    takes_balanced = (balanced is not None and not symmetric
                      and index == _n_strength_plans(static))
    takes_steep = tiers is None and steep is not None and not symmetric and index == 1
    tier = None if tiers is None else index
    return dict(tier=tier, balanced=takes_balanced, steep=takes_steep, one_ray=symmetric,
                path=path, value=value)


def _base_plans(static, aberrations=None):
    """The plans of ``static``: the tiers' (or the one fixed grid and, when the preset has
    one, its steep grid, ``HIGH_STEEP_GRID``), then the balanced grid when there is one
    (``BALANCED_GRID``, ``HIGH_BALANCED_GRID``), with the overlap rule ``DEGREE_OVERLAP``,
    the OTF nodes ``DEGREE_NODES`` and the fine S_e nodes ``DEGREE_SE_NODES`` when
    ``aberrations`` can be of higher degree than Seidel's (``_degree_program``)."""
    options, tiers, _, _, balanced, steep, _ = static.value
    if tiers is not None:
        plans = _tier_plans(options, tiers)
    elif steep is not None:
        plans = ((options, None), ({**options, **steep, "_remat_otf": _REMAT_OTF}, None))
    else:
        plans = ((options, None),)
    if balanced is not None:
        if _degree_program(aberrations):
            balanced = {**balanced, **DEGREE_OVERLAP, "nodes": DEGREE_NODES,
                        "se_nodes": DEGREE_SE_NODES}
        plans = (*plans, ({**options, **balanced, "_remat_otf": _REMAT_OTF}, None))
    if any(options.get(floor) is not None for floor, _, _ in _FLOORS):
        plans = tuple((_with_floors(plan, options), shortcut) for plan, shortcut in plans)
    return plans


def _with_floors(plan, options):
    """``plan`` with at least ``options``'s ``se_angular`` angular fine S_e nodes and
    ``otf_radial`` radial OTF nodes (``jmse``'s options, ``_FLOORS``; the tiers' shortcuts
    never reach here, ``jmse_options``)."""
    for floor, entry, index in _FLOORS:
        if options.get(floor) is not None:
            pair = list(plan[entry])
            pair[index] = max(pair[index], options[floor])
            plan = {**plan, entry: tuple(pair)}
    return plan


def _degree_program(aberrations):
    """Whether designs of this model and structure can be of higher degree than Seidel's
    (``beyond_seidel_degree`` not statically False: a Zernike design with terms of radial
    order 5 or more, a model of unknown degree), so that ``_tier_of`` routes them and the
    balanced plan takes ``DEGREE_OVERLAP`` (``_base_plans``)."""
    return aberrations is not None and aberrations.beyond_seidel_degree() is not False


def _tier_plans_of(static, plans):
    """The plans of ``_base_plans`` from which the one-ray plans are drawn: the tiers by
    strength, or a preset's one fixed grid (not its steep or balanced grid)."""
    tiers = static.value[1]
    return plans[:1 if tiers is None else len(tiers)]


def _one_ray_plans_of(static, plans):
    """The one-ray plans of ``static`` drawn from its ``plans`` (``_base_plans``) and the
    first plan index of their second group (``_radial_plans``)."""
    return _radial_plans(_tier_plans_of(static, plans), static.value[6])


def _one_ray_plan_of(static, plans, by_strength):
    """The one-ray plan a rotationally symmetric design of the concrete tier ``by_strength``
    takes (its group's, ``_radial_plans``), as ``(options, None)``."""
    radial, split = _one_ray_plans_of(static, plans)
    return radial[int(len(radial) > 1 and by_strength >= split)]


def _tier_of(static, aberrations, field, u, signal=None, noise=None, cancelling=False):
    """``(index, tier, cancellation)``: the plan (of ``_base_plans``) this design takes, its
    tier by ``aberration_strength`` alone (``_tier_index``), which picks its one-ray plan,
    and its ``_cancellation`` (all traceable). With the spectra, the default's weak tiers
    are skipped above ``WEAK_TIER_SNR`` and tiers 1 to 3 above ``EDGE_TIER_SNR`` (and
    ``"high"`` takes its steep grid there on bands that reach the cutoff), for the plan, not
    the one-ray plan's choice. A
    design whose terms cancel (``_balancing``) takes the balanced tier. One beyond Seidel's
    shapes (``beyond_seidel_degree``, e.g. a Zernike term of radial order 5 or more, or
    trefoil) takes, from
    ``CANCELLING_STRENGTH``, the default's steep tier if it does not cancel and is no
    steeper than ``DEGREE_STEEP_SLOPE``, else the balanced tier (``"high"``: its balanced tier),
    whose grid then has the overlap rule ``DEGREE_OVERLAP``, the OTF nodes
    ``DEGREE_NODES`` and the fine S_e nodes ``DEGREE_SE_NODES`` (``_base_plans``). The tiers
    were calibrated on Seidel designs only; on random Zernike designs of Noll 4-22 to 4-45
    (``benchmarks/zernike_routes.py``, session 67) the tiers by strength were up to 5.0e-3
    off at slope 24, the steep tier's grid held those that do not cancel within 8.7e-6 up
    to ``STEEP_SLOPE`` (at 0.4x the balanced grid's time) but not past it (1.1e-3 at slope
    46), and the balanced grid needed ``DEGREE_OVERLAP`` (3.1e-3 off at slope 46 without
    it). The cancellation is
    computed only where it can matter, with the balanced tier or ``cancelling`` (for the
    warnings) and from ``CANCELLING_STRENGTH`` (most designs are weaker than that); elsewhere
    it is 1."""
    tiers, balanced, steep = static.value[1], static.value[4], static.value[5]
    zero = jnp.zeros((), jnp.int32)
    if tiers is None and balanced is None and steep is None and not cancelling:
        return zero, zero, jnp.ones(())
    strength = _strength(aberrations, field, u)
    cancellation = jnp.ones((), strength.dtype)
    if balanced is not None or cancelling:
        cancellation = _cancellation_from(strength, aberrations, field, u)
    # Without tiers (``"high"``) the one fixed grid is plan 0, the steep grid plan 1 (taken,
    # as the default's steep tier, past ``STEEP_SLOPE``) and the balanced grid the last.
    if tiers is not None:
        u_ = jax.lax.stop_gradient(u)
        tier = by_strength = _tier_index(strength, u_, tiers)
        if signal is not None and _snr_bounds(tiers):
            snr = jax.lax.stop_gradient(_ring_snr(strength, u_, signal, noise))
            edge = jax.lax.stop_gradient(_edge_snr(u_, signal, noise))
            tier = _tier_index(strength, u_, tiers, snr.astype(strength.dtype),
                               edge.astype(strength.dtype))
    elif steep is not None:
        # "high": its steep grid past STEEP_SLOPE or HIGH_STRONG_STRENGTH, and on bands that
        # reach the cutoff past EDGE_TIER_SNR there.
        u_ = jax.lax.stop_gradient(u)
        tier = by_strength = (_steep(strength, u_)
                              | (strength > HIGH_STRONG_STRENGTH)).astype(jnp.int32)
        if signal is not None:
            edge = jax.lax.stop_gradient(_edge_snr(u_, signal, noise))
            tier = tier | ((u_ > _REACHES_CUTOFF_U)
                           & (edge > EDGE_TIER_SNR)).astype(jnp.int32)
    else:
        tier = by_strength = zero
    if balanced is None:
        return tier, by_strength, cancellation
    balancing = _balancing(strength, cancellation)
    index = tier
    if _degree_program(aberrations):  # the tiers were calibrated on Seidel's degree
        beyond = (strength >= CANCELLING_STRENGTH) & aberrations.beyond_seidel_degree()
        if tiers is not None:
            # The default's steep tier up to DEGREE_STEEP_SLOPE, the balanced plan past it.
            steep_tier = beyond & ~_steep(strength, jax.lax.stop_gradient(u),
                                          DEGREE_STEEP_SLOPE)
            index = jnp.where(steep_tier, len(tiers) - 1, index)
            beyond = beyond & ~steep_tier
        balancing = balancing | beyond
    index = jnp.where(balancing, _n_strength_plans(static), index)
    return index.astype(jnp.int32), by_strength, cancellation


def _cancellation_from(strength, aberrations, field, u):
    """``_cancellation`` of a design of this ``aberration_strength``, computed only from
    ``CANCELLING_STRENGTH`` (1 below it, where nothing looks at it; traceable)."""
    return jax.lax.cond(strength >= CANCELLING_STRENGTH,
                        lambda *a: _cancellation(*a).astype(strength.dtype),
                        lambda *_: jnp.ones((), strength.dtype), aberrations, field, u)


def _n_strength_plans(static):
    """The number of plans before the balanced one (``_base_plans``): the tiers', or a
    preset's one fixed grid and its steep grid if it has one."""
    tiers, steep = static.value[1], static.value[5]
    return len(tiers) if tiers is not None else 1 + (steep is not None)


def _balancing(strength, cancellation):
    """Whether a design of this ``aberration_strength`` and ``_cancellation`` takes the
    default's balanced tier (``BALANCED_CANCELLATION``; arrays or scalars, traceable)."""
    return (strength >= CANCELLING_STRENGTH) & (cancellation >= BALANCED_CANCELLATION)


def _plans_and_index(static, aberrations, field, u, signal=None, noise=None):
    """All plans of ``static``, the index of the one this design takes, its tier (the index
    among the plans before the one-ray ones) and the number of those plans when the choice
    of a one-ray plan depends on the values (else None), all traceable.

    A one-ray plan chosen because the values happen to be symmetric (coma and astigmatism
    zero off the axis, or on the axis at all) gives the right value, and the right first
    derivatives in the directions that break the symmetry only where
    ``first_order_symmetric`` holds: elsewhere ``_switched_merit``'s derivative rule takes
    the gradient from the design's own tier (``_switched_merit_jvp``).
    """
    plans = _base_plans(static, aberrations)
    index, by_strength, _ = _tier_of(static, aberrations, field, u, signal, noise)
    tier = index
    # A rotationally symmetric design (any design on the axis) is integrated along one ray:
    # more plans in the same switch (``_radial_plans``).
    symmetric = aberrations.radially_symmetric(field) if static.value[2] else False
    n_base = None
    if symmetric is not False:
        radial_plans, split = _one_ray_plans_of(static, plans)
        group = (by_strength >= split).astype(jnp.int32) if len(radial_plans) > 1 else 0
        if symmetric is True:
            plans, index = radial_plans, group + jnp.zeros((), jnp.int32)
        else:
            symmetric = jax.lax.stop_gradient(symmetric)
            n_base = len(plans)
            index = jnp.where(symmetric, n_base + group, index)
            plans = plans + radial_plans
    return plans, index, tier, n_base


@functools.partial(jax.jit, static_argnums=0)
def _traced_merit(static, inputs):
    """``jmse`` after validation, for traced inputs (under ``jit``, ``vmap``, ``grad``).

    Jitted itself, so that a transformation applied without ``jit`` (``jax.grad(jmse)``
    called eagerly, say) compiles the program once and then reuses it, instead of running
    the tiers' switch primitive by primitive on every call; under an outer ``jit`` the call
    is inlined.
    """
    dtype = static.value[3]
    inputs, finite = _sanitise(inputs)
    aberrations, field, u, signal, noise = inputs
    # |H| does not depend on tilt; removing it smooths H over the band (fewer OTF nodes).
    aberrations = aberrations.without_tilt()
    operands = (aberrations, field, u, signal, noise)
    plans, index, tier, n_base = _plans_and_index(static, aberrations, field, u, signal,
                                                  noise)
    if len(plans) == 1 and plans[0][1] is None:
        value = _merit_value(plans[0][0], dtype, *operands)
    else:
        value = _switched_merit(_Static((plans, dtype, n_base)), (index, tier), operands)
    return jnp.where(finite, value, jnp.inf)


@functools.partial(jax.jit, static_argnums=0)
def _concrete_choice(static, aberrations, field, u, signal=None, noise=None):
    """``(plan index, tier by strength, radial symmetry, strength, cancellation)`` of a
    design (``_tier_of``; symmetry False if no one-ray plan applies; the cancellation 1
    below ``CANCELLING_STRENGTH``, where no warning looks at it)."""
    aberrations = aberrations.without_tilt()
    symmetric = aberrations.radially_symmetric(field) if static.value[2] else False
    index, by_strength, cancellation = _tier_of(static, aberrations, field, u, signal, noise,
                                                cancelling=True)
    return (index, by_strength, jnp.asarray(symmetric), _strength(aberrations, field, u),
            cancellation)


@jax.jit
def _peak_snr(u, signal, noise):
    """``max S_x / S_n`` over a 17 x 17 grid of the band's quadrant ``[0, u]^2`` (for the
    package's spectra: at ``nu = 0``), and of its x-mirror ``[-u, 0] x [0, u]`` too for
    spectra not ``x_symmetric``, in the spectra's dtype; one small compiled program
    (eager, the grid's spectra cost about 0.6 ms of every concrete call)."""
    axis = jnp.linspace(0.0, 1.0, 17) * u
    return _max_snr(*jnp.meshgrid(axis, axis), signal, noise)


def _snr_peaks(peaks, tiers) -> bool:
    """Whether calls with the options ``peaks`` and ``tiers`` (``jmse_options``) are held to
    ``CHECKED_SNR_PEAKS`` rather than ``CHECKED_SNR``: with the peaks and without the
    default's tiers (``"high"``). The default's steep tier has the peaks and was measured
    4.7e-4 off at a peak ratio of 1.1e8 (``CHECKED_SNR``), so ``peaks=True`` does not lift
    the default's bound."""
    return bool(peaks) and tiers is None


#: The angular counts of fine S_e nodes (``jmse``'s ``se_angular``) that hold ``"high"``'s
#: gradient off the axis up to each peak ``S_x / S_n``, as ``(bound, count)`` pairs:
#: ``se_angular_for``. Under flat signal spectra at high SNR ``S_e`` turns from
#: ``S_n / |H|^2`` to ``S_x`` along curves that the rays cross obliquely, narrower as the
#: SNR grows, and the gradient's integrand (the turn's derivative) is a ridge along them.
#: Calibrated in session 86 (``benchmarks/se_angular.py``) on the two designs where
#: session 85's climbs found ``"high"``'s 960 far off, against 11520 angular nodes. On the
#: balanced one (strength 11.7, u 0.93): at a peak ratio of 2e7 960 leave 5.4e-3, 1920
#: 6.3e-6; at 6e7 1920 7.4e-4, 2880 1.4e-5, 3840 8.6e-7; at 1.3e8 3840 5.2e-5, 5760
#: 5.0e-8; at 2e8 3840 2.8e-4, 4800 1.8e-5, 5760 1.6e-6. On the steep one (strength 12,
#: u 0.85, 1.9e8): 960 5.8e-3, 1920 1.3e-4, 3840 4.7e-7. The values hold either way (2e-6).
#: With the blocks of the fine stage rematerialised (``_FINE_REMAT``) the count costs time,
#: not memory.
SE_ANGULAR_BY_SNR = ((CHECKED_SNR, PRESETS["high"]["se_nodes"][1]), (2e7, 1920), (6e7, 3840),
                     (CHECKED_SNR_PEAKS, 5760))


#: The radial OTF nodes (``jmse``'s ``otf_radial``) that hold ``"high"``'s value and
#: gradient off the axis up to each peak ``S_x / S_n``, as ``(bound, count)`` pairs:
#: ``otf_radial_for``. The fine S_e nodes interpolate ``H`` from the OTF nodes; where
#: ``S_e`` turns from ``S_n / |H|^2`` to ``S_x``, at ``|H|^2 ~ S_n / S_x``, an error ``dH``
#: moves it by ``2 dH / |H|``, so the lower the noise the more radial OTF nodes the turn
#: needs. Calibrated in session 88 (``benchmarks/otf_radial.py``, against 256 radial OTF
#: nodes) on session 87's two climb designs where they bound. On the own grid's (80;
#: strength 12.7, u 0.70): gradient 8.3e-5 at a peak ratio of 2e6 and 3.2e-4 at 2e7, with
#: 120 4.7e-7 and 8.2e-6, 160 the same digits. On ``HIGH_STEEP_GRID``'s (128; strength
#: 24.2, u 0.84): 1.4e-6, 3.0e-5, 1.4e-4 and 3.3e-4 at 2e6, 2e7, 6e7 and 2e8 (value 6.2e-5
#: there), with 160 5e-10, 1.7e-8, 8.7e-8 and 4.0e-7 (value 7.5e-8). Session 86's two
#: designs (balanced and steep grids) change by less than 1e-8 with more. One count, 160
#: (the balanced grid's own), beyond ``CHECKED_SNR``.
OTF_RADIAL_BY_SNR = ((CHECKED_SNR, PRESETS["high"]["nodes"][0]), (CHECKED_SNR_PEAKS, 160))


def _table_count(table, snr) -> int:
    """The count of ``table`` (``(bound, count)`` pairs) for the peak ratio ``snr`` (its
    last beyond it)."""
    for bound, count in table:
        if snr <= bound:
            return count
    return table[-1][1]


def _se_angular_for_snr(snr) -> int:
    """``SE_ANGULAR_BY_SNR``'s count for the peak ratio ``snr``."""
    return _table_count(SE_ANGULAR_BY_SNR, snr)


def _counts_for_snr(snr) -> dict:
    """``{floor: count}`` (``_FLOORS``) that hold ``"high"``'s gradient at the peak ratio
    ``snr``: ``SE_ANGULAR_BY_SNR``'s and ``OTF_RADIAL_BY_SNR``'s."""
    return dict(se_angular=_se_angular_for_snr(snr),
                otf_radial=_table_count(OTF_RADIAL_BY_SNR, snr))


def _check_spectra(u, signal, noise):
    check_range("u", u, 0.0, U_MAX, low_inclusive=False)
    _check_spectrum_types(signal, noise)


def se_angular_for(u, signal, noise) -> int:
    """The ``se_angular`` (``jmse``'s option) that holds ``preset="high"``'s gradient off
    the axis at the peak ``S_x / S_n`` of these spectra over the band of ``u``
    (``SE_ANGULAR_BY_SNR``): 960, ``"high"``'s own, up to ``CHECKED_SNR``, more beyond.
    ``optimise`` takes it by itself for ``"high"``, and so do ``jmse``'s and ``lens_merit``'s
    gradients where ``u`` and the spectra are concrete (``grad_se_angular``); give it to
    gradients of your own whose ``u`` or spectra are traced, as ``jmse(...,
    preset="high", grad_se_angular=se_angular_for(u, signal, noise),
    grad_otf_radial=otf_radial_for(u, signal, noise))``."""
    _check_spectra(u, signal, noise)
    return _se_angular_for_snr(float(_peak_snr(u, signal, noise)))


def otf_radial_for(u, signal, noise) -> int:
    """The ``otf_radial`` (``jmse``'s option) that holds ``preset="high"``'s value and
    gradient off the axis at the peak ``S_x / S_n`` of these spectra over the band of
    ``u`` (``OTF_RADIAL_BY_SNR``): 80, ``"high"``'s own, up to ``CHECKED_SNR``, more
    beyond. Taken as ``se_angular_for``'s count is (``optimise``; ``jmse``'s and
    ``lens_merit``'s gradients where ``u`` and the spectra are concrete)."""
    _check_spectra(u, signal, noise)
    return _table_count(OTF_RADIAL_BY_SNR, float(_peak_snr(u, signal, noise)))


def _warn_snr_of_traced_design(static, u, signal, noise, stacklevel):
    """``_warn_beyond_checked_snr`` for a ``jmse`` call with a preset's grids whose design
    is traced (the caller's ``jit`` or ``vmap``) while ``u`` and the spectra are concrete:
    the ratio is known when the call is traced, so the warning costs nothing at run time.
    Whether the design takes a one-ray plan (held to ``CHECKED_SNR_PEAKS``, as ``"high"``
    is) is not known then: ``"fast"`` and the default warn past ``CHECKED_SNR`` and say that
    a rotationally symmetric design is held further. ``stacklevel``: ``warnings.warn``'s,
    here (2 names the line that called this)."""
    with jax.ensure_compile_time_eval():  # concrete even inside the caller's jit
        _warn_beyond_checked_snr(u, signal, noise, stacklevel + 1,
                                 peaks=_snr_peaks(static.value[0]["peaks"], static.value[1]),
                                 traced_design=True)


def _warn_beyond_checked_snr(u, signal, noise, stacklevel, peaks=False, gradient=False,
                             se_angular=None, otf_radial=None, traced_design=False):
    """An ``AccuracyWarning`` when the concrete spectra's peak ``S_x / S_n`` exceeds
    ``CHECKED_SNR`` (for calls with a preset's grids), or ``CHECKED_SNR_PEAKS`` with the
    closed-form peaks (``peaks``: ``_snr_peaks`` of the options, or a one-ray plan).
    ``gradient`` (``optimise``, which follows the gradient): with the peaks, a warning
    between the two bounds too unless ``se_angular`` and ``otf_radial`` (the options) are
    at least ``_counts_for_snr``'s, since ``"high"``'s own counts hold its gradient off the
    axis only to ``CHECKED_SNR``. ``traced_design``: the design is traced
    (``_warn_snr_of_traced_design``), and the warning past ``CHECKED_SNR`` says that a
    rotationally symmetric one is held to ``CHECKED_SNR_PEAKS``."""
    _warn_snr(float(_peak_snr(u, signal, noise)), stacklevel + 1, peaks=peaks,
              gradient=gradient, se_angular=se_angular, otf_radial=otf_radial,
              traced_design=traced_design)


def _warn_snr(snr, stacklevel, peaks=False, gradient=False, se_angular=None, otf_radial=None,
              traced_design=False, shown=None, suffix=""):
    """``_warn_beyond_checked_snr`` at the peak ratio ``snr`` (a float). ``shown`` replaces
    ``= <snr>`` in the text and ``suffix`` ends it (the run-time check of a traced call,
    ``_warn_traced_designs``, whose texts do not change with the values)."""
    shown = shown or f"= {snr:.3g}"
    given = dict(se_angular=se_angular or 0, otf_radial=otf_radial or 0)
    needed = _counts_for_snr(snr)
    if (peaks and gradient and CHECKED_SNR < snr <= CHECKED_SNR_PEAKS
            and any(given[k] < n for k, n in needed.items())):
        give = ", ".join(f"{k}={n}" for k, n in needed.items() if given[k] < n)
        warnings.warn(
            f"the peak signal-to-noise ratio max S_x/S_n {shown} is beyond what the "
            f"gradients of the polar grids were checked at off the axis with their own "
            f"counts ({CHECKED_SNR:.0e} with preset='high''s {SE_ANGULAR_BY_SNR[0][1]} "
            f"angular fine S_e nodes and {OTF_RADIAL_BY_SNR[0][1]} radial OTF nodes): under "
            f"a flat signal spectrum S_e turns from S_n/|H|^2 to S_x along narrow curves, "
            f"and the gradient the optimiser follows may be off by percents where the value "
            f"is right (preset='high' at 2e8: value 1e-6, gradient 1e-1; "
            f"benchmarks/default_climb.py --preset high --gradient --noise). Give {give} "
            f"(jmse_options; jmse_jax.se_angular_for, otf_radial_for), which optimise takes "
            f"by itself when none of se_angular, otf_radial and their grad_ twins is given",
            AccuracyWarning, stacklevel=stacklevel)
        return
    if peaks:
        if snr > CHECKED_SNR_PEAKS:
            warnings.warn(
                f"the peak signal-to-noise ratio max S_x/S_n {shown} is beyond what the "
                f"grids with closed-form peaks (peaks=True outside the default's tiers, as in "
                f"preset='high', and the one-ray plans of designs on the axis) were checked at "
                f"({CHECKED_SNR_PEAKS:.0e}; "
                f"benchmarks/low_noise.py, default_climb.py --noise, balanced_one_ray.py): "
                f"the JMSE and its gradient may be off by more than 1e-4 (1e-2 measured at "
                f"1.6e10 on defocus balanced against spherical aberration). Give finer grids "
                f"and compare two of them" + suffix,
                AccuracyWarning, stacklevel=stacklevel)
        return
    if snr > CHECKED_SNR:
        warnings.warn(
            f"the peak signal-to-noise ratio max S_x/S_n {shown} is beyond what the "
            f"polar grids of 'fast' and the default were checked at ({CHECKED_SNR:.0e}): "
            f"narrow features of S_e (its peaks where the OTF nearly vanishes on a ring, "
            f"near the axis; its turn from S_n/|H|^2 to S_x under a flat signal spectrum) "
            f"outgrow the grids, and the JMSE may be off by 1e-4 to percents, its gradient "
            f"by more (measured at 2e6-2e8: 'fast' 1e-2 near the axis; the default 4.7e-4 "
            f"off the axis under a power-law spectrum, its gradient 1e-1; "
            f"benchmarks/low_noise.py, default_climb.py --noise). Use preset='high' "
            f"(checked to {CHECKED_SNR_PEAKS:.0e}), or give finer se_nodes and compare two "
            f"of them"
            + (f". The design is traced here (jit or vmap), so this is said for any design: "
               f"a rotationally symmetric one (on the axis), which takes the one-ray plan, "
               f"was checked to {CHECKED_SNR_PEAKS:.0e}"
               if traced_design and snr <= CHECKED_SNR_PEAKS else "") + suffix,
            AccuracyWarning, stacklevel=stacklevel)


def _strength_message(which: str) -> str:
    """The warning for a design (or designs: ``which``) beyond ``CHECKED_STRENGTH``; the
    command line gives it too, for designs it runs under ``jit``."""
    return (f"aberration_strength {which} is beyond what the presets and the default's tiers "
            f"were checked at ({CHECKED_STRENGTH:g}; {CHECKED_STRENGTH_ONE_RAY:g} for a "
            f"rotationally symmetric design): the JMSE may be far off. Give grids sized for it "
            f"(nodes, se_nodes, overlap_nodes; see jmse's docstring and the README) and "
            f"compare two of them (are the coefficients in waves?)")


def _slope_message(which: str) -> str:
    """The warning for a design (or designs: ``which``) whose wavefront slope is beyond
    ``CHECKED_SLOPE`` while its strength is inside ``CHECKED_STRENGTH``; the command line
    gives it too."""
    return (f"the wavefront slope max |grad W| of {which} [waves per pupil radius] is beyond "
            f"what the default's tiers were checked at ({CHECKED_SLOPE:g}), although "
            f"aberration_strength is inside: at small u, many waves of aberration were "
            f"measured far off (16 % for 74 waves of coma at u = 0.1; "
            f"benchmarks/small_u_single_terms.py). Compare with grids of your own, larger "
            f"overlap_nodes and overlap_floor in particular (see jmse's docstring)")


def _cancellation_message(which: str, balanced: bool) -> str:
    """The warning for a design (or designs: ``which``) whose terms cancel each other's slope
    beyond what its preset was checked at: ``BALANCED_CANCELLATION`` for a preset without
    the balanced tier, ``CHECKED_CANCELLATION`` with it (``balanced``); the command line
    gives it too."""
    start = (f"the terms of the design cancel much of each other's wavefront slope: their "
             f"aberration_strength taken one by one sums to {which} times the design's")
    if balanced:
        return (f"{start}, beyond what the balanced grids of the default and 'high' were "
                f"checked at ({CHECKED_CANCELLATION:g}; defocus set against spherical "
                f"aberration reaches 7 at most): the JMSE may be off. Compare two grids of "
                f"your own, finer in every count than HIGH_BALANCED_GRID (nodes, se_nodes, "
                f"overlap_nodes, overlap_floor; see jmse's docstring)")
    return (f"{start} (from {BALANCED_CANCELLATION:g} at a strength of "
            f"{CANCELLING_STRENGTH:g} the default and 'high' take a balanced grid). Grids "
            f"calibrated on random designs were measured far off on defocus set against "
            f"spherical aberration off the axis (up to 2.6e-1 with 'high''s own grid, 8e-2 with "
            f"the default's tiers by strength; benchmarks/balanced_polar.py; on the axis the "
            f"one-ray plans hold): use preset='default' or 'high', or compare two grids of "
            f"your own, finer in every count (nodes, se_nodes, overlap_nodes, overlap_floor; "
            f"see jmse's docstring)")


def _beyond_checked(strength, u, symmetric, cancellation=1.0, balanced=False, xp=np):
    """``(strength beyond, slope beyond, cancelling beyond, slope)`` for designs (arrays or
    scalars) of the given ``aberration_strength``, ``u``, symmetry and ``_cancellation``
    (each design gets at most one of the three); ``balanced``: the preset has the balanced
    tier (checked to ``CHECKED_CANCELLATION``), else designs that would take it are beyond
    (from ``BALANCED_CANCELLATION``). ``xp``: ``np`` on the host, ``jnp`` for traced
    values (``_design_check``)."""
    strength, u, symmetric = xp.asarray(strength), xp.asarray(u), xp.asarray(symmetric, bool)
    slope = strength / xp.asarray(_band_reach(u), strength.dtype)
    strong = strength > xp.where(symmetric, CHECKED_STRENGTH_ONE_RAY, CHECKED_STRENGTH)
    steep = ~strong & (slope > CHECKED_SLOPE)
    cancellation = xp.asarray(cancellation)
    # With the balanced tier: beyond its checked bound, to rounding (r = -2/3 gives 7 + 3e-15)
    # and to what a trace of astigmatism adds in a Zernike design's Seidel form (the same
    # design with 1e-7 waves: 7 + 2e-8; ``Zernike.seidel_like_terms``).
    beyond = (cancellation > CHECKED_CANCELLATION * (1.0 + 1e-6) if balanced
              else _balancing(strength, cancellation))
    cancelling = ~strong & ~steep & ~symmetric & (strength >= CANCELLING_STRENGTH) & beyond
    return strong, steep, cancelling, slope


#: Set (``_checked_already``) by a caller that gave ``warn_like_jmse``'s warnings itself
#: (``sweep_jmse``, the command line): ``jmse`` calls traced meanwhile then carry no
#: run-time check of their designs (``_design_check``), so they are not given twice.
_CHECKED_ALREADY = contextvars.ContextVar("jmse_jax_checked_already", default=False)


@contextlib.contextmanager
def _setting(variable: contextvars.ContextVar, value):
    """``variable`` set to ``value`` inside the block."""
    token = variable.set(value)
    try:
        yield
    finally:
        variable.reset(token)


def _checked_already():
    return _setting(_CHECKED_ALREADY, True)


#: The environment variable that sets the process's default for ``run_time_checks``
#: (``1`` or ``0``; unset: on).
RUN_TIME_CHECKS_VARIABLE = "JMSE_JAX_RUN_TIME_CHECKS"
_RUN_TIME_CHECKS: contextvars.ContextVar[bool | None] = contextvars.ContextVar(
    "jmse_jax_run_time_checks", default=None)
_SWITCH_VALUES = {"1": True, "true": True, "on": True, "0": False, "false": False, "off": False}


@contextlib.contextmanager
def run_time_checks(enabled: bool = True):
    """Whether ``jmse`` calls traced inside the block carry the run-time checks.

    A ``jmse`` call under one's own ``jit``, ``vmap`` or ``grad`` with a preset's grids
    checks its design when the program runs and warns beyond the checked range (strength,
    slope, cancelling terms, peak ``S_x / S_n``; ``"high"``'s low-noise counts), through a
    host callback. JAX does not store a program with a host callback in its persistent
    compilation cache (``jax_compilation_cache_dir``), so such a program compiles anew in
    every process (the default's ``value_and_grad``: about 30-60 s on 2 cores). Inside
    ``run_time_checks(False)`` the program has no callback and is cached; its values and
    gradients are the same bit for bit, but a design beyond the checked range is not
    reported: call ``aberration_strength`` or ``jmse`` on concrete designs to see it.
    Concrete calls, derivatives taken without ``jit`` and ``sweep_jmse`` warn either way
    (from the values, before anything runs).

    The setting is read when a call is traced (a program traced before is reused as it
    is). Outside any block the environment variable ``JMSE_JAX_RUN_TIME_CHECKS``
    (``RUN_TIME_CHECKS_VARIABLE``: ``1`` or ``0``) gives it; unset, the checks are on.

    Examples
    --------
    >>> import jax
    >>> import jmse_jax as jj
    >>> ab = jj.Seidel(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
    >>> merit = jax.jit(lambda w: jj.jmse(ab, w, 0.2, jj.MarkovSignal(1.0, 5.0),
    ...                                   jj.WhiteNoise(1e-3), preset="fast"))
    >>> with jj.run_time_checks(False):
    ...     program = merit.lower(0.95)  # no host callback: cacheable
    >>> "callback" in program.as_text()
    False
    """
    if not isinstance(enabled, (bool, np.bool_)):
        raise ValueError(f"run_time_checks: enabled must be True or False, got {enabled!r}")
    with _setting(_RUN_TIME_CHECKS, bool(enabled)):
        yield


def _run_time_checks_on() -> bool:
    """Whether a ``jmse`` call traced now carries the run-time checks: ``run_time_checks``'
    setting, else ``JMSE_JAX_RUN_TIME_CHECKS``'s, else on."""
    enabled = _RUN_TIME_CHECKS.get()
    if enabled is not None:
        return enabled
    value = os.environ.get(RUN_TIME_CHECKS_VARIABLE)
    if value is None:
        return True
    enabled = _SWITCH_VALUES.get(value.strip().lower())
    if enabled is None:
        raise ValueError(f"the environment variable {RUN_TIME_CHECKS_VARIABLE} must be 1 or 0 "
                         f"(or true/false, on/off), got {value!r}")
    return enabled


def _warn_design(static, inputs, choice, stacklevel):
    """The ``AccuracyWarning`` of a concrete design (``inputs``, as ``jmse``'s) beyond what the
    presets were checked at: its strength (``CHECKED_STRENGTH``), else its wavefront slope,
    else its cancelling terms, and the peak ``S_x / S_n`` of the spectra. ``choice``: the
    design's ``_concrete_choice`` as Python scalars; ``stacklevel``: ``warnings.warn``'s,
    here (2 names the line that called this)."""
    _, _, symmetric, strength, cancellation = choice
    balanced = static.value[4] is not None
    strong, steep, cancelling, slope = _beyond_checked(
        strength, float(inputs[2]), symmetric, cancellation, balanced=balanced)
    if strong:
        warnings.warn(_strength_message(f"{strength:.3g}"), AccuracyWarning, stacklevel=stacklevel)
    elif steep:
        warnings.warn(_slope_message(f"{float(slope):.3g}"), AccuracyWarning,
                      stacklevel=stacklevel)
    elif cancelling:
        warnings.warn(_cancellation_message(f"{cancellation:.3g}", balanced), AccuracyWarning,
                      stacklevel=stacklevel)
    # The one-ray plans integrate the peaks in closed form, as peaks=True does.
    _warn_beyond_checked_snr(*inputs[2:], stacklevel=stacklevel + 1, peaks=bool(symmetric)
                             or _snr_peaks(static.value[0]["peaks"], static.value[1]))


@jax.jit
def _in_range(inputs):
    """Whether ``inputs`` are finite and in range (``_sanitise``), as one compiled program."""
    return _sanitise(inputs)[1]


def _eager_derivative(static, inputs, primal, choice):
    """``jmse`` differentiated outside ``jit`` (an eager ``jax.grad``, ``jax.hessian``),
    where the tracers carry the concrete design ``primal`` (``choice``: its
    ``_concrete_choice``): the grid the design takes is chosen on ``primal`` as a concrete
    call chooses it (``_eager_tier_choice``), and only that grid's program is
    differentiated, instead of the program of every tier. Its derivatives are those of
    the traced program (the gradient and Hessian of the grid whose value is returned).
    A rotationally symmetric design takes its one-ray plan, as the traced program does
    where the one ray's first derivatives hold (``first_order_symmetric``; its second
    derivatives are the polar grid's, ``_one_ray_merit``), and elsewhere its tier's polar
    grid. None where this does not apply: a single plan and an asymmetric design (nothing
    to choose), or inputs out of range (the traced program returns ``+inf``)."""
    plans = _base_plans(static, primal[0])
    index, by_strength, symmetric = choice[:3]
    if (len(plans) == 1 and plans[0][1] is None and not symmetric) or not bool(
            _in_range(primal)):
        return None
    dtype = static.value[3]
    if symmetric and bool(primal[0].without_tilt().first_order_symmetric(primal[1])):
        ray = _one_ray_plan_of(static, plans, by_strength)[0]
        if ray.get("peaks") and reverse_over_derivative(inputs):
            raise ValueError(f"{_SECOND_REVERSE}: {_ONE_RAY_REVERSE}")
        return _grid_with_rule(_Static(ray), False, dtype, inputs)
    plan = plans[index]
    _, path = _eager_tier_choice(plan, dtype, primal)
    grid, shortcut = plan
    if path != "grid":  # a shortcut's grid was kept
        trial_grid, _, _, _, first_grid, _ = shortcut
        grid = first_grid if path == "first" else trial_grid
    return _grid_with_rule(_Static(grid), path == "first", dtype, inputs)


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def _grid_with_rule(grid, estimated, dtype, inputs):
    """The merit on the grid ``grid.value`` (``_compiled_merit``, or with ``estimated``
    the value of ``_compiled_estimated``, as a shortcut's first grid forms it), under the
    derivative rule the tiers' switch has (``_switched_merit``): a tangent is the inner
    product of the reverse-mode gradient in the leaves that carry one with their
    tangents, so that a Hessian (forward over reverse) holds the gradient as its only
    residual, and both match the traced program's."""
    if estimated:
        def value_of(operands):
            return _compiled_estimated(grid, dtype, operands)[0]
    else:
        value_of = functools.partial(_compiled_merit, grid, dtype)
    return _gradient_rule(value_of, functools.partial(_value_and_grad, value_of))(inputs)


def _concrete_merit(static, inputs, warn=False):
    """``jmse`` after validation, for concrete inputs: the plan this design takes is chosen
    first, and only the grids it needs are compiled (each once per process) and run.
    Returns ``(value, plan index, one-ray plan taken, path)`` (``_eager_tier_choice``; the
    index is the tier by strength when a one-ray plan is taken, since it picks that plan);
    ``warn``: an ``AccuracyWarning`` when the design is stronger than the presets were checked at
    (``CHECKED_STRENGTH``)."""
    dtype = static.value[3]
    plans = _base_plans(static, inputs[0])
    choice = tuple(x.item() for x in _concrete_choice(static, *inputs))
    index, by_strength, symmetric = choice[:3]
    if warn:
        _warn_design(static, inputs, choice, stacklevel=4)
    plan = plans[index]
    if symmetric:
        plan = _one_ray_plan_of(static, plans, by_strength)
    value, path = _eager_tier_choice(plan, dtype, inputs)
    # A one-ray plan is drawn from the tiers by strength (not the balanced tier).
    return value, by_strength if symmetric else index, bool(symmetric), path


#: ``baseline_jmse`` warns below this many lags ``1 / B`` per half-band ``u`` (``u * B``):
#: its rectangle rule then sees fewer than about 10 lags across the band. At the Fig. 1
#: point (u = 0.2) it was -99.8 % to +232 % off for ``u * B`` from 0.2 to 4.8 (B = 1-24),
#: erratically (a lucky B lands within a few percent: -1.4 % at B = 23); from 5 on it is
#: still up to tens of percent off, falling about as 1 / B (-34 % at B = 25, 7.5 % at 32,
#: -8 % at 64; session 79).
BASELINE_MIN_LAGS = 5.0


def _warn_coarse_band(u, B):
    if not is_concrete(u):
        return
    lags = float(u) * B
    if lags < BASELINE_MIN_LAGS:
        warnings.warn(
            f"baseline_jmse: the band |nu_x|, |nu_y| < u = {float(u):.3g} spans only "
            f"u * B = {lags:.3g} lags of 1/B on each side at B = {B}; the square grid's "
            f"rectangle rule is then off by tens of percent or more, erratically in B "
            f"(measured -99.8 % to +232 % at the Fig. 1 point for u * B < 5). Use "
            f"B >= {math.ceil(BASELINE_MIN_LAGS / float(u))}",
            AccuracyWarning, stacklevel=3)


def baseline_jmse(aberrations, field, u, signal, noise, B: int = 64):
    """The paper's square-grid baseline (Berkner & Shroff Sec. III-A), exactly.

    Pupil sampled at the centres of a ``B x B`` grid over ``[-1, 1]**2``, zero-padded to
    ``2B x 2B``, FFT to the PSF, FFT to the OTF (lags ``nu = k / B``), then the rectangle
    rule ``(1/B)**2 sum S_e`` over the lags strictly inside the band ``|nu_x|, |nu_y| < u``,
    divided by ``2 pi``. Converges erratically (first order in ``1/B``): about -8 % at
    ``B = 64`` on the paper's Fig. 1 point. For ``u > 1`` the band reaches past the lag grid
    (``|nu| < 1``); the rule then runs on over the lags out to ``u``, where ``H = 0``.

    Parameters are as in ``jmse``; ``B`` is the pupil grid size (``>= 1``). Bad concrete
    input raises ``ValueError``; under ``jit`` non-finite or out-of-range values give
    ``+inf``, as in ``jmse``, and so does ``u > U_MAX`` (the lags past the grid are summed out
    to ``U_MAX`` only; ``jmse`` computes such bands). A concrete ``u`` with
    ``u * B < BASELINE_MIN_LAGS`` (5) warns: the band then holds too few lags for the
    rectangle rule.
    """
    check_count("B", B)
    _validate(aberrations, field, u, signal, noise)
    _warn_coarse_band(u, B)
    dtype = common_dtype(aberrations, field, u, signal, noise)
    # Under jit: +inf for non-finite or out-of-range values, as jmse gives.
    (aberrations, field, u, signal, noise), ok = _sanitise(
        (aberrations, jnp.asarray(field, dtype), jnp.asarray(u, dtype), signal, noise))
    # _sanitise lets bands past U_MAX through (jmse computes them); this rule's lags past
    # the grid stop at U_MAX, so a wider band would be summed short.
    ok = ok & (u <= U_MAX)
    grid_otf = otf_fft_grid(aberrations, field, B, dtype)
    k = jnp.fft.fftfreq(2 * B, 1.0 / (2 * B)).astype(dtype)
    nu_x, nu_y = jnp.meshgrid(k / B, k / B, indexing="xy")
    band = (jnp.abs(nu_x) < u) & (jnp.abs(nu_y) < u)
    s_e = error_spectral_density(grid_otf, signal(nu_x, nu_y), noise(nu_x, nu_y))
    total = jnp.sum(jnp.where(band, s_e, 0.0))
    # For u > 1 the band reaches past the lag grid (|nu| < 1), where H = 0 and S_e = S_x:
    # the same rectangle rule on the lags out to U_MAX (skipped when u <= 1).
    total = total + jax.lax.cond(u > 1.0, functools.partial(_lags_past_the_grid, B),
                                 lambda *_: jnp.zeros((), dtype), u, signal)
    value = total / (B * B) / (2.0 * math.pi)
    return jnp.where(ok, value, jnp.inf)


def _lags_past_the_grid(B, u, signal):
    """``sum S_x`` over the integer lags ``k`` with ``|k_x|, |k_y| < u B`` outside the
    baseline's lag grid ``[-B, B - 1]^2`` (there ``H = 0``, so ``S_e = S_x``)."""
    reach = int(math.ceil(U_MAX * B))
    k = jnp.arange(-reach, reach + 1, dtype=u.dtype)
    kx, ky = jnp.meshgrid(k, k, indexing="xy")
    band = (jnp.abs(kx) < u * B) & (jnp.abs(ky) < u * B)
    on_grid = (kx >= -B) & (kx <= B - 1) & (ky >= -B) & (ky <= B - 1)
    return jnp.sum(jnp.where(band & ~on_grid, signal(kx / B, ky / B), 0.0))

"""Closed-form peaks of ``S_e`` along the rays of the polar fine grid.

At a high signal-to-noise ratio ``S_e = S_n / (|H|^2 + S_n / S_x)`` has a peak wherever
``|H|^2`` nearly vanishes, of height ``S_n / (m + S_n / S_x)`` (``m`` the minimum of
``|H|^2``) and half-width ``sqrt((m + S_n / S_x) / G)`` along the ray (``G = (|H|^2)'' / 2``).
A design near the axis has an OTF that nearly vanishes on rings, which every ray crosses,
and those peaks grow narrower than the fine nodes: at the bank's noise of 1e-4 they put
6e-6 into the value of the default's middle-tier grid and 5e-2 into its gradient on 6
waves of defocus with 0.5 wave of astigmatism at field 0.1 (``tests/test_ridges.py``). This
is the polar counterpart of the one-ray plan's ``_radial._zero_peaks``, which it follows;
there the OTF is real and ``m = 0``, here it is complex along each ray, and the peaks sit
at the minima of ``|H|^2`` rather than at sign changes.

Along a ray in ``t = |nu| / R`` the fine rule sums ``w_i t_i S_e(t_i)`` over sub-panels of
at most ``FINE_SUB_PANEL`` Gauss nodes (``jmse_jax._quadrature.fine_sub_panels``). At each
narrow minimum, with ``d = t - t0``,

    ``|H|^2 = m + G d^2 + K d^3``, ``S_n = S_n0 (1 + s d)``, ``S_n / S_x + m = e0 (1 + k d)``,

from the cubics through the four fine nodes around it, and ``t S_e`` is, to first order in
``d``, ``(S_n0 / e0) (t0 + c z) M(z)`` with ``z = d / c``, ``c = sqrt(e0 / G)`` and ``M`` the
model of ``_radial._model_integral`` with ``k = (c s, c K / G, c k)``. The fine rule's sum of
that model over the minimum's sub-panel and its two neighbours is replaced by the model's
integral there in closed form, so that the fine rule integrates only the difference, which
has no peak of width ``c``; the sub-panels beyond see the model's smooth tail, which their
Gauss rules integrate to rounding. A peak wide enough for the fine rule gets a correction
of rounding size, and none beyond ``_RESOLVED`` of its sub-panel. What is left is the
model's second-order error, a few times ``(c K / G)^2`` of the peak's share of the total
(against adaptive quadrature of an analytic ray: 4e-6 of the total at ``S_n / S_x`` = 1e-6
where the plain rule is 4e-2 off, 6e-7 below; the derivative, a few 1e-4 where the plain
rule's is 50 times off).

Cost: the search is one fused reduction over the fine grid; the closed forms run only in a
block that holds a narrow minimum (``lax.cond``). Where they run they cost: 6 waves of
defocus with 0.5 of astigmatism at field 0.1 and noise 1e-4 took ``value_and_grad`` from
5.2 to 13.4 ms with the ``fast`` grid and from 19.5 to 31.5 ms with the default's tiers
(one core; 20.5 and 38.2 ms before the adjoint's split into forward and reverse parts).
The compile counts too: each grid with the peaks adds about 1.1 s to the compile of a
program that holds it and 2.7 s with a gradient, so that the default's four tier grids
with them took the Fig. 1 point's compile from 13 to 19 s (value) and from 29 to 40 s
(``value_and_grad``), one core. On CPU ``vmap`` of ``jmse`` runs the designs one at a
time (``_merit.SEQUENTIAL_VMAP_BACKENDS``), so the cond skips the branch for each design
that has no narrow minimum; on 32 random designs within +-3 waves, noise 1e-4, u = 0.3
(15 of them have narrow minima), ``fast``'s ``value_and_grad`` takes 7.1 ms per design
against 3.8 without the peaks (``benchmarks/vmap_batches.py``, one core). Vectorised over
a batch, as on a GPU, a plain ``lax.cond`` would become a select, so the cond is
``batch_skipping_cond``: nothing runs for a block of the batch where no design has a narrow
minimum, and otherwise the branch runs vectorised (or, on the backends of
``_numerics.SEQUENTIAL_BRANCH_BACKENDS``, design by design: on CPU the vectorised branch
cost about three times a single design's per design; 25.1 against 15.3 ms per design on
the designs above, 11.3 without the peaks).
The peaks are therefore the option ``peaks`` of ``jmse``, on in the
``"high"`` preset and, since session 84, in the own grids of the default's strong tiers (2,
3 and steep, ``_merit.DEFAULT_TIERS``): there the value hardly needs them, but the gradient
does (a near-axis design under a power-law spectrum, tier 3: value 1.3e-6 off, gradient
3.1e-2 off without them, 2.4e-5 with them; ``benchmarks/gradient_accuracy.py``), for about
3 % of those tiers' time where no minimum is narrow and 30-45 % where one is, and about 2 s
of the default's value compile and 5 s of its ``value_and_grad``'s. The shortcuts' first
and check grids never take them (``_merit._tier_plans``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._numerics import batch_skipping_cond
from ._radial import _window_change

__all__ = ["ridge_peaks"]

#: A minimum is left to the fine rule when its peak's half-width exceeds this fraction of
#: its sub-panel (whose Gauss rule integrates such a peak to rounding).
_RESOLVED = 0.25

#: The minima are looked for in blocks of this many fine nodes along each ray, and the first
#: narrow one in each of the first ``_PEAKS`` blocks that hold one gets its closed form
#: (nearest the origin first, where ``S_x`` is largest).
_BLOCK = 32
_PEAKS = 12

#: The most search steps for the minimum of |H|^2 on the cubics through four fine nodes
#: before the two differentiated Newton steps (``_fit``), whose derivatives are exact only
#: from a converged minimum; the search stops earlier once no minimum moves by more than
#: rounding. Until 2026-12-02 it was three plain Newton steps, which left minima short of
#: convergence and some in a cycle: on two random Zernike designs of the default's balanced
#: plan, at peak S_x / S_n 3.3e11 and 1.6e8, the gradient was 3.8e-6 and 2.2e-4 off the
#: derivative of the value (one component 1.8e-3; ``benchmarks/gradient_fuzz.py``; the
#: second needed seven Newton steps). Of 4000 random minima with strong quadratic and cubic
#: terms (``tests/test_ridges.py``), three steps left 1123 more than 1e-10 of a node spacing off,
#: and three never converged however many steps they took: from a node where |p|^2 bends
#: little, plain Newton jumped to the interval's end and back for ever, and the model was
#: then expanded away from the minimum (so the value was off too, not only its
#: derivative). The damped search (``_HALVINGS``) converges on all of them.
_NEWTON = 64
#: Each search step tries the Newton step (cut at the interval's ends) and this many
#: halvings of it, and keeps the one with the least |p|^2 (``_fit``).
_HALVINGS = 6


def _divided_differences(x, y):
    """Newton coefficients of the cubics through ``(x, y)``: ``x`` is ``(P, 4)``, ``y``
    ``(P, 4, C)`` (``C`` channels sharing the nodes); four ``(P, C)`` arrays."""
    x = x[..., None]
    c = [y[:, i] for i in range(4)]
    for level in range(1, 4):
        for i in range(3, level - 1, -1):
            c[i] = (c[i] - c[i - 1]) / (x[:, i] - x[:, i - level])
    return c


def _cubic(x, c, z):
    """Value and first three derivatives at ``z`` (``(P,)``) of the cubics with Newton
    coefficients ``c`` on the nodes ``x`` (``_divided_differences``); each ``(P, C)``."""
    z = z[:, None]
    p, dp, d2p = c[3], jnp.zeros_like(c[3]), jnp.zeros_like(c[3])
    for i in (2, 1, 0):
        step = z - x[:, i, None]
        d2p = d2p * step + 2.0 * dp
        dp = dp * step + p
        p = p * step + c[i]
    return p, dp, d2p, 6.0 * c[3]


def _cubic_value(x, c, z):
    """The value alone at ``z`` of the first two channels (``Re H``, ``Im H``) of
    ``_cubic``: the search's trial points need nothing else."""
    c = [k[:, :2] for k in c]
    p = c[3]
    for i in (2, 1, 0):
        p = p * (z - x[:, i])[:, None] + c[i]
    return p


def _slope_and_bend(x, c, z):
    """``(|p|^2)' / 2`` and ``(|p|^2)'' / 2`` at ``z`` of ``p = Re H + i Im H`` (``_cubic``)."""
    p, dp, d2p, _ = _cubic(x, c, z)
    slope = jnp.sum(p[:, :2] * dp[:, :2], axis=-1)
    bend = jnp.sum(dp[:, :2] * dp[:, :2] + p[:, :2] * d2p[:, :2], axis=-1)
    return slope, bend


def _narrow_minima(d, denominator, s_x, t_host, starts, edges):
    """Flags ``(..., N - 2)``: the interior discrete minima of ``d = |H|^2`` along the rays whose
    peak is narrow against its sub-panel: ``(d + S_n / S_x) / G < (_RESOLVED L)^2`` with
    ``G`` from the parabola through the three nodes (``G = (d[i+1] - d[i]) a_i -
    (d[i] - d[i-1]) b_i``), written with the fine rule's ``denominator = d S_x + S_n`` and
    host constants so that it costs a few multiply-adds per node."""
    ids = np.repeat(np.arange(len(starts) - 1), np.diff(starts))
    width = (_RESOLVED * np.diff(edges)[ids[1:-1]]) ** 2
    tl, tc, tr = t_host[:-2], t_host[1:-1], t_host[2:]
    a, b = (jnp.asarray(width / x, d.dtype) for x in ((tr - tc) * (tr - tl),
                                                      (tc - tl) * (tr - tl)))
    dl, dc, dr = d[..., :-2], d[..., 1:-1], d[..., 2:]
    bend = (dr - dc) * a - (dc - dl) * b
    return (dc <= dl) & (dc < dr) & (denominator[..., 1:-1] < s_x[..., 1:-1] * bend)


def _search(d, narrow):
    """``(j, live, stencil)`` along one ray: the first narrow minimum ``j`` in each of the first
    ``_PEAKS`` blocks of ``_BLOCK`` nodes that hold one (``live``), and the four nodes around
    it (``j - 2 .. j + 1`` when the left neighbour is lower, else ``j - 1 .. j + 2``)."""
    n = d.shape[0]
    blocks = -(-n // _BLOCK)
    flags = jnp.pad(narrow, (0, blocks * _BLOCK - n)).reshape(blocks, _BLOCK)
    held = jnp.any(flags, axis=1)
    (chosen,) = jnp.nonzero(held, size=min(_PEAKS, blocks), fill_value=0)
    j = chosen * _BLOCK + jnp.argmax(flags[chosen], axis=1)
    left = d[jnp.maximum(j - 1, 0)] < d[jnp.minimum(j + 1, n - 1)]
    stencil = jnp.clip(j - 1 - left, 0, n - 4)[:, None] + jnp.arange(4)
    return j, held[chosen], stencil


def _fit(y_re, y_im, y_q, y_n, j, live, stencil, t):
    """The model of each minimum found by ``_search`` along one ray (module docstring):
    ``y_re, y_im, y_q, y_n`` are ``Re H``, ``Im H``, ``S_n / S_x`` and ``S_n`` at each
    minimum's ``stencil`` (``(P, 4)``), ``t`` the fine nodes. Returns ``(t0, c, k_s, k_q,
    k_t, S_n0 / e0)`` (``(P,)`` each; harmless values where not ``live``) and ``live``."""
    n = t.shape[0]
    # Entries without a live minimum get a harmless stencil, so that no derivative is NaN.
    dummy = jnp.arange(4, dtype=t.dtype)
    x = jnp.where(live[:, None], t[stencil], dummy)
    # Channels Re H, Im H, S_n / S_x, S_n, each through the same four nodes.
    y = jnp.where(live[:, None, None], jnp.stack([y_re, y_im, y_q, y_n], axis=-1),
                  jnp.stack([dummy - 1.5, 0.0 * dummy, 1.0 + 0.0 * dummy, 1.0 + 0.0 * dummy],
                            axis=-1))
    c = _divided_differences(x, y)
    jl, jr = jnp.maximum(j - 1, 0), jnp.minimum(j + 1, n - 1)
    lo, hi = jnp.where(live, t[jl], 1.0), jnp.where(live, t[jr], 2.0)
    # Newton's method on (|p|^2)' / 2 = Re(p conj p') from the node's own position. Only
    # the last two steps are differentiated: from the converged minimum, the last step's
    # first derivative is the implicit one, -d(slope) / bend, and two steps' first and
    # second derivatives are the implicit ones (the Newton map's own derivative in t
    # vanishes at the minimum), so that Hessians hold too (one step: first only).
    def newton(x, c, t0):
        slope, bend = _slope_and_bend(x, c, t0)
        ok = bend > 0.0
        return jnp.clip(t0 - jnp.where(ok, slope / jnp.where(ok, bend, 1.0), 0.0), lo, hi)

    # The steps before them (on the cubics' values alone, in a loop) must converge, and
    # plain Newton need not: from a node where |p|^2 bends little it can overshoot to the
    # interval's end and come back, for ever (a near-zero of H between two nodes). So each
    # of them takes the Newton step (cut at the interval's ends), or half, a quarter, ...
    # of it, whichever gives the least |p|^2 (none, if none lowers it), and a step down the
    # slope where |p|^2 bends the wrong way; |p|^2 then falls at every step, to a minimum.
    fixed = jax.lax.stop_gradient((x, c))
    rounding = 16.0 * jnp.finfo(t.dtype).eps

    def unsettled(state):
        step, _, moved = state
        return (step < _NEWTON) & moved

    def search(state):
        step, t0, _ = state
        slope, bend = _slope_and_bend(*fixed, t0)
        ok = bend > 0.0
        move = jnp.where(ok, -slope / jnp.where(ok, bend, 1.0),
                         -jnp.sign(slope) * 0.5 * (hi - lo))
        move = jnp.clip(t0 + move, lo, hi) - t0
        trials = [t0] + [t0 + move * 0.5 ** k for k in range(_HALVINGS)]
        square = [jnp.sum(_cubic_value(*fixed, z) ** 2, axis=-1) for z in trials]
        best = jnp.argmin(jnp.stack(square), axis=0)
        new = jnp.choose(best, trials, mode="clip")
        return step + 1, new, jnp.any(jnp.abs(new - t0) > rounding * jnp.abs(new))

    _, t0, _ = jax.lax.while_loop(unsettled, search,
                                  (0, jnp.where(live, t[j], 1.5), jnp.asarray(True)))
    for _ in range(2):
        t0 = newton(x, c, t0)
    p, dp, d2p, d3p = _cubic(x, c, t0)
    m = jnp.sum(p[:, :2] * p[:, :2], axis=-1)
    g2 = jnp.sum(dp[:, :2] * dp[:, :2] + p[:, :2] * d2p[:, :2], axis=-1)
    kappa = jnp.sum(dp[:, :2] * d2p[:, :2] + p[:, :2] * d3p[:, :2] / 3.0, axis=-1)
    q0, dq, n0, dn = p[:, 2], dp[:, 2], p[:, 3], dp[:, 3]
    e0 = q0 + m
    live = live & (g2 > 0.0) & (e0 > 0.0) & (n0 > 0.0)
    g2 = jnp.where(live, g2, 1.0)
    e0 = jnp.where(live, e0, 1.0)
    n0 = jnp.where(live, n0, 1.0)
    t0 = jnp.where(live, t0, 1.5)
    c = jnp.sqrt(e0 / g2)
    return (t0, c, c * dn / n0, c * kappa / g2, c * dq / e0, n0 / e0), live


def _window(model, live, j, t, bare, starts, edges):
    """The corrections ``(P,)`` to ``sum(bare S_e)`` along one ray of the minima with the
    ``model`` of ``_fit``: over the sub-panel that holds each ``t0`` and its neighbours, the
    model's integral in closed form less the fine rule's sum of it (``bare``: the bare
    weights; ``starts`` and ``edges``: the sub-panels, ``fine_sub_panels``)."""
    t0, c, k_s, k_q, k_t, scale = model
    count = len(starts) - 1
    ids = np.repeat(np.arange(count), np.diff(starts))
    edges_j = jnp.asarray(edges, t.dtype)
    # t0 lies between the nodes j - 1 and j + 1, so in one of their sub-panels.
    home = jnp.asarray(ids)[j]
    home = jnp.where(t0 < edges_j[home], home - 1, jnp.where(t0 > edges_j[home + 1],
                                                             home + 1, home))
    home = jnp.clip(home, 0, count - 1)
    first = jnp.maximum(home - 1, 0)
    last = jnp.minimum(home + 1, count - 1)
    span = 3 * int(np.max(np.diff(starts)))
    starts_j = jnp.asarray(starts)
    change = _window_change(t, bare, starts_j[first], starts_j[last + 1], edges_j[first],
                            edges_j[last + 1], t0, c, (k_s, k_q, k_t), span)
    return jnp.where(live, scale * change, 0.0)


def ridge_peaks(h, denominator, s_x, s_n, t, bare, row_weights, starts, edges,
                adjoint=None):
    """Correction to the fine rule's sum ``sum_a row_weights[a] sum_i bare_i S_e`` over a
    block of rays (module docstring): ``h`` holds ``H`` at the fine nodes as
    ``(rows, re/im, triangles, N)``, ``denominator = |H|^2 S_x + S_n`` and the spectra
    broadcast to ``(rows, triangles, N)``, ``t`` (host) and ``bare`` are the fine radial
    nodes and bare weights ``(N,)``, ``starts`` and ``edges`` the host description of their
    sub-panels. With ``adjoint = (g_re, g_im)`` (the fine rule's own derivatives in ``Re H``
    and ``Im H``), returns ``(correction, g_re + d/dRe H, g_im + d/dIm H)``.

    Nothing but the search runs when no minimum is narrow (a ``lax.cond`` on one fused
    reduction, which stays a branch under ``vmap``: ``batch_skipping_cond``). The branch's
    operands and results are copied, so it takes ``H``, the spectra and the weights but not
    ``denominator`` (it recomputes it), and returns a scalar (with the adjoint, the fine
    rule's derivatives too): the correction depends on ``H`` at four nodes per minimum, and
    its derivative is added to the fine rule's at those nodes.
    """
    rows, _, triangles, n = h.shape
    shape = (rows, triangles, n)

    def narrow_of(h, denominator, s_x):
        d = h[:, 0] * h[:, 0] + h[:, 1] * h[:, 1]
        return d, _narrow_minima(d, denominator, jnp.broadcast_to(s_x, shape), t, starts,
                                 edges)

    def correct(operands):  # closes over nothing traced (``batch_skipping_cond``)
        h, s_x, s_n, bare, row_weights, *g = operands
        t_j = jnp.asarray(t, h.dtype)
        q = jnp.broadcast_to(s_n / s_x, shape).reshape(-1, n)
        s_n = jnp.broadcast_to(s_n, shape).reshape(-1, n)
        denominator = (h[:, 0] * h[:, 0] + h[:, 1] * h[:, 1]) * s_x + s_n.reshape(shape)
        d, narrow = narrow_of(h, denominator, s_x)
        edge = jnp.zeros(shape[:-1] + (1,), bool)
        narrow = jnp.concatenate([edge, narrow, edge], axis=-1).reshape(-1, n)
        j, live, stencil = jax.vmap(_search)(d.reshape(-1, n), narrow)
        ray = jnp.arange(rows * triangles)[:, None, None]
        index = (ray * n + stencil).reshape(-1)  # into (rows, triangles, N), flattened
        h_re, h_im = (h[:, i].reshape(-1) for i in (0, 1))

        spectra = [jnp.take_along_axis(a, stencil.reshape(a.shape[0], -1), axis=1).reshape(
            stencil.shape) for a in (q, s_n)]

        def fit(y_re, y_im):  # each peak's model (rays, P), from its own nodes
            return jax.vmap(lambda *a: _fit(*a, t_j))(y_re, y_im, *spectra, j, live, stencil)

        weights = jnp.repeat(row_weights, triangles)[:, None]  # (rays, 1)

        def total(model, alive):
            return jnp.sum(weights * jax.vmap(
                lambda *a: _window(*a, t_j, bare, starts, edges))(model, alive, j))

        y = tuple(part[index].reshape(stencil.shape) for part in (h_re, h_im))
        if adjoint is None:
            return total(*fit(*y))
        # Each peak's model depends on its own eight stencil values, so eight forward-mode
        # directions (the k-th value of every stencil at once) give its derivatives; the
        # window's sum over some 48 nodes, which costs most, is differentiated once in
        # reverse mode in the model's six numbers (eight forward directions through it took
        # three times as long).
        model, linear, alive = jax.linearize(fit, *y, has_aux=True)
        basis = jnp.eye(8, dtype=h.dtype).reshape(8, 2, 1, 1, 4)
        d_model = jax.vmap(lambda e: linear(*(jnp.broadcast_to(x, stencil.shape)
                                              for x in e)))(basis)
        value, partial = jax.value_and_grad(total)(model, alive)
        slopes = sum(p[None] * d for p, d in zip(partial, d_model, strict=True))  # (8, rays, P)
        return (value,
                *(part.reshape(-1).at[index].add(
                    jnp.moveaxis(slopes[4 * i:4 * i + 4], 0, -1).reshape(-1)).reshape(part.shape)
                  for i, part in enumerate(g)))

    def skip(operands):
        zero = jnp.zeros((), h.dtype)
        return zero if adjoint is None else (zero, *operands[5:])

    _, narrow = narrow_of(h, denominator, s_x)
    return batch_skipping_cond(
        jnp.any(narrow), correct, skip,
        (h, s_x, s_n, bare, row_weights) + (() if adjoint is None else tuple(adjoint)))

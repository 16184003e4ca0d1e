"""NaN-safe primitives, host-side quadrature constants and argument checks.

Everything here is a leaf of the pipeline: no other ``jmse_jax`` module is imported.

The ``safe_*`` functions use the double-``where`` pattern (guard the *input* of the
singular function, then select the output) so that both values and gradients are finite at
the singular point; each one is checked by a gradient test at that point.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "EXACT",
    "AccuracyWarning",
    "SEQUENTIAL_BRANCH_BACKENDS",
    "abs2",
    "all_finite",
    "barycentric_matrix",
    "batch_skipping_cond",
    "check_choice",
    "check_count",
    "check_finite_tree",
    "check_range",
    "common_dtype",
    "cos_2pi",
    "cos_sin_2pi",
    "cos_sin_2pi_stacked",
    "gauss_legendre",
    "concrete_primal",
    "is_concrete",
    "is_single_precision",
    "map_batch",
    "materialise",
    "one_at_a_time",
    "runtime_one",
    "safe_arccos",
    "safe_norm",
    "safe_sqrt",
    "select_batch",
    "spread_batch",
    "with_batching_rule",
]


#: Precision of every matrix product in the pipeline. On GPUs and TPUs JAX's default runs
#: float32 products on reduced-precision units (TF32, bfloat16 passes), which put relative
#: errors of about 5e-4 into a float32 JMSE (measured on an H100); full precision keeps
#: float32 within about 1e-6 of float64. CPUs compute every product in full precision.
EXACT = jax.lax.Precision.HIGHEST


class AccuracyWarning(UserWarning):
    """The category of every warning ``jmse_jax`` gives: a result that may be less accurate
    than the call's preset or grids were checked to give (a design stronger or steeper than
    the checked range, terms that cancel beyond it, a peak ``S_x / S_n`` beyond the checked
    noise, too few ``otf`` nodes, a square grid too coarse for ``baseline_jmse``'s band).
    A ``UserWarning``, so Python shows it once per place by default; select it by category,
    e.g. ``warnings.simplefilter("error", jmse_jax.AccuracyWarning)`` to stop on one, or
    ``"ignore"`` in a sweep that knows its designs lie outside the checked range. The
    command line prints these as ``jmse-jax: warning: ...`` and any other warning in
    Python's own form."""


# --------------------------------------------------------------------------------------
# NaN-safe primitives
# --------------------------------------------------------------------------------------


def safe_sqrt(x):
    """``sqrt(max(x, 0))`` whose gradient is 0 (not inf/NaN) where ``x <= 0``; NaN stays
    NaN (a NaN input must not come out as a plausible 0)."""
    positive = x > 0
    x_safe = jnp.where(positive, x, jnp.ones_like(x))
    return jnp.where(positive, jnp.sqrt(x_safe), jnp.where(jnp.isnan(x), x, jnp.zeros_like(x)))


def safe_norm(x, y):
    """Euclidean norm ``hypot(x, y)`` with a zero (finite) gradient at the origin."""
    r2 = x * x + y * y
    return safe_sqrt(r2)


def safe_arccos(x):
    """``arccos(clip(x, -1, 1))`` with finite gradients at and beyond ``|x| = 1``.

    The true derivative is infinite at ``|x| = 1``; there the gradient is set to 0, which
    is the right limit wherever the result is multiplied by a quantity vanishing at least
    like ``sqrt(1 - x**2)`` (as in every use in this package).
    """
    inside = jnp.abs(x) < 1
    x_safe = jnp.where(inside, x, jnp.zeros_like(x))
    edge = jnp.where(x >= 1, jnp.zeros_like(x), jnp.full_like(x, math.pi))
    return jnp.where(inside, jnp.arccos(x_safe), edge)


def abs2(z):
    """``|z|**2`` as ``Re(z)**2 + Im(z)**2`` (differentiable at ``z = 0``, unlike ``abs``)."""
    return jnp.real(z) ** 2 + jnp.imag(z) ** 2


# Near-minimax polynomials on the half angle h in [-pi/2, pi/2], in powers of h^2:
# cos h ~ sum_k _COS_H[k] h^2k and sin h ~ h sum_k _SIN_H[k] h^2k. Each is the Chebyshev
# series of cos(sqrt z), resp. sin(sqrt z) / sqrt z, on z in [0, (pi/2)^2], computed in
# extended precision and cut at degree 8 in z (the first coefficient left out is ~1e-17),
# then written in powers of z (``tests/test_numerics.py`` recomputes them). Nine terms
# each instead of the twelve a Taylor series needs for the same error (~5e-16).
_COS_H = (
    1.0, -0.4999999999999997, 0.04166666666666392, -0.0013888888888773808,
    2.4801587277515865e-05, -2.7557316397955354e-07, 2.0876562104714277e-09,
    -1.1462907113556422e-11, 4.609017554610764e-14,
)
_SIN_H = (
    1.0, -0.16666666666666666, 0.0083333333333332, -0.0001984126984120999,
    2.7557319211189647e-06, -2.5052106872995896e-08, 1.6058939554909289e-10,
    -7.642984436934732e-13, 2.721074754781312e-15,
)

# sin(pi r) ~ r sum_k _SIN_PI_R[k] r^2k on r in [-1/2, 1/2]: the same fit for
# sin(pi sqrt z) / sqrt z on z in [0, 1/4] (pi folded into the coefficients, one product
# less per entry than ``_SIN_H`` at pi r).
_SIN_PI_R = (
    3.141592653589793, -5.167712780049969, 2.5501640398773073, -0.5992645293190848,
    0.08214588657461501, -0.007370430514890813, 0.00046629984512946976,
    -2.1903542801737785e-05, 7.698079571127892e-07,
)

#: The same fit cut at degree 4 in z, for float32 (``cos_sin_2pi_stacked``): absolute error
#: about 2e-7 in ``sin(pi r)``, at float32's rounding (degree 5 is no better there).
_SIN_PI_R_F32 = (
    3.141592640130707, -5.167710083507896, 2.5500775232145503, -0.5982912856197554,
    0.07765766030371939,
)


def is_single_precision(dtype) -> bool:
    """Whether ``dtype`` is float32 or narrower: such computations take the float32 paths
    (``cos_sin_2pi_stacked``'s shorter polynomial, ``_otf.along_chord_order``)."""
    return jnp.finfo(dtype).bits <= 32


def _even_poly(coefficients, z):
    result = jnp.full_like(z, coefficients[-1])
    for a in coefficients[-2::-1]:
        result = result * z + a
    return result


@jax.custom_jvp
def cos_sin_2pi(x):
    """``(cos(2 pi x), sin(2 pi x))`` for a phase ``x`` in waves, fast and vectorisable.

    The range reduction ``x - round(x)`` is exact (phases are in waves), the half angle
    ``pi (x - round(x))`` lies in ``[-pi/2, pi/2]`` where two degree-16/17 polynomials are
    accurate to rounding, and one double-angle step restores the angle. About 4x faster
    than ``jnp.cos`` + ``jnp.sin`` on CPU; absolute error below 1e-15 in float64. The
    derivative is exact: ``(-2 pi sin, 2 pi cos)``.
    """
    half = math.pi * (x - jnp.round(x))
    t2 = half * half
    c = _even_poly(_COS_H, t2)
    s = _even_poly(_SIN_H, t2) * half
    return c * c - s * s, 2.0 * s * c


@cos_sin_2pi.defjvp
def _cos_sin_2pi_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    c, s = cos_sin_2pi(x)
    scale = 2.0 * math.pi * dx
    return (c, s), (-s * scale, c * scale)


def cos_2pi(x):
    """``cos(2 pi x)`` for a phase ``x`` in waves, one polynomial per entry:
    ``1 - 2 sin(pi r)^2`` with ``r = x - round(x)`` (exact). The kernel of
    ``cos_sin_2pi_stacked``, whose sine entries are the cosine at ``x - 1/4``; alone, for
    integrands known to be even, whose sine part cancels (the overlap engine's rotationally
    symmetric path). No derivative rule of its own: its callers differentiate through
    ``cos_sin_2pi_stacked``, and a derivative taken through it is the polynomial's own."""
    r = x - jnp.round(x)
    coefficients = _SIN_PI_R_F32 if is_single_precision(x.dtype) else _SIN_PI_R
    s = _even_poly(coefficients, r * r) * r
    return 1.0 - 2.0 * (s * s)


@jax.custom_jvp
def cos_sin_2pi_stacked(x):
    """``cos(2 pi x)`` and ``sin(2 pi x)`` stacked on a new axis before the last:
    ``(..., n) -> (..., 2, n)``, each entry from one polynomial.

    ``cos_sin_2pi`` evaluates both half-angle polynomials for either output, and XLA's CPU
    fusion computes each output in its own loop, so a consumer of both pays for four
    polynomials per phase. Here each entry is ``cos(2 pi y) = 1 - 2 sin(pi r)^2`` with
    ``r = y - round(y)`` (exact) and ``y = x`` for the cosine, ``y = x - 1/4`` for the sine:
    one polynomial per entry, and the stacked array is one loop. Absolute error about
    1e-15 in float64, plus the rounding of ``x - 1/4`` (half an ulp of ``x``, below the
    rounding already in a phase computed as a difference of wavefronts). The derivative is
    exact: ``2 pi (-sin, cos)``.
    """
    shift = jnp.asarray([[0.0], [0.25]], x.dtype)
    return cos_2pi(x[..., None, :] - shift)


@cos_sin_2pi_stacked.defjvp
def _cos_sin_2pi_stacked_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    e = cos_sin_2pi_stacked(x)
    rotated = jnp.stack([-e[..., 1, :], e[..., 0, :]], axis=-2)
    return e, (2.0 * math.pi) * rotated * dx[..., None, :]


def runtime_one(x):
    """1, computed from ``x`` at run time so that XLA cannot prove it (see ``materialise``);
    no derivative flows through it."""
    magnitude = jnp.abs(jax.lax.stop_gradient(x)) + 1.0
    return magnitude / magnitude


def materialise(*arrays):
    """The arrays divided by a run-time 1 that XLA cannot prove to be 1.

    XLA's CPU fusion copies element-wise producers into every consumer, even expensive ones
    (``sin``, ``cos``, long polynomials): an intermediate with many consumers, or one
    broadcast over a larger array, would be recomputed for every consumer and every element
    of the broadcast. A division counts as expensive enough that XLA computes its operand
    once and stores it. The run-time 1 is ``m / m`` with ``m = |arrays[0]| + 1``; XLA
    rewrites ``a / (m / m)`` as ``(a m) / m``, so values and derivatives change by at most an
    ulp, for arrays whose ``|a| m`` stays inside the float range (here: chord geometry and
    phases of order 1 to 1e3). A select instead of ``m / m`` would be exact, but XLA then
    fuses the producers again.
    """
    one = runtime_one(arrays[0])
    return tuple(a / one for a in arrays)


def spread_batch(axis_size, tree, batched):
    """``tree`` with every leaf not marked in ``batched`` (a ``custom_vmap`` rule's
    ``in_batched``) broadcast along a new leading axis of ``axis_size``."""
    def spread(x, is_batched):
        return x if is_batched else jnp.broadcast_to(x, (axis_size, *jnp.shape(x)))

    return jax.tree_util.tree_map(spread, tree, batched)


def select_batch(mask, chosen, other):
    """``chosen`` where the batch's ``mask`` (leading axis) holds, else ``other``."""
    return jnp.where(mask.reshape(mask.shape + (1,) * (chosen.ndim - 1)), chosen, other)


def with_batching_rule(fun, rule):
    """``fun`` (positional arguments) with the ``vmap`` rule ``rule`` (``custom_vmap``'s
    signature: ``rule(axis_size, in_batched, *args) -> (out, out_batched)``).

    Derivatives go through ``fun`` itself (``custom_vmap`` has no reverse-mode rule, and a
    derivative rule for the batching would be a second copy of it), so ``vmap`` of a
    derivative batches ``fun`` as JAX does. A rule called with nothing batched (``vmap``
    batching a traced body, as under ``jax.hessian``) is not consulted: ``fun`` runs as it
    is, unbatched.
    """

    @jax.custom_batching.custom_vmap
    def batched(*args):
        return fun(*args)

    @batched.def_vmap
    def batched_rule(axis_size, in_batched, *args):
        if not any(jax.tree_util.tree_leaves(in_batched)):
            out = fun(*args)
            return out, jax.tree_util.tree_map(lambda _: False, out)
        return rule(axis_size, tuple(in_batched), *args)

    @jax.custom_jvp
    def run(*args):
        return batched(*args)

    @run.defjvp
    def run_jvp(primals, tangents):
        return jax.jvp(fun, primals, tangents)

    return run


def map_batch(fn, in_batched, args):
    """``lax.map`` of ``fn(*args)`` over the leading axis of the leaves of ``args`` marked in
    ``in_batched`` (a ``custom_vmap`` rule's); the other leaves are shared by every member,
    so that a constant stays one and each member gets bit for bit what it gets alone."""
    leaves, treedef = jax.tree_util.tree_flatten(args)
    flags = jax.tree_util.tree_leaves(in_batched)

    def member(batched):
        it = iter(batched)
        full = [next(it) if flag else leaf for leaf, flag in zip(leaves, flags, strict=True)]
        return fn(*jax.tree_util.tree_unflatten(treedef, full))

    return jax.lax.map(member, [leaf for leaf, flag in zip(leaves, flags, strict=True) if flag])


def one_at_a_time(fn):
    """``fn`` (positional arguments) whose ``vmap`` runs the members one by one
    (``map_batch``); derivatives as ``with_batching_rule``'s."""

    def rule(axis_size, in_batched, *args):
        out = map_batch(fn, in_batched, args)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return with_batching_rule(fn, rule)


#: Backends on which ``batch_skipping_cond`` runs the branch member by member under ``vmap``
#: (``sequential=None``). On CPU the vectorised branch of ``jmse_jax._ridges`` measured
#: about three times the cost of one member's branch per member (its gathers and scatters
#: gain nothing from the batch), and a loop skips the members that do not take it.
SEQUENTIAL_BRANCH_BACKENDS = ("cpu",)


def batch_skipping_cond(pred, true_fn, false_fn, operands, *, sequential=None):
    """``lax.cond(pred, true_fn, false_fn, operands)`` that still skips ``true_fn`` under
    ``vmap``.

    ``vmap`` of a ``lax.cond`` whose predicate is batched evaluates both branches for every
    member of the batch and selects. Here the batch runs ``true_fn`` only when the
    predicate holds for some member, inside a ``lax.cond`` on that (unbatched) fact, and
    each member gets its own branch's result, exactly as alone. Then, with ``sequential``,
    the members go through the plain ``lax.cond`` one at a time (``lax.map``), so that only
    those that take ``true_fn`` run it; without, ``true_fn`` runs vectorised over the whole
    batch and each member's result is selected. ``sequential=None`` picks the loop on the
    backends of ``SEQUENTIAL_BRANCH_BACKENDS`` (the default backend's, at trace time). For a
    ``true_fn`` that is costly and rarely needed (the closed-form peaks of
    ``jmse_jax._ridges``).

    The branches must close over no traced value (``operands`` carry every array they
    use): the batching rule (``custom_vmap``) may run after the trace that made such a
    value has ended (``vmap`` of a ``lax.scan`` batches the scan's traced body).
    Derivatives of the call go through the plain ``lax.cond`` (``custom_vmap`` has no
    reverse-mode rule), so ``vmap`` of a derivative of it runs both branches; a value that
    is only evaluated inside a derivative rule (as ``jmse_jax._merit._fine_stage_jvp``
    evaluates the peaks' adjoint) keeps the skip.
    """
    if sequential is None:
        sequential = jax.default_backend() in SEQUENTIAL_BRANCH_BACKENDS

    def plain(pred, operands):
        return jax.lax.cond(pred, true_fn, false_fn, operands)

    def rule(axis_size, in_batched, pred, operands):
        spread = spread_batch(axis_size, operands, in_batched[1])
        on, off = jax.vmap(true_fn), jax.vmap(false_fn)
        if not in_batched[0]:
            out = jax.lax.cond(pred, on, off, spread)
        elif sequential:
            def each(_):
                return map_batch(plain, in_batched, (pred, operands))

            out = jax.lax.cond(jnp.any(pred), each, off, spread)
        else:
            def either(ops):
                return jax.tree_util.tree_map(functools.partial(select_batch, pred), on(ops),
                                              off(ops))

            out = jax.lax.cond(jnp.any(pred), either, off, spread)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return with_batching_rule(plain, rule)(pred, operands)


def common_dtype(*args):
    """Floating dtype of the result: the promotion of the inputs (at least float32/64 default)."""
    leaves = [leaf for arg in args for leaf in jax.tree_util.tree_leaves(arg)]
    dtype = jnp.result_type(float, *leaves) if leaves else jnp.result_type(float)
    if jnp.issubdtype(dtype, jnp.complexfloating):
        dtype = jnp.finfo(dtype).dtype
    return dtype


# --------------------------------------------------------------------------------------
# Host-side quadrature constants (NumPy float64, cached)
# --------------------------------------------------------------------------------------


#: Above this many nodes the Gauss–Legendre rule comes from Newton's method on the
#: three-term recurrence (``_gauss_legendre_newton``, O(n^2) vectorised work) instead of
#: NumPy's ``leggauss``, whose dense eigenvalue solve is O(n^3): 2.7 s at 3840 nodes and
#: 24 s at 7680, the outer radial panel of ``se_nodes=(19200, ...)``, once per process
#: (0.25 s by Newton). Every preset's rules are at or below it and keep ``leggauss``'s.
NEWTON_GAUSS_ABOVE = 1024


def _gauss_legendre_newton(n: int):
    """Gauss–Legendre rule on [-1, 1] by Newton's method on ``P_n`` (three-term recurrence)
    from Tricomi's approximation of the roots, weights ``2 / ((1 - x^2) P_n'(x)^2)``;
    nodes ascending. On ``exp``, ``sqrt(1.5 - x)`` and ``1 / (1.01 - x)`` it integrates to
    2e-16-3e-15 relative for 1100-5000 nodes (``leggauss``: 3e-15-2e-12)."""
    m = (n + 1) // 2
    k = np.arange(1, m + 1)
    theta = np.pi * (4 * k - 1) / (4 * n + 2)
    x = np.cos(theta) * (1.0 - (n - 1) / (8.0 * n**3)
                         - (39.0 - 28.0 / np.sin(theta) ** 2) / (384.0 * n**4))

    def legendre(x):  # P_n(x), P_{n-1}(x)
        p_prev, p = np.ones_like(x), x.copy()
        for j in range(2, n + 1):
            p_prev, p = p, ((2 * j - 1) * x * p - (j - 1) * p_prev) / j
        return p, p_prev

    for _ in range(10):
        p, p_prev = legendre(x)
        step = p * (x * x - 1.0) / (n * (x * p - p_prev))
        x = x - step
        if np.max(np.abs(step)) <= 2e-16:
            break
    if n % 2:
        x[-1] = 0.0  # the middle root, exactly
    p, p_prev = legendre(x)
    derivative = n * (x * p - p_prev) / (x * x - 1.0)
    w = 2.0 / ((1.0 - x * x) * derivative * derivative)
    # x holds the roots in (0, 1] from the largest down (and 0 last for odd n).
    mirror = slice(None, None, -1) if n % 2 == 0 else slice(-2, None, -1)
    return np.concatenate([-x, x[mirror]]), np.concatenate([w, w[mirror]])


@functools.cache
def _gauss_legendre_unit(n: int):
    if n > NEWTON_GAUSS_ABOVE:
        x, w = _gauss_legendre_newton(n)
    else:
        x, w = np.polynomial.legendre.leggauss(n)
    x.setflags(write=False)
    w.setflags(write=False)
    return x, w


def gauss_legendre(n: int, a: float = -1.0, b: float = 1.0):
    """Gauss–Legendre nodes and weights on ``[a, b]`` (NumPy float64, computed on the host).

    Exact for polynomials of degree ``2 n - 1``.
    """
    check_count("n", n)
    x, w = _gauss_legendre_unit(int(n))
    half = 0.5 * (b - a)
    return a + half * (x + 1.0), half * w


def barycentric_matrix(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Matrix ``L`` with ``L @ f(source) = p(target)``, ``p`` the polynomial interpolant.

    Barycentric Lagrange interpolation (Berrut & Trefethen 2004) in float64 on the host.
    Well conditioned for Gauss–Legendre or Chebyshev source nodes.
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    diff = source[:, None] - source[None, :]
    np.fill_diagonal(diff, 1.0)
    bary = 1.0 / np.prod(diff, axis=1)
    delta = target[:, None] - source[None, :]
    exact = np.isclose(delta, 0.0, rtol=0.0, atol=1e-15)
    delta = np.where(exact, 1.0, delta)
    terms = bary[None, :] / delta
    matrix = terms / terms.sum(axis=1, keepdims=True)
    rows = exact.any(axis=1)
    matrix[rows] = exact[rows].astype(np.float64)
    return matrix


# --------------------------------------------------------------------------------------
# Argument checks (raise ValueError when values are concrete; silent under tracing)
# --------------------------------------------------------------------------------------


def all_finite(tree):
    """Whether every inexact leaf of ``tree`` is finite everywhere, as a traceable bool
    (integer leaves are always finite)."""
    leaves = [jnp.all(jnp.isfinite(leaf)) for leaf in jax.tree_util.tree_leaves(tree)
              if jnp.issubdtype(jnp.result_type(leaf), jnp.inexact)]
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.asarray(True)


def is_concrete(x) -> bool:
    """True when every leaf of ``x`` has a value now (not a tracer under jit/vmap/grad)."""
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(x))


def concrete_primal(tree):
    """``tree`` with each tracer replaced by the concrete value it carries, where every
    leaf is concrete or a chain of forward-mode or linearisation tracers over a concrete
    value (an eager ``jax.grad``, ``jax.jvp`` or ``jax.jacfwd``, nested or not); None
    otherwise (under ``jit`` or ``vmap``). Reads the tracers' ``primal``."""

    def value(leaf):
        for _ in range(64):
            if not isinstance(leaf, jax.core.Tracer):
                return leaf
            leaf = getattr(leaf, "primal", None)
        return None

    leaves, treedef = jax.tree_util.tree_flatten(tree)
    values = [value(leaf) for leaf in leaves]
    if any(v is None for v in values):
        return None
    return jax.tree_util.tree_unflatten(treedef, values)


def reverse_over_derivative(tree) -> bool:
    """Whether a leaf of ``tree`` (a function's arguments) is traced by reverse mode over
    another derivative taken inside it (``jax.grad`` of ``jax.grad`` or of ``jax.jvp``,
    ``jax.jacrev`` of ``jax.jacrev``, with or without an outer ``jit`` or ``vmap``): a
    linearisation tracer (``jax.grad``, ``jax.vjp``) below the innermost tracer of its
    chain. False under forward over reverse (``jax.hessian``), for a first derivative, and
    where the chain cannot be read (a ``jit`` between the two derivatives)."""

    def nested(leaf):
        for depth in range(64):
            if not isinstance(leaf, jax.core.Tracer):
                return False
            if depth and type(leaf).__name__ == "LinearizeTracer":
                return True
            leaf = getattr(leaf, "primal", None)
        return False

    return any(nested(leaf) for leaf in jax.tree_util.tree_leaves(tree))


@functools.cache
def _reverse_sentinel(message):
    """The identity primitive of ``refuse_reverse_over`` for ``message`` (one per message,
    so that no parameter clutters a printed jaxpr): its derivative rule raises
    ``ValueError(message)`` when partial evaluation linearizes it (its tangent is then a
    ``JaxprTracer``: reverse mode, ``jax.linearize``; JAX's direct linearization, the
    default since jax 0.7, the floor of ``_requirements``) and otherwise passes the primal
    through itself again, so that forward mode of any order goes on as before."""
    from jax.extend.core import Primitive
    from jax.interpreters import ad, batching, mlir

    sentinel = Primitive("jmse_reverse_over_derivative")
    sentinel.def_impl(lambda x: x)
    sentinel.def_abstract_eval(lambda x: x)

    def jvp(primals, tangents):
        (x,), (t,) = primals, tangents
        if type(t).__name__ == "JaxprTracer":
            raise ValueError(message)
        return sentinel.bind(x), t

    def batch(args, dims):
        return sentinel.bind(args[0]), dims[0]

    ad.primitive_jvps[sentinel] = jvp
    batching.primitive_batchers[sentinel] = batch
    mlir.register_lowering(sentinel, lambda ctx, x: [x])
    return sentinel


def refuse_reverse_over(tree, message):
    """``tree`` (a function's arguments) unchanged, such that reverse mode over a
    derivative of what is computed from it raises ``ValueError(message)`` as soon as the
    outer derivative linearizes, also where a ``jit`` between the two derivatives hides
    the outer one from ``reverse_over_derivative`` (``jax.grad(jax.jit(jax.grad(f)))``).

    An identity with a derivative rule (run by any derivative of the result) passes the
    primal through ``_reverse_sentinel``'s primitive, which thereby stays in the
    derivative's program, and whose own derivative rule refuses to be linearized. A first
    derivative, forward or reverse, never runs the sentinel's rule; forward over reverse
    (``jax.hessian``) runs it in forward mode, which it allows. Only floating leaves take
    part; the values are the same to the bit (both are identities)."""

    def floating(leaf):
        try:
            return jnp.issubdtype(jnp.result_type(leaf), jnp.inexact)
        except TypeError:  # not an array (a string, an object)
            return False

    leaves, treedef = jax.tree_util.tree_flatten(tree)
    marked = [i for i, leaf in enumerate(leaves) if floating(leaf)]
    if not marked:
        return tree

    @jax.custom_jvp
    def watched(values):
        return values

    def watched_jvp(primals, tangents):
        # Symbolic zeros pass through as they are: the derivative rules downstream take
        # gradients only in the operands that carry a tangent (``_live_tangents``).
        (values,), (d_values,) = primals, tangents
        sentinel = _reverse_sentinel(message)
        return [sentinel.bind(v) for v in values], list(d_values)

    watched.defjvp(watched_jvp, symbolic_zeros=True)

    for i, leaf in zip(marked, watched([leaves[i] for i in marked]), strict=True):
        leaves[i] = leaf
    return jax.tree_util.tree_unflatten(treedef, leaves)


def _describe(value) -> str:
    arr = np.asarray(value)
    if arr.ndim == 0:
        return repr(arr.item())
    return np.array2string(arr, threshold=6, precision=6)


def _real_array(name: str, value) -> np.ndarray:
    """``value`` as a float64 array; ``TypeError`` naming ``name`` when it is not real
    numbers (a string, a bool, ``None``, a complex number, a ragged list)."""
    raw = value
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError):
        pass
    kind = getattr(raw, "dtype", np.dtype(object)).kind
    if kind not in "iuf":
        raise TypeError(f"{name} must be a real number (or array of them), got {value!r}")
    return raw.astype(np.float64)


def check_range(
    name: str,
    value,
    low: float | None = None,
    high: float | None = None,
    *,
    low_inclusive: bool = True,
    high_inclusive: bool = True,
) -> None:
    """Raise ``ValueError`` naming ``name`` when a concrete ``value`` is non-finite or out of range.

    Traced values are not checked (their values are unknown at trace time).
    """
    if not is_concrete(value):
        return
    arr = _real_array(name, value)
    lo = "(" if not low_inclusive else "["
    hi = ")" if not high_inclusive else "]"
    allowed = f"{lo}{'-inf' if low is None else low}, {'inf' if high is None else high}{hi}"
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite and in {allowed}, got {_describe(value)}")
    bad = np.zeros(arr.shape, dtype=bool)
    if low is not None:
        bad |= (arr < low) if low_inclusive else (arr <= low)
    if high is not None:
        bad |= (arr > high) if high_inclusive else (arr >= high)
    if np.any(bad):
        raise ValueError(f"{name} must be in {allowed}, got {_describe(value)}")


def check_finite_tree(name: str, tree) -> None:
    """Raise ``ValueError`` when any concrete float leaf of ``tree`` is NaN or infinite, and
    ``TypeError`` when a leaf is not real numbers (a string, a bool: ``w020=True`` would
    otherwise pass as one wave)."""
    for path, leaf in jax.tree_util.tree_leaves_with_path(tree):
        if not is_concrete(leaf):
            continue
        where = jax.tree_util.keystr(path)
        try:
            arr = np.asarray(leaf)
        except (TypeError, ValueError):
            arr = np.asarray(None)
        if arr.dtype.kind in "USOcb":
            raise TypeError(f"{name}{where} must be a real number (or array of them), "
                            f"got {leaf!r}")
        if np.issubdtype(arr.dtype, np.number) and not np.all(np.isfinite(arr)):
            raise ValueError(f"{name}{where} must be finite, got {_describe(arr)}")


def check_count(name: str, value, minimum: int = 1) -> None:
    """Raise ``ValueError`` unless ``value`` is an integer ``>= minimum`` (a static size)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")


def check_choice(name: str, value, choices) -> None:
    """Raise ``ValueError`` unless ``value`` is one of ``choices``."""
    if value not in choices:
        options = ", ".join(repr(c) for c in choices)
        raise ValueError(f"{name} must be one of {options}, got {value!r}")

"""The reset's draws as plain-float kernels: a target and an initial state from a block of uniforms.

:meth:`~flatbody_env.env.task.ReachStationaryEllipse.sample_target` and
:meth:`~flatbody_env.env.task.ReachStationaryEllipse.sample_initial_state` draw from a numpy
``Generator``: three uniforms per candidate target shape, then ten (nine without torque) for the
initial state. The formulas they apply to those numbers live once, as plain-float kernels that both
run — the settling-rate table's :func:`~flatbody_env.env.targets.decide_kernel`, the inverse problem
and stability test :func:`~flatbody_env.physics.equilibria.stationary_shape_kernel`, and
:func:`initial_state_kernel`. The candidate loop of ``sample_target`` (which also serves bodies these
kernels do not: custom potentials, a thickness found by root finding) is mirrored here by
:func:`candidate_kernel` and :func:`sample_episode_kernel`, so that the batched reset
(:func:`sample_episodes`, compiled by :mod:`flatbody_env.env.compiled`) draws the same episodes from
the same stream, bit for bit — the tests hold the two to that.

The batched reset takes, per body, a block of uniforms drawn ahead from that body's generator; it
returns how many of them the episode used (the caller puts the generator back where the Python
methods would have left it), or a code: :data:`NEED_MORE` (the block ran out), :data:`NEED_DECISION`
(the table is unsure about a candidate: the exact Riccati test decides, in Python, and the kernel
is run again with the answer in ``decisions``) or :data:`NO_TARGET` (the attempts ran out).

``cfg`` (:data:`CFG_SIZE`): 0–1 λ* range lo, hi; 2–3 aspect range lo, hi; 4 the settling-rate
threshold; 5 how reachability is decided (1: the settling-rate table, 0: the exact test for every
shape, 2: no filter applies); 6 the initial noise; 7 1 with torque; 8 ϱ* (the body's equilibrium
thickness, constant for the built-in thickness potential); 9 1 for the rotation branch (|s3| > |p_θ|),
0 for the circulation branch; 10 the stability class of a target (:data:`STABLE`: q < 0 and the shape
Hessian positive definite; :data:`HYPERBOLIC`: q > 0 with growth rate √q in [cfg[11], cfg[12]] and the
shape Hessian positive definite); 13 the start (:data:`START_NOISE`: :func:`initial_state_kernel`;
:data:`START_BALL`: :func:`ball_state_kernel` with distance radii [cfg[14], cfg[15]]; :data:`START_NONE`: none,
``y`` is left as it is). ``P``: the
body's kernel parameters (:meth:`~flatbody_env.physics.body.Body.kernel_params`).
"""

from __future__ import annotations

import importlib
import math

import numpy as np

from flatbody_env.env.targets import ACCEPT, REJECT, UNSURE, decide_kernel
from flatbody_env.physics.controllability import settling_rate, target_state
from flatbody_env.physics.equilibria import equilibrium_thickness, stationary_shape_kernel, stencil_step
from flatbody_env.physics.potentials import potential_kernel

CFG_SIZE = 16
"""Length of the sampler's configuration vector (module docstring)."""
STABLE, HYPERBOLIC = 0.0, 1.0
"""Stability classes of a target (``cfg[10]``)."""
START_NOISE, START_BALL, START_NONE = 0.0, 1.0, 2.0
"""How the start is drawn (``cfg[13]``); :data:`START_NONE`: no start, the target only (the caller draws the start)."""
BALL_DRAWS = 12
"""Uniforms of :func:`ball_state_kernel`."""
MAX_ATTEMPTS = 500
"""Candidate shapes drawn before a reset gives up (:data:`NO_TARGET`)."""
NEED_MORE, NEED_DECISION, NO_TARGET = -1, -2, -3
DECIDE_ACCEPT, DECIDE_REJECT = 1, 2
"""Values of ``decisions[a]`` for candidate a, set by the caller after the exact test (0: not decided)."""


def potential_stencil_kernel(P, lam, mu, rho, pot):
    """:func:`~flatbody_env.physics.equilibria.potential_stencil` for a built-in potential (the body's
    kernel parameters ``P``): ``pot`` (7, 4) receives (V, ∂V/∂λ, ∂V/∂μ, ∂V/∂ϱ) at (λ, μ, ϱ) and at the
    point moved by ±h along each coordinate, in that layout."""
    h = stencil_step(lam, mu, rho)
    for r in range(7):
        c = (r - 1) // 2
        d = 0.0 if r == 0 else (h if r % 2 == 1 else -h)
        x0 = lam + d if c == 0 else lam
        x1 = mu + d if c == 1 else mu
        x2 = rho + d if c == 2 else rho
        v, gl, gm, gr = potential_kernel(P[3], P[4], P[5], P[6], P[7], x0, x1, x2)
        pot[r, 0] = v
        pot[r, 1] = gl
        pot[r, 2] = gm
        pot[r, 3] = gr


def candidate_kernel(
    u_lam,
    u_aspect,
    u_sign,
    cfg,
    P,
    pot,
    table_code,
    grid,
    rate,
    margin,
    invalid,
    edge_lo,
    edge_hi,
    refined,
    fine_rate,
    fine_margin,
    cand,
):
    """Decide one candidate target from its three uniforms (the loop body of
    :meth:`~flatbody_env.env.task.ReachStationaryEllipse.sample_target`).

    λ* = lo + (hi − lo)·u₁, λ*/μ* = lo + (hi − lo)·u₂, sign = +1 if u₃ < 0.5 else −1; the table (if
    ``cfg[5]`` = 1; 0: the exact test decides every shape; 2: no reachability filter) may reject the shape outright; else the stationary ellipse of the circulation family
    is built (:func:`~flatbody_env.physics.equilibria.stationary_shape_kernel`) and must exist and be
    spectrally stable (q < 0, shape Hessian positive definite).

    ``pot`` (7, 4): work space (the potential stencil, :func:`potential_stencil_kernel`).
    ``table_code`` (1,) int64 receives the table's answer. ``cand`` (10,) receives λ*, μ*, ϱ*, s3*,
    p_θ*, ω3, θ̇, q, h_min of the stationary ellipse (when it exists) and the sign. The branch
    (``cfg[9]``) and the stability class a target must have (``cfg[10]``–``cfg[12]``) are in the
    module docstring.

    Returns
    -------
    int
        :data:`~flatbody_env.env.targets.ACCEPT` (a target), :data:`~flatbody_env.env.targets.REJECT`
        or :data:`~flatbody_env.env.targets.UNSURE` (a stable ellipse the table cannot judge: the exact
        test decides).
    """
    lam = cfg[0] + (cfg[1] - cfg[0]) * u_lam
    aspect = cfg[2] + (cfg[3] - cfg[2]) * u_aspect
    mu = lam / aspect
    sign = 1.0 if u_sign < 0.5 else -1.0
    code = UNSURE if cfg[5] == 0.0 else ACCEPT
    if cfg[5] == 1.0:
        code = decide_kernel(
            lam, aspect, cfg[4], grid, rate, margin, invalid, edge_lo, edge_hi, refined, fine_rate, fine_margin
        )
    table_code[0] = code
    if code == REJECT:
        return REJECT
    rho = cfg[8]
    potential_stencil_kernel(P, lam, mu, rho, pot)
    cand[0] = lam
    cand[1] = mu
    cand[2] = rho
    cand[9] = sign
    if not stationary_shape_kernel(P[0], P[2], lam, mu, rho, pot, cfg[9] != 0.0, sign, cand[3:]):
        return REJECT
    if cfg[10] == STABLE:
        if not (cand[7] < 0.0 and cand[8] > 0.0):  # q < 0 and the shape Hessian positive definite
            return REJECT
    else:  # hyperbolic: the out-of-plane saddle s̈1 = q s1, q > 0, growth rate √q in range
        if not (cand[7] > 0.0 and cand[8] > 0.0):
            return REJECT
        growth = math.sqrt(cand[7])
        if growth < cfg[11] or growth > cfg[12]:
            return REJECT
    if code == UNSURE:
        return UNSURE
    return ACCEPT  # ACCEPT, or ACCEPT_IF_STABLE on a stable ellipse


def initial_state_kernel(u, noise, torque, lam, mu, rho, s3t, pt, y):
    """The initial state y (11,) near the target from ``u`` (10 uniforms with torque, else 9) (the
    body of :meth:`~flatbody_env.env.task.ReachStationaryEllipse.sample_initial_state`).

    Offsets d = −n + 2n·u (n = ``noise``): s1, s2 = d·max(|s3*|, 0.1); s3 = s3*(1 + d) with torque,
    else on the sphere |s| = |s3*| (|s|² is conserved without torque); p_θ = p_θ* (conserved by
    every control); p_λ, p_μ, p_ϱ = d; λ = λ* e^d, μ = min(μ* e^d, 0.95 λ), ϱ = ϱ* e^d; θ uniform in [−π, π).
    """
    n = noise
    w = n - -n
    scale = max(abs(s3t), 0.1)
    s1 = (-n + w * u[0]) * scale
    s2 = (-n + w * u[1]) * scale
    if torque:
        s3 = s3t * (1.0 + (-n + w * u[2]))
        o = 3
    else:
        s3 = math.copysign(math.sqrt(max(s3t * s3t - s1 * s1 - s2 * s2, 0.0)), s3t)
        o = 2
    lam0 = lam * math.exp(-n + w * u[o + 3])
    pi = math.pi
    y[0] = s1
    y[1] = s2
    y[2] = s3
    y[3] = pt
    y[4] = -n + w * u[o]
    y[5] = -n + w * u[o + 1]
    y[6] = -n + w * u[o + 2]
    y[7] = lam0
    y[8] = min(mu * math.exp(-n + w * u[o + 4]), 0.95 * lam0)
    y[9] = rho * math.exp(-n + w * u[o + 5])
    y[10] = -pi + (pi - -pi) * u[o + 6]


def ball_state_kernel(u, r_lo, r_hi, lam, mu, rho, s3t, pt, J, J3, y):
    """A state at task distance R from the target, R uniform in [``r_lo``, ``r_hi``], in a uniformly
    random direction, from 12 uniforms ``u`` (the start of :class:`~flatbody_env.env.hold.HoldUnstableEllipse`).

    The distance coordinates are e = (Δλ, Δμ, Δϱ, Δs3, ω1, ω2, p_λ, p_μ, p_ϱ) (the task distance
    d = ‖e‖, :func:`~flatbody_env.env.task.score_kernel`): e = R z/‖z‖ with z nine standard normals
    from u[0:10] by the Box–Muller transform (z₂ₖ, z₂ₖ₊₁ = √(−2 ln(1 − u₂ₖ)) (cos, sin)(2π u₂ₖ₊₁));
    R = r_lo + (r_hi − r_lo) u[10]; θ = −π + 2π u[11]. The state: λ = λ* + e₀, μ = μ* + e₁,
    ϱ = ϱ* + e₂, s3 = s3* + e₃, s1 = e₄ (Jμ² + J3ϱ²), s2 = e₅ (Jλ² + J3ϱ²) (so that ω1, ω2 =
    e₄, e₅ by the inverse Legendre map after eq. (31) of [1]), p_θ = p_θ* (conserved), p = e₆…₈.

    References
    ----------
    .. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
       degenerate dimension", arXiv:0902.3573 (2009).
    """
    z0 = 0.0
    z1 = 0.0
    z2 = 0.0
    z3 = 0.0
    z4 = 0.0
    z5 = 0.0
    z6 = 0.0
    z7 = 0.0
    z8 = 0.0
    for k in range(5):
        r = math.sqrt(-2.0 * math.log(1.0 - u[2 * k]))
        c = r * math.cos(2.0 * math.pi * u[2 * k + 1])
        s = r * math.sin(2.0 * math.pi * u[2 * k + 1])
        if k == 0:
            z0 = c
            z1 = s
        elif k == 1:
            z2 = c
            z3 = s
        elif k == 2:
            z4 = c
            z5 = s
        elif k == 3:
            z6 = c
            z7 = s
        else:
            z8 = c
    norm = math.sqrt(z0 * z0 + z1 * z1 + z2 * z2 + z3 * z3 + z4 * z4 + z5 * z5 + z6 * z6 + z7 * z7 + z8 * z8)
    radius = r_lo + (r_hi - r_lo) * u[10]
    f = radius / norm if norm > 0.0 else 0.0
    lam0 = lam + f * z0
    mu0 = mu + f * z1
    rho0 = rho + f * z2
    y[0] = f * z4 * (J * mu0 * mu0 + J3 * rho0 * rho0)
    y[1] = f * z5 * (J * lam0 * lam0 + J3 * rho0 * rho0)
    y[2] = s3t + f * z3
    y[3] = pt
    y[4] = f * z6
    y[5] = f * z7
    y[6] = f * z8
    y[7] = lam0
    y[8] = mu0
    y[9] = rho0
    y[10] = -math.pi + 2.0 * math.pi * u[11]


def sample_episode_kernel(
    D,
    n,
    cfg,
    P,
    grid,
    rate,
    margin,
    invalid,
    edge_lo,
    edge_hi,
    refined,
    fine_rate,
    fine_margin,
    decisions,
    y,
    tgt,
    pot,
    table_code,
    cand,
):
    """One episode (target and initial state) from the uniforms ``D[:n]`` of one body.

    ``decisions`` (:data:`MAX_ATTEMPTS`,) int64: the exact test's answers for unsure candidates
    (:data:`DECIDE_ACCEPT`, :data:`DECIDE_REJECT`; 0 = not asked yet). Outputs ``y`` (11,), ``tgt``
    (6,) = (λ*, μ*, ϱ*, s3*, p_θ*, sign); ``cand`` (10,) holds the last candidate (on :data:`NEED_DECISION`:
    the one to test, its index in ``table_code[0]``).

    Returns the number of uniforms used (> 0), or :data:`NEED_MORE`, :data:`NEED_DECISION`, :data:`NO_TARGET`.
    """
    ball = cfg[13] == START_BALL
    m = BALL_DRAWS if ball else (0 if cfg[13] == START_NONE else (10 if cfg[7] != 0.0 else 9))
    for a in range(MAX_ATTEMPTS):
        if 3 * a + 3 > n:
            return NEED_MORE
        code = candidate_kernel(
            D[3 * a],
            D[3 * a + 1],
            D[3 * a + 2],
            cfg,
            P,
            pot,
            table_code,
            grid,
            rate,
            margin,
            invalid,
            edge_lo,
            edge_hi,
            refined,
            fine_rate,
            fine_margin,
            cand,
        )
        if code == REJECT:
            continue
        if code == UNSURE:
            if decisions[a] == 0:
                table_code[0] = a
                return NEED_DECISION
            if decisions[a] != DECIDE_ACCEPT:
                continue
        used = 3 * a + 3
        if used + m > n:
            return NEED_MORE
        for i in range(5):
            tgt[i] = cand[i]
        tgt[5] = cand[9]
        if cfg[13] == START_NONE:
            return used
        if ball:
            ball_state_kernel(
                D[used : used + m], cfg[14], cfg[15], cand[0], cand[1], cand[2], cand[3], cand[4], P[0], P[2], y
            )
        else:
            initial_state_kernel(
                D[used : used + m], cfg[6], cfg[7] != 0.0, cand[0], cand[1], cand[2], cand[3], cand[4], y
            )
        return used + m
    return NO_TARGET


def sample_episodes(
    D,
    counts,
    cfg,
    P,
    grid,
    rate,
    margin,
    invalid,
    edge_lo,
    edge_hi,
    refined,
    fine_rate,
    fine_margin,
    decisions,
    Y,
    cols,
    TG,
    used,
    pot,
    table_code,
    cand,
):
    """:func:`sample_episode_kernel` for m bodies: body b's uniforms in ``D[b, :counts[b]]`` (m, K), its
    decisions in ``decisions[b]`` (m, :data:`MAX_ATTEMPTS`); its state into column ``cols[b]`` of
    ``Y`` (11, N), its target (λ*, μ*, ϱ*, s3*, p_θ*, sign) into ``TG[b]`` (m, 6), the uniforms used (or the
    code) into ``used[b]``, its last candidate into ``cand[b]`` (m, 10) and ``table_code[b]`` (m,)."""
    for b in range(D.shape[0]):
        used[b] = sample_episode_kernel(
            D[b],
            counts[b],
            cfg,
            P,
            grid,
            rate,
            margin,
            invalid,
            edge_lo,
            edge_hi,
            refined,
            fine_rate,
            fine_margin,
            decisions[b],
            Y[:, cols[b]],
            TG[b],
            pot,
            table_code[b : b + 1],
            cand[b],
        )


class EpisodeSampler:
    """Resets for one or many bodies, each with its own ``Generator``, through :func:`sample_episodes`.

    Draws exactly what :meth:`~flatbody_env.env.task.ReachStationaryEllipse.sample_target` followed by
    :meth:`~flatbody_env.env.task.ReachStationaryEllipse.sample_initial_state` draw from the same
    generators, and leaves each generator where they would: a block of :data:`DRAWS` uniforms is
    drawn ahead, the generator is put back to its state before the block and advanced by the
    uniforms the episode used. Applies (:attr:`applies`) to built-in, in-plane isotropic potentials
    with the thickness potential (ϱ* constant) when reachability is decided by the settling-rate table
    or not filtered; otherwise the caller uses the task's methods.

    Parameters
    ----------
    task : ReachStationaryEllipse
    body : Body
    limits : (4,) control limits
    control : str
    kernels : module
        :mod:`flatbody_env.env.compiled` (compiled) or this module (plain Python): ``sample_episodes``;
        handed in by the caller (this module imports neither :mod:`~flatbody_env.env.compiled` nor anything above it).
    """

    DRAWS = 3 * 32 + 10
    """Uniforms drawn ahead per body (32 candidate shapes; about 5 are needed on average)."""

    def __init__(self, task, body, limits, control: str, kernels) -> None:
        self.task, self.body, self.control, self.kernels = task, body, control, kernels
        self._compiled = kernels.__name__ != __name__
        self.limits = np.asarray(limits, dtype=float)
        filtered = task.filter_applies(control)
        table = task.table_for(body, self.limits, control) if filtered else None
        self.applies = bool(
            task.compiled_targets
            and body.compiled
            and body.inertia.is_isotropic
            and body.thickness is not None
            and (table is not None or not filtered)
        )
        """Whether resets go through the kernels (class docstring)."""
        if not self.applies:
            return
        mode = 1.0 if table is not None else 2.0
        (l0, l1), (a0, a1) = task.target_lambda, task.target_aspect
        self.cfg = np.array(
            [
                l0,
                l1,
                a0,
                a1,
                task.min_settling_rate,
                mode,
                task.initial_noise,
                1.0 if "torque" in control else 0.0,
                equilibrium_thickness(body, l0, l0 / a1),
                *task.sampler_settings(),
            ]
        )
        assert self.cfg.size == CFG_SIZE
        self.P = np.ascontiguousarray(body.kernel_params(), dtype=np.float64)
        if table is not None:
            self.table = table.kernel_arrays()
        else:  # never read (mode 2): arrays of the right types
            self.table = (
                np.zeros(6),
                np.zeros((2, 2)),
                np.zeros((1, 1)),
                np.zeros((1, 1), np.uint8),
                np.zeros((1, 1)),
                np.zeros((1, 1)),
                np.full((1, 1), -1, np.int64),
                np.zeros((1, 2, 2)),
                np.zeros((1, 1, 1)),
            )
        self._pot = np.empty((7, 4))
        self.refills = 0
        """Bodies that needed more uniforms than the block drawn ahead (a diagnostic count)."""

    def __getstate__(self):
        state = dict(self.__dict__)
        state["kernels"] = self.kernels.__name__  # a module: pickled by name, re-imported on unpickling
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        # by the name the caller's module had: this module never names :mod:`.compiled`, which imports it
        # (no import circle; the caller hands the kernels in)
        self.kernels = importlib.import_module(state["kernels"])

    def sample(self, rngs, Y: np.ndarray, cols) -> np.ndarray:
        """Draw one episode per generator in ``rngs``: body b's initial state into column ``cols[b]``
        of ``Y`` (11, N); returns the targets (m, 6) = (λ*, μ*, ϱ*, s3*, p_θ*, sign of (s3*, p_θ*)).

        Raises
        ------
        ValueError
            As :meth:`~flatbody_env.env.task.ReachStationaryEllipse.sample_target` when no target is
            found in :data:`MAX_ATTEMPTS` candidates.
        """
        if not self.applies:
            raise RuntimeError(
                "EpisodeSampler.sample: this configuration draws through the task's methods (see applies)"
            )
        m = len(rngs)
        cols = np.asarray(cols, dtype=np.int64)
        D = np.empty((m, self.DRAWS))
        states = []
        for b, rng in enumerate(rngs):
            states.append(rng.bit_generator.state)
            rng.random(out=D[b])
        counts = np.full(m, self.DRAWS, dtype=np.int64)
        decisions = np.zeros((m, MAX_ATTEMPTS), dtype=np.int64)
        TG = np.empty((m, 6))
        used = np.empty(m, dtype=np.int64)
        codes = np.empty(m, dtype=np.int64)
        cand = np.empty((m, 10))
        self.kernels.sample_episodes(
            D, counts, self.cfg, self.P, *self.table, decisions, Y, cols, TG, used, self._pot, codes, cand
        )
        for b in np.flatnonzero(used < 0):
            row = D[b : b + 1]
            while used[b] < 0:
                if used[b] == NO_TARGET:
                    raise ValueError(self.task.no_target_message)
                if used[b] == NEED_MORE:  # a long run of rejections: draw enough for every attempt
                    rngs[b].bit_generator.state = states[b]
                    row = rngs[b].random((1, 3 * MAX_ATTEMPTS + 10))
                    self.refills += 1
                    counts[b] = row.shape[1]
                else:  # NEED_DECISION: the exact test for candidate codes[b]
                    c = cand[b]
                    y = target_state(c[0], c[1], c[2], c[3], c[4])
                    rate = settling_rate(self.body, y, self.limits, np.ones(4, dtype=bool))
                    decisions[b, codes[b]] = DECIDE_ACCEPT if rate >= self.task.min_settling_rate else DECIDE_REJECT
                self.kernels.sample_episodes(
                    row,
                    counts[b : b + 1],
                    self.cfg,
                    self.P,
                    *self.table,
                    decisions[b : b + 1],
                    Y,
                    cols[b : b + 1],
                    TG[b : b + 1],
                    used[b : b + 1],
                    self._pot,
                    codes[b : b + 1],
                    cand[b : b + 1],
                )
        for b, rng in enumerate(rngs):
            rng.bit_generator.state = states[b]
            rng.random(int(used[b]))
        return TG


__all__ = [
    "BALL_DRAWS",
    "CFG_SIZE",
    "DECIDE_ACCEPT",
    "EpisodeSampler",
    "DECIDE_REJECT",
    "HYPERBOLIC",
    "MAX_ATTEMPTS",
    "NEED_DECISION",
    "NEED_MORE",
    "NO_TARGET",
    "STABLE",
    "START_BALL",
    "START_NOISE",
    "START_NONE",
    "ball_state_kernel",
    "candidate_kernel",
    "initial_state_kernel",
    "potential_stencil_kernel",
    "sample_episode_kernel",
    "sample_episodes",
]

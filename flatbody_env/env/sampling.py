"""The reset's draws as plain-float kernels: a target and an initial state from uniforms.

:meth:`~flatbody_env.env.task.ReachStationaryEllipse.sample_target` and
:meth:`~flatbody_env.env.task.ReachStationaryEllipse.sample_initial_state` (the v0 ids' draws) take their
uniforms from a numpy ``Generator``: three per candidate target shape, then ten (nine without torque) for the
initial state; the v1 ids' draws (:func:`flatbody_env.env.transition.draw_body`) take theirs from a counter-based
stream. The formulas both apply to those numbers live once, as plain-float kernels — the settling-rate table's
:func:`~flatbody_env.env.targets.decide_kernel`, the inverse problem and stability test
:func:`~flatbody_env.physics.equilibria.stationary_shape_kernel`, :func:`initial_state_kernel` and
:func:`ball_state_kernel`. :func:`candidate_kernel` is the candidate loop's body of ``sample_target`` (which also
serves bodies these kernels do not: custom potentials, a thickness found by root finding) for the compiled draws;
the tests hold it to ``sample_target``'s choices on the same uniforms, bit for bit. :func:`draw_config` gives the
compiled draws their configuration.

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

import math

import numpy as np

from flatbody_env.env.targets import ACCEPT, REJECT, UNSURE, decide_kernel
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


def normal_pair(u, k):
    """Two standard normals from the uniforms ``u[2k]``, ``u[2k + 1]`` by the Box–Muller transform:
    √(−2 ln(1 − u₂ₖ)) (cos, sin)(2π u₂ₖ₊₁)."""
    r = math.sqrt(-2.0 * math.log(1.0 - u[2 * k]))
    return r * math.cos(2.0 * math.pi * u[2 * k + 1]), r * math.sin(2.0 * math.pi * u[2 * k + 1])


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
    z0, z1 = normal_pair(u, 0)
    z2, z3 = normal_pair(u, 1)
    z4, z5 = normal_pair(u, 2)
    z6, z7 = normal_pair(u, 3)
    z8, _ = normal_pair(u, 4)
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


def draw_config(task, body, limits, control: str) -> np.ndarray | None:
    """The configuration vector ``cfg`` (:data:`CFG_SIZE`, module docstring) of the compiled draws of ``task`` for
    ``body``, the control ``limits`` (4,) and ``control``, or None where they do not apply: they need a built-in,
    in-plane isotropic potential with the thickness potential (ϱ* constant), and reachability decided by the
    settling-rate table or not filtered (elsewhere the task's Python methods draw)."""
    limits = np.asarray(limits, dtype=float)
    filtered = task.filter_applies(control)
    table = task.table_for(body, limits, control) if filtered else None
    if not (
        task.compiled_targets
        and body.compiled
        and body.inertia.is_isotropic
        and body.thickness is not None
        and (table is not None or not filtered)
    ):
        return None
    (l0, l1), (a0, a1) = task.target_lambda, task.target_aspect
    cfg = np.array(
        [
            l0, l1, a0, a1, task.min_settling_rate, 1.0 if table is not None else 2.0, task.initial_noise,
            1.0 if "torque" in control else 0.0, equilibrium_thickness(body, l0, l0 / a1), *task.sampler_settings(),
        ]
    )  # fmt: skip
    assert cfg.size == CFG_SIZE
    return cfg


__all__ = [
    "BALL_DRAWS",
    "CFG_SIZE",
    "HYPERBOLIC",
    "MAX_ATTEMPTS",
    "STABLE",
    "START_BALL",
    "START_NOISE",
    "START_NONE",
    "ball_state_kernel",
    "candidate_kernel",
    "initial_state_kernel",
    "draw_config",
    "potential_stencil_kernel",
]

"""Independent oracles of the test suite, in one place.

Each oracle computes a quantity a different way from the package (matrices instead of closed
forms, finite differences instead of derivatives, the paper's printed equations verbatim), so a
test that compares the two can fail.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_continuous_are

from flatbody_env.physics.body import Body
from flatbody_env.physics.hamiltonian import VELOCITY_NAMES
from flatbody_env.physics.kinematics import configuration_rate


def independent_mass_matrix(y: np.ndarray, body: Body) -> np.ndarray:
    """M_ij = Tr(J A_iᵀ A_j) with A_i = ∂Φ̇/∂v_i from eq. (27) of the paper (matrices, not eq. (30))."""
    lam, mu, rho, theta = y[7:11]
    E = np.eye(7)
    A = configuration_rate(lam, mu, rho, theta, {name: E[:, i] for i, name in enumerate(VELOCITY_NAMES)})
    J = body.inertia.matrix
    AtA = np.einsum("iba,jbc->ijac", A, A)  # (A_iᵀ A_j)_ac
    M = np.einsum("ca,ijac->ij", J, AtA)  # Tr(J A_iᵀ A_j)
    return 0.5 * (M + M.T)


def independent_hamiltonian(y: np.ndarray, body: Body) -> float:
    """H = ½ pᵀ M⁻¹ p + V with M built from matrices (independent of the closed forms)."""
    M = independent_mass_matrix(y, body)
    p = y[:7]
    return 0.5 * p @ np.linalg.solve(M, p) + body.potential_terms(y[7], y[8], y[9])[0]


def hamilton_rhs(y: np.ndarray, body: Body, h: float = 1e-4) -> np.ndarray:
    """Hamilton's equations with ∂H by the five-point central difference (error O(h⁴))."""
    g = np.empty(11)
    H = independent_hamiltonian
    for i in range(11):
        e = np.zeros(11)
        e[i] = h
        g[i] = (8 * (H(y + e, body) - H(y - e, body)) - (H(y + 2 * e, body) - H(y - 2 * e, body))) / (12 * h)
    omega, s = g[:3], y[:3]
    # order: s (3), p_θ, p_λ, p_μ, p_ϱ, λ, μ, ϱ, θ
    return np.concatenate([np.cross(omega, s), -g[[10, 7, 8, 9]], g[[4, 5, 6, 3]]])


def printed_eqs_44_46(y: np.ndarray, J: float, J3: float) -> np.ndarray:
    """ds/dt exactly as printed in eqs. (44)–(46) of the paper (with ρ read as ϱ)."""
    s1, s2, s3, pt = y[0], y[1], y[2], y[3]
    lam, mu, rho = y[7], y[8], y[9]
    D2 = J * (lam**2 - mu**2) ** 2
    ds1 = (
        s2
        / D2
        * (
            (J * mu**2 * (3 * lam**2 - mu**2) + J3 * rho**2 * (lam**2 + mu**2)) / (J * lam**2 + J3 * rho**2) * s3
            - 2 * lam * mu * pt
        )
    )
    ds2 = (
        s1
        / D2
        * (
            (J * lam**2 * (lam**2 - 3 * mu**2) - J3 * rho**2 * (lam**2 + mu**2)) / (J * mu**2 + J3 * rho**2) * s3
            + 2 * lam * mu * pt
        )
    )
    ds3 = J * (mu**2 - lam**2) * s1 * s2 / ((J * lam**2 + J3 * rho**2) * (J * mu**2 + J3 * rho**2))
    return np.array([ds1, ds2, ds3])


def printed_eqs_47_49(y: np.ndarray, J: float, J3: float, body: Body) -> np.ndarray:
    """dp/dt exactly as printed in eqs. (47)–(49) (correct as printed, NOTES §2)."""
    s1, s2, s3, pt = y[0], y[1], y[2], y[3]
    lam, mu, rho = y[7], y[8], y[9]
    _, gl, gm, gr = body.potential_terms(lam, mu, rho)
    D3 = J * (lam**2 - mu**2) ** 3
    q = s3**2 + pt**2
    dpl = (
        -gl
        + J * lam * s2**2 / (J * lam**2 + J3 * rho**2) ** 2
        + (lam * (lam**2 + 3 * mu**2) * q - 2 * mu * (mu**2 + 3 * lam**2) * s3 * pt) / D3
    )
    dpm = (
        -gm
        + J * mu * s1**2 / (J * mu**2 + J3 * rho**2) ** 2
        - (mu * (mu**2 + 3 * lam**2) * q - 2 * lam * (lam**2 + 3 * mu**2) * s3 * pt) / D3
    )
    dpr = -gr + J3 * rho * s1**2 / (J * mu**2 + J3 * rho**2) ** 2 + J3 * rho * s2**2 / (J * lam**2 + J3 * rho**2) ** 2
    return np.array([dpl, dpm, dpr])


def lqr_rate(A, B, Q, R):
    """(slowest closed-loop decay rate, gain K) of the LQR for ẋ = Ax + Bu (scipy's Riccati solver)."""
    P = solve_continuous_are(A, B, Q, R)
    K = np.linalg.solve(R, B.T @ P)
    return -np.max(np.linalg.eigvals(A - B @ K).real), K


# --- the reward, the distance and the domain as documented (docs/env.md, docs/tasks.md) --------------------
# Written from the docs' tables, not from flatbody_env.env's kernels: the weights are the documented numbers
# (never read from the env), ω1, ω2 come from the mass matrix of eq. (27) (velocities v = M⁻¹p), norms by
# numpy.linalg.norm. A test comparing the env's terms with these fails when a weight, a sign or a formula moves.
DOCUMENTED_WEIGHTS = {"shape": 1.0, "spin": 0.5, "tumble": 0.5, "rest": 0.5, "action": 0.05, "failure": 10.0}
"""docs/env.md's reward row: shape −‖(Δλ, Δμ, Δϱ)‖, spin −0.5|Δs3|, tumble −0.5‖(ω1, ω2)‖, rest −0.5‖(p_λ, p_μ, p_ϱ)‖,
action −0.05‖a‖², failure −10 on a failing step (every task of docs/tasks.md)."""
DOCUMENTED_ALIVE = 1.0
"""docs/tasks.md, FlatBodyHoldUnstable-v0: ``alive`` +1 on every step that does not end the episode."""
DOCUMENTED_TOLERANCE = 0.05
"""docs/env.md: success is distance ≤ 0.05."""
DOCUMENTED_DOMAIN = {"stretch": (0.2, 4.0), "rho": (0.1, 4.0), "momentum": 50.0, "gap": 1e-3}
"""docs/env.md's episode end: λ, μ ∈ [0.2, 4], ϱ ∈ [0.1, 4], |s|, |p| ≤ 50 (entry by entry), and for two-polar
integrators |λ − μ|/(λ + μ) ≥ 1e-3."""


def _columns(y) -> np.ndarray:
    """State(s) as (11, N) float64."""
    y = np.asarray(y, dtype=np.float64)
    return y.reshape(11, -1)


def tumble_rates(y, body: Body) -> np.ndarray:
    """(ω1, ω2) of state(s) ``y`` (11,) or (11, N), shape (2, N): the first two velocities v = M⁻¹p with M from
    matrices (:func:`independent_mass_matrix`), not the closed inverse Legendre map the env uses."""
    Y = _columns(y)
    out = np.empty((2, Y.shape[1]))
    for k in range(Y.shape[1]):
        v = np.linalg.solve(independent_mass_matrix(Y[:, k], body), Y[:7, k])
        out[:, k] = v[:2]
    return out


def documented_distance(y, target, body: Body) -> np.ndarray:
    """d = ‖(Δλ, Δμ, Δϱ, Δs3, ω1, ω2, p_λ, p_μ, p_ϱ)‖ (docs/env.md, success), shape (N,)."""
    Y = _columns(y)
    T = np.asarray(target, dtype=np.float64).reshape(4, -1)
    w = tumble_rates(Y, body)
    e = np.stack([Y[7] - T[0], Y[8] - T[1], Y[9] - T[2], Y[2] - T[3], w[0], w[1], Y[4], Y[5], Y[6]])
    return np.linalg.norm(e, axis=0)


def documented_reward_terms(y, target, action, ended, body: Body, *, weights=None, alive=None) -> dict[str, np.ndarray]:
    """Each reward term of docs/env.md (and ``alive`` of docs/tasks.md when ``alive`` is a weight), arrays (N,).

    ``y`` (11,) or (11, N): the state the step keeps; ``target`` (4,) or (4, N): (λ*, μ*, ϱ*, s3*); ``action``
    (n,) or (N, n): the raw action (clipped to [−1, 1] here, "before scaling"); ``ended``: bool or (N,), the step
    ends the episode by failure (integrator, domain, or the ball of the hold task); ``weights``: the keywords'
    values (default :data:`DOCUMENTED_WEIGHTS`).
    """
    w = dict(DOCUMENTED_WEIGHTS, **(weights or {}))
    Y = _columns(y)
    n = Y.shape[1]
    T = np.asarray(target, dtype=np.float64).reshape(4, -1)
    A = np.clip(np.asarray(action, dtype=np.float64).reshape(n, -1), -1.0, 1.0)
    ended = np.broadcast_to(np.asarray(ended, dtype=bool), (n,))
    om = tumble_rates(Y, body)
    terms = {
        "shape": -w["shape"] * np.linalg.norm(Y[7:10] - T[0:3], axis=0),
        "spin": -w["spin"] * np.abs(Y[2] - T[3]),
        "tumble": -w["tumble"] * np.linalg.norm(om, axis=0),
        "rest": -w["rest"] * np.linalg.norm(Y[4:7], axis=0),
        "action": -w["action"] * np.einsum("ki,ki->k", A, A),
        "failure": np.where(ended, -w["failure"], 0.0),
    }
    if alive is not None:
        terms["alive"] = np.where(ended, 0.0, alive)
    return terms


DOCUMENTED_TOLERANCE_REWARD = {"beta": 0.2, "margin": 0.5}
"""docs/env.md, the v1 ids' reward: ``success`` = (1 − β) within the tolerance, ``proximity`` = β·g(d), g = 1 within
the tolerance and exp(−ln 10·((d − tol)/m)²) outside; both 0 on a step that ends the episode by failure."""


def documented_tolerance_terms(y, target, ended, body: Body) -> dict[str, np.ndarray]:
    """The v1 ids' reward terms (:data:`DOCUMENTED_TOLERANCE_REWARD`) of the state(s) ``y`` the step keeps, arrays (N,);
    ``ended``: the step ends the episode by failure (integrator, domain, or the hold task's ball)."""
    b, m, tol = DOCUMENTED_TOLERANCE_REWARD["beta"], DOCUMENTED_TOLERANCE_REWARD["margin"], DOCUMENTED_TOLERANCE
    d = documented_distance(y, target, body)
    alive = ~np.broadcast_to(np.asarray(ended, dtype=bool), d.shape)
    g = np.where(d <= tol, 1.0, 10.0 ** (-(((d - tol) / m) ** 2)))
    return {"success": np.where(alive & (d <= tol), 1.0 - b, 0.0), "proximity": np.where(alive, b * g, 0.0)}


def documented_in_domain(y, *, two_polar: bool) -> np.ndarray:
    """Whether state(s) ``y`` lie in docs/env.md's domain, shape (N,)."""
    Y = _columns(y)
    d = DOCUMENTED_DOMAIN
    with np.errstate(invalid="ignore"):
        ok = np.all(np.isfinite(Y), axis=0)
        for i, (lo, hi) in ((7, d["stretch"]), (8, d["stretch"]), (9, d["rho"])):
            ok &= (Y[i] >= lo) & (Y[i] <= hi)
        ok &= np.all(np.abs(Y[:7]) <= d["momentum"], axis=0)
        if two_polar:
            ok &= np.abs(Y[7] - Y[8]) >= d["gap"] * (Y[7] + Y[8])
    return ok

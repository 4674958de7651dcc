"""The energy the controls put into the body: the power P = ω·τ + ϱ̇ f_ϱ and its integral, the work W.

Hamilton's equations (the equations of motion, eqs. 44–49 of the paper, spin bracket corrected) with the
controls u = (τ1, τ2, τ3, f_ϱ) (:mod:`flatbody_env.physics.equations`;
docs/physics.md §4, "Controls") are ṡ = ω × s + τ with ω = ∂H/∂s, and ṗ_ϱ = −∂H/∂ϱ + f_ϱ. Along a
motion the free part conserves H (ω·(ω × s) = 0 and the canonical pairs cancel), so

    dH/dt = ∂H/∂s · τ + ∂H/∂p_ϱ · f_ϱ = ω·τ + ϱ̇ f_ϱ = P,

and H(t) − H(0) = W(t) = ∫₀ᵗ P dt. An env holds u constant over each step [t_{k−1}, t_k]; the work of
one step is computed with the corrected trapezoidal rule (Euler–Maclaurin with the end-point
derivatives, error O(h⁵) per step):

    ΔW_k = h/2 (P_a + P_b) + h²/12 (Ṗ_a − Ṗ_b),

where P_a, P_b are the power at the step's two ends under the step's u and Ṗ = ∇_y P · ẏ(y, u) is
taken by a central difference along the flow. ``tests/recording/test_work.py`` checks H(t) − H(0) = W
against an independent fine quadrature of a controlled episode.

Pure numpy; no rerun.
"""

from __future__ import annotations

import numpy as np


def _velocities(Y: np.ndarray, body) -> tuple[np.ndarray, np.ndarray]:
    """ω (n, 3) and ϱ̇ (n,) of the states ``Y`` (11, n): ∂H/∂s and ∂H/∂p_ϱ."""
    from flatbody_env.physics.hamiltonian import kinetic_iso, kinetic_kernel

    Y = np.asarray(Y, dtype=np.float64)
    P = body.kernel_params()
    if P[0] == P[1]:
        with np.errstate(all="ignore"):
            _, w1, w2, w3, _, _, _, rd, _, _, _ = kinetic_iso(*(Y[i] for i in range(10)), float(P[0]), float(P[2]))
        return np.stack(
            [np.broadcast_to(w1, Y.shape[1:]), np.broadcast_to(w2, Y.shape[1:]), np.broadcast_to(w3, Y.shape[1:])],
            axis=-1,
        ), np.asarray(rd, dtype=np.float64)
    n = Y.shape[1]
    w = np.empty((n, 3))
    rd = np.empty(n)
    vel, force = np.empty(7), np.empty(4)
    for k in range(n):
        kinetic_kernel(np.ascontiguousarray(Y[:, k]), P, vel, force)
        w[k] = vel[:3]
        rd[k] = vel[6]
    return w, rd


def control_power(Y: np.ndarray, U: np.ndarray, body) -> np.ndarray:
    """P = ω·τ + ϱ̇ f_ϱ of the states ``Y`` (11, n) under the controls ``U`` (n, 4) → (n,)."""
    U = np.asarray(U, dtype=np.float64).reshape(-1, 4)
    w, rd = _velocities(Y, body)
    return np.einsum("ij,ij->i", w, U[:, :3]) + rd * U[:, 3]


def _flow(Y: np.ndarray, U: np.ndarray, body) -> np.ndarray:
    """ẏ (11, n) of the states ``Y`` under the controls ``U`` (n, 4)."""
    from flatbody_env.physics.equations import rhs, rhs_iso

    P = body.kernel_params()
    if P[0] == P[1]:
        _, gl, gm, gr = body.potential_terms(Y[7], Y[8], Y[9])
        with np.errstate(all="ignore"):
            out = rhs_iso(
                *(Y[i] for i in range(10)),
                U[:, 0],
                U[:, 1],
                U[:, 2],
                U[:, 3],
                float(P[0]),
                float(P[2]),
                float(P[8]),
                gl,
                gm,
                gr,
            )
        return np.stack([np.broadcast_to(np.asarray(v, dtype=np.float64), Y.shape[1:]) for v in out[:11]])
    return np.stack([rhs(0.0, np.ascontiguousarray(Y[:, k]), U[k], body) for k in range(Y.shape[1])], axis=1)


def power_rate(Y: np.ndarray, U: np.ndarray, body) -> np.ndarray:
    """dP/dt along the flow under ``U`` (held constant), by a central difference along ẏ → (n,)."""
    Y = np.asarray(Y, dtype=np.float64)
    U = np.asarray(U, dtype=np.float64).reshape(-1, 4)
    f = _flow(Y, U, body)
    size = np.maximum(np.abs(Y).max(axis=0), 1.0)
    speed = np.maximum(np.abs(f).max(axis=0), 1e-300)
    eps = 1e-5 * size / speed  # a step of ~1e-5 of the state's size
    return (control_power(Y + eps * f, U, body) - control_power(Y - eps * f, U, body)) / (2.0 * eps)


def step_work(t_a, Y_a, t_b, Y_b, U, body) -> np.ndarray:
    """Work of the controls over steps [t_a, t_b] with u = ``U`` (n, 4) held constant, from the states at
    both ends (11, n each): the corrected trapezoidal rule of the module docstring → (n,)."""
    U = np.asarray(U, dtype=np.float64).reshape(-1, 4)
    h = np.asarray(t_b, dtype=np.float64) - np.asarray(t_a, dtype=np.float64)
    Pa, Pb = control_power(Y_a, U, body), control_power(Y_b, U, body)
    dPa, dPb = power_rate(Y_a, U, body), power_rate(Y_b, U, body)
    return 0.5 * h * (Pa + Pb) + h * h / 12.0 * (dPa - dPb)

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
    ds1 = s2 / D2 * ((J * mu**2 * (3 * lam**2 - mu**2) + J3 * rho**2 * (lam**2 + mu**2)) / (J * lam**2 + J3 * rho**2) * s3 - 2 * lam * mu * pt)
    ds2 = s1 / D2 * ((J * lam**2 * (lam**2 - 3 * mu**2) - J3 * rho**2 * (lam**2 + mu**2)) / (J * mu**2 + J3 * rho**2) * s3 + 2 * lam * mu * pt)
    ds3 = J * (mu**2 - lam**2) * s1 * s2 / ((J * lam**2 + J3 * rho**2) * (J * mu**2 + J3 * rho**2))
    return np.array([ds1, ds2, ds3])


def printed_eqs_47_49(y: np.ndarray, J: float, J3: float, body: Body) -> np.ndarray:
    """dp/dt exactly as printed in eqs. (47)–(49) (correct as printed, NOTES §2)."""
    s1, s2, s3, pt = y[0], y[1], y[2], y[3]
    lam, mu, rho = y[7], y[8], y[9]
    _, gl, gm, gr = body.potential_terms(lam, mu, rho)
    D3 = J * (lam**2 - mu**2) ** 3
    q = s3**2 + pt**2
    dpl = -gl + J * lam * s2**2 / (J * lam**2 + J3 * rho**2) ** 2 + (lam * (lam**2 + 3 * mu**2) * q - 2 * mu * (mu**2 + 3 * lam**2) * s3 * pt) / D3
    dpm = -gm + J * mu * s1**2 / (J * mu**2 + J3 * rho**2) ** 2 - (mu * (mu**2 + 3 * lam**2) * q - 2 * lam * (lam**2 + 3 * mu**2) * s3 * pt) / D3
    dpr = -gr + J3 * rho * s1**2 / (J * mu**2 + J3 * rho**2) ** 2 + J3 * rho * s2**2 / (J * lam**2 + J3 * rho**2) ** 2
    return np.array([dpl, dpm, dpr])


def lqr_rate(A, B, Q, R):
    """(slowest closed-loop decay rate, gain K) of the LQR for ẋ = Ax + Bu (scipy's Riccati solver)."""
    P = solve_continuous_are(A, B, Q, R)
    K = np.linalg.solve(R, B.T @ P)
    return -np.max(np.linalg.eigvals(A - B @ K).real), K

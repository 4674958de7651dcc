"""Kinematics of the flat body: Φ = R D U(θ)⁻¹, its rates, and the deformation tensors G and C.

All functions broadcast over leading dimensions: scalars give (3, 3) matrices, arrays of
shape (n,) give (n, 3, 3).

============================  ==========================================================
function                      formula (equation of [1]; correction in [2])
============================  ==========================================================
:func:`material_rotation`     U(θ) with U(θ)⁻¹ = [[c, s, 0], [−s, c, 0], [0, 0, 1]], eq. (24)
:func:`configuration`         Φ = R D U⁻¹, D = diag(λ, μ, ϱ), eqs. (23)–(24)
:func:`configuration_rate`    Φ̇ = R (Ḋ + W(ω) D − D ϑ) U⁻¹, eq. (27)
:func:`kirchhoff_love_residual`  Φ₃ − ℓ Φ₁ × Φ₂ with ℓ = ϱ/(λμ), eqs. (21)–(22)
:func:`green_tensor`          G = ΦᵀΦ = U D² U⁻¹, eq. (33)
:func:`cauchy_tensor`         C = Φ⁻ᵀΦ⁻¹ = R D⁻² R⁻¹ (eq. (51)'s remark, erratum E7)
:func:`deformation_invariants`  eigenvalues λ², μ², ϱ² of G, eqs. (34)–(35)
:func:`green_rate`            Ġ = U (ϑD² − D²ϑ + 2DḊ) U⁻¹, eq. (51) (+ the Ḋ term)
:func:`cauchy_rate`           Ċ = R (W D⁻² − D⁻² W − 2D⁻³Ḋ) R⁻¹, eq. (51) with E7
:func:`decompose`             Φ → (R, λ, μ, ϱ, θ), inverse of eq. (23) (docs/physics.md §7)
:func:`stretches_kernel`      λ ≥ μ, ϱ from the invariants of ΦᵀΦ, eqs. (34)–(35) (a plain-float kernel)
:func:`decompose_kernel`      :func:`decompose` with a reference, in closed form (a plain-float kernel)
============================  ==========================================================

:func:`column_dot`, :func:`stretches_kernel` and :func:`decompose_kernel` are plain-float kernels on the packed columns
q = (φ1, φ2, ψ) (9,) of Φ — no numpy calls beyond ``np.empty``, so that the compiled integrators
compile this very code (:func:`flatbody_env.integrators.jit.retarget`).

W(ω) is eq. (25) of [1], [[0, ω3, −ω2], [−ω3, 0, ω1], [ω2, −ω1, 0]] = −hat(ω), and
ϑ = U⁻¹U̇ = θ̇ [[0, −1, 0], [1, 0, 0], [0, 0, 0]] (eq. (26)).

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_J = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
QUARTER_TURN = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
HALF_TURN = np.diag([-1.0, -1.0, 1.0])


def _diag(a, b, c) -> np.ndarray:
    a, b, c = np.broadcast_arrays(*(np.asarray(x, float) for x in (a, b, c)))
    D = np.zeros(a.shape + (3, 3))
    D[..., 0, 0] = a
    D[..., 1, 1] = b
    D[..., 2, 2] = c
    return D


def _identity_like(shape) -> np.ndarray:
    return np.broadcast_to(np.eye(3), tuple(shape) + (3, 3)).copy()


def _T(M: np.ndarray) -> np.ndarray:
    return np.swapaxes(M, -1, -2)


def material_rotation(theta) -> np.ndarray:
    """U(θ) ∈ SO(3), the inverse of eq. (24)'s U(θ)⁻¹: [[c, −s, 0], [s, c, 0], [0, 0, 1]]."""
    theta = np.asarray(theta, float)
    c, s = np.cos(theta), np.sin(theta)
    U = np.zeros(theta.shape + (3, 3))
    U[..., 0, 0] = c
    U[..., 0, 1] = -s
    U[..., 1, 0] = s
    U[..., 1, 1] = c
    U[..., 2, 2] = 1.0
    return U


def omega_matrix(omega) -> np.ndarray:
    """W(ω) of eq. (25) of [1] from ω of shape (..., 3)."""
    omega = np.asarray(omega, float)
    w1, w2, w3 = omega[..., 0], omega[..., 1], omega[..., 2]
    W = np.zeros(omega.shape[:-1] + (3, 3))
    W[..., 0, 1] = w3
    W[..., 0, 2] = -w2
    W[..., 1, 0] = -w3
    W[..., 1, 2] = w1
    W[..., 2, 0] = w2
    W[..., 2, 1] = -w1
    return W


def configuration(lam, mu, rho, theta, R=None) -> np.ndarray:
    """Φ = R D(λ, μ, ϱ) U(θ)⁻¹ (eqs. (23)–(24) of [1]); R defaults to the identity."""
    D = _diag(lam, mu, rho)
    U = material_rotation(np.broadcast_to(np.asarray(theta, float), D.shape[:-2]))
    R = _identity_like(D.shape[:-2]) if R is None else np.asarray(R, float)
    return R @ D @ _T(U)


def configuration_rate(lam, mu, rho, theta, velocities, R=None) -> np.ndarray:
    """Φ̇ = R (Ḋ + W(ω) D − D ϑ) U⁻¹ (eq. (27) of [1]).

    ``velocities`` is a mapping with ``omega1, omega2, omega3, theta_dot, lambda_dot, mu_dot,
    rho_dot`` (see :data:`flatbody_env.physics.hamiltonian.VELOCITY_NAMES`).
    """
    v = velocities
    D = _diag(lam, mu, rho)
    Dd = _diag(v["lambda_dot"], v["mu_dot"], v["rho_dot"])
    W = omega_matrix(np.stack(np.broadcast_arrays(v["omega1"], v["omega2"], v["omega3"]), axis=-1))
    theta_dot = np.asarray(v["theta_dot"], float)
    shape = np.broadcast_shapes(D.shape[:-2], W.shape[:-2], theta_dot.shape)
    vartheta = theta_dot[..., None, None] * _J
    U = material_rotation(np.broadcast_to(np.asarray(theta, float), shape))
    R = _identity_like(shape) if R is None else np.asarray(R, float)
    return R @ (Dd + W @ D - D @ vartheta) @ _T(U)


def kirchhoff_love_residual(Phi: np.ndarray, lam=None, mu=None, rho=None) -> np.ndarray:
    """Residual of eq. (21) of [1]: Φ₃ − ℓ ε Φ₁ Φ₂ with ℓ = ϱ/(λμ) (eq. (22)), shape (..., 3).

    Without (λ, μ, ϱ) given, ℓ is taken from Φ itself: ℓ = |Φ₃| / |Φ₁ × Φ₂|.
    """
    Phi = np.asarray(Phi, float)
    cross = np.cross(Phi[..., :, 0], Phi[..., :, 1])
    if lam is None:
        ell = np.linalg.norm(Phi[..., :, 2], axis=-1) / np.linalg.norm(cross, axis=-1)
    else:
        ell = np.asarray(rho, float) / (np.asarray(lam, float) * np.asarray(mu, float))
    return Phi[..., :, 2] - ell[..., None] * cross


def green_tensor(lam, mu, rho, theta) -> np.ndarray:
    """Green deformation tensor G = ΦᵀΦ = U D² U⁻¹ (eq. (33) of [1]); independent of R."""
    U = material_rotation(theta)
    return U @ _diag(np.square(lam), np.square(mu), np.square(rho)) @ _T(U)


def cauchy_tensor(lam, mu, rho, R) -> np.ndarray:
    """Cauchy deformation tensor C = Φ⁻ᵀΦ⁻¹ = R D⁻² R⁻¹ (eq. (51)'s remark, erratum E7 of [2])."""
    R = np.asarray(R, float)
    D2 = _diag(1.0 / np.square(lam), 1.0 / np.square(mu), 1.0 / np.square(rho))
    return R @ D2 @ _T(R)


def deformation_invariants(G: np.ndarray) -> np.ndarray:
    """The deformation invariants 𝒦 of eq. (34) of [1]: eigenvalues of G, ascending, shape (..., 3).

    By eq. (35) of [1] they are {λ², μ², ϱ²}: insensitive to both R and U.
    """
    return np.linalg.eigvalsh(np.asarray(G, float))


def green_rate(lam, mu, rho, theta, theta_dot, lambda_dot=0.0, mu_dot=0.0, rho_dot=0.0) -> np.ndarray:
    """dG/dt = U (ϑ D² − D² ϑ + 2 D Ḋ) U⁻¹ (eq. (51) of [1]; the Ḋ term vanishes at a stationary ellipse)."""
    D = _diag(lam, mu, rho)
    D2 = D @ D
    Dd = _diag(lambda_dot, mu_dot, rho_dot)
    vartheta = np.asarray(theta_dot, float)[..., None, None] * _J
    U = material_rotation(theta)
    return U @ (vartheta @ D2 - D2 @ vartheta + 2.0 * D @ Dd) @ _T(U)


def cauchy_rate(lam, mu, rho, R, omega, lambda_dot=0.0, mu_dot=0.0, rho_dot=0.0) -> np.ndarray:
    """dC/dt = R (W D⁻² − D⁻² W − 2 D⁻³ Ḋ) R⁻¹ (eq. (51) of [1] with erratum E7 of [2])."""
    Di2 = _diag(1.0 / np.square(lam), 1.0 / np.square(mu), 1.0 / np.square(rho))
    Di3Dd = _diag(
        np.asarray(lambda_dot, float) / np.power(lam, 3),
        np.asarray(mu_dot, float) / np.power(mu, 3),
        np.asarray(rho_dot, float) / np.power(rho, 3),
    )
    W = omega_matrix(omega)
    R = np.asarray(R, float)
    return R @ (W @ Di2 - Di2 @ W - 2.0 * Di3Dd) @ _T(R)


@dataclass(frozen=True)
class Decomposition:
    """Φ = R · diag(λ, μ, ϱ) · U(θ)⁻¹ (eq. (23) of [1])."""

    R: np.ndarray
    lam: float
    mu: float
    rho: float
    theta: float


def decompose(
    Phi: np.ndarray, reference: Decomposition | None = None, *, kl_tol: float = 1e-9, keep_order: bool = False
) -> Decomposition:
    """Inverse of eq. (23) of [1]: a Kirchhoff–Love Φ → (R, λ, μ, ϱ, θ) (docs/physics.md §7).

    The thin SVD of the in-plane columns φ = [Φ₁, Φ₂] = W Σ V₂ᵀ gives λ, μ (singular values),
    U₂(θ) = V₂ ∈ SO(2), R = [w₁, w₂, w₁ × w₂] and ϱ = Φ₃ · R e₃.

    The decomposition is unique only up to (R·Q, μ, λ, θ + π/2) with Q the quarter turn about
    e₃, (R·diag(−1, −1, 1), λ, μ, θ + π), and θ + 2π. With ``reference`` the candidate nearest
    to it is returned (continuity along a trajectory); with ``keep_order`` also the sign of
    λ − μ is kept — the chart cannot cross λ = μ while σ₋ = s3 − p_θ ≠ 0 (the centrifugal
    barrier of docs/physics.md §7), it turns θ by ±π/2 instead; without ``reference``, λ ≥ μ, θ ∈ (−π, π] and of the
    two half-turn related candidates the one with R nearer the identity.

    ``kl_tol`` is the allowed violation of the Kirchhoff–Love condition relative to max|Φ|
    (``np.inf`` for trial points of an integrator, slightly off the constraint set).

    Raises
    ------
    ValueError
        If Φ is not of the constrained form with det Φ > 0, or is singular (λμϱ = 0).

    Notes
    -----
    Near λ = μ the chart's R and θ turn fast, and two candidates can be equally near the
    reference; :func:`flatbody_env.physics.regular.follow_chart` samples finely enough to avoid that.
    """
    Phi = np.asarray(Phi, float)
    if Phi.shape != (3, 3) or not np.all(np.isfinite(Phi)):
        raise ValueError("Phi: expected a finite 3×3 matrix")
    phi = Phi[:, :2]
    Wm, sig, Vt = np.linalg.svd(phi, full_matrices=False)
    V = Vt.T
    if np.linalg.det(V) < 0:
        V[:, 1] *= -1.0
        Wm[:, 1] *= -1.0
    n = np.cross(Wm[:, 0], Wm[:, 1])
    rho = float(Phi[:, 2] @ n)
    scale = float(np.max(np.abs(Phi)))
    if sig[1] <= 1e-14 * scale:
        raise ValueError("Phi: the in-plane columns are (nearly) parallel: μ = 0 is outside the domain μ > 0")
    if rho <= 0.0:
        raise ValueError("Phi: det Φ ≤ 0 — the thickness column must point along Φ₁ × Φ₂ (ϱ > 0)")
    off = np.linalg.norm(Phi[:, 2] - rho * n)
    if off > kl_tol * max(scale, 1.0):
        raise ValueError(f"Phi: violates the Kirchhoff–Love condition (eq. (21)) by {off:.3g}")
    R = np.column_stack([Wm[:, 0], Wm[:, 1], n])
    lam, mu = float(sig[0]), float(sig[1])
    theta = float(np.arctan2(V[1, 0], V[0, 0]))
    if reference is None:
        if np.trace(R) < np.trace(R @ HALF_TURN):
            R, theta = R @ HALF_TURN, theta + np.pi
        theta = float(np.arctan2(np.sin(theta), np.cos(theta)))
        return Decomposition(R=R, lam=lam, mu=mu, rho=rho, theta=theta)
    best = None
    best_score = np.inf
    for swap in (False, True):
        for half in (False, True):
            Rc, lc, mc, tc = R, lam, mu, theta
            if swap:
                Rc, lc, mc, tc = Rc @ QUARTER_TURN, mu, lam, tc + 0.5 * np.pi
            if half:
                Rc, tc = Rc @ HALF_TURN, tc + np.pi
            # nearest 2π copy of θ
            tc = tc + 2.0 * np.pi * np.round((reference.theta - tc) / (2.0 * np.pi))
            score = (
                np.linalg.norm(Rc - reference.R)
                + abs(tc - reference.theta)
                + abs(lc - reference.lam)
                + abs(mc - reference.mu)
            )
            if keep_order and (lc - mc) * (reference.lam - reference.mu) < 0.0:
                continue
            if score < best_score:
                best, best_score = Decomposition(R=Rc, lam=lc, mu=mc, rho=rho, theta=float(tc)), score
    return best


def column_dot(z, a, b):
    """z[a:a+3] · z[b:b+3], the dot product of two packed columns (plain-float kernel)."""
    return z[a] * z[b] + z[a + 1] * z[b + 1] + z[a + 2] * z[b + 2]


def stretches_kernel(z):
    """(λ, μ, ϱ) with λ ≥ μ of q = z[:9]: the eigenvalues of φᵀφ from tr and det, and ϱ = |ψ| (plain-float kernel).

    λ², μ² = tr/2 ± √((|φ1|² − |φ2|²)²/4 + (φ1·φ2)²) (eqs. (34)–(35) of [1]); μ = √det/λ.
    """
    n11 = column_dot(z, 0, 0)
    n22 = column_dot(z, 3, 3)
    n12 = column_dot(z, 0, 3)
    half = 0.5 * (n11 + n22)
    disc = math.sqrt(0.25 * (n11 - n22) ** 2 + n12 * n12)
    lam = math.sqrt(half + disc)
    det = n11 * n22 - n12 * n12
    mu = math.sqrt(det) / lam if det > 0.0 else 0.0
    return lam, mu, math.sqrt(column_dot(z, 6, 6))


def decompose_kernel(Phi9, ref, keep_order, out):
    """:func:`decompose` with a reference, in closed form (plain-float kernel, allocation-free but for 3-vectors).

    The rule of :func:`decompose` (its four discrete candidates (R·Q, μ, λ, θ + π/2) and
    (R·diag(−1, −1, 1), λ, μ, θ + π), the nearest 2π copy of θ, the one nearest the reference,
    ``keep_order``) by another algorithm, on purpose: the closed-form eigen-decomposition of the
    2×2 φᵀφ (θ = ½ atan2(2φ1·φ2, |φ1|² − |φ2|²), λ² + μ² = tr, λ²μ² = det) instead of LAPACK's
    SVD, so that it never raises inside an integrator's step loop; the two agree to round-off,
    not bit for bit. It does not check the Kirchhoff–Love condition (eq. (21) of [1]).

    Parameters
    ----------
    Phi9 : array of shape (9,)
        q = (φ1, φ2, ψ), the columns of Φ (eq. (23) of [1]).
    ref : array of shape (13,)
        The reference decomposition (R row-major (9), λ, μ, ϱ, θ).
    keep_order : bool
        Keep the sign of λ − μ of ``ref``.
    out : array of shape (13,), output
        The candidate nearest ``ref`` (score ‖R − R_ref‖_F + |θ − θ_ref| + |λ − λ_ref| + |μ − μ_ref|).

    Returns
    -------
    float
        The frame jump |θ − θ_ref| + ‖R − R_ref‖_F.
    """
    lam, mu, _ = stretches_kernel(Phi9)
    n11 = column_dot(Phi9, 0, 0)
    n22 = column_dot(Phi9, 3, 3)
    n12 = column_dot(Phi9, 0, 3)
    th = 0.5 * math.atan2(2.0 * n12, n11 - n22)
    c = math.cos(th)
    s = math.sin(th)
    w1 = np.empty(3)
    w2 = np.empty(3)
    for i in range(3):
        w1[i] = (Phi9[i] * c + Phi9[3 + i] * s) / lam
        w2[i] = (-Phi9[i] * s + Phi9[3 + i] * c) / mu
    nrm = np.empty(3)
    nrm[0] = w1[1] * w2[2] - w1[2] * w2[1]
    nrm[1] = w1[2] * w2[0] - w1[0] * w2[2]
    nrm[2] = w1[0] * w2[1] - w1[1] * w2[0]
    rho = Phi9[6] * nrm[0] + Phi9[7] * nrm[1] + Phi9[8] * nrm[2]
    best = np.inf
    bjump = np.inf
    cols = np.empty((3, 3))
    for swap in range(2):
        for hlf in range(2):
            if swap == 0:
                lc = lam
                mc = mu
                tc = th
                sg = -1.0 if hlf else 1.0
                for i in range(3):
                    cols[i, 0] = sg * w1[i]
                    cols[i, 1] = sg * w2[i]
                    cols[i, 2] = nrm[i]
            else:
                lc = mu
                mc = lam
                tc = th + 0.5 * math.pi
                sg = -1.0 if hlf else 1.0
                for i in range(3):
                    cols[i, 0] = sg * w2[i]
                    cols[i, 1] = -sg * w1[i]
                    cols[i, 2] = nrm[i]
            if hlf:
                tc += math.pi
            if keep_order and (lc - mc) * (ref[9] - ref[10]) < 0.0:
                continue
            tc = tc + 2.0 * math.pi * np.round((ref[12] - tc) / (2.0 * math.pi))
            dR = 0.0
            for i in range(3):
                for j in range(3):
                    d = cols[i, j] - ref[3 * i + j]
                    dR += d * d
            dR = math.sqrt(dR)
            score = dR + abs(tc - ref[12]) + abs(lc - ref[9]) + abs(mc - ref[10])
            if score < best:
                best = score
                bjump = abs(tc - ref[12]) + dR
                for i in range(3):
                    for j in range(3):
                        out[3 * i + j] = cols[i, j]
                out[9] = lc
                out[10] = mc
                out[11] = rho
                out[12] = tc
    return bjump

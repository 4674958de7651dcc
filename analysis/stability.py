"""Linear (spectral) and energy–Casimir stability of stationary ellipses (docs/physics.md §9 of [2]).

For J1 = J2 the angle θ is cyclic (ṗ_θ = 0, eq. (46) of [1]), so a stationary ellipse is an
equilibrium of the *reduced* system x = (s1, s2, s3, p_θ, p_λ, p_μ, p_ϱ, λ, μ, ϱ) — the
state without θ (:data:`REDUCED_NAMES`). :func:`reduced_jacobian` differentiates the package's
right-hand side :func:`flatbody_env.physics.equations.rhs` numerically: central differences are exact
for the momenta (the equations are quadratic in them) and Richardson-extrapolated (fourth order)
for λ, μ, ϱ; the error is ~1e-11 relative.

Classification of the spectrum (eigenvalues come in ± pairs, Hamiltonian system):

* ``"hyperbolic"`` — an eigenvalue with Re > 0: linearly, hence nonlinearly, unstable; the
  deviation grows like exp(max Re · t) (``growth_rate``);
* ``"elliptic"`` — every eigenvalue on the imaginary axis and semisimple, the only zero
  eigenvalues those of the conserved |s|² and p_θ (the zero modes: left null vectors ∇|s|²
  and ∇p_θ, checked, and the right null vectors along the two-parameter family (s3, p_θ)):
  spectrally stable. Linear theory alone does not decide nonlinear stability then;
* ``"degenerate"`` — on the imaginary axis but with extra zero eigenvalues or a Jordan block
  (e.g. at a fold or a Krein collision): linear theory is inconclusive.

The energy–Casimir test (sufficient for nonlinear stability): at a relative equilibrium
∇H = a ∇|s|² + b ∇p_θ; if the Hessian of H − a|s|² − b p_θ restricted to the tangent space of
{|s|² = const, p_θ = const} is definite, the ellipse is Lyapunov stable in the reduced variables.
``nonlinear`` is then ``"stable"``; ``"unstable"`` for hyperbolic ones; ``"inconclusive"``
otherwise.

Cross-check (docs/physics.md §9): on branch N the out-of-plane block decouples, s̈1 = q s1 with
q = (s3/I2 − ω3)(ω3 − s3/I1); its eigenvalues are ±√q (``out_of_plane_q``).

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009), eqs. (44)–(54).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]), §6–§7.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flatbody_env.physics.body import Body
from flatbody_env.physics.equations import rhs
from flatbody_env.physics.hamiltonian import kinetic_kernel
from flatbody_env.physics import validation
from flatbody_env.physics.state import STATE_NAMES

from analysis.stationary import (
    DEFAULT_TOL,
    SearchBox,
    StationaryEllipse,
    check_isotropic,
    spins_for_shape,
    stationary_ellipses,
    steady_rotations,
)

REDUCED_NAMES: tuple[str, ...] = STATE_NAMES[:10]
"""The reduced state (θ is cyclic for J1 = J2 and dropped)."""

CLASSIFICATIONS = ("elliptic", "hyperbolic", "degenerate")
_POSITIONS = (7, 8, 9)


@dataclass(frozen=True, kw_only=True)
class ZeroMode:
    """A zero eigenvalue accounted for by a conserved quantity (its gradient is a left null vector)."""

    quantity: str
    """``"casimir"`` (|s|²) or ``"p_theta"``."""
    eigenvalue: complex
    """The computed near-zero eigenvalue."""
    left_residual: float
    """|Jᵀ ∇q| / (|J| |∇q|): how exactly ∇q is a left null vector (≈ 1e-12 when identified)."""


@dataclass(frozen=True, kw_only=True)
class StabilityResult:
    """Stability of one stationary ellipse."""

    ellipse: StationaryEllipse
    """The equilibrium analysed."""
    eigenvalues: tuple[complex, ...]
    """Eigenvalues of the reduced Jacobian (10), sorted by decreasing real part, then imaginary part."""
    max_real_part: float
    """max Re of the eigenvalues (the predicted growth rate when > 0)."""
    classification: str
    """``"elliptic"``, ``"hyperbolic"`` or ``"degenerate"`` (module docstring)."""
    nonlinear: str
    """``"stable"`` (energy–Casimir definite), ``"unstable"`` (hyperbolic) or ``"inconclusive"``."""
    zero_modes: tuple[ZeroMode, ...]
    """Zero eigenvalues identified with conserved quantities."""
    unexplained_zero_modes: int
    """Zero eigenvalues not accounted for by |s|² and p_θ (> 0 → degenerate)."""
    energy_casimir: str
    """``"definite"``, ``"indefinite"`` or ``"not applicable"``."""
    energy_casimir_eigenvalues: tuple[float, ...]
    """Eigenvalues of the restricted Hessian of H − a|s|² − b p_θ."""
    out_of_plane_q: float | None
    """q of docs/physics.md §9 (branch N only): the out-of-plane block has eigenvalues ±√q."""
    jacobian: np.ndarray = field(repr=False, compare=False)
    """The reduced Jacobian, shape (10, 10), order :data:`REDUCED_NAMES`."""
    notes: tuple[str, ...] = ()

    @property
    def stable(self) -> bool:
        """Spectrally stable (classification ``"elliptic"``)."""
        return self.classification == "elliptic"

    @property
    def growth_rate(self) -> float:
        """Predicted exponential growth rate of small perturbations (0 unless hyperbolic)."""
        return self.max_real_part if self.classification == "hyperbolic" else 0.0

    @property
    def frequencies(self) -> tuple[float, ...]:
        """Positive imaginary parts of the non-zero eigenvalues (oscillation frequencies)."""
        return tuple(sorted({round(abs(e.imag), 12) for e in self.eigenvalues if abs(e.imag) > 1e-9}))

    def unstable_mode(self) -> np.ndarray | None:
        """A real unit vector of the most unstable eigenspace (reduced coordinates), or None."""
        if self.classification != "hyperbolic":
            return None
        w, V = np.linalg.eig(self.jacobian)
        k = int(np.argmax(w.real))
        v = V[:, k]
        v = v * np.exp(-1j * np.angle(v[np.argmax(np.abs(v))]))
        r = v.real
        return r / np.linalg.norm(r)

    def to_dict(self) -> dict[str, Any]:
        """``{"state", "eigenvalues": [[re, im], ...], "max_real_part", "classification"}``."""
        return {
            "state": {name: float(self.ellipse.state[name]) for name in STATE_NAMES},
            "eigenvalues": [[float(e.real), float(e.imag)] for e in self.eigenvalues],
            "max_real_part": float(self.max_real_part),
            "classification": self.classification,
        }


# --------------------------------------------------------------------------------------------
def _reduced_rhs(body: Body, x: np.ndarray, theta: float) -> np.ndarray:
    y = np.empty(11)
    y[:10] = x
    y[10] = theta
    return rhs(0.0, y, None, body)[:10]


def _derivative(f, x: np.ndarray, i: int) -> np.ndarray:
    """∂f/∂x_i: exact central difference for momenta, fourth-order Richardson for λ, μ, ϱ.

    The step in λ, μ is a small fraction of min(x_i, |λ − μ|): the equations vary on the scale of
    the gap λ − μ near the circle (terms in σ₋²/(λ − μ)³).
    """
    if i in _POSITIONS:
        scale = abs(x[i]) if i == 9 else min(abs(x[i]), abs(x[7] - x[8]))
        h = 2e-3 * scale

        def d(hh):
            xp = x.copy()
            xm = x.copy()
            xp[i] += hh
            xm[i] -= hh
            return (f(xp) - f(xm)) / (2.0 * hh)

        return (4.0 * d(0.5 * h) - d(h)) / 3.0
    h = 1e-3 * max(1.0, abs(x[i]))
    xp = x.copy()
    xm = x.copy()
    xp[i] += h
    xm[i] -= h
    return (f(xp) - f(xm)) / (2.0 * h)


def reduced_jacobian(body: Body, y: np.ndarray) -> np.ndarray:
    """∂ẋ/∂x of the reduced system (θ dropped) at the packed state ``y`` (11,), shape (10, 10).

    Order :data:`REDUCED_NAMES`. Differentiates :func:`flatbody_env.physics.equations.rhs` (eqs. (44)–(49)
    of [1] with the corrected bracket, erratum E3–E4).
    """
    check_isotropic(body)
    y = np.asarray(y, float)
    x = y[:10].copy()
    f = lambda z: _reduced_rhs(body, z, y[10])  # noqa: E731
    return np.column_stack([_derivative(f, x, i) for i in range(10)])


def hamiltonian_gradient(body: Body, x: np.ndarray) -> np.ndarray:
    """∇H in reduced coordinates: (ω1, ω2, ω3, θ̇, λ̇, μ̇, ϱ̇, ∂H/∂λ, ∂H/∂μ, ∂H/∂ϱ), shape (10,)."""
    y = np.zeros(11)
    y[:10] = x
    vel = np.empty(7)
    force = np.empty(4)
    kinetic_kernel(y, body.kernel_params(), vel, force)
    _, gl, gm, gr = body.potential_terms(x[7], x[8], x[9])
    return np.concatenate([vel, [gl - force[1], gm - force[2], gr - force[3]]])


def hamiltonian_hessian(body: Body, x: np.ndarray) -> np.ndarray:
    """Hessian of H in reduced coordinates (numerical, symmetrised), shape (10, 10)."""
    x = np.asarray(x, float)
    g = lambda z: hamiltonian_gradient(body, z)  # noqa: E731
    Hs = np.column_stack([_derivative(g, x, i) for i in range(10)])
    return 0.5 * (Hs + Hs.T)


def out_of_plane_q(body: Body, ell: StationaryEllipse) -> float | None:
    """q = (s3/I2 − ω3)(ω3 − s3/I1) of docs/physics.md §9 (branch N); the block (s1, s2) has eigenvalues ±√q."""
    if ell.branch != "N":
        return None
    J, J3 = body.inertia.J1, body.inertia.J3
    I1 = J * ell.mu**2 + J3 * ell.rho**2
    I2 = J * ell.lam**2 + J3 * ell.rho**2
    s3, w3 = ell.s3, ell.omega3
    return (s3 / I2 - w3) * (w3 - s3 / I1)


def _energy_casimir(body: Body, x: np.ndarray, scale: float) -> tuple[str, tuple[float, ...]]:
    grad_H = hamiltonian_gradient(body, x)
    grad_C = np.zeros(10)
    grad_C[:3] = 2.0 * x[:3]
    grad_P = np.zeros(10)
    grad_P[3] = 1.0
    A = np.column_stack([grad_C, grad_P])
    coef, *_ = np.linalg.lstsq(A, grad_H, rcond=None)
    if np.linalg.norm(A @ coef - grad_H) > 1e-7 * max(1.0, np.linalg.norm(grad_H)) or np.linalg.norm(grad_C) == 0.0:
        return "not applicable", ()
    hess = hamiltonian_hessian(body, x)
    hess[:3, :3] -= 2.0 * coef[0] * np.eye(3)
    from scipy.linalg import null_space  # here, not at import (flatbody --help imports this module's neighbours)

    N = null_space(A.T)
    ev = np.linalg.eigvalsh(N.T @ hess @ N)
    tol = 1e-8 * max(1.0, float(np.max(np.abs(ev))))
    if np.all(ev > tol) or np.all(ev < -tol):
        return "definite", tuple(float(e) for e in ev)
    return "indefinite", tuple(float(e) for e in ev)


def analyse_stability(body: Body, ellipse: StationaryEllipse) -> StabilityResult:
    """Eigenvalues, classification and energy–Casimir test of a stationary ellipse.

    Parameters
    ----------
    body : Body
        The isotropic body the ellipse belongs to.
    ellipse : StationaryEllipse
        From :func:`~analysis.stationary.stationary_ellipses`, :func:`~analysis.stationary.steady_rotations`
        or :func:`~analysis.stationary.spins_for_shape`.

    Returns
    -------
    StabilityResult
    """
    check_isotropic(body)
    y = ellipse.y
    Jac = reduced_jacobian(body, y)
    w = np.linalg.eigvals(Jac)
    norm = max(1.0, float(np.max(np.abs(w))))
    tol_zero = 1e-7 * norm
    tol_re = 1e-6 * norm
    order = np.lexsort((-w.imag, -np.round(w.real / tol_re) * tol_re))
    w = w[order]
    # zero modes and conserved quantities
    x = y[:10]
    grads = {}
    gC = np.zeros(10)
    gC[:3] = 2.0 * x[:3]
    if np.linalg.norm(gC) > 0:
        grads["casimir"] = gC
    gP = np.zeros(10)
    gP[3] = 1.0
    grads["p_theta"] = gP
    jnorm = max(np.linalg.norm(Jac), 1e-300)
    zero_idx = [k for k in range(w.size) if abs(w[k]) < tol_zero]
    modes = []
    notes: list[str] = []
    for (name, g), k in zip(grads.items(), zero_idx):
        res = float(np.linalg.norm(Jac.T @ g) / (jnorm * np.linalg.norm(g)))
        if res < 1e-8:
            modes.append(ZeroMode(quantity=name, eigenvalue=complex(w[k]), left_residual=res))
    unexplained = len(zero_idx) - len(modes)
    max_re = float(np.max(w.real))
    # semisimplicity of repeated eigenvalues on the imaginary axis (Jordan blocks → degenerate)
    jordan = False
    used = np.zeros(w.size, bool)
    for k in range(w.size):
        if used[k]:
            continue
        cluster = np.nonzero(np.abs(w - w[k]) < 1e-5 * norm)[0]
        used[cluster] = True
        if cluster.size > 1:
            lam0 = w[cluster].mean()
            sv = np.linalg.svd(Jac - lam0 * np.eye(10), compute_uv=False)
            geo = int(np.sum(sv < 1e-6 * norm))
            if geo < cluster.size:
                jordan = True
                notes.append(
                    f"eigenvalue {lam0:.6g} has algebraic multiplicity {cluster.size} but geometric {geo} (Jordan block)"
                )
    if max_re > tol_re:
        classification = "hyperbolic"
        k = int(np.argmax(w.real))
        kind = "a real saddle pair" if abs(w[k].imag) < tol_zero else "a complex quartet (Krein collision)"
        notes.append(f"linearly unstable: {kind}, growth rate {max_re:.6g}")
    elif unexplained > 0 or jordan:
        classification = "degenerate"
        if unexplained > 0:
            notes.append(
                f"{unexplained} zero eigenvalue(s) beyond those of |s|^2 and p_theta: linear theory inconclusive"
            )
        else:
            notes.append("linear theory inconclusive (non-semisimple eigenvalue)")
    else:
        classification = "elliptic"
    ec, ec_ev = _energy_casimir(body, x, norm)
    if classification == "hyperbolic":
        nonlinear = "unstable"
    elif ec == "definite":
        nonlinear = "stable"
        notes.append("energy-Casimir: the restricted Hessian of H - a|s|^2 - b p_theta is definite: Lyapunov stable")
    else:
        nonlinear = "inconclusive"
        if classification == "elliptic":
            notes.append(
                "spectrally stable; energy-Casimir test "
                + ("indefinite" if ec == "indefinite" else "not applicable")
                + ": nonlinear stability not decided by linear theory"
            )
    return StabilityResult(
        ellipse=ellipse,
        eigenvalues=tuple(complex(e) for e in w),
        max_real_part=max_re,
        classification=classification,
        nonlinear=nonlinear,
        zero_modes=tuple(modes),
        unexplained_zero_modes=unexplained,
        energy_casimir=ec,
        energy_casimir_eigenvalues=ec_ev,
        out_of_plane_q=out_of_plane_q(body, ellipse),
        jacobian=Jac,
        notes=tuple(notes),
    )


def stability_of(
    body: Body, s3: float, p_theta: float, *, box: SearchBox | None = None, tol: float = DEFAULT_TOL
) -> list[StabilityResult]:
    """Every branch-N stationary ellipse for (s3, p_θ) with its stability (one call for the environment)."""
    return [analyse_stability(body, e) for e in stationary_ellipses(body, s3, p_theta, box=box, tol=tol)]


def stability_of_shape(body: Body, lam: float, mu: float, *, include_reversed: bool = False) -> list[StabilityResult]:
    """For a target shape (λ, μ): the spins that make it stationary (inverse problem) and their stability."""
    return [analyse_stability(body, e) for e in spins_for_shape(body, lam, mu, include_reversed=include_reversed)]


def steady_rotation_stability(body: Body, spin: float, *, box: SearchBox | None = None) -> list[StabilityResult]:
    """Branch A (docs/physics.md §8) steady rotations about in-plane axes with their stability."""
    return [analyse_stability(body, e) for e in steady_rotations(body, spin, box=box)]


def sample_stable_target(
    body: Body,
    rng: np.random.Generator,
    *,
    lam_range: tuple[float, float] = (1.05, 2.5),
    mu_range: tuple[float, float] = (0.4, 1.5),
    kind: str | None = None,
    require: str = "elliptic",
    max_tries: int = 200,
) -> StabilityResult:
    """Draw a random stationary ellipse that is stable, for use as an environment target.

    Shapes (λ, μ) with λ > μ are drawn uniformly in the ranges; the inverse problem gives the spins
    (:func:`~analysis.stationary.spins_for_shape`); the first candidate whose classification is
    ``require`` (``"elliptic"``; or pass ``"stable"`` to demand the energy–Casimir certificate) and,
    if given, whose ``kind`` is ``"rigid"`` or ``"circulating"`` is returned.

    Raises
    ------
    ValueError
        If no such ellipse is found in ``max_tries`` draws (the message names the ranges).
    """
    check_isotropic(body)
    validation.string("require", require, choices=("elliptic", "stable"))
    validation.requirement("kind", kind, kind in (None, "rigid", "circulating"), "be None, 'rigid' or 'circulating'")
    for _ in range(max_tries):
        lam = float(rng.uniform(*lam_range))
        mu = float(rng.uniform(*mu_range))
        if not lam > mu:
            continue
        cands = stability_of_shape(body, lam, mu)
        rng.shuffle(cands)
        for res in cands:
            if kind is not None and res.ellipse.kind != kind:
                continue
            ok = res.classification == "elliptic" if require == "elliptic" else res.nonlinear == "stable"
            if ok:
                return res
    raise ValueError(
        f"lam_range: no {require} stationary ellipse found in {max_tries} draws over lambda in {lam_range}, mu in {mu_range}"
    )


__all__ = [
    "CLASSIFICATIONS",
    "REDUCED_NAMES",
    "StabilityResult",
    "ZeroMode",
    "analyse_stability",
    "hamiltonian_gradient",
    "hamiltonian_hessian",
    "out_of_plane_q",
    "reduced_jacobian",
    "sample_stable_target",
    "stability_of",
    "stability_of_shape",
    "steady_rotation_stability",
]

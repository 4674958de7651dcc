"""Stationary ellipses (relative equilibria) of the isotropic flat body (section 3.4 of [1]).

Branch N (the paper's, eqs. (52)–(54) of [1]): s1 = s2 = 0, all shape momenta zero, λ, μ, ϱ
constant, ω3 and θ̇ constant. With u = λ + μ, v = λ − μ and σ± = s3 ± p_θ, eqs. (52)–(53) are
equivalent to (docs/physics.md §8 of [2])

.. math::
    \\frac{\\partial V}{\\partial\\lambda} = \\frac{\\sigma_+^2}{2Ju^3} + \\frac{\\sigma_-^2}{2Jv^3},
    \\qquad
    \\frac{\\partial V}{\\partial\\mu} = \\frac{\\sigma_+^2}{2Ju^3} - \\frac{\\sigma_-^2}{2Jv^3},
    \\qquad \\frac{\\partial V}{\\partial\\varrho} = 0 \\quad\\text{(eq. (54))},

i.e. stationarity of the amended potential W = σ₊²/(4Ju²) + σ₋²/(4Jv²) + V. Then

.. math:: \\omega_3 = \\frac{\\sigma_+}{2Ju^2} + \\frac{\\sigma_-}{2Jv^2}, \\qquad
   \\dot\\theta = \\frac{\\sigma_+}{2Ju^2} - \\frac{\\sigma_-}{2Jv^2}.

V1 has the closed form (λ+μ)⁴ = σ₊²/(kJ), (λ−μ)⁴ = σ₋²/(kJ) (docs/physics.md §8), used by
:func:`v1_closed_form`; every other potential (V2, V3, :class:`~flatbody_env.physics.potentials.CustomPotential`)
is solved numerically by :func:`stationary_ellipses`: sign changes of the equations on a
logarithmic grid over a search box seed a Newton (MINPACK ``hybr``) solve; each root is then
verified on the package's equations of motion (:func:`flatbody_env.physics.equations.rhs`): the
*residual* of a solution is max |dy/dt| over the ten reduced components (θ excluded, it is
cyclic), and only roots with residual ≤ ``tol`` (default 1e-10) are returned.

Branch A (beyond the paper, erratum E8 / docs/physics.md §8): steady rotations about an in-plane axis,
s = (s1, 0, 0), p_θ = 0: ∂V/∂λ = 0, ∂V/∂μ = Jμ s1²/I1², V_ϱ′ = J3 ϱ s1²/I1² (I1 = Jμ² + J3ϱ²),
and the analogue about axis 2 — :func:`steady_rotations`.

The inverse problem (shape → spins): σ₊² = 2Ju³ ∂V/∂u, σ₋² = 2Jv³ ∂V/∂v (docs/physics.md §8) —
:func:`spins_for_shape`.

Symmetric potentials (V1, V3, V2 with c = d, custom ones found symmetric) have the chart
symmetry (λ, μ, θ) ~ (μ, λ, θ + π/2) (docs/physics.md §7), so only λ > μ is searched; for V2 with c ≠ d
both orders are distinct ellipses (the c-axis long or short, docs/physics.md §8) and both are searched.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (verified formulas and errata of [1]), §6 (and errata E7, E8).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flatbody_env.physics.body import Body
from flatbody_env.physics.equilibria import StationaryEllipse, squared_sigmas
from flatbody_env.physics.equations import rhs
from flatbody_env.physics.hamiltonian import hamiltonian, velocities_from_momenta
from flatbody_env.physics.potentials import KIND_CUSTOM, V1, V2, potential_kernel
from flatbody_env.physics.state import STATE_NAMES
from flatbody_env.physics import validation
from flatbody_env.physics.validation import SEARCH_GRID_RANGE

DEFAULT_TOL = 1e-10
"""Largest accepted residual max |dy/dt| (θ excluded) of a returned solution."""

BRANCHES = ("N", "A1", "A2")
"""Branch N: s1 = s2 = 0 (eqs. (52)–(54) of [1]); A1/A2: steady rotation about material axis 1/2."""


# --------------------------------------------------------------------------------------------
# records
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class SearchBox:
    """Where the numerical solver looks: λ, μ (and ϱ where it is coupled) in closed ranges.

    The ranges are sampled on logarithmic grids of ``n`` (λ, μ) and ``n_rho`` (ϱ) points;
    roots closer together than one grid cell, or closer to λ = μ than one cell, can be missed.
    """

    lam: tuple[float, float] = (0.02, 50.0)
    """Range of λ."""
    mu: tuple[float, float] = (0.02, 50.0)
    """Range of μ."""
    rho: tuple[float, float] = (0.02, 50.0)
    """Range of ϱ (searched only where ϱ is coupled: custom potentials and branch A)."""
    n: int = 121
    """Grid points per in-plane axis."""
    n_rho: int = 41
    """Grid points along ϱ."""

    def __post_init__(self) -> None:
        for name in ("lam", "mu", "rho"):
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 < lo < hi):
                raise ValueError(f"box.{name}: need 0 < low < high (finite), got ({lo!r}, {hi!r})")
        lo, hi = SEARCH_GRID_RANGE
        validation.integer("box.n", self.n, low=lo, high=hi)
        validation.integer("box.n_rho", self.n_rho, low=4, high=401)


# --------------------------------------------------------------------------------------------
# checks and helpers
# --------------------------------------------------------------------------------------------
def check_isotropic(body: Body) -> float:
    """J = J1 = J2, or ValueError: the reductions of section 3.4 of [1] need J1 = J2."""
    if not isinstance(body, Body):
        raise ValueError("body: expected a flatbody_env.Body")
    if not body.inertia.is_isotropic:
        raise ValueError(
            f"params.J2: stationary-ellipse analysis needs an isotropic body J1 = J2 (eq. (31) of [1]), "
            f"got J1 = {body.inertia.J1:g}, J2 = {body.inertia.J2:g}"
        )
    if body.spin_convention != "corrected":
        raise ValueError("spin_convention: the analysis uses the corrected bracket (erratum E3); got 'paper'")
    return float(body.inertia.J1)


def _finite(name: str, value: Any) -> float:
    return validation.number(name, value)


def _positive(name: str, value: Any) -> float:
    return validation.number(name, value, positive=True)


def is_symmetric(body: Body) -> bool:
    """V(λ, μ, ϱ) = V(μ, λ, ϱ)? (erratum E9 of [2]); tested at sample points for custom potentials."""
    pot = body.potential
    if isinstance(pot, V2):
        return pot.c == pot.d
    if pot.kind != KIND_CUSTOM:
        return True
    rng = np.random.default_rng(7)
    for lam, mu, rho in rng.uniform(0.3, 3.0, size=(6, 3)):
        a = body.potential_terms(lam, mu, rho)
        b = body.potential_terms(mu, lam, rho)
        if abs(a[0] - b[0]) > 1e-12 * max(1.0, abs(a[0])):
            return False
    return True


def _gradient(body: Body, lam, mu, rho):
    """(∂V/∂λ, ∂V/∂μ, ∂V/∂ϱ), vectorised over arrays."""
    P = body.kernel_params()
    if body.potential.kind != KIND_CUSTOM:
        _, gl, gm, gr = potential_kernel(int(P[3]), P[4], P[5], P[6], P[7], lam, mu, rho)
        return np.asarray(gl, float), np.asarray(gm, float), np.asarray(gr, float)
    lam, mu, rho = np.broadcast_arrays(*(np.asarray(x, float) for x in (lam, mu, rho)))
    out = np.empty((3,) + lam.shape)
    for idx in np.ndindex(lam.shape):
        out[(slice(None),) + idx] = body.potential_terms(float(lam[idx]), float(mu[idx]), float(rho[idx]))[1:]
    return out[0], out[1], out[2]


def _rho_coupled(body: Body, branch: str) -> bool:
    """Whether ϱ must be solved for together with λ, μ (else ϱ* of eq. (54) or a fixed ϱ)."""
    return branch != "N" or body.potential.kind == KIND_CUSTOM


def _fixed_rho(body: Body, rho: float | None) -> float:
    """ϱ* = (a/b)^{1/3} (eq. (54) of [1]) for built-in potentials; a given ϱ when V does not depend on ϱ."""
    if body.thickness is not None:
        return body.thickness.rho_star
    if rho is None:
        return 1.0
    return _positive("rho", rho)


def equilibrium_equations(body: Body, branch: str, params: tuple[float, float], lam, mu, rho):
    """The force balance of a branch, vectorised: (F_λ, F_μ, F_ϱ) = (ṗ_λ, ṗ_μ, ṗ_ϱ) at the candidate state.

    Branch N: F = (−V_λ + A + B, −V_μ + A − B, −V_ϱ), A = σ₊²/(2Ju³), B = σ₋²/(2Jv³) (eqs. (52)–(54)
    of [1], docs/physics.md §8), ``params = (s3, p_θ)``. Branch A1: F = (−V_λ, −V_μ + Jμc, −V_ϱ + J3ϱc),
    c = s²/I1²; A2: (−V_λ + Jλc, −V_μ, −V_ϱ + J3ϱc), c = s²/I2² (docs/physics.md §8), ``params = (s, 0)``.
    """
    J = body.inertia.J1
    J3 = body.inertia.J3
    gl, gm, gr = _gradient(body, lam, mu, rho)
    if branch == "N":
        s3, pt = params
        sp, sm = s3 + pt, s3 - pt
        u = lam + mu
        v = lam - mu
        A = sp * sp / (2.0 * J * u**3)
        B = sm * sm / (2.0 * J * v**3)
        return -gl + A + B, -gm + A - B, -gr
    s = params[0]
    if branch == "A1":
        I1 = J * mu * mu + J3 * rho * rho
        c = s * s / (I1 * I1)
        return -gl, -gm + J * mu * c, -gr + J3 * rho * c
    if branch == "A2":
        I2 = J * lam * lam + J3 * rho * rho
        c = s * s / (I2 * I2)
        return -gl + J * lam * c, -gm, -gr + J3 * rho * c
    raise validation.refusal("branch", f"be one of {', '.join(BRANCHES)}", branch)


def make_state(branch: str, params: tuple[float, float], lam: float, mu: float, rho: float) -> dict[str, float]:
    """The full state of a candidate equilibrium (momenta of the shape zero, θ = 0)."""
    state = dict.fromkeys(STATE_NAMES, 0.0)
    state.update({"lambda": float(lam), "mu": float(mu), "rho": float(rho)})
    if branch == "N":
        state["s3"], state["p_theta"] = float(params[0]), float(params[1])
    elif branch == "A1":
        state["s1"] = float(params[0])
    else:
        state["s2"] = float(params[0])
    return state


def residual_of(body: Body, y: np.ndarray) -> float:
    """max |dy/dt| over the ten reduced components (θ excluded) from :func:`flatbody_env.physics.equations.rhs`."""
    f = rhs(0.0, np.asarray(y, float), None, body)
    return float(np.max(np.abs(f[:10])))


def build_ellipse(body: Body, branch: str, params, lam: float, mu: float, rho: float, method: str) -> StationaryEllipse:
    """Record of the equilibrium at (λ, μ, ϱ): velocities, energy and residual."""
    state = make_state(branch, params, lam, mu, rho)
    y = np.array([state[n] for n in STATE_NAMES])
    vel = velocities_from_momenta(y, body)
    return StationaryEllipse(
        branch=branch,
        state=state,
        omega=(vel["omega1"], vel["omega2"], vel["omega3"]),
        theta_dot=vel["theta_dot"],
        energy=float(hamiltonian(y, body)),
        residual=residual_of(body, y),
        method=method,
    )


# --------------------------------------------------------------------------------------------
# V1 closed form
# --------------------------------------------------------------------------------------------
def v1_closed_form(body: Body, s3: float, p_theta: float, *, rho: float | None = None) -> list[StationaryEllipse]:
    """Branch N for V1 in closed form (docs/physics.md §8): (λ+μ)⁴ = σ₊²/(kJ), (λ−μ)⁴ = σ₋²/(kJ).

    λ, μ > 0 needs |σ₊| > |σ₋| (s3·p_θ > 0); σ₋ = 0 gives the circle λ = μ (outside the chart).
    Returns a list with zero or one ellipse (λ > μ).
    """
    J = check_isotropic(body)
    if not isinstance(body.potential, V1):
        raise ValueError("potential: the closed form is for V1 only (use stationary_ellipses)")
    s3 = _finite("s3", s3)
    p_theta = _finite("p_theta", p_theta)
    k = body.potential.k
    sp, sm = s3 + p_theta, s3 - p_theta
    if sm == 0.0 or abs(sp) <= abs(sm):
        return []
    u = (sp * sp / (k * J)) ** 0.25
    v = (sm * sm / (k * J)) ** 0.25
    return [build_ellipse(body, "N", (s3, p_theta), 0.5 * (u + v), 0.5 * (u - v), _fixed_rho(body, rho), "closed-form")]


# --------------------------------------------------------------------------------------------
# numerical solver
# --------------------------------------------------------------------------------------------
def _grid(lo: float, hi: float, n: int) -> np.ndarray:
    return np.geomspace(lo, hi, n)


def _sign_change_seeds(
    F: tuple[np.ndarray, ...], coords: tuple[np.ndarray, ...], valid: np.ndarray
) -> list[np.ndarray]:
    """Centres of grid cells in which every equation takes both signs (cells marked valid)."""
    nd = len(coords)
    ok = valid.copy()
    for Fi in F:
        pos = np.zeros(ok.shape, bool)
        neg = np.zeros(ok.shape, bool)
        for corner in np.ndindex(*(2,) * nd):
            sl = tuple(slice(c, c + s - 1) for c, s in zip(corner, Fi.shape))
            pos |= Fi[sl] >= 0.0
            neg |= Fi[sl] <= 0.0
        ok &= pos & neg
    seeds = []
    for idx in zip(*np.nonzero(ok)):
        seeds.append(np.array([math.sqrt(c[i] * c[i + 1]) for c, i in zip(coords, idx)]))
    return seeds


def _newton(fun, z0: np.ndarray, *, tol: float = 1e-14, maxiter: int = 60):
    """MINPACK hybr from z0, then plain Newton polishing with a central-difference Jacobian."""

    def jac(z):
        n = z.size
        Jm = np.empty((n, n))
        for i in range(n):
            h = 1e-6 * max(abs(z[i]), 1e-3)
            zp = z.copy()
            zm = z.copy()
            zp[i] += h
            zm[i] -= h
            Jm[:, i] = (fun(zp) - fun(zm)) / (2.0 * h)
        return Jm

    from scipy.optimize import root  # here, not at import: flatbody --help reads SearchBox without scipy

    try:
        with np.errstate(all="ignore"):
            sol = root(fun, z0, jac=jac, method="hybr", options={"xtol": 1e-14, "maxfev": 400})
    except (ValueError, ZeroDivisionError, FloatingPointError):
        return None
    z = sol.x
    if not np.all(np.isfinite(z)) or np.any(z <= 0.0):
        return None
    with np.errstate(all="ignore"):
        for _ in range(4):
            f = fun(z)
            if not np.all(np.isfinite(f)):
                return None
            try:
                dz = np.linalg.solve(jac(z), -f)
            except np.linalg.LinAlgError:
                break
            z_new = z + dz
            if np.any(z_new <= 0.0) or not np.all(np.isfinite(z_new)):
                break
            if np.max(np.abs(fun(z_new))) > np.max(np.abs(f)):
                break
            z = z_new
            if np.max(np.abs(dz)) <= tol * max(1.0, np.max(np.abs(z))):
                break
    return z


@dataclass(frozen=True, kw_only=True)
class SolveReport:
    """What a numerical search found: the verified solutions and how many candidates failed."""

    solutions: tuple[StationaryEllipse, ...]
    rejected: int = 0
    """Newton limits whose residual exceeded the tolerance (or that left the domain)."""
    seeds: int = 0
    """Grid cells in which every equation changes sign."""
    notes: tuple[str, ...] = field(default_factory=tuple)


def solve_branch(
    body: Body,
    branch: str,
    params: tuple[float, float],
    *,
    box: SearchBox | None = None,
    tol: float = DEFAULT_TOL,
    rho: float | None = None,
) -> SolveReport:
    """All equilibria of one branch in the search box, each verified to residual ≤ ``tol``.

    Parameters
    ----------
    body : Body
        Isotropic body (J1 = J2).
    branch : {"N", "A1", "A2"}
        See :data:`BRANCHES`.
    params : (float, float)
        (s3, p_θ) for branch N; (s, 0) for branch A (s the spin about the axis).
    box : SearchBox, optional
        Search ranges and grid resolution.
    tol : float
        Largest accepted residual (max |dy/dt|, θ excluded).
    rho : float, optional
        ϱ when V does not depend on ϱ at all (built-in potential without thickness term).

    Returns
    -------
    SolveReport
    """
    check_isotropic(body)
    validation.string("branch", branch, choices=BRANCHES)
    box = box or SearchBox()
    tol = _positive("tol", tol)
    params = (_finite("s3" if branch == "N" else "spin", params[0]), _finite("p_theta", params[1]))
    symmetric = is_symmetric(body)
    coupled = _rho_coupled(body, branch)
    notes: list[str] = []
    if branch == "N" and params[0] == params[1] and symmetric:
        notes.append(
            "s3 = p_theta: sigma_- = 0, the stationary figure is a circle lambda = mu (outside the two-polar chart)"
        )
    if branch != "N" and body.thickness is None and body.potential.kind != KIND_CUSTOM:
        notes.append("no thickness potential: the centrifugal force on rho is unbalanced, branch A does not exist")
        return SolveReport(solutions=(), notes=tuple(notes))
    lam_g = _grid(*box.lam, box.n)
    mu_g = _grid(*box.mu, box.n)
    if coupled:
        rho_g = _grid(*box.rho, box.n_rho if body.potential.kind != KIND_CUSTOM else max(4, box.n_rho // 2))
        L, M, Rr = np.meshgrid(lam_g, mu_g, rho_g, indexing="ij")
        coords = (lam_g, mu_g, rho_g)
    else:
        rho_fixed = _fixed_rho(body, rho)
        L, M = np.meshgrid(lam_g, mu_g, indexing="ij")
        Rr = np.full_like(L, rho_fixed)
        coords = (lam_g, mu_g)
    with np.errstate(all="ignore"):
        F = equilibrium_equations(body, branch, params, L, M, Rr)
    F = F if coupled else F[:2]
    F = tuple(np.where(np.isfinite(Fi), Fi, np.nan) for Fi in F)
    # cells must not straddle the singular set λ = μ; symmetric V: search λ > μ only
    D = L - M
    corners_pos = np.ones(tuple(s - 1 for s in D.shape), bool)
    corners_neg = np.ones_like(corners_pos)
    finite = np.ones_like(corners_pos)
    for corner in np.ndindex(*(2,) * D.ndim):
        sl = tuple(slice(c, c + s - 1) for c, s in zip(corner, D.shape))
        corners_pos &= D[sl] > 0
        corners_neg &= D[sl] < 0
        for Fi in F:
            finite &= np.isfinite(Fi[sl])
    valid = (corners_pos if symmetric else (corners_pos | corners_neg)) & finite
    seeds = _sign_change_seeds(tuple(np.nan_to_num(Fi) for Fi in F), coords, valid)

    if coupled:

        def fun(z):
            return np.array(equilibrium_equations(body, branch, params, z[0], z[1], z[2]), float)

    else:

        def fun(z):
            return np.array(equilibrium_equations(body, branch, params, z[0], z[1], rho_fixed)[:2], float)

    found: list[np.ndarray] = []
    rejected = 0
    for z0 in seeds:
        z = _newton(fun, z0)
        if z is None:
            rejected += 1
            continue
        full = z if coupled else np.array([z[0], z[1], rho_fixed])
        if full[0] == full[1] or (symmetric and full[0] < full[1]):
            continue
        if any(np.max(np.abs(full - g) / np.maximum(np.abs(g), 1e-12)) < 1e-7 for g in found):
            continue
        ell = build_ellipse(body, branch, params, *full, "numeric")
        if not ell.residual <= tol:
            rejected += 1
            continue
        found.append(full)
    sols = [build_ellipse(body, branch, params, *g, "numeric") for g in found]
    sols.sort(key=lambda e: (e.lam - e.mu < 0, -e.lam, e.mu))
    return SolveReport(solutions=tuple(sols), rejected=rejected, seeds=len(seeds), notes=tuple(notes))


def stationary_ellipses(
    body: Body,
    s3: float,
    p_theta: float,
    *,
    method: str = "auto",
    box: SearchBox | None = None,
    tol: float = DEFAULT_TOL,
    rho: float | None = None,
) -> list[StationaryEllipse]:
    """All stationary ellipses of branch N (eqs. (52)–(54) of [1]) for given (s3, p_θ).

    Parameters
    ----------
    body : Body
        Isotropic body (J1 = J2); V1, V2, V3 or a custom potential.
    s3, p_theta : float
        The conserved spin component and material momentum.
    method : {"auto", "closed-form", "numeric"}
        ``"auto"``: the closed form for V1 (docs/physics.md §8), root finding otherwise.
    box : SearchBox, optional
        Search ranges of the numerical solver.
    tol : float
        Largest accepted residual max |dy/dt| (θ excluded).
    rho : float, optional
        ϱ when V does not depend on ϱ (no thickness term); default 1.

    Returns
    -------
    list of StationaryEllipse
        Sorted with λ > μ first, then by decreasing λ.
    """
    validation.string("method", method, choices=("auto", "closed-form", "numeric"))
    check_isotropic(body)
    if method == "closed-form" or (method == "auto" and isinstance(body.potential, V1)):
        return v1_closed_form(body, s3, p_theta, rho=rho)
    return list(solve_branch(body, "N", (s3, p_theta), box=box, tol=tol, rho=rho).solutions)


def steady_rotations(
    body: Body, spin: float, *, axes: tuple[int, ...] = (1, 2), box: SearchBox | None = None, tol: float = DEFAULT_TOL
) -> list[StationaryEllipse]:
    """Branch A (docs/physics.md §8, beyond the paper, erratum E8): steady rotations about material axis 1 or 2.

    s = (s, 0, 0) [axis 1] or (0, s, 0) [axis 2], p_θ = 0, θ̇ = 0; λ, μ, ϱ solve
    ∂V/∂λ = 0, ∂V/∂μ = Jμ s²/I1², V_ϱ′ = J3ϱ s²/I1² (axis 1; I1 = Jμ² + J3ϱ²) or the axis-2 analogue.
    V1 has none (∂V1/∂λ = kλ ≠ 0).

    Parameters
    ----------
    spin : float
        The spin s ≠ 0 about the axis (|s|, the Casimir's square root, up to sign).
    axes : tuple of {1, 2}
        Which in-plane axes.
    """
    check_isotropic(body)
    spin = _finite("spin", spin)
    validation.requirement("spin", spin, spin != 0.0, "be non-zero for a steady rotation (allowed: any finite s != 0)")
    out: list[StationaryEllipse] = []
    for axis in axes:
        validation.requirement("axes", axis, axis in (1, 2), "hold only 1 or 2")
        out.extend(solve_branch(body, f"A{axis}", (spin, 0.0), box=box, tol=tol).solutions)
    return out


# --------------------------------------------------------------------------------------------
# inverse problem
# --------------------------------------------------------------------------------------------
def spins_for_shape(
    body: Body,
    lam: float,
    mu: float,
    *,
    rho: float | None = None,
    include_reversed: bool = False,
    tol: float = DEFAULT_TOL,
) -> list[StationaryEllipse]:
    """The (s3, p_θ) that make the shape (λ, μ) a stationary ellipse (docs/physics.md §8), as full solutions.

    σ₊² = 2Ju³ ∂V/∂u and σ₋² = 2Jv³ ∂V/∂v with u = λ + μ, v = λ − μ, ∂V/∂u = (V_λ + V_μ)/2,
    ∂V/∂v = (V_λ − V_μ)/2. A shape is stationary iff both right-hand sides are ≥ 0 (for V3 and λ > μ:
    iff λμ ≥ 1). The sign pairs (σ₊, σ₋) and (σ₊, −σ₋) are the dual pair (s3 ↔ p_θ, docs/physics.md §8):
    one turns rigidly (|ω3| > |θ̇|), the other circulates (|θ̇| > |ω3|). With ``include_reversed``
    the time-reversed pair (−σ₊, ∓σ₋) is added.

    ϱ is ϱ* (eq. (54)) for built-in potentials, the root of ∂V/∂ϱ = 0 near ``rho`` (default 1) for
    custom potentials.

    Returns
    -------
    list of StationaryEllipse
        Empty when the shape cannot be stationary.
    """
    J = check_isotropic(body)
    lam = _positive("lambda", lam)
    mu = _positive("mu", mu)
    if lam == mu:
        raise ValueError("lambda: must differ from mu (lambda = mu is the singular set of the two-polar chart)")
    if body.potential.kind == KIND_CUSTOM:
        from scipy.optimize import root

        r0 = 1.0 if rho is None else _positive("rho", rho)
        sol = root(lambda r: [body.potential_terms(lam, mu, float(r[0]))[3]], [r0], method="hybr")
        if not sol.success or sol.x[0] <= 0:
            return []
        rho_v = float(sol.x[0])
    else:
        rho_v = _fixed_rho(body, rho)
    _, gl, gm, _ = body.potential_terms(lam, mu, rho_v)
    u, v = lam + mu, lam - mu
    sp2, sm2 = squared_sigmas(body, lam, mu, rho_v)
    scale = 2.0 * J * (abs(u) ** 3 + abs(v) ** 3) * (abs(gl) + abs(gm)) + 1e-300
    if sp2 < -1e-14 * scale or sm2 < -1e-14 * scale:
        return []
    sp, sm = math.sqrt(max(sp2, 0.0)), math.sqrt(max(sm2, 0.0))
    pairs = [(sp, sm), (sp, -sm)]
    if include_reversed:
        pairs += [(-sp, -sm), (-sp, sm)]
    out = []
    seen = set()
    for a, b in pairs:
        s3, pt = 0.5 * (a + b), 0.5 * (a - b)
        key = (round(s3, 14), round(pt, 14))
        if key in seen:
            continue
        seen.add(key)
        ell = build_ellipse(body, "N", (s3, pt), lam, mu, rho_v, "inverse")
        if ell.residual <= max(tol, 1e-10):
            out.append(ell)
    return out


__all__ = [
    "BRANCHES",
    "DEFAULT_TOL",
    "SearchBox",
    "SolveReport",
    "StationaryEllipse",
    "build_ellipse",
    "check_isotropic",
    "equilibrium_equations",
    "is_symmetric",
    "make_state",
    "residual_of",
    "solve_branch",
    "spins_for_shape",
    "stationary_ellipses",
    "steady_rotations",
    "v1_closed_form",
]

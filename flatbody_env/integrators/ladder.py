"""A ladder of models: integrate no more of the body than the scene's own invariants leave moving.

Every rung is derived from the equations of motion of the two-polar chart (eqs. (44)–(49) of
[1], with the bracket and signs corrected as in [2]) and is exact on its invariant set; the
rungs below the full models are tried cheapest first:

=====  ==============  ====================================================  ==========================
rung   name            invariant set (checked on the initial state)          solution
=====  ==============  ====================================================  ==========================
1      ``stationary``  J1 = J2, no control, s1 = s2 = p_λ = p_μ = p_ϱ = 0     closed form, O(1) per time
                       and ṗ_λ = ṗ_μ = ṗ_ϱ = 0 (eqs. (52)–(54)) to
                       :data:`STATIONARY_TOL`
3      ``planar-V1``   the planar set below with the potential V1 (eq. (37))  closed form (in-plane) +
                       (no gap condition: exact through λ = μ)               the ϱ oscillator
2      ``planar``      J1 = J2, s1 = s2 = 0, τ1 = τ2 = τ3 = 0, V = V_λμ(λ,   two small compiled systems,
                       μ) + V_ϱ(ϱ) (a built-in potential, eq. (36)), and     each with its own steps
                       σ₋ = 0 or the in-plane energy bound keeps |λ − μ| ≥
                       :data:`GAP_MIN`
4      ``two-polar``   J1 = J2 and the energy bound keeps |λ − μ| ≥           the 11-variable chart
                       :data:`GAP_MIN` (``flatbody_env.simulation``)
5      ``regular``     everything else                                       Φ = [φ1, φ2, ψ], 18 + 2
=====  ==============  ====================================================  ==========================

(The numbers are those of the rungs' derivation; ``planar-V1`` is the special case of
``planar`` and is tried before it.) Rungs 4 and 5 are today's models, chosen in
:func:`flatbody_env.simulation.choose_model`; this module holds rungs 1–3, each a model with the
:class:`~flatbody_env.integrators.base.Method` interface (``integrate(body, y0, times, tol=,
u=, R0=, with_rotation=)``).

Derivations
-----------
*Planar set.* With s1 = s2 = 0 and J1 = J2, ω1 = s1/I1 = ω2 = s2/I2 = 0, so ṡ1 = ω2 s3 − ω3 s2 + τ1
= τ1 and ṡ2 = τ2 (eqs. (44)–(45), corrected sign): the set is invariant exactly when τ1 = τ2 = 0;
ṡ3 = ω1 s2 − ω2 s1 + τ3 = τ3 (eq. (46)) and ṗ_θ = 0, so s3, p_θ and σ± = s3 ± p_θ are constant
when also τ3 = 0. R turns about the normal: Ṙ = R W(0, 0, ω3) (eq. (25), W the negative of the
usual hat map) gives R(t) = R₀·exp(α W(e3)), α̇ = ω3 = σ₊/(2J(λ+μ)²) + σ₋/(2J(λ−μ)²). In eqs.
(47)–(49) the s1, s2 terms vanish, so for V = V_λμ(λ, μ) + V_ϱ(ϱ)

* (λ, μ): λ̇ = p_λ/J, μ̇ = p_μ/J, ṗ_λ = −∂V/∂λ + σ₊²/(2J(λ+μ)³) + σ₋²/(2J(λ−μ)³),
  ṗ_μ = −∂V/∂μ + σ₊²/(2J(λ+μ)³) − σ₋²/(2J(λ−μ)³), with θ̇ = σ₊/(2J(λ+μ)²) − σ₋/(2J(λ−μ)²) and
  α̇ = ω3 by quadrature;
* (ϱ, p_ϱ): ϱ̇ = p_ϱ/J3, ṗ_ϱ = −V_ϱ′(ϱ) + J3ϱ(s1²/I1² + s2²/I2²) + f_ϱ = −V_ϱ′(ϱ) + f_ϱ
  (eqs. (40), (49)): a one-degree-of-freedom oscillator, the only place a dilatation control enters.

The in-plane energy σ₊²/(4J(λ+μ)²) + σ₋²/(4J(λ−μ)²) + (p_λ² + p_μ²)/(2J) + V_λμ is conserved by
the first system alone (even under f_ϱ), which bounds |λ − μ| ≥ |σ₋|/√(4J(H_λμ − inf V_λμ)).

*Stationary ellipse.* If moreover p_λ = p_μ = p_ϱ = 0 and the forces vanish (eqs. (52)–(54)),
every variable but θ is constant: θ(t) = θ₀ + θ̇t and R(t) = R₀·exp(ω3 t W(e3)).

*Planar V1.* For V1 = k/2·(λ² + μ²) = k/2·tr ΦᵀΦ the regular form (eq. (28) with a constant
mass matrix) gives J φ̈_A = −k φ_A + Λ_A ψ; on the planar set φ1, φ2 stay in the plane and ψ
along its normal, so Λ_A = 0 and the in-plane 2×2 block Φ₂ = Q(α) diag(λ, μ) U₂(θ)⁻¹ of
Φ = R D U⁻¹ (eqs. (23)–(24)) is an isotropic harmonic oscillator,
Φ₂(t) = Φ₂(0) cos ωt + Φ̇₂(0) sin(ωt)/ω, ω = √(k/J). Its SVD in closed form: Φ₂ =
z₊ + z₋ (conformal + anti-conformal parts) with, as complex numbers,
z₊ = (λ+μ)/2·e^{−i(α+θ)} and z₋ = (λ−μ)/2·e^{i(θ−α)}; each is a planar harmonic orbit
z(t) = z(0) cos ωt + ż(0) sin(ωt)/ω whose angular momentum Im(z̄ ż) = −σ±/(4J) is constant.
Writing z = P e^{iωt} + Q e^{−iωt}, arg z = ±ωt + arg(P or Q) + Arg(1 + (Q/P)e^{−2iωt} or its
mirror), a continuous branch whenever σ± ≠ 0 (z never passes through 0): this is the branch
continuity through close approaches (the chart's θ turns by ±π/2 at each pass). For σ₋ = 0 the
orbit of z₋ is a segment through 0: θ − α is constant and λ − μ = 2 Re(z₋ e^{−i(θ−α)}) changes sign
— the motion through λ = μ, with the labels λ, μ swapped after it. det Φ₂ = |z₊|² − |z₋|² =
c₀ + c₁ cos 2ωt + c₂ sin 2ωt: the collapse μ → 0 of V1 (no barrier) is found exactly.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md``: the corrected bracket (ṡ = ω × s), the sign of eqs. (44)–(46), and
   the closest-approach bound of the λ = μ barrier.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from flatbody_env.physics import validation
from flatbody_env.physics.body import Body
from flatbody_env.physics.equations import rhs
from flatbody_env.physics.hamiltonian import hamiltonian, kinetic_kernel, velocities_from_momenta
from flatbody_env.physics.kinematics import material_rotation
from flatbody_env.physics.potentials import KIND_CUSTOM, V1, potential_kernel
from flatbody_env.integrators.base import IntegrationError, MethodInfo, Solution, Tolerances, budget_error

GAP_MIN = 1e-2
"""Smallest guaranteed |λ − μ| for which a chart model (``planar``, ``two-polar``) is chosen."""

STATIONARY_TOL = 1e-12
"""Largest |s1|, |s2|, |p_λ|, |p_μ|, |p_ϱ| and residual |ṗ_λ|, |ṗ_μ|, |ṗ_ϱ| of eqs. (52)–(54) for the
``stationary`` rung. A residual r makes the true motion leave the ellipse like r·t²/(2J)."""

LADDER_RUNGS = ("stationary", "planar-V1", "planar")
"""The rungs below the full models, in the order ``model="auto"`` tries them."""

RUNGS = LADDER_RUNGS + ("two-polar", "regular")
"""Every rung, cheapest first."""


@dataclass(frozen=True, kw_only=True)
class RungChoice:
    """Which rung a scene runs on, and why."""

    rung: str
    """One of :data:`RUNGS`."""
    invariant: str
    """The invariant that held (or why the full model is needed), in words."""
    measured: dict = field(default_factory=dict)
    """The measured size of each quantity the choice rests on."""

    def as_meta(self) -> dict:
        """The entries a trajectory's ``meta`` carries: ``rung``, ``rung_invariant``, ``rung_measured``."""
        return {"rung": self.rung, "rung_invariant": self.invariant, "rung_measured": dict(self.measured)}


# --------------------------------------------------------------------------------------------- checks
def _controls(u) -> np.ndarray:
    if u is None:
        return np.zeros(4)
    u = np.array(u, dtype=np.float64).ravel()
    if u.shape != (4,) or not np.all(np.isfinite(u)):
        raise ValueError("u: expected 4 finite controls (tau1, tau2, tau3, f_rho)")
    return u


def stationary_residual(y: np.ndarray, body: Body) -> float:
    """max(|s1|, |s2|, |p_λ|, |p_μ|, |p_ϱ|, |ṗ_λ|, |ṗ_μ|, |ṗ_ϱ|): zero on a stationary ellipse (eqs. (52)–(54))."""
    r = rhs(0.0, np.asarray(y, float), None, body)
    return float(max(abs(y[0]), abs(y[1]), abs(y[4]), abs(y[5]), abs(y[6]), abs(r[4]), abs(r[5]), abs(r[6])))


def planar_gap_lower_bound(y: np.ndarray, body: Body) -> float:
    """Lower bound of |λ − μ| along the planar motion from the conserved in-plane energy (0 if none).

    H_λμ = 𝒯(p_ϱ = 0) + V_λμ ≥ σ₋²/(4J(λ−μ)²) + inf V_λμ at s1 = s2 = 0 (module docstring), so
    |λ − μ| ≥ |σ₋| / √(4J(H_λμ − inf V_λμ)). Needs a built-in potential (its lower bound).
    """
    lb = float(body.potential.lower_bound)
    if not math.isfinite(lb):
        return 0.0
    P = body.kernel_params()
    z = np.array(y, dtype=float)
    z[6] = 0.0
    kin = kinetic_kernel(z, P, np.empty(7), np.empty(4))
    v_plane = potential_kernel(int(P[3]), P[4], P[5], 0.0, 0.0, z[7], z[8], z[9])[0]
    sigma_minus = abs(z[2] - z[3])
    avail = kin + v_plane - lb
    if avail <= 0.0:
        return math.inf if sigma_minus > 0 else 0.0
    return sigma_minus / math.sqrt(4.0 * body.inertia.J1 * avail)


def _planar_reasons(y: np.ndarray, body: Body, u: np.ndarray) -> list[str]:
    out = []
    if not body.inertia.is_isotropic:
        out.append(f"J1 = {body.inertia.J1:g} != J2 = {body.inertia.J2:g}")
    if body.potential.kind == KIND_CUSTOM:
        out.append("a custom potential V(lambda, mu, rho) need not separate into V_lm(lambda, mu) + V_rho(rho)")
    if y[0] != 0.0 or y[1] != 0.0:
        out.append(f"s1, s2 = {y[0]:.3g}, {y[1]:.3g} (need exactly 0)")
    if u[0] != 0.0 or u[1] != 0.0:
        out.append("torques tau1, tau2 tilt the plane")
    if u[2] != 0.0:
        out.append("a torque tau3 changes s3 (sigma+- no longer constant)")
    return out


def _measure_planar(y: np.ndarray, body: Body) -> dict:
    return {"max_abs_s1_s2": float(max(abs(y[0]), abs(y[1]))), "sigma_minus": float(y[2] - y[3])}


def check_rung(rung: str, y0, body: Body, u=None) -> RungChoice:
    """The :class:`RungChoice` for ``rung`` (one of :data:`LADDER_RUNGS`) at the initial state ``y0``.

    Raises
    ------
    ValueError
        Naming the rung and the invariant the scene breaks, with its measured size.
    """
    if rung not in LADDER_RUNGS:
        raise ValueError(f"model: {rung!r} is no rung below the full models (allowed: {', '.join(LADDER_RUNGS)})")
    y = np.asarray(y0, dtype=float)
    uu = _controls(u)
    if rung == "stationary":
        reasons = []
        if not body.inertia.is_isotropic:
            reasons.append(f"J1 = {body.inertia.J1:g} != J2 = {body.inertia.J2:g}")
        if np.any(uu != 0.0):
            reasons.append("controls are given")
        res = stationary_residual(y, body)
        if res > STATIONARY_TOL:
            reasons.append(
                f"the state is no stationary ellipse: residual of eqs. (52)-(54) {res:.3g} > {STATIONARY_TOL:g}"
            )
        if reasons:
            raise ValueError(
                f"model: the scene leaves the invariant set of the 'stationary' rung: {'; '.join(reasons)}"
            )
        return RungChoice(
            rung="stationary",
            invariant="stationary ellipse: s1 = s2 = p_lambda = p_mu = p_rho = 0 and eqs. (52)-(54) hold (J1 = J2, no control)",
            measured={"residual": res},
        )
    reasons = _planar_reasons(y, body, uu)
    measured = _measure_planar(y, body)
    if rung == "planar-V1":
        if not isinstance(body.potential, V1):
            reasons.append(f"the in-plane potential is {body.potential.name}, not V1")
        if reasons:
            raise ValueError(f"model: the scene leaves the invariant set of the 'planar-V1' rung: {'; '.join(reasons)}")
        return RungChoice(
            rung="planar-V1",
            invariant="planar motion (s1 = s2 = 0, J1 = J2, no tau) with V1: the in-plane block of Phi is an isotropic oscillator",
            measured=measured,
        )
    if not reasons:
        bound = planar_gap_lower_bound(y, body)
        measured["gap_lower_bound"] = float(bound)
        if y[2] != y[3] and bound < GAP_MIN:
            reasons.append(
                f"the in-plane energy bound only guarantees |lambda - mu| >= {bound:.3g} < {GAP_MIN:g} (sigma- = {y[2] - y[3]:.3g})"
            )
    if reasons:
        raise ValueError(f"model: the scene leaves the invariant set of the 'planar' rung: {'; '.join(reasons)}")
    why = (
        "sigma- = 0 (no barrier: smooth through lambda = mu)"
        if y[2] == y[3]
        else f"|lambda - mu| >= {measured['gap_lower_bound']:.3g}"
    )
    return RungChoice(
        rung="planar",
        invariant=f"planar motion (s1 = s2 = 0, J1 = J2, no tau, V = V_lm + V_rho) and {why}",
        measured=measured,
    )


def choose_rung(y0, body: Body, u=None) -> RungChoice | None:
    """The lowest rung of :data:`LADDER_RUNGS` valid at ``y0`` (with controls ``u``), or None."""
    for rung in LADDER_RUNGS:
        try:
            return check_rung(rung, y0, body, u)
        except ValueError:
            continue
    return None


def rung_reasons(y0, body: Body, u=None) -> dict[str, str]:
    """Why each rung of :data:`LADDER_RUNGS` does not apply (empty string where it does)."""
    out = {}
    for rung in LADDER_RUNGS:
        try:
            check_rung(rung, y0, body, u)
            out[rung] = ""
        except ValueError as exc:
            out[rung] = str(exc).split(": ", 2)[-1]
    return out


# --------------------------------------------------------------------------------------------- helpers
def rotation_about_normal(R0: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """R₀·exp(α W(e3)) (eq. (25): W the negative of the usual hat map), shape (n, 3, 3).

    exp(α W(e3)) = [[cos α, sin α, 0], [−sin α, cos α, 0], [0, 0, 1]] = U(−α) of eq. (24).
    """
    return np.asarray(R0, float) @ material_rotation(-np.asarray(alpha, float))


def _energy(Y: np.ndarray, P: np.ndarray, times: np.ndarray, tol: Tolerances, name: str, u: np.ndarray) -> np.ndarray:
    from flatbody_env.integrators.twopolar_kernels import energy_series

    H = np.empty(Y.shape[1])
    energy_series(np.ascontiguousarray(Y), P, H)
    if not np.any(u):
        err = np.abs(H - H[0])
        bad = err > tol.energy_tol
        if np.any(bad):
            k = int(np.argmax(bad))
            raise IntegrationError(
                f"energy error {err[k]:.3g} exceeds the tolerance {tol.energy_tol:.3g}",
                t=times[k],
                method=name,
                kind="energy",
            )
    return H


def _times(times) -> np.ndarray:
    times = np.array(times, dtype=np.float64).ravel()
    if times.size < 1 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise validation.refusal("times", "be finite and strictly increasing")
    return times


def _small(
    solve,
    x0,
    times,
    template,
    u,
    P,
    tol: Tolerances,
    check_gap: bool,
    name: str,
    *,
    spent: tuple[int, float] = (0, 0.0),
):
    """One small system through ``times`` within the run's budgets, ``tol.max_nfev`` and ``tol.max_wall_time``,
    less what the run has ``spent`` already (RHS evaluations, seconds): the compiled DOP853's budget of
    evaluations checked before every step, and the wall clock read between the pieces of
    :class:`~.budget.WallClockBudget` (each piece continues the last: the result bit for bit that of one call). Out of
    budget: ``IntegrationError(kind="budget")``."""
    from flatbody_env.integrators.budget import WallClockBudget
    from flatbody_env.integrators.failure import BUDGET, raise_for
    from flatbody_env.integrators.twopolar_kernels import carry_size

    nfev_left = tol.max_nfev - int(spent[0])
    seconds_left = tol.max_wall_time - float(spent[1])
    if nfev_left < 1 or seconds_left <= 0.0:
        raise budget_error(
            t=float(times[0]),
            method=name,
            tol=tol,
            used=f"{int(spent[0])} RHS evaluations, {spent[1]:.3g} s before this part",
        )
    X = np.empty((x0.size, times.size))
    counters = np.zeros(4, np.int64)  # [nfev, accepted, rejected, budget of nfev]
    fail = np.zeros(1)
    carry = np.zeros(carry_size(x0.size))
    x0 = np.ascontiguousarray(x0, dtype=np.float64)
    rtol, atol = float(tol.rtol), float(tol.atol)
    status = [0]

    def advance(limit: int) -> tuple[int, int]:  # on from where the last piece stopped, to ``limit`` evaluations
        counters[3] = limit
        status[0] = solve(x0, times, template, u, P, rtol, atol, check_gap, X, counters, fail, carry)
        return 1, int(status[0] == BUDGET)

    start = time.perf_counter()
    wall = WallClockBudget(max_nfev=nfev_left, max_wall_time=seconds_left).run(advance)
    st = status[0]
    if st == BUDGET:
        used = f"{int(spent[0] + counters[0])} RHS evaluations in {int(counters[1] + counters[2])} steps, {spent[1] + time.perf_counter() - start:.3g} s"
        raise budget_error(
            t=float(fail[0]), method=name, tol=tol, used=used + (" (the wall-clock budget)" if wall else "")
        )
    raise_for(st, t=fail[0], method=name)
    return X, counters


def _check_adaptive(name: str, tol: Tolerances) -> None:
    if tol.step is not None:
        raise ValueError(
            f"step: the {name} model integrates with its own adaptive (or exact) solver; step= applies to fixed-step methods only"
        )


# --------------------------------------------------------------------------------------------- models
class StationaryModel:
    """Rung 1: the stationary ellipse, exact (module docstring)."""

    info = MethodInfo(
        name="ladder-stationary",
        adaptive=True,
        order=0,
        chart="stationary",
        compiled=False,
        preserves=("all invariants (exact)",),
        description="closed form of a stationary ellipse (eqs. (52)-(54)): theta and R turn uniformly, O(1) per output time",
    )

    def integrate(self, body: Body, y0, times, *, tol: Tolerances, u=None, R0=None, with_rotation=False) -> Solution:
        _check_adaptive("stationary", tol)
        y0 = np.array(y0, dtype=float)
        check_rung("stationary", y0, body, u)
        times = _times(times)
        vel = velocities_from_momenta(y0, body)
        dt = times - times[0]
        Y = np.repeat(y0[:, None], times.size, axis=1)
        Y[10] = y0[10] + vel["theta_dot"] * dt
        rotation = rotation_about_normal(np.eye(3) if R0 is None else R0, vel["omega3"] * dt) if with_rotation else None
        H = np.full(times.size, hamiltonian(y0, body))
        return Solution(
            t=times.copy(),
            Y=Y,
            rotation=rotation,
            nfev=0,
            stats={"energy": H, "theta_dot": vel["theta_dot"], "omega3": vel["omega3"]},
        )


def _template(y0: np.ndarray) -> np.ndarray:
    t = np.array(y0, dtype=np.float64)
    t[0] = 0.0
    t[1] = 0.0
    return t


def _thickness(y0, times, u, P, tol, name, *, spent: tuple[int, float] = (0, 0.0)):
    from flatbody_env.integrators import ladder_kernels as _lk

    return _small(
        _lk.dop853_thickness, np.array([y0[9], y0[6]]), times, _template(y0), u, P, tol, False, name, spent=spent
    )


class PlanarModel:
    """Rung 2: planar motion as two small compiled systems, each with its own steps (module docstring)."""

    info = MethodInfo(
        name="ladder-planar",
        adaptive=True,
        order=8,
        chart="planar",
        compiled=True,
        preserves=("s1 = s2 = 0", "s3", "p_theta"),
        description="planar motion: (lambda, mu, p_lambda, p_mu, theta, alpha) and (rho, p_rho) apart, compiled DOP853 each",
    )

    def integrate(self, body: Body, y0, times, *, tol: Tolerances, u=None, R0=None, with_rotation=False) -> Solution:
        from flatbody_env.integrators import ladder_kernels as _lk
        from flatbody_env.integrators.compiled_methods import kernel_params

        name = self.info.name
        _check_adaptive("planar", tol)
        y0 = np.array(y0, dtype=float)
        uu = _controls(u)
        check_rung("planar", y0, body, uu)
        times = _times(times)
        P = kernel_params(body)
        x0 = np.array([y0[7], y0[8], y0[4], y0[5], y0[10], 0.0])
        check_gap = bool(y0[2] != y0[3])
        start = time.perf_counter()
        Xp, cp = _small(_lk.dop853_inplane, x0, times, _template(y0), uu, P, tol, check_gap, name)
        Xr, cr = _thickness(
            y0, times, uu, P, tol, name, spent=(int(cp[0]), time.perf_counter() - start)
        )  # one budget for both
        Y = np.repeat(_template(y0)[:, None], times.size, axis=1)
        Y[7], Y[8], Y[4], Y[5], Y[10] = Xp[0], Xp[1], Xp[2], Xp[3], Xp[4]
        Y[9], Y[6] = Xr[0], Xr[1]
        rotation = rotation_about_normal(np.eye(3) if R0 is None else R0, Xp[5]) if with_rotation else None
        H = _energy(Y, P, times, tol, name, uu)
        stats = {
            "energy": H,
            "inplane_steps": int(cp[1]),
            "thickness_steps": int(cr[1]),
            "inplane_nfev": int(cp[0]),
            "thickness_nfev": int(cr[0]),
        }
        return Solution(t=times.copy(), Y=Y, rotation=rotation, nfev=int(cp[0] + cr[0]), stats=stats)


def _phase_change(z0: complex, zd0: complex, w: float, dt: np.ndarray) -> np.ndarray:
    """arg z(t) − arg z(0), continuous, along z(t) = z0 cos wt + (zd0/w) sin wt (module docstring).

    With z = P e^{iwt} + Q e^{−iwt}, P = (z0 − i zd0/w)/2, Q = (z0 + i zd0/w)/2: for |P| > |Q|,
    arg z = wt + arg P + Arg(1 + (Q/P) e^{−2iwt}) with |Q/P| < 1, so the last term is a principal
    value that never jumps (and the mirror formula for |Q| > |P|). ``dt`` starts at 0.
    """
    B = zd0 / w
    Pc = 0.5 * (z0 - 1j * B)
    Qc = 0.5 * (z0 + 1j * B)
    if abs(Pc) >= abs(Qc):
        ph = w * dt + np.angle(1.0 + (Qc / Pc) * np.exp(-2j * w * dt))
        ph0 = np.angle(1.0 + Qc / Pc)
    else:
        ph = -w * dt + np.angle(1.0 + (Pc / Qc) * np.exp(2j * w * dt))
        ph0 = np.angle(1.0 + Pc / Qc)
    return ph - ph0


def _sq_modulus_coeffs(z0: complex, B: complex) -> tuple[float, float, float]:
    """|z0 cos x + B sin x|² = c0 + c1 cos 2x + c2 sin 2x."""
    a2, b2 = abs(z0) ** 2, abs(B) ** 2
    return 0.5 * (a2 + b2), 0.5 * (a2 - b2), float((np.conj(z0) * B).real)


def first_collapse_time(zp0: complex, zpd0: complex, zm0: complex, zmd0: complex, w: float) -> float:
    """First t ≥ 0 with det Φ₂ = |z₊|² − |z₋|² ≤ 0 (μ → 0: V1 has no barrier, erratum E10), or inf."""
    p = _sq_modulus_coeffs(zp0, zpd0 / w)
    m = _sq_modulus_coeffs(zm0, zmd0 / w)
    c0, c1, c2 = p[0] - m[0], p[1] - m[1], p[2] - m[2]
    rho = math.hypot(c1, c2)
    if c0 - rho > 0.0:
        return math.inf
    phi = math.atan2(c2, c1)
    beta = math.acos(max(-1.0, min(1.0, -c0 / rho)))
    x0 = (-phi) % (2.0 * math.pi)
    if beta <= x0 <= 2.0 * math.pi - beta:
        return 0.0
    x = (beta - x0) if x0 < beta else (2.0 * math.pi + beta - x0)
    return x / (2.0 * w)


class PlanarV1Model:
    """Rung 3: planar motion with V1, the in-plane block in closed form (module docstring)."""

    info = MethodInfo(
        name="ladder-planar-V1",
        adaptive=True,
        order=8,
        chart="planar-V1",
        compiled=True,
        preserves=("s1 = s2 = 0", "s3", "p_theta", "in-plane motion exact"),
        description="planar V1: the in-plane block of Phi is an isotropic oscillator (exact, O(1) per time); rho by compiled DOP853",
    )

    def integrate(self, body: Body, y0, times, *, tol: Tolerances, u=None, R0=None, with_rotation=False) -> Solution:
        from flatbody_env.integrators.compiled_methods import kernel_params

        name = self.info.name
        _check_adaptive("planar-V1", tol)
        y0 = np.array(y0, dtype=float)
        uu = _controls(u)
        check_rung("planar-V1", y0, body, uu)
        times = _times(times)
        J = body.inertia.J1
        w = math.sqrt(body.potential.k / J)
        lam0, mu0, th0 = y0[7], y0[8], y0[10]
        vel = velocities_from_momenta(y0, body)
        # z± and their rates at t = 0 (module docstring; α(0) = 0, α̇ = ω3, eq. (25)):
        # z₊ = (λ+μ)/2·e^{−i(α+θ)}, z₋ = (λ−μ)/2·e^{i(θ−α)}
        u0, v0 = lam0 + mu0, lam0 - mu0
        ud0, vd0 = vel["lambda_dot"] + vel["mu_dot"], vel["lambda_dot"] - vel["mu_dot"]
        ep, em = complex(math.cos(th0), -math.sin(th0)), complex(math.cos(th0), math.sin(th0))
        zp0 = 0.5 * u0 * ep
        zm0 = 0.5 * v0 * em
        zpd0 = complex(0.5 * ud0, -0.5 * u0 * (vel["omega3"] + vel["theta_dot"])) * ep
        zmd0 = complex(0.5 * vd0, 0.5 * v0 * (vel["theta_dot"] - vel["omega3"])) * em
        dt = times - times[0]
        t_hit = first_collapse_time(zp0, zpd0, zm0, zmd0, w)
        if t_hit <= dt[-1]:
            raise IntegrationError(
                "mu reached 0: V1 has no barrier and the plate collapsed to a segment (det Phi = 0)",
                t=times[0] + t_hit,
                method=name,
                kind="domain",
            )
        c, s = np.cos(w * dt), np.sin(w * dt)
        zp = zp0 * c + zpd0 * s / w
        zm = zm0 * c + zmd0 * s / w
        zpd = -w * zp0 * s + zpd0 * c
        zmd = -w * zm0 * s + zmd0 * c
        sp, sm = y0[2] + y0[3], y0[2] - y0[3]
        if sp != 0.0:
            upart = 2.0 * np.abs(zp)
            udot = 2.0 * (np.conj(zp) * zpd).real / np.abs(zp)
            bplus = th0 - _phase_change(zp0, zpd0, w, dt)  # α + θ = −arg z₊
        else:  # z₊ on a segment: α + θ constant, λ + μ signed (reaching 0 is a collapse, caught above)
            e = np.exp(1j * th0)
            upart = 2.0 * (zp * e).real
            udot = 2.0 * (zpd * e).real
            bplus = np.full(dt.shape, th0)
        if sm != 0.0:
            sgn = 1.0 if lam0 > mu0 else -1.0
            vpart = sgn * 2.0 * np.abs(zm)
            vdot = sgn * 2.0 * (np.conj(zm) * zmd).real / np.abs(zm)
            bminus = th0 + _phase_change(zm0, zmd0, w, dt)  # θ − α = arg z₋ (+ π when λ < μ)
        else:  # z₋ on a segment through 0: θ − α constant, λ − μ changes sign at λ = μ
            e = np.exp(-1j * th0)
            vpart = 2.0 * (zm * e).real
            vdot = 2.0 * (zmd * e).real
            bminus = np.full(dt.shape, th0)
        P = kernel_params(body)
        Xr, cr = _thickness(y0, times, uu, P, tol, name)
        Y = np.repeat(_template(y0)[:, None], times.size, axis=1)
        Y[7] = 0.5 * (upart + vpart)
        Y[8] = 0.5 * (upart - vpart)
        Y[4] = 0.5 * J * (udot + vdot)
        Y[5] = 0.5 * J * (udot - vdot)
        Y[10] = 0.5 * (bplus + bminus)
        Y[7, 0], Y[8, 0], Y[4, 0], Y[5, 0], Y[10, 0] = y0[7], y0[8], y0[4], y0[5], y0[10]
        Y[9], Y[6] = Xr[0], Xr[1]
        alpha = 0.5 * (bplus - bminus)
        rotation = rotation_about_normal(np.eye(3) if R0 is None else R0, alpha) if with_rotation else None
        H = _energy(Y, P, times, tol, name, uu)
        return Solution(
            t=times.copy(),
            Y=Y,
            rotation=rotation,
            nfev=int(cr[0]),
            stats={"energy": H, "thickness_steps": int(cr[1]), "omega": w},
        )


LADDER_MODELS = {"stationary": StationaryModel(), "planar-V1": PlanarV1Model(), "planar": PlanarModel()}
"""The model object of each rung of :data:`LADDER_RUNGS`."""


def rung_model(rung: str):
    """The model (:class:`~flatbody_env.integrators.base.Method` interface) of a rung of :data:`LADDER_RUNGS`."""
    if rung not in LADDER_MODELS:
        raise ValueError(f"model: {rung!r} is no rung below the full models (allowed: {', '.join(LADDER_RUNGS)})")
    return LADDER_MODELS[rung]


__all__ = [
    "GAP_MIN",
    "LADDER_MODELS",
    "LADDER_RUNGS",
    "PlanarModel",
    "PlanarV1Model",
    "RUNGS",
    "RungChoice",
    "STATIONARY_TOL",
    "StationaryModel",
    "check_rung",
    "choose_rung",
    "first_collapse_time",
    "planar_gap_lower_bound",
    "rotation_about_normal",
    "rung_model",
    "rung_reasons",
    "stationary_residual",
]

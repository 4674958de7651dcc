"""Families of stationary ellipses: pseudo-arclength continuation with fold detection.

A family follows the branch-N solutions (eqs. (52)–(54) of [1]) while one parameter varies:
``s3`` or ``p_theta`` (with the other fixed), or a constant of the body (``k``, ``c``, ``d``,
``kappa``, ``a``, ``b``, ``J``, ``J3``). With X = (λ, μ[, ϱ], p) and F the force balance of
:func:`analysis.stationary.equilibrium_equations`, each step predicts along the tangent T (the
null vector of [F_z | F_p]) and corrects by Newton on {F = 0, T·(X − X_pred) = 0}, so the
continuation passes folds (turning points in p), where two solutions meet and disappear. A fold
is detected where p turns back along the branch and is reported only when {F = 0, det F_z = 0}
has a solution there (so a sharp bend near the circle λ = μ is not mistaken for a fold).

The continuation never evaluates the equations outside the requested range [start, stop] (the
Jacobian's difference quotient is one-sided at the range's ends, a step that would leave the range
lands on its end instead), so a range whose ends are a constant's allowed bounds works. A range over
two or more decades is followed in a scaled coordinate — ln p for a constant of the body, asinh(p/σ)
for a spin (σ = max(1, |the held spin|)) — with seeds evenly spaced in it, so each decade gets its
share of steps and seeds. Where each branch ends, and why (the range's end, the search box's edge, the
circle λ = μ, a step that found no solution), is kept in :attr:`Family.ends`.

Seeds: all solutions at several parameter values (the root finder of :mod:`analysis.stationary`);
a seed already on a traced branch is skipped (checked by a Newton solve from the branch). Along
every branch each point is verified (residual) and classified (:mod:`analysis.stability`); changes
of classification are reported as stability changes.

:func:`write_family_csv` / :func:`read_family_csv` save and load the table that
:mod:`analysis.plots` draws.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009), eqs. (52)–(54).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]), §6–§7.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from flatbody_env.physics import validation
from flatbody_env.output import atomic_open
from flatbody_env.physics.body import Body, Inertia
from flatbody_env.physics.potentials import KIND_CUSTOM, V1, V2, V3, ThicknessPotential
from flatbody_env.physics.validation import FAMILY_SEEDS_RANGE

from analysis.stability import analyse_stability, stability_of_shape
from analysis.stationary import (
    DEFAULT_TOL,
    SearchBox,
    build_ellipse,
    check_isotropic,
    equilibrium_equations,
    stationary_ellipses,
)

SPIN_PARAMETERS = ("s3", "p_theta")
BODY_PARAMETERS = ("k", "c", "d", "kappa", "a", "b", "J", "J3")
PARAMETERS = SPIN_PARAMETERS + BODY_PARAMETERS

# --- the defaults of a family and of a stability map: named once here, imported by the command
# (``flatbody family``, ``flatbody stability-map``, ``flatbody sweep``), the service's models and answers ---
DEFAULT_S3 = 2.0
"""s3 held fixed while another parameter varies (:func:`follow_family`, ``--s3``, the family job's ``s3``)."""
DEFAULT_P_THETA = 0.5
"""p_θ held fixed while another parameter varies (:func:`follow_family`, ``--p-theta``, the family job's ``p_theta``)."""
DEFAULT_SEEDS = 5
"""Parameter values at which all solutions are sought (:func:`follow_family`'s ``seeds``, ``--seeds``); bounds:
:data:`~flatbody_env.physics.validation.FAMILY_SEEDS_RANGE`."""
DEFAULT_FAMILY_RANGE = (0.05, 4.0)
"""The parameter range [from, to] of ``flatbody family`` (``--from``, ``--to``), ``flatbody sweep family``
(``--ranges``) and the family job."""
MAP_LAM_RANGE = (1.02, 3.0)
"""The λ range of a stability map (:func:`shape_stability_grid`; ``flatbody stability-map --lam-range``)."""
MAP_MU_RANGE = (0.3, 3.0)
"""The μ range of a stability map (only μ < λ is used; ``--mu-range``)."""
MAP_GRID = 30
"""Grid points per axis of a stability map (``--grid``)."""
GAP_MIN = 1e-3
"""A branch stops where (λ − μ)/(λ + μ) falls below this or changes sign (the circle λ = μ is
outside the two-polar chart; for symmetric V the ellipses tend to it as s3 → p_θ, docs/physics.md §7–§8)."""

CSV_COLUMNS = (
    "branch",
    "event",
    "param_name",
    "param",
    "lambda",
    "mu",
    "rho",
    "s3",
    "p_theta",
    "omega3",
    "theta_dot",
    "energy",
    "residual",
    "max_real_part",
    "classification",
    "nonlinear",
    "kind",
)


@dataclass(frozen=True, kw_only=True)
class FamilyPoint:
    """One point of a branch."""

    param: float
    lam: float
    mu: float
    rho: float
    s3: float
    p_theta: float
    omega3: float
    theta_dot: float
    energy: float
    residual: float
    max_real_part: float
    classification: str
    nonlinear: str
    kind: str


@dataclass(frozen=True, kw_only=True)
class FamilyEvent:
    """A fold (turning point in the parameter) or a change of stability along a branch."""

    kind: str
    """``"fold"`` or ``"stability-change"``."""
    branch: int
    param: float
    lam: float
    mu: float
    detail: str = ""


@dataclass(frozen=True, kw_only=True)
class FamilyEnd:
    """Where a branch stops, and why (two per branch: one at each end)."""

    branch: int
    param: float
    lam: float
    mu: float
    reason: str
    """One of :data:`END_REASONS`."""
    detail: str
    """The reason in words, with the bound or the step that stopped the branch."""


END_REASONS = ("range", "box", "circle", "no-solution", "points")
"""Why a branch ends: ``range`` the end of the requested range; ``box`` the edge of the search box (λ or μ
would leave it); ``circle`` the circle λ = μ (outside the two-polar chart); ``no-solution`` no solution
found within the smallest continuation step; ``points`` the point limit (``max_points``)."""


@dataclass(frozen=True, kw_only=True)
class Family:
    """Branches of stationary ellipses over a parameter range."""

    param_name: str
    param_range: tuple[float, float]
    s3: float
    p_theta: float
    body: Body
    branches: tuple[tuple[FamilyPoint, ...], ...]
    events: tuple[FamilyEvent, ...]
    ends: tuple[FamilyEnd, ...] = ()
    """Where and why each branch stops (:class:`FamilyEnd`), two per branch, in branch order."""
    scale: str = "linear"
    """The continuation coordinate: ``"linear"`` (p), ``"log"`` (ln p) or ``"asinh"`` (a spin over decades)."""
    seeds: tuple[float, ...] = ()
    """The parameter values at which all solutions were sought."""
    empty_seeds: tuple[float, ...] = ()
    """The seeds at which the search box held no stationary ellipse and no branch passes."""

    @property
    def folds(self) -> tuple[FamilyEvent, ...]:
        return tuple(e for e in self.events if e.kind == "fold")


# --------------------------------------------------------------------------------------------
def body_with(body: Body, name: str, value: float) -> Body:
    """A copy of ``body`` with one constant replaced (ValueError if the body has no such constant, or naming
    ``name`` when ``value`` is outside the constant's allowed range)."""
    J, J3 = body.inertia.J1, body.inertia.J3
    pot, th = body.potential, body.thickness
    try:
        if name == "J":
            return replace(body, inertia=Inertia.isotropic(value, J3))
        if name == "J3":
            return replace(body, inertia=Inertia.isotropic(J, value))
        if name in ("a", "b"):
            if th is None:
                raise ValueError(f"param: the body has no thickness potential, cannot vary {name!r}")
            return replace(
                body, thickness=ThicknessPotential(a=value if name == "a" else th.a, b=value if name == "b" else th.b)
            )
        if name == "k" and isinstance(pot, V1):
            return replace(body, potential=V1(k=value))
        if name in ("c", "d") and isinstance(pot, V2):
            return replace(body, potential=V2(c=value if name == "c" else pot.c, d=value if name == "d" else pot.d))
        if name == "kappa" and isinstance(pot, V3):
            return replace(body, potential=V3(kappa=value))
    except ValueError as exc:
        text = str(exc)
        if text.startswith("param:"):
            raise
        # the body's own check names its field (params.J1, potential.kappa): name the constant varied instead
        raise ValueError(f"{name}:{text.split(':', 1)[1] if ':' in text else ' ' + text}") from None
    raise ValueError(
        f"param: {name!r} is not a constant of this body ({body.describe()}); allowed: {', '.join(_allowed(body))}"
    )


def _allowed(body: Body) -> list[str]:
    out = list(SPIN_PARAMETERS) + ["J", "J3"]
    if body.thickness is not None:
        out += ["a", "b"]
    pot = body.potential
    out += {"V1": ["k"], "V2": ["c", "d"], "V3": ["kappa"]}.get(getattr(pot, "name", ""), [])
    return out


DECADES = 2.0
"""A range that spans this many decades or more is followed in a scaled coordinate (:func:`family_scale`)."""


def family_scale(param: str, start: float, stop: float, *, s3: float = DEFAULT_S3, p_theta: float = DEFAULT_P_THETA):
    """The continuation coordinate of a family: ``("linear", 1)``, ``("log", 1)`` for a constant of the body whose
    range spans :data:`DECADES` or more (stop/start ≥ 100), or ``("asinh", σ)`` for a spin whose largest |value|
    is ≥ 100 σ, σ = max(1, |the spin held fixed|) (a range through 0 over decades)."""
    if param in BODY_PARAMETERS:
        return ("log", 1.0) if start > 0 and stop / start >= 10.0**DECADES else ("linear", 1.0)
    sigma = max(1.0, abs(p_theta if param == "s3" else s3))
    return ("asinh", sigma) if max(abs(start), abs(stop)) >= 10.0**DECADES * sigma else ("linear", 1.0)


class _OutsideRange(ValueError):
    """A continuation coordinate outside the requested range: the equations are not evaluated there."""


class _Problem:
    """F(z, q) for the continuation; z = (λ, μ) or (λ, μ, ϱ), q the continuation coordinate of the parameter
    (p itself, ln p or asinh(p/σ): :func:`family_scale`), which never leaves [q(start), q(stop)]."""

    def __init__(
        self,
        body: Body,
        name: str,
        s3: float,
        p_theta: float,
        rho: float | None,
        start: float,
        stop: float,
        scale: tuple[str, float] = ("linear", 1.0),
    ) -> None:
        self.body0, self.name, self.s3, self.pt, self.rho = body, name, s3, p_theta, rho
        self.coupled = body.potential.kind == KIND_CUSTOM
        self._cache: dict[float, Body] = {}
        self.start, self.stop = float(start), float(stop)
        self.scale, self.sigma = scale
        self.q_lo, self.q_hi = self.coord(self.start), self.coord(self.stop)
        self.calls: list[float] = []
        """Every parameter value the equations were evaluated at (kept only while ``record`` is set; tests)."""
        self.record = False

    # the continuation coordinate q of a parameter value p, and back (clamped into [start, stop])
    def coord(self, p: float) -> float:
        if self.scale == "log":
            return math.log(p)
        if self.scale == "asinh":
            return math.asinh(p / self.sigma)
        return float(p)

    def value(self, q: float) -> float:
        q = float(q)
        if not (self.q_lo <= q <= self.q_hi):
            raise _OutsideRange(f"{self.name}: outside the range [{self.start:g}, {self.stop:g}]")
        if q == self.q_lo:
            return self.start
        if q == self.q_hi:
            return self.stop
        p = math.exp(q) if self.scale == "log" else self.sigma * math.sinh(q) if self.scale == "asinh" else q
        return min(max(p, self.start), self.stop)

    def body(self, p: float) -> Body:
        if self.record:
            self.calls.append(p)
        if self.name in SPIN_PARAMETERS:
            return self.body0
        b = self._cache.get(p)
        if b is None:
            if not (math.isfinite(p) and p > 0):
                raise ValueError("non-positive constant")
            b = body_with(self.body0, self.name, p)
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[p] = b
        return b

    def spins(self, p: float) -> tuple[float, float]:
        if self.name == "s3":
            return (p, self.pt)
        if self.name == "p_theta":
            return (self.s3, p)
        return (self.s3, self.pt)

    def rho_of(self, z: np.ndarray, p: float) -> float:
        if self.coupled:
            return float(z[2])
        b = self.body(p)
        if b.thickness is not None:
            return b.thickness.rho_star
        return 1.0 if self.rho is None else self.rho

    def F(self, X: np.ndarray) -> np.ndarray:
        z, p = X[:-1], self.value(X[-1])
        b = self.body(p)
        f = equilibrium_equations(b, "N", self.spins(p), z[0], z[1], self.rho_of(z, p))
        return np.array(f if self.coupled else f[:2], float)

    def jac(self, X: np.ndarray) -> np.ndarray:
        """∂F/∂(z, q) by difference quotients: central, and one-sided in q at the ends of the range."""
        n = X.size
        out = np.empty((n - 1, n))
        for i in range(n):
            h = 1e-6 * max(abs(X[i]), 1e-2)
            hp = hm = h
            if i == n - 1:
                hp, hm = min(h, self.q_hi - X[i]), min(h, X[i] - self.q_lo)
                if hp + hm <= 0.0:
                    raise _OutsideRange(f"{self.name}: the range is a single point")
            Xp = X.copy()
            Xm = X.copy()
            Xp[i] += hp
            Xm[i] -= hm
            out[:, i] = (self.F(Xp) - self.F(Xm)) / (Xp[i] - Xm[i])
        return out

    def point(self, X: np.ndarray, tol: float) -> FamilyPoint | None:
        z, p = X[:-1], self.value(X[-1])
        b = self.body(p)
        s3, pt = self.spins(p)
        ell = build_ellipse(b, "N", (s3, pt), float(z[0]), float(z[1]), self.rho_of(z, p), "continuation")
        if not ell.residual <= tol:
            return None
        st = analyse_stability(b, ell)
        return FamilyPoint(
            param=p,
            lam=ell.lam,
            mu=ell.mu,
            rho=ell.rho,
            s3=s3,
            p_theta=pt,
            omega3=ell.omega3,
            theta_dot=ell.theta_dot,
            energy=ell.energy,
            residual=ell.residual,
            max_real_part=st.max_real_part,
            classification=st.classification,
            nonlinear=st.nonlinear,
            kind=ell.kind,
        )


def _tangent(prob: _Problem, X: np.ndarray, prev: np.ndarray | None, direction: float) -> np.ndarray:
    _, _, Vt = np.linalg.svd(prob.jac(X))
    T = Vt[-1]
    if prev is not None:
        if T @ prev < 0:
            T = -T
    elif T[-1] * direction < 0:
        T = -T
    return T / np.linalg.norm(T)


def _correct(prob: _Problem, Xp: np.ndarray, T: np.ndarray, tol: float) -> tuple[np.ndarray | None, int, bool]:
    """Newton on {F = 0, T·(X − Xp) = 0} from the predictor Xp: (X or None, iterations, whether an iterate
    left the range)."""
    X = Xp.copy()
    for it in range(1, 12):
        try:
            f = prob.F(X)
            g = np.concatenate([f, [T @ (X - Xp)]])
            if not np.all(np.isfinite(g)):
                return None, it, False
            A = np.vstack([prob.jac(X), T])
            dX = np.linalg.solve(A, -g)
        except _OutsideRange:
            return None, it, True
        except (ValueError, ZeroDivisionError, FloatingPointError, np.linalg.LinAlgError):
            return None, it, False
        X = X + dX
        if np.any(X[:-1] <= 0):
            return None, it, False
        if not (prob.q_lo <= X[-1] <= prob.q_hi):
            return None, it, True
        if np.max(np.abs(dX)) < 1e-13 * max(1.0, np.max(np.abs(X))):
            return X, it, False
    f = prob.F(X)
    return (X, 12, False) if np.max(np.abs(f)) < tol else (None, 12, False)


def _in_domain(X: np.ndarray, box: SearchBox, prob: _Problem) -> bool:
    lam, mu = X[0], X[1]
    if not (box.lam[0] <= lam <= box.lam[1] and box.mu[0] <= mu <= box.mu[1]):
        return False
    return abs(lam - mu) / (lam + mu) >= GAP_MIN


def _why_outside(X: np.ndarray, box: SearchBox) -> tuple[str, str]:
    """(reason, detail) of a continuation point outside the domain (:func:`_in_domain`)."""
    lam, mu = float(X[0]), float(X[1])
    for sym, v, (lo, hi) in (("λ", lam, box.lam), ("μ", mu, box.mu)):
        if v > hi:
            return "box", f"{sym} would exceed {hi:g}, the search box's edge (lam_range, mu_range widen it)"
        if v < lo:
            return "box", f"{sym} would fall below {lo:g}, the search box's edge (lam_range, mu_range widen it)"
    return "circle", "it reaches the circle λ = μ, outside the two-polar chart"


def _solve_at(prob: _Problem, z0: np.ndarray, q: float) -> np.ndarray | None:
    def f(z):
        return prob.F(np.concatenate([z, [q]]))

    from scipy.optimize import root  # here, not at import: flatbody --help reads the defaults without scipy

    try:
        with np.errstate(all="ignore"):
            sol = root(f, z0, method="hybr", options={"xtol": 1e-14})
    except (ValueError, ZeroDivisionError):
        return None
    if not np.all(np.isfinite(sol.x)) or np.any(sol.x <= 0) or np.max(np.abs(f(sol.x))) > 1e-10:
        return None
    return sol.x


def _trace(
    prob: _Problem,
    X0: np.ndarray,
    direction: float,
    box: SearchBox,
    h0: float,
    h_max: float,
    max_points: int,
    tol: float,
) -> tuple[list[np.ndarray], tuple[str, str]]:
    """Follow the branch through X0 in ``direction``: its points, and (reason, detail) of where it stops
    (:data:`END_REASONS`). A step that would leave the range lands on the range's end instead."""
    p_lo, p_hi = prob.q_lo, prob.q_hi
    pts = [X0]
    X = X0
    T = _tangent(prob, X, None, direction)
    h = h0
    while len(pts) < max_points:
        Xp = X + h * T
        outside = not (p_lo <= Xp[-1] <= p_hi)
        Xn = None
        if not outside:
            Xn, its, outside = _correct(prob, Xp, T, tol)
        if outside:
            # land exactly on the end of the parameter range the step would cross
            pb = p_hi if Xp[-1] > X[-1] else p_lo
            if abs(pb - X[-1]) <= 1e-12 * max(1.0, abs(pb)):
                return pts, ("range", "the end of the requested range")
            frac = (pb - X[-1]) / (Xp[-1] - X[-1]) if Xp[-1] != X[-1] else 1.0
            zb = _solve_at(prob, X[:-1] + min(max(frac, 0.0), 1.0) * (Xp[:-1] - X[:-1]), pb)
            if zb is not None:
                Xb = np.concatenate([zb, [pb]])
                if not _in_domain(Xb, box, prob) or (Xb[0] - Xb[1]) * (X0[0] - X0[1]) <= 0:
                    return pts, _why_outside(Xb, box)
                pts.append(Xb)
                return pts, ("range", "the end of the requested range")
        if Xn is None or np.linalg.norm(Xn - X) > 3 * h:
            h *= 0.5
            if h < 1e-6 * h_max:
                return pts, (
                    "no-solution",
                    f"no solution within a continuation step of {h:.2g} (a fold or a singularity?)",
                )
            continue
        if not _in_domain(Xn, box, prob) or (Xn[0] - Xn[1]) * (X0[0] - X0[1]) <= 0:
            return pts, _why_outside(Xn, box)
        if _ends_at_circle(prob, X, Xn):
            return pts, ("circle", "it reaches the circle λ = μ where s3 = p_θ (outside the two-polar chart)")
        T = _tangent(prob, Xn, T, direction)
        pts.append(Xn)
        X = Xn
        if its <= 3:
            h = min(1.5 * h, h_max)
    return pts, ("points", f"the point limit ({max_points} points per direction)")


def _sigma_minus(prob: _Problem, q: float) -> float:
    s3, pt = prob.spins(prob.value(q))
    return s3 - pt


def _ends_at_circle(prob: _Problem, X: np.ndarray, Xn: np.ndarray) -> bool:
    """Does the branch run into the circle λ = μ between X and Xn?

    The equations depend on σ₋² only, so where σ₋ = s3 − p_θ changes sign a branch either passes
    smoothly (a solution with λ ≠ μ at σ₋ = 0, e.g. V2 with c ≠ d) or ends on the circle λ = μ
    (v ~ |σ₋|^{1/2} → 0, outside the chart) — there the arcs for σ₋ > 0 and σ₋ < 0 meet in a cusp
    that a continuation step would jump across, faking a fold.
    """
    if prob.name not in SPIN_PARAMETERS:
        return False
    a, b = _sigma_minus(prob, X[-1]), _sigma_minus(prob, Xn[-1])
    if a * b > 0:
        return False
    q_star = prob.coord(prob.pt if prob.name == "s3" else prob.s3)
    w = 0.5 if Xn[-1] == X[-1] else (q_star - X[-1]) / (Xn[-1] - X[-1])
    zi = X[:-1] + w * (Xn[:-1] - X[:-1])
    zs = _solve_at(prob, zi, q_star)
    if zs is None or abs(zs[0] - zs[1]) / (zs[0] + zs[1]) < GAP_MIN:
        return True
    return bool(np.linalg.norm(zs - zi) > 0.5 * np.linalg.norm(Xn[:-1] - X[:-1]) + 1e-9)


def _refine_fold(prob: _Problem, Xa: np.ndarray, Xm: np.ndarray, Xb: np.ndarray) -> np.ndarray | None:
    """Solve {F = 0, det F_z = 0} from the extreme point Xm of the parameter; None unless it converges
    to a genuine fold (F ≈ 0, F_z singular) between the neighbours Xa, Xb (and inside the range)."""

    def g(X):
        Jz = prob.jac(X)[:, :-1]
        return np.concatenate([prob.F(X), [np.linalg.det(Jz)]])

    from scipy.optimize import root

    try:
        with np.errstate(all="ignore"):
            sol = root(g, Xm, method="hybr", options={"xtol": 1e-13})
    except (ValueError, ZeroDivisionError):
        return None
    X = sol.x
    if not np.all(np.isfinite(X)) or np.any(X[:-1] <= 0) or not (prob.q_lo <= X[-1] <= prob.q_hi):
        return None
    span = np.linalg.norm(Xb - Xa) + 1e-12
    if np.linalg.norm(X - Xm) > span:
        return None
    Jz = prob.jac(X)[:, :-1]
    if np.max(np.abs(prob.F(X))) > 1e-9 or abs(np.linalg.det(Jz)) > 1e-6 * max(1.0, np.linalg.norm(Jz)) ** Jz.shape[0]:
        return None
    return X


def _refine_change(prob: _Problem, Xa: np.ndarray, Xb: np.ndarray, cls_a: str, iterations: int = 40) -> np.ndarray:
    """Bisect in the parameter between two branch points of different classification (the branch is
    single-valued there unless a fold lies between; then the midpoint is returned)."""
    lo, hi = Xa, Xb
    for _ in range(iterations):
        pm = 0.5 * (lo[-1] + hi[-1])
        zi = 0.5 * (lo[:-1] + hi[:-1])
        z = _solve_at(prob, zi, pm)
        if z is None:
            break
        Xm = np.concatenate([z, [pm]])
        fp = prob.point(Xm, 1e-9)
        if fp is None:
            break
        if fp.classification == cls_a:
            lo = Xm
        else:
            hi = Xm
        if abs(hi[-1] - lo[-1]) < 1e-10 * max(1.0, abs(pm)):
            break
    return 0.5 * (lo + hi)


def check_range(
    param: str, start: Any, stop: Any, *, names: tuple[str, str] = ("start", "stop")
) -> tuple[float, float]:
    """A family's range [start, stop], checked before any work: finite numbers, start < stop and, for a constant
    of the body, both within its allowed range (:data:`~flatbody_env.physics.validation.PARAM_RANGE`). ``names``:
    the fields' names in the caller's words (``("from", "to")`` for the service, ``("--from", "--to")`` for the
    command), which the messages start with."""
    validation.string("param", param, choices=PARAMETERS)
    lo_name, hi_name = names
    if param in BODY_PARAMETERS:
        low, high = validation.PARAM_RANGE
        start = validation.number(lo_name, start, low=low, high=high)
        stop = validation.number(hi_name, stop, low=low, high=high)
    else:
        start = validation.number(lo_name, start, low=-validation.MOMENTUM_MAX, high=validation.MOMENTUM_MAX)
        stop = validation.number(hi_name, stop, low=-validation.MOMENTUM_MAX, high=validation.MOMENTUM_MAX)
    validation.requirement(hi_name, stop, start < stop, f"be greater than {lo_name} ({start:g})")
    return start, stop


def follow_family(
    body: Body,
    param: str,
    start: float,
    stop: float,
    *,
    s3: float = DEFAULT_S3,
    p_theta: float = DEFAULT_P_THETA,
    seeds: int = DEFAULT_SEEDS,
    box: SearchBox | None = None,
    step: float | None = None,
    max_points: int = 2000,
    tol: float = DEFAULT_TOL,
    rho: float | None = None,
    progress: bool = False,
    _problem: list | None = None,
) -> Family:
    """Follow every branch-N family while ``param`` runs over [start, stop].

    The equations are never evaluated outside [start, stop] (module docstring); a range over two or more
    decades is followed in a scaled coordinate (:func:`family_scale`).

    Parameters
    ----------
    body : Body
        Isotropic body.
    param : str
        ``"s3"``, ``"p_theta"`` or a constant of the body (:data:`BODY_PARAMETERS`).
    start, stop : float
        The parameter range (start < stop; a constant's within its allowed range, :func:`check_range`).
    s3, p_theta : float
        The spins held fixed (the varied one is ignored).
    seeds : int
        Parameter values (evenly spaced in the continuation coordinate, ends included) at which all
        solutions are sought.
    box : SearchBox, optional
        Search box of the root finder; branches stop at its edges.
    step : float, optional
        Largest continuation step (arclength, in the continuation coordinate: p, ln p or asinh(p/σ));
        default its range/60.
    tol : float
        Residual every point must meet.

    Returns
    -------
    Family
        With :attr:`Family.ends`: where and why each branch stops.
    """
    check_isotropic(body)
    for nm, v in (("s3", s3), ("p_theta", p_theta)):
        validation.number(nm, v)
    start, stop = check_range(param, start, stop)
    if param in BODY_PARAMETERS:
        body_with(body, param, start)  # raises if the body has no such constant
    seeds_lo, seeds_hi = FAMILY_SEEDS_RANGE
    validation.integer("seeds", seeds, low=seeds_lo, high=seeds_hi)
    box = box or SearchBox()
    scale = family_scale(param, start, stop, s3=float(s3), p_theta=float(p_theta))
    prob = _Problem(body, param, float(s3), float(p_theta), rho, start, stop, scale)
    if _problem is not None:  # tests: every parameter value the equations see
        prob.record = True
        _problem.append(prob)
    h_max = step if step is not None else (prob.q_hi - prob.q_lo) / 60.0
    validation.requirement("step", step, h_max > 0, "be > 0")
    traced: list[list[np.ndarray]] = []
    ends_of: list[tuple[tuple[str, str], tuple[str, str]]] = []
    seed_q = np.linspace(prob.q_lo, prob.q_hi, seeds)
    seed_q[0], seed_q[-1] = prob.q_lo, prob.q_hi
    seed_params = [prob.value(q) for q in seed_q]
    empty: list[float] = []
    iterator = list(zip(seed_q, seed_params))
    if progress:
        from flatbody_env.progress import progress_bar

        iterator = progress_bar(iterator, desc=f"family over {param}", unit="seed")
    for qs, ps in iterator:
        b = prob.body(ps)
        s3_p, pt_p = prob.spins(ps)
        found = stationary_ellipses(
            b, s3_p, pt_p, box=box, tol=tol, method="numeric" if prob.coupled else "auto", rho=rho
        )
        if not found:
            empty.append(ps)
        for ell in found:
            z = np.array([ell.lam, ell.mu, ell.rho] if prob.coupled else [ell.lam, ell.mu])
            if _on_branch(prob, traced, z, float(qs)):
                continue
            X0 = np.concatenate([z, [float(qs)]])
            back, back_end = _trace(prob, X0, -1.0, box, 0.2 * h_max, h_max, max_points, 1e-10)
            fwd, fwd_end = _trace(prob, X0, +1.0, box, 0.2 * h_max, h_max, max_points, 1e-10)
            traced.append(back[::-1] + fwd[1:])
            ends_of.append((back_end, fwd_end))
    spans = [(min(X[-1] for X in pts), max(X[-1] for X in pts)) for pts in traced]
    empty = [ps for ps in empty if not any(lo <= prob.coord(ps) <= hi for lo, hi in spans)]
    branches: list[tuple[FamilyPoint, ...]] = []
    events: list[FamilyEvent] = []
    ends: list[FamilyEnd] = []
    for bi, pts in enumerate(traced):
        for X, (reason, detail) in ((pts[0], ends_of[bi][0]), (pts[-1], ends_of[bi][1])):
            ends.append(
                FamilyEnd(
                    branch=bi, param=prob.value(X[-1]), lam=float(X[0]), mu=float(X[1]), reason=reason, detail=detail
                )
            )
        fam = [prob.point(X, tol) for X in pts]
        keep = [k for k, fp in enumerate(fam) if fp is not None]
        pts = [pts[k] for k in keep]
        fam = [fam[k] for k in keep]
        branches.append(tuple(fam))
        for k in range(1, len(pts) - 1):
            d0, d1 = pts[k][-1] - pts[k - 1][-1], pts[k + 1][-1] - pts[k][-1]
            if d0 * d1 < 0:
                Xf = _refine_fold(prob, pts[k - 1], pts[k], pts[k + 1])
                if Xf is not None:
                    events.append(
                        FamilyEvent(
                            kind="fold",
                            branch=bi,
                            param=prob.value(Xf[-1]),
                            lam=float(Xf[0]),
                            mu=float(Xf[1]),
                            detail="turning point in the parameter: two stationary ellipses merge",
                        )
                    )
        for k in range(len(pts) - 1):
            if fam[k].classification != fam[k + 1].classification:
                a, c = fam[k], fam[k + 1]
                Xs = _refine_change(prob, pts[k], pts[k + 1], a.classification)
                events.append(
                    FamilyEvent(
                        kind="stability-change",
                        branch=bi,
                        param=prob.value(Xs[-1]),
                        lam=float(Xs[0]),
                        mu=float(Xs[1]),
                        detail=f"{a.classification} -> {c.classification}",
                    )
                )
    return Family(
        param_name=param,
        param_range=(float(start), float(stop)),
        s3=float(s3),
        p_theta=float(p_theta),
        body=body,
        branches=tuple(branches),
        events=tuple(events),
        ends=tuple(ends),
        scale=scale[0],
        seeds=tuple(seed_params),
        empty_seeds=tuple(empty),
    )


def _on_branch(prob: _Problem, traced: list[list[np.ndarray]], z: np.ndarray, p: float) -> bool:
    for pts in traced:
        for Xa, Xb in zip(pts[:-1], pts[1:]):
            pa, pb = Xa[-1], Xb[-1]
            if min(pa, pb) - 1e-12 <= p <= max(pa, pb) + 1e-12:
                w = 0.0 if pb == pa else (p - pa) / (pb - pa)
                zi = Xa[:-1] + w * (Xb[:-1] - Xa[:-1])
                if np.max(np.abs(zi - z) / z) > 0.2:
                    continue
                zs = _solve_at(prob, zi, p)
                if zs is not None and np.max(np.abs(zs - z) / z) < 1e-7:
                    return True
    return False


def stability_grid(body: Body, s3_values, p_theta_values, *, box: SearchBox | None = None) -> list[dict[str, Any]]:
    """Classification of every branch-N ellipse on a grid of (s3, p_θ) (rows of plain values)."""
    rows = []
    for s3 in s3_values:
        for pt in p_theta_values:
            for ell in stationary_ellipses(body, float(s3), float(pt), box=box):
                st = analyse_stability(body, ell)
                rows.append(
                    {
                        "s3": float(s3),
                        "p_theta": float(pt),
                        "lambda": ell.lam,
                        "mu": ell.mu,
                        "rho": ell.rho,
                        "kind": ell.kind,
                        "classification": st.classification,
                        "nonlinear": st.nonlinear,
                        "max_real_part": st.max_real_part,
                    }
                )
    return rows


SHAPE_COLUMNS = (
    "lambda",
    "mu",
    "rho",
    "s3",
    "p_theta",
    "omega3",
    "theta_dot",
    "energy",
    "kind",
    "classification",
    "nonlinear",
    "max_real_part",
)


def shape_stability_grid(body: Body, lam_values, mu_values, *, progress: bool = False) -> list[dict[str, Any]]:
    """For each shape (λ, μ) with λ > μ on the grid: the spins that make it stationary (inverse problem,
    docs/physics.md §8) — one rigid-like (|s3| > |p_θ|) and one circulating (|p_θ| > |s3|) solution with σ₊ ≥ 0 —
    and their stability. Shapes that cannot be stationary give no row. ``progress``: a bar over the λ rows
    (:func:`flatbody_env.progress.progress_bar`)."""
    from flatbody_env.progress import progress_bar

    rows = []
    for lam in progress_bar(lam_values, desc="stability map", unit="row", enabled=progress):
        for mu in mu_values:
            if not float(lam) > float(mu):
                continue
            for st in stability_of_shape(body, float(lam), float(mu)):
                e = st.ellipse
                rows.append(
                    {
                        "lambda": e.lam,
                        "mu": e.mu,
                        "rho": e.rho,
                        "s3": e.s3,
                        "p_theta": e.p_theta,
                        "omega3": e.omega3,
                        "theta_dot": e.theta_dot,
                        "energy": e.energy,
                        "kind": e.kind,
                        "classification": st.classification,
                        "nonlinear": st.nonlinear,
                        "max_real_part": st.max_real_part,
                    }
                )
    return rows


def write_table_csv(rows: list[dict[str, Any]], path: str | Path, columns: tuple[str, ...] = SHAPE_COLUMNS) -> Path:
    """Write plain rows (e.g. of :func:`shape_stability_grid`) as CSV."""
    path = Path(path)
    with atomic_open(path) as fh:
        w = csv.DictWriter(fh, fieldnames=list(columns))
        w.writeheader()
        for row in rows:
            w.writerow({k: (repr(row[k]) if isinstance(row[k], float) else row[k]) for k in columns})
    return path


# --------------------------------------------------------------------------------------------
def family_rows(family: Family) -> list[dict[str, Any]]:
    rows = []
    for bi, branch in enumerate(family.branches):
        for fp in branch:
            rows.append(
                {
                    "branch": bi,
                    "event": "",
                    "param_name": family.param_name,
                    "param": fp.param,
                    "lambda": fp.lam,
                    "mu": fp.mu,
                    "rho": fp.rho,
                    "s3": fp.s3,
                    "p_theta": fp.p_theta,
                    "omega3": fp.omega3,
                    "theta_dot": fp.theta_dot,
                    "energy": fp.energy,
                    "residual": fp.residual,
                    "max_real_part": fp.max_real_part,
                    "classification": fp.classification,
                    "nonlinear": fp.nonlinear,
                    "kind": fp.kind,
                }
            )
    for ev in family.events:
        row = dict.fromkeys(CSV_COLUMNS, "")
        row.update(
            {
                "branch": ev.branch,
                "event": ev.kind,
                "param_name": family.param_name,
                "param": ev.param,
                "lambda": ev.lam,
                "mu": ev.mu,
                "classification": ev.detail,
            }
        )
        rows.append(row)
    return rows


def write_family_csv(family: Family, path: str | Path) -> Path:
    """Save the family table (one row per point; events as rows with ``event`` set)."""
    path = Path(path)
    with atomic_open(path) as fh:
        w = csv.DictWriter(fh, fieldnames=list(CSV_COLUMNS))
        w.writeheader()
        for row in family_rows(family):
            w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in row.items()})
    return path


def read_family_csv(path: str | Path) -> list[dict[str, Any]]:
    """Load a table written by :func:`write_family_csv` (numbers as floats, ``branch`` as int)."""
    import io

    path = Path(path)
    if not path.exists():
        raise ValueError(f"family: no file {str(path)!r}")
    out = []
    reader = csv.DictReader(io.StringIO(validation.read_text("family", path), newline=""))  # the one reading door
    if reader.fieldnames is None or "param" not in reader.fieldnames:
        raise ValueError(f"family: {path} is not a family table (columns {', '.join(CSV_COLUMNS)})")
    for row in reader:
        rec: dict[str, Any] = {}
        for k, v in row.items():
            if k in ("event", "param_name", "classification", "nonlinear", "kind"):
                rec[k] = v
            elif k == "branch":
                rec[k] = int(v)
            else:
                rec[k] = float(v) if v != "" else math.nan
        out.append(rec)
    return out


__all__ = [
    "BODY_PARAMETERS",
    "CSV_COLUMNS",
    "DEFAULT_FAMILY_RANGE",
    "DEFAULT_P_THETA",
    "DEFAULT_S3",
    "DEFAULT_SEEDS",
    "MAP_GRID",
    "MAP_LAM_RANGE",
    "MAP_MU_RANGE",
    "Family",
    "FamilyEvent",
    "FamilyEnd",
    "FamilyPoint",
    "END_REASONS",
    "check_range",
    "family_scale",
    "PARAMETERS",
    "SPIN_PARAMETERS",
    "body_with",
    "family_rows",
    "follow_family",
    "read_family_csv",
    "SHAPE_COLUMNS",
    "shape_stability_grid",
    "stability_grid",
    "write_table_csv",
    "write_family_csv",
]

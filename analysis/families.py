"""Families of stationary ellipses: pseudo-arclength continuation with fold detection.

A family follows the branch-N solutions (eqs. (52)–(54) of [1]) while one parameter varies:
``s3`` or ``p_theta`` (with the other fixed), or a constant of the body (``k``, ``c``, ``d``,
``kappa``, ``a``, ``b``, ``J``, ``J3``). With X = (λ, μ[, ϱ], p) and F the force balance of
:func:`analysis.stationary.equilibrium_equations`, each step predicts along the tangent T (the
null vector of [F_z | F_p]) and corrects by Newton on {F = 0, T·(X − X_pred) = 0}, so the
continuation passes folds (turning points in p), where two solutions meet and disappear. A fold
is detected where p turns back along the branch and is reported only when {F = 0, det F_z = 0}
has a solution there (so a sharp bend near the circle λ = μ is not mistaken for a fold).

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
class Family:
    """Branches of stationary ellipses over a parameter range."""

    param_name: str
    param_range: tuple[float, float]
    s3: float
    p_theta: float
    body: Body
    branches: tuple[tuple[FamilyPoint, ...], ...]
    events: tuple[FamilyEvent, ...]

    @property
    def folds(self) -> tuple[FamilyEvent, ...]:
        return tuple(e for e in self.events if e.kind == "fold")


# --------------------------------------------------------------------------------------------
def body_with(body: Body, name: str, value: float) -> Body:
    """A copy of ``body`` with one constant replaced (ValueError if the body has no such constant)."""
    J, J3 = body.inertia.J1, body.inertia.J3
    pot, th = body.potential, body.thickness
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


class _Problem:
    """F(z, p) for the continuation; z = (λ, μ) or (λ, μ, ϱ)."""

    def __init__(self, body: Body, name: str, s3: float, p_theta: float, rho: float | None) -> None:
        self.body0, self.name, self.s3, self.pt, self.rho = body, name, s3, p_theta, rho
        self.coupled = body.potential.kind == KIND_CUSTOM
        self._cache: dict[float, Body] = {}

    def body(self, p: float) -> Body:
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
        z, p = X[:-1], float(X[-1])
        b = self.body(p)
        f = equilibrium_equations(b, "N", self.spins(p), z[0], z[1], self.rho_of(z, p))
        return np.array(f if self.coupled else f[:2], float)

    def jac(self, X: np.ndarray) -> np.ndarray:
        n = X.size
        out = np.empty((n - 1, n))
        for i in range(n):
            h = 1e-6 * max(abs(X[i]), 1e-2)
            Xp = X.copy()
            Xm = X.copy()
            Xp[i] += h
            Xm[i] -= h
            out[:, i] = (self.F(Xp) - self.F(Xm)) / (2.0 * h)
        return out

    def point(self, X: np.ndarray, tol: float) -> FamilyPoint | None:
        z, p = X[:-1], float(X[-1])
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


def _correct(prob: _Problem, Xp: np.ndarray, T: np.ndarray, tol: float) -> tuple[np.ndarray | None, int]:
    X = Xp.copy()
    for it in range(1, 12):
        try:
            f = prob.F(X)
        except (ValueError, ZeroDivisionError, FloatingPointError):
            return None, it
        g = np.concatenate([f, [T @ (X - Xp)]])
        if not np.all(np.isfinite(g)):
            return None, it
        A = np.vstack([prob.jac(X), T])
        try:
            dX = np.linalg.solve(A, -g)
        except np.linalg.LinAlgError:
            return None, it
        X = X + dX
        if np.any(X[:-1] <= 0):
            return None, it
        if np.max(np.abs(dX)) < 1e-13 * max(1.0, np.max(np.abs(X))):
            return X, it
    f = prob.F(X)
    return (X, 12) if np.max(np.abs(f)) < tol else (None, 12)


def _in_domain(X: np.ndarray, box: SearchBox, prob: _Problem) -> bool:
    lam, mu = X[0], X[1]
    if not (box.lam[0] <= lam <= box.lam[1] and box.mu[0] <= mu <= box.mu[1]):
        return False
    return abs(lam - mu) / (lam + mu) >= GAP_MIN


def _solve_at(prob: _Problem, z0: np.ndarray, p: float) -> np.ndarray | None:
    def f(z):
        return prob.F(np.concatenate([z, [p]]))

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
    p_lo: float,
    p_hi: float,
    box: SearchBox,
    h0: float,
    h_max: float,
    max_points: int,
    tol: float,
) -> list[np.ndarray]:
    pts = [X0]
    X = X0
    T = _tangent(prob, X, None, direction)
    h = h0
    while len(pts) < max_points:
        Xn, its = _correct(prob, X + h * T, T, tol)
        if Xn is None or np.linalg.norm(Xn - X) > 3 * h:
            h *= 0.5
            if h < 1e-6 * h_max:
                break
            continue
        if not (p_lo <= Xn[-1] <= p_hi):
            # land exactly on the boundary of the parameter range
            pb = p_hi if Xn[-1] > p_hi else p_lo
            if abs(pb - X[-1]) <= 1e-12 * max(1.0, abs(pb)):
                break
            frac = (pb - X[-1]) / (Xn[-1] - X[-1])
            zb = _solve_at(prob, X[:-1] + frac * (Xn[:-1] - X[:-1]), pb)
            if zb is not None:
                Xb = np.concatenate([zb, [pb]])
                if _in_domain(Xb, box, prob) and (Xb[0] - Xb[1]) * (X0[0] - X0[1]) > 0:
                    pts.append(Xb)
            break
        if not _in_domain(Xn, box, prob) or (Xn[0] - Xn[1]) * (X0[0] - X0[1]) <= 0:
            break
        if _ends_at_circle(prob, X, Xn):
            break
        T = _tangent(prob, Xn, T, direction)
        pts.append(Xn)
        X = Xn
        if its <= 3:
            h = min(1.5 * h, h_max)
    return pts


def _sigma_minus(prob: _Problem, p: float) -> float:
    s3, pt = prob.spins(p)
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
    p_star = prob.pt if prob.name == "s3" else prob.s3
    w = 0.5 if Xn[-1] == X[-1] else (p_star - X[-1]) / (Xn[-1] - X[-1])
    zi = X[:-1] + w * (Xn[:-1] - X[:-1])
    zs = _solve_at(prob, zi, p_star)
    if zs is None or abs(zs[0] - zs[1]) / (zs[0] + zs[1]) < GAP_MIN:
        return True
    return bool(np.linalg.norm(zs - zi) > 0.5 * np.linalg.norm(Xn[:-1] - X[:-1]) + 1e-9)


def _refine_fold(prob: _Problem, Xa: np.ndarray, Xm: np.ndarray, Xb: np.ndarray) -> np.ndarray | None:
    """Solve {F = 0, det F_z = 0} from the extreme point Xm of the parameter; None unless it converges
    to a genuine fold (F ≈ 0, F_z singular) between the neighbours Xa, Xb."""

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
    if not np.all(np.isfinite(X)) or np.any(X[:-1] <= 0):
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
) -> Family:
    """Follow every branch-N family while ``param`` runs over [start, stop].

    Parameters
    ----------
    body : Body
        Isotropic body.
    param : str
        ``"s3"``, ``"p_theta"`` or a constant of the body (:data:`BODY_PARAMETERS`).
    start, stop : float
        The parameter range (start < stop; constants > 0).
    s3, p_theta : float
        The spins held fixed (the varied one is ignored).
    seeds : int
        Parameter values (evenly spaced, ends included) at which all solutions are sought.
    box : SearchBox, optional
        Search box of the root finder; branches stop at its edges.
    step : float, optional
        Largest continuation step (arclength); default (stop − start)/60.
    tol : float
        Residual every point must meet.

    Returns
    -------
    Family
    """
    check_isotropic(body)
    if param not in PARAMETERS:
        raise ValueError(f"param: must be one of {', '.join(PARAMETERS)}, got {param!r}")
    for nm, v in (("start", start), ("stop", stop), ("s3", s3), ("p_theta", p_theta)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"{nm}: must be a finite number, got {v!r}")
    if not start < stop:
        raise ValueError(f"stop: must be greater than start ({start!r}), got {stop!r}")
    if param in BODY_PARAMETERS:
        if start <= 0:
            raise ValueError(f"start: the constant {param} must stay > 0 (allowed range (0, inf)), got {start!r}")
        body_with(body, param, start)  # raises if the body has no such constant
    seeds_lo, seeds_hi = FAMILY_SEEDS_RANGE
    if not (isinstance(seeds, int) and seeds_lo <= seeds <= seeds_hi):
        raise ValueError(f"seeds: must be an integer in [{seeds_lo}, {seeds_hi}], got {seeds!r}")
    box = box or SearchBox()
    prob = _Problem(body, param, float(s3), float(p_theta), rho)
    h_max = step if step is not None else (stop - start) / 60.0
    if not h_max > 0:
        raise ValueError(f"step: must be > 0, got {step!r}")
    traced: list[list[np.ndarray]] = []
    seed_params = np.linspace(start, stop, seeds)
    iterator = seed_params
    if progress:
        from flatbody_env.progress import progress_bar

        iterator = progress_bar(seed_params, desc=f"family over {param}", unit="seed")
    for ps in iterator:
        b = prob.body(float(ps))
        s3_p, pt_p = prob.spins(float(ps))
        for ell in stationary_ellipses(
            b, s3_p, pt_p, box=box, tol=tol, method="numeric" if prob.coupled else "auto", rho=rho
        ):
            z = np.array([ell.lam, ell.mu, ell.rho] if prob.coupled else [ell.lam, ell.mu])
            if _on_branch(prob, traced, z, float(ps)):
                continue
            X0 = np.concatenate([z, [float(ps)]])
            back = _trace(prob, X0, -1.0, start, stop, box, 0.2 * h_max, h_max, max_points, 1e-10)
            fwd = _trace(prob, X0, +1.0, start, stop, box, 0.2 * h_max, h_max, max_points, 1e-10)
            traced.append(back[::-1] + fwd[1:])
    branches: list[tuple[FamilyPoint, ...]] = []
    events: list[FamilyEvent] = []
    for bi, pts in enumerate(traced):
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
                            param=float(Xf[-1]),
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
                        param=float(Xs[-1]),
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
    "FamilyPoint",
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

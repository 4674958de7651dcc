"""Invariants along a trajectory, and a drift table.

Along a :class:`~flatbody_env.simulation.Trajectory` (or its saved JSON,
``flatbody simulate --with-rotation --out FILE``) this computes

=====================  ====================================================================  ===========
name                   definition                                                            conserved?
=====================  ====================================================================  ===========
``energy``             H (eq. (41) of [1])                                                   yes
``casimir``            |s|² (eq. (43) of [1])                                                yes
``p_theta``            p_θ (eq. (46) of [1], J1 = J2)                                        yes
``lab_spin``           R s (docs/physics.md §6; needs R)                                               yes
``K1, K2, K3``         deformation invariants: eigenvalues of G = ΦᵀΦ, ascending             at stationary
                       (eqs. (34)–(35) of [1]: {λ², μ², ϱ²})                                 ellipses only
``trace_G, det_G``     tr G = λ²+μ²+ϱ², det G = (λμϱ)²                                       idem
``dG/dt, dC/dt``       Frobenius norms of Ġ = U(ϑD² − D²ϑ + 2DḊ)U⁻¹ and                       —
                       Ċ = R(W D⁻² − D⁻² W − 2D⁻³Ḋ)R⁻¹ (eq. (51) of [1] with erratum E7)
=====================  ====================================================================  ===========

At a stationary ellipse Ġ and Ċ are non-zero (G and C rotate rigidly) while every invariant is
constant — the remark at eq. (51) of [1], with C = R D⁻² R⁻¹ (erratum E7, docs/physics.md).

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (verified formulas and errata of [1]), §4, E7.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flatbody_env.physics.body import Body
from flatbody_env.physics.invariants import casimir, laboratory_spin
from flatbody_env.physics.hamiltonian import hamiltonian_series, velocities_from_momenta
from flatbody_env.physics.kinematics import cauchy_rate, cauchy_tensor, deformation_invariants, green_rate, green_tensor
from flatbody_env.simulation import Trajectory, read_trajectory
from flatbody_env.physics.state import STATE_NAMES

CONSERVED = ("energy", "casimir", "p_theta", "lab_spin")
"""Quantities conserved along every uncontrolled isotropic motion (docs/physics.md §6)."""


@dataclass(frozen=True, kw_only=True)
class DriftRow:
    """One row of the drift table."""

    name: str
    initial: float
    """|q(0)| for vectors, q(0) for scalars."""
    max_abs_drift: float
    """max_t |q(t) − q(0)| (vector norm for R s)."""
    max_rel_drift: float
    """max_abs_drift / max(|q(0)|, 1e-300)."""
    conserved: bool
    """Whether the quantity is conserved along every motion (else only at stationary ellipses)."""


@dataclass(frozen=True, kw_only=True)
class InvariantReport:
    """Invariants and deformation tensors along a trajectory."""

    t: np.ndarray
    """Times, shape (n,)."""
    series: dict[str, np.ndarray]
    """Scalar series by name (module table; ``lab_spin`` has shape (n, 3))."""
    G: np.ndarray
    """Green tensor G = ΦᵀΦ, shape (n, 3, 3) (eq. (33) of [1])."""
    C: np.ndarray | None
    """Cauchy tensor C = R D⁻² Rᵀ, shape (n, 3, 3), or None without R (E7)."""
    G_rate: np.ndarray | None
    """Ġ, shape (n, 3, 3), or None without a body (velocities need the inertia)."""
    C_rate: np.ndarray | None
    """Ċ, shape (n, 3, 3), or None without R or body."""
    drift: tuple[DriftRow, ...]

    def drift_dict(self) -> dict[str, float]:
        return {row.name: row.max_abs_drift for row in self.drift}

    def to_dict(self) -> dict[str, Any]:
        """JSON form: the drift table and the final values."""
        return {
            "samples": int(self.t.size),
            "t_end": float(self.t[-1]),
            "drift": [
                {
                    "name": r.name,
                    "initial": r.initial,
                    "max_abs_drift": r.max_abs_drift,
                    "max_rel_drift": r.max_rel_drift,
                    "conserved": r.conserved,
                }
                for r in self.drift
            ],
            "rates": {
                "dG_dt_norm_mean": None
                if self.G_rate is None
                else float(np.mean(np.linalg.norm(self.G_rate, axis=(1, 2)))),
                "dC_dt_norm_mean": None
                if self.C_rate is None
                else float(np.mean(np.linalg.norm(self.C_rate, axis=(1, 2)))),
            },
        }


def _arrays(source: Trajectory | Mapping[str, Any] | str | Path):
    """(t, Y, R, E) of a trajectory, its JSON form or a saved file (read and validated by
    :func:`flatbody_env.simulation.read_trajectory` / :meth:`Trajectory.from_dict`)."""
    if isinstance(source, (str, Path)):
        source = read_trajectory(source)
    elif not isinstance(source, Trajectory):
        source = Trajectory.from_dict(source)
    return source.t, source.y, source.rotation, (source.energy if source.has_energy else None)


def _row(name: str, q: np.ndarray, conserved: bool) -> DriftRow:
    q = np.asarray(q, float)
    if q.ndim == 2:
        d = np.linalg.norm(q - q[0], axis=-1)
        q0 = float(np.linalg.norm(q[0]))
    else:
        d = np.abs(q - q[0])
        q0 = float(q[0])
    m = float(np.max(d))
    return DriftRow(name=name, initial=q0, max_abs_drift=m, max_rel_drift=m / max(abs(q0), 1e-300), conserved=conserved)


def invariants_along(source: Trajectory | Mapping[str, Any] | str | Path, body: Body | None = None) -> InvariantReport:
    """Invariants, G, C and their rates along a trajectory, with a drift table.

    Parameters
    ----------
    source : Trajectory, dict or path
        A trajectory from :func:`flatbody_env.simulation.simulate`, its ``to_dict()`` form, or a
        saved JSON file.
    body : Body, optional
        Needed for H (when the file has no ``energy``) and for the rates Ġ, Ċ (velocities from
        momenta); without it those are taken from the file or left out.

    Returns
    -------
    InvariantReport
    """
    t, Y, R, E = _arrays(source)
    with np.errstate(all="ignore"):  # a singular state gives NaN/inf, refused below with the reason (no warnings)
        return _invariants(t, Y, R, E, body)


def _invariants(t, Y, R, E, body: Body | None) -> InvariantReport:
    st = {n: Y[i] for i, n in enumerate(STATE_NAMES)}
    lam, mu, rho, theta = st["lambda"], st["mu"], st["rho"], st["theta"]
    G = green_tensor(lam, mu, rho, theta)
    K = deformation_invariants(G)
    series: dict[str, np.ndarray] = {}
    if body is not None:
        series["energy"] = hamiltonian_series(Y, body)
    elif E is not None:
        series["energy"] = E
    series["casimir"] = casimir(st["s1"], st["s2"], st["s3"])
    series["p_theta"] = st["p_theta"].copy()
    C = None
    if R is not None:
        series["lab_spin"] = laboratory_spin(R, Y[:3].T)
        C = cauchy_tensor(lam, mu, rho, R)
    series["K1"], series["K2"], series["K3"] = K[:, 0], K[:, 1], K[:, 2]
    series["trace_G"] = np.trace(G, axis1=1, axis2=2)
    series["det_G"] = np.linalg.det(G)
    G_rate = C_rate = None
    if body is not None:
        vel = [velocities_from_momenta(Y[:, k], body) for k in range(t.size)]
        v = {name: np.array([x[name] for x in vel]) for name in vel[0]}
        G_rate = green_rate(lam, mu, rho, theta, v["theta_dot"], v["lambda_dot"], v["mu_dot"], v["rho_dot"])
        series["dG/dt"] = np.linalg.norm(G_rate, axis=(1, 2))
        if R is not None:
            omega = np.stack([v["omega1"], v["omega2"], v["omega3"]], axis=-1)
            C_rate = cauchy_rate(lam, mu, rho, R, omega, v["lambda_dot"], v["mu_dot"], v["rho_dot"])
            series["dC/dt"] = np.linalg.norm(C_rate, axis=(1, 2))
    # no silent non-finite numbers: a singular state (e.g. lambda = mu, where the two-polar velocities
    # diverge) makes a quantity NaN/inf; it is refused with the reason, never reported or called conserved
    from flatbody_env.physics import validation

    validation.finite_result("invariants", {**series, "G": G, "C": C})
    rows = [_row(name, series[name], True) for name in CONSERVED if name in series]
    rows += [_row(name, series[name], False) for name in ("K1", "K2", "K3", "trace_G", "det_G")]
    return InvariantReport(t=t, series=series, G=G, C=C, G_rate=G_rate, C_rate=C_rate, drift=tuple(rows))


def format_drift_table(report: InvariantReport) -> str:
    """Human-readable drift table."""
    lines = [f"{report.t.size} samples, t in [{report.t[0]:g}, {report.t[-1]:g}]", ""]
    lines.append(f"{'quantity':<10} {'initial':>16} {'max |drift|':>12} {'relative':>10}  conserved")
    for r in report.drift:
        lines.append(
            f"{r.name:<10} {r.initial:16.10g} {r.max_abs_drift:12.3e} {r.max_rel_drift:10.2e}  "
            f"{'always' if r.conserved else 'at stationary ellipses'}"
        )
    if report.G_rate is not None:
        g = report.series["dG/dt"]
        lines.append("")
        lines.append(
            f"|dG/dt| in [{g.min():.4g}, {g.max():.4g}]"
            + (
                f", |dC/dt| in [{report.series['dC/dt'].min():.4g}, {report.series['dC/dt'].max():.4g}]"
                if report.C_rate is not None
                else ""
            )
        )
    return "\n".join(lines)


__all__ = ["CONSERVED", "DriftRow", "InvariantReport", "format_drift_table", "invariants_along"]

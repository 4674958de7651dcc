"""``simulate``: integrate a scene and return a :class:`Trajectory` in the paper's variables.

Model selection ("model no more than a scene needs")
-----------------------------------------------------
``model="auto"`` picks the lowest rung of the model ladder (:mod:`flatbody_env.integrators.ladder`)
that the initial state, the body and the controls allow: a stationary ellipse (exact), planar
motion with V1 (exact in-plane), planar motion (two small systems) — these three with an
adaptive method only — then the two-polar equations (eqs. (44)–(49) of [1], 11 variables)
when the scene provably stays away from the chart's singular set λ = μ, and the regular
matrix formulation (18 variables plus two constraints) otherwise. ``model=`` names a rung to
force it (a ``ValueError`` says which invariant the scene breaks); ``Trajectory.model`` and
``meta["rung"]`` name the rung, ``meta["rung_invariant"]`` / ``meta["rung_measured"]`` why.
Between the two full models:

* J1 = J2 (p_θ and σ₋ = s3 − p_θ conserved) and the energy bound of the centrifugal barrier
  σ₋²/(4J(λ−μ)²) ≤ H − inf V gives |λ − μ| ≥ |σ₋| / √(4J (H − inf V)) ≥ :data:`GAP_MIN`
  along the whole trajectory → ``"two-polar"``;
* otherwise (J1 ≠ J2, σ₋ too small, or no lower bound of V known) → ``"regular"``.

A method name that belongs to one chart (``"DOP853"`` two-polar, ``"DOP853-regular"``) is
mapped to its twin in the chosen chart when one exists; a method without a twin (the compiled
ones, e.g. ``"RK4"``) runs in its own chart, and a failure near λ = μ is reported
(:class:`IntegrationError`), not hidden. Fixed-step methods need ``step=``.

References
----------
.. [1] A. Kovalchuk, E. Rożko, the paper on affinely-rigid bodies with thickness in degenerate
   dimension; its corrected equations and errata: ``docs/physics.md``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flatbody_env.physics.body import Body
from flatbody_env.physics.invariants import casimir, laboratory_spin
from flatbody_env.physics.hamiltonian import hamiltonian
from flatbody_env.integrators import IntegrationError, Tolerances, get_method
from flatbody_env.scene import Scene, SceneError, load_scene
from flatbody_env.physics.state import STATE_NAMES, pack, unpack

from flatbody_env.integrators.ladder import GAP_MIN, LADDER_RUNGS, RUNGS, RungChoice, check_rung, choose_rung, rung_model, rung_reasons

FIXED_STEP_ENERGY_TOL = 1e-3
"""Default relative energy tolerance of fixed-step methods (a blow-up detector, not an accuracy target)."""

MODELS = ("auto",) + RUNGS
DEFAULT_SAMPLES = 101


def gap_lower_bound(state: Mapping[str, float] | np.ndarray, body: Body) -> float:
    """A rigorous lower bound of |λ − μ| along the uncontrolled isotropic motion (0 if none).

    From H = 𝒯 + V with every term of 𝒯 (eq. (32) of [1]; docs/physics.md) non-negative,
    σ₋²/(4J(λ−μ)²) ≤ H − inf V, so |λ − μ| ≥ |σ₋| / √(4J(H − inf V)).
    """
    y = pack(state, validate=False) if isinstance(state, Mapping) else np.asarray(state, float)
    if not body.inertia.is_isotropic:
        return 0.0
    lb = body.potential_lower_bound
    if not math.isfinite(lb):
        return 0.0
    sigma_minus = abs(y[2] - y[3])
    avail = hamiltonian(y, body) - lb
    if avail <= 0.0:
        return math.inf if sigma_minus > 0 else 0.0
    return sigma_minus / math.sqrt(4.0 * body.inertia.J1 * avail)


def choose_model(state: Mapping[str, float] | np.ndarray, body: Body, u: np.ndarray | None = None, *, ladder: bool = True) -> str:
    """The rung ``model="auto"`` runs (:data:`MODELS`), per the rule in the module docstring."""
    return explain_model(state, body, u, ladder=ladder).rung


def explain_model(state: Mapping[str, float] | np.ndarray, body: Body, u: np.ndarray | None = None, *, ladder: bool = True) -> RungChoice:
    """The rung ``model="auto"`` runs and why (:class:`~flatbody_env.integrators.ladder.RungChoice`);
    ``ladder=False`` chooses between the two full models only."""
    y = pack(state, validate=False) if isinstance(state, Mapping) else np.asarray(state, float)
    if ladder:
        low = choose_rung(y, body, u)
        if low is not None:
            return low
    bound = gap_lower_bound(y, body) if u is None or not np.any(u) else 0.0
    if bound >= GAP_MIN:
        return RungChoice(rung="two-polar", invariant=f"J1 = J2 and the energy bound keeps |lambda - mu| >= {bound:.3g} >= {GAP_MIN:g}",
                          measured={"gap_lower_bound": float(bound)})
    why = "; ".join(f"{r}: {t}" for r, t in rung_reasons(y, body, u).items() if t)
    return RungChoice(rung="regular", invariant=f"no lower rung holds (two-polar: |lambda - mu| >= {bound:.3g} < {GAP_MIN:g} guaranteed"
                      + (f"; {why})" if why else ")"), measured={"gap_lower_bound": float(bound)})


@dataclass
class Trajectory:
    """A solution in the paper's variables.

    Attributes
    ----------
    t : ndarray (n,)
        Times.
    state : dict[str, ndarray (n,)]
        The eleven state entries (:data:`flatbody_env.physics.state.STATE_NAMES`).
    energy : ndarray (n,)
        H (eq. (41) of [1]).
    casimir : ndarray (n,)
        |s|².
    p_theta : ndarray (n,)
        p_θ (conserved for J1 = J2).
    rotation : ndarray (n, 3, 3) or None
        R(t), when asked for (``with_rotation=True``) or when the regular model ran.
    method, model : str
        What integrated it.
    nfev : int
        Right-hand-side evaluations.
    wall_time : float
        Seconds spent integrating.
    """

    t: np.ndarray
    state: dict[str, np.ndarray]
    energy: np.ndarray
    casimir: np.ndarray
    p_theta: np.ndarray
    rotation: np.ndarray | None
    method: str
    model: str
    nfev: int = 0
    wall_time: float = 0.0
    scene: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def lab_spin(self) -> np.ndarray | None:
        """R s, shape (n, 3) (conserved with the corrected bracket; docs/physics.md), or None without R."""
        if self.rotation is None:
            return None
        s = np.stack([self.state["s1"], self.state["s2"], self.state["s3"]], axis=-1)
        return laboratory_spin(self.rotation, s)

    @property
    def y(self) -> np.ndarray:
        """Packed states, shape (11, n)."""
        return np.stack([self.state[name] for name in STATE_NAMES])

    def drift(self) -> dict[str, float]:
        """Max |q(t) − q(0)| of H, |s|², p_θ (and |R s − R₀ s₀| when R is known)."""
        out = {
            "energy": float(np.max(np.abs(self.energy - self.energy[0]))),
            "casimir": float(np.max(np.abs(self.casimir - self.casimir[0]))),
            "p_theta": float(np.max(np.abs(self.p_theta - self.p_theta[0]))),
        }
        ls = self.lab_spin
        if ls is not None:
            out["lab_spin"] = float(np.max(np.linalg.norm(ls - ls[0], axis=-1)))
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON form: ``{"t", "state", "energy", "casimir", "p_theta", ["rotation"], "meta"}``."""
        out: dict[str, Any] = {
            "t": self.t.tolist(),
            "state": {name: self.state[name].tolist() for name in STATE_NAMES},
            "energy": self.energy.tolist(),
            "casimir": self.casimir.tolist(),
            "p_theta": self.p_theta.tolist(),
        }
        if self.rotation is not None:
            out["rotation"] = self.rotation.tolist()
        out["meta"] = {"scene": self.scene, "method": self.method, "model": self.model, "nfev": self.nfev, "wall_time": self.wall_time, **self.extra}
        return out


def _resolve_times(t_end: float, times: Sequence[float] | np.ndarray | None) -> np.ndarray:
    if isinstance(t_end, bool) or not isinstance(t_end, (int, float, np.floating, np.integer)) or not math.isfinite(float(t_end)) or t_end <= 0:
        raise ValueError(f"t_end: must be a finite number > 0 (allowed range (0, inf)), got {t_end!r}")
    if times is None:
        return np.linspace(0.0, float(t_end), DEFAULT_SAMPLES)
    arr = np.asarray(times, dtype=float).ravel()
    if arr.size == 0:
        raise ValueError("times: must hold at least one time in [0, t_end]")
    if not np.all(np.isfinite(arr)):
        raise ValueError("times: must be finite numbers")
    if np.any(arr < 0) or np.any(arr > t_end):
        raise ValueError(f"times: every time must lie in [0, t_end] = [0, {t_end:g}]")
    if np.any(np.diff(arr) <= 0):
        raise ValueError("times: must be strictly increasing")
    if arr[0] != 0.0:
        arr = np.concatenate([[0.0], arr])
    return arr


def _check_tol(name: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name}: must be a finite number > 0 (allowed range (0, inf)), got {value!r}")
    return float(value)


def simulate(
    scene: Scene | Mapping[str, Any] | str,
    *,
    t_end: float,
    times: Sequence[float] | np.ndarray | None = None,
    method: str = "DOP853",
    rtol: float = 1e-10,
    atol: float = 1e-10,
    with_rotation: bool = False,
    step: float | None = None,
    model: str = "auto",
    energy_tol: float | None = None,
) -> Trajectory:
    """Integrate a scene from t = 0 to ``t_end``.

    Parameters
    ----------
    scene : Scene, dict or str
        A :class:`~flatbody_env.scene.Scene`, a scene dict, a JSON path or a built-in name.
    t_end : float
        Final time, > 0.
    times : sequence of float, optional
        Output times in [0, t_end] (0 is prepended if missing); default 101 even samples.
    method : str
        Integrator name (``flatbody methods``); default scipy ``DOP853``.
    rtol, atol : float
        Tolerances of adaptive methods.
    with_rotation : bool
        Also integrate R (Ṙ = R W(ω), eq. (25) of [1]) and return ``Trajectory.rotation``.
    step : float, optional
        Step size of fixed-step methods (required for them, refused by adaptive ones).
    model : {"auto", "stationary", "planar-V1", "planar", "two-polar", "regular"}
        The rung of the model ladder (module docstring).
    energy_tol : float, optional
        Allowed |H(t) − H(0)| before the run is declared failed; default
        ``max(1e-8, 1e4 · max(rtol, atol)) · max(1, |H(0)|)`` for adaptive methods and
        ``FIXED_STEP_ENERGY_TOL · max(1, |H(0)|)`` for fixed-step ones; ``math.inf`` disables the check.

    Returns
    -------
    Trajectory

    Raises
    ------
    ValueError
        Bad arguments or scene (naming the field).
    IntegrationError
        The integration failed; the message says when and why.
    """
    try:
        sc = scene if isinstance(scene, Scene) else load_scene(scene)
    except SceneError:
        raise
    times_arr = _resolve_times(t_end, times)
    rtol = _check_tol("rtol", rtol)
    atol = _check_tol("atol", atol)
    if step is not None:
        step = _check_tol("step", step)
    if model not in MODELS:
        raise ValueError(f"model: must be one of {', '.join(MODELS)}, got {model!r}")
    body = sc.body
    y0 = pack(sc.state)
    meth = get_method(method)
    if model in LADDER_RUNGS or (model == "auto" and meth.info.adaptive and meth.info.chart != "regular" and step is None):
        low = check_rung(model, y0, body) if model != "auto" else choose_rung(y0, body)
        if low is not None:
            return _simulate_rung(sc, low, times_arr, rtol, atol, step, energy_tol, with_rotation)
    chosen = model
    if model == "auto":
        choice = explain_model(y0, body, ladder=False)
        chosen = meth.info.chart if meth.info.chart == "regular" else choice.rung
        if body.spin_convention == "paper":
            chosen = "two-polar"
        if chosen != choice.rung:
            choice = RungChoice(rung=chosen, invariant=f"method {method!r} runs in the {chosen} chart", measured=choice.measured)
    else:
        choice = RungChoice(rung=chosen, invariant=f"model={model!r} was asked for")
    if chosen != meth.info.chart:
        twin = _twin(method, chosen)
        if twin is None and model != "auto":
            raise ValueError(f"method: {method!r} integrates the {meth.info.chart} chart, but model={chosen!r} was asked for")
        if twin is not None:
            meth = get_method(twin)
        # model="auto" and no twin: the method asked for by name runs in its own chart; near
        # lambda = mu its failure is detected and reported (IntegrationError), never hidden.
        if twin is None:
            choice = RungChoice(rung=meth.info.chart, invariant=f"method {method!r} has no twin in the {chosen} chart and runs in its own",
                                measured=choice.measured)
    if meth.info.adaptive and step is not None:
        raise ValueError(f"step: {meth.info.name} is adaptive; step= (--step) applies to fixed-step methods only")
    if not meth.info.adaptive and step is None:
        raise ValueError(f"step: {meth.info.name} is a fixed-step method; give step= (CLI: --step H), e.g. step=0.01")
    H0 = hamiltonian(y0, body)
    if energy_tol is None:
        if meth.info.adaptive:
            energy_tol = max(1e-8, 1e4 * max(rtol, atol)) * max(1.0, abs(H0))
        else:
            # fixed step: the tolerance only catches blow-ups (see docs/README-integrators.md)
            energy_tol = FIXED_STEP_ENERGY_TOL * max(1.0, abs(H0))
    tol = Tolerances(rtol=rtol, atol=atol, step=step, energy_tol=float(energy_tol))
    start = time.perf_counter()
    sol = meth.integrate(body, y0, times_arr, tol=tol, with_rotation=with_rotation)
    wall = time.perf_counter() - start
    state = unpack(sol.Y)
    energy = sol.stats.get("energy")
    if energy is None:
        energy = np.array([hamiltonian(sol.Y[:, k], body) for k in range(sol.Y.shape[1])])
    return Trajectory(
        t=np.asarray(sol.t, float),
        state=state,
        energy=np.asarray(energy, float),
        casimir=casimir(state["s1"], state["s2"], state["s3"]),
        p_theta=state["p_theta"].copy(),
        rotation=sol.rotation,
        method=meth.info.name,
        model=meth.info.chart,
        nfev=sol.nfev,
        wall_time=wall,
        scene=sc.name,
        extra=choice.as_meta(),
    )


def _simulate_rung(sc: Scene, choice: RungChoice, times_arr, rtol, atol, step, energy_tol, with_rotation) -> Trajectory:
    """Integrate on a rung below the full models (:mod:`flatbody_env.integrators.ladder`)."""
    model = rung_model(choice.rung)
    H0 = hamiltonian(pack(sc.state), sc.body)
    if energy_tol is None:
        energy_tol = max(1e-8, 1e4 * max(rtol, atol)) * max(1.0, abs(H0))
    tol = Tolerances(rtol=rtol, atol=atol, step=step, energy_tol=float(energy_tol))
    start = time.perf_counter()
    sol = model.integrate(sc.body, pack(sc.state), times_arr, tol=tol, with_rotation=with_rotation)
    wall = time.perf_counter() - start
    state = unpack(sol.Y)
    return Trajectory(
        t=np.asarray(sol.t, float), state=state, energy=np.asarray(sol.stats["energy"], float),
        casimir=casimir(state["s1"], state["s2"], state["s3"]), p_theta=state["p_theta"].copy(),
        rotation=sol.rotation, method=model.info.name, model=choice.rung, nfev=sol.nfev, wall_time=wall,
        scene=sc.name, extra=choice.as_meta(),
    )


def _twin(method: str, chart: str) -> str | None:
    from flatbody_env.integrators import available_methods

    names = {m.name: m for m in available_methods()}
    base = method[: -len("-regular")] if method.endswith("-regular") else method
    candidate = base if chart == "two-polar" else f"{base}-regular"
    if candidate in names and names[candidate].chart == chart:
        return candidate
    return None


__all__ = ["GAP_MIN", "MODELS", "Trajectory", "simulate", "choose_model", "explain_model", "gap_lower_bound", "IntegrationError"]

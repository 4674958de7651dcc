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

Output times follow scipy's ``t_eval`` convention: a trajectory holds exactly the requested
times; the initial state is :attr:`Trajectory.initial_state`. Every run has a work budget
(``max_nfev``, ``max_wall_time``; :class:`~flatbody_env.integrators.Tolerances`).

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md``: the corrected equations and the errata of [1].
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flatbody_env.physics.body import Body
from flatbody_env.physics.invariants import casimir, laboratory_spin
from flatbody_env.physics.hamiltonian import hamiltonian, hamiltonian_series
from flatbody_env.integrators import DEFAULT_MAX_NFEV, DEFAULT_MAX_WALL_TIME, IntegrationError, Tolerances, get_method
from flatbody_env.integrators.base import Solution, check_step
from flatbody_env.physics import validation
from flatbody_env.physics.state import STATE_NAMES, pack, unpack, validate_state
from flatbody_env.scene import Scene, load_scene

from flatbody_env.integrators.auto import AUTO, auto_method, integrate_auto
from flatbody_env.integrators.ladder import (
    GAP_MIN,
    LADDER_RUNGS,
    RUNGS,
    RungChoice,
    check_rung,
    choose_rung,
    rung_model,
    rung_reasons,
)

FIXED_STEP_ENERGY_TOL = 1e-3
"""Default relative energy tolerance of fixed-step methods (a blow-up detector, not an accuracy target)."""
ADAPTIVE_ENERGY_TOL_FLOOR = 1e-8
"""Smallest default relative energy tolerance of adaptive methods (:func:`energy_tol_scale`)."""
ADAPTIVE_ENERGY_TOL_FACTOR = 1e4
"""Default relative energy tolerance of adaptive methods per unit of max(rtol, atol) (:func:`energy_tol_scale`)."""


def energy_tol_scale(rtol: float, atol: float, *, adaptive: bool = True) -> float:
    """The default relative energy tolerance — the one rule of :func:`simulate`, ``simulate_batch`` and the
    studies: ``max(ADAPTIVE_ENERGY_TOL_FLOOR, ADAPTIVE_ENERGY_TOL_FACTOR · max(rtol, atol))`` for adaptive
    methods, :data:`FIXED_STEP_ENERGY_TOL` for fixed-step ones (``rtol``, ``atol`` unused there)."""
    if not adaptive:
        return FIXED_STEP_ENERGY_TOL
    return max(ADAPTIVE_ENERGY_TOL_FLOOR, ADAPTIVE_ENERGY_TOL_FACTOR * max(rtol, atol))


def default_energy_tol(H0: float, rtol: float, atol: float, *, adaptive: bool = True) -> float:
    """The default absolute energy tolerance of an integration starting at energy ``H0``:
    :func:`energy_tol_scale` · max(1, |H0|)."""
    return energy_tol_scale(rtol, atol, adaptive=adaptive) * max(1.0, abs(H0))


MODELS = ("auto",) + RUNGS
DEFAULT_SAMPLES = 101
"""Even output times of :func:`simulate` when neither ``times`` nor ``samples`` is given (``flatbody simulate``, the service)."""


def gap_lower_bound(state: Mapping[str, float] | np.ndarray, body: Body) -> float:
    """A rigorous lower bound of |λ − μ| along the uncontrolled isotropic motion (0 if none).

    From H = 𝒯 + V with every term of 𝒯 (eq. (32) of [1], docs/physics.md §4) non-negative,
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


def choose_model(
    state: Mapping[str, float] | np.ndarray, body: Body, u: np.ndarray | None = None, *, ladder: bool = True
) -> str:
    """The rung ``model="auto"`` runs (:data:`MODELS`), per the rule in the module docstring."""
    return explain_model(state, body, u, ladder=ladder).rung


def explain_model(
    state: Mapping[str, float] | np.ndarray, body: Body, u: np.ndarray | None = None, *, ladder: bool = True
) -> RungChoice:
    """The rung ``model="auto"`` runs and why (:class:`~flatbody_env.integrators.ladder.RungChoice`);
    ``ladder=False`` chooses between the two full models only."""
    y = pack(state, validate=False) if isinstance(state, Mapping) else np.asarray(state, float)
    if ladder:
        low = choose_rung(y, body, u)
        if low is not None:
            return low
    bound = gap_lower_bound(y, body) if u is None or not np.any(u) else 0.0
    if bound >= GAP_MIN:
        return RungChoice(
            rung="two-polar",
            invariant=f"J1 = J2 and the energy bound keeps |lambda - mu| >= {bound:.3g} >= {GAP_MIN:g}",
            measured={"gap_lower_bound": float(bound)},
        )
    why = "; ".join(f"{r}: {t}" for r, t in rung_reasons(y, body, u).items() if t)
    return RungChoice(
        rung="regular",
        invariant=f"no lower rung holds (two-polar: |lambda - mu| >= {bound:.3g} < {GAP_MIN:g} guaranteed"
        + (f"; {why})" if why else ")"),
        measured={"gap_lower_bound": float(bound)},
    )


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
    initial_state : dict[str, float] or None
        The state at t = 0 (the scene's), whether or not 0 is among the output times.
    initial_energy : float or None
        H at t = 0; with ``initial_state`` the reference of :meth:`drift`.
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
    initial_state: dict[str, float] | None = None
    initial_energy: float | None = None

    @property
    def lab_spin(self) -> np.ndarray | None:
        """R s, shape (n, 3) (conserved with the corrected bracket, docs/physics.md §6), or None without R."""
        if self.rotation is None:
            return None
        s = np.stack([self.state["s1"], self.state["s2"], self.state["s3"]], axis=-1)
        return laboratory_spin(self.rotation, s)

    @property
    def y(self) -> np.ndarray:
        """Packed states, shape (11, n)."""
        return np.stack([self.state[name] for name in STATE_NAMES])

    def drift(self) -> dict[str, float]:
        """Max |q(t) − q(0)| of H, |s|², p_θ (and |R s − R(t₀) s(t₀)| when R is known).

        q(0) is the initial state's value when it is known (:attr:`initial_state`), else the first row's.
        """
        e0, c0, p0 = self.energy[0], self.casimir[0], self.p_theta[0]
        if self.initial_state is not None and self.initial_energy is not None:
            y0 = self.initial_state
            e0, c0, p0 = self.initial_energy, float(casimir(y0["s1"], y0["s2"], y0["s3"])), y0["p_theta"]
        out = {
            "energy": float(np.max(np.abs(self.energy - e0))),
            "casimir": float(np.max(np.abs(self.casimir - c0))),
            "p_theta": float(np.max(np.abs(self.p_theta - p0))),
        }
        ls = self.lab_spin
        if ls is not None:
            out["lab_spin"] = float(np.max(np.linalg.norm(ls - ls[0], axis=-1)))
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON form: ``{"t", "state", "energy", "casimir", "p_theta", ["rotation"], ["initial_state"], "meta"}``
        (read back by :meth:`from_dict` / :func:`read_trajectory`)."""
        out: dict[str, Any] = {
            "t": self.t.tolist(),
            "state": {name: self.state[name].tolist() for name in STATE_NAMES},
            "energy": self.energy.tolist(),
            "casimir": self.casimir.tolist(),
            "p_theta": self.p_theta.tolist(),
        }
        if self.rotation is not None:
            out["rotation"] = self.rotation.tolist()
        if self.initial_state is not None:
            out["initial_state"] = {name: float(self.initial_state[name]) for name in STATE_NAMES}
        meta = {
            "scene": self.scene,
            "method": self.method,
            "model": self.model,
            "nfev": self.nfev,
            "wall_time": self.wall_time,
            **self.extra,
        }
        if self.initial_energy is not None:
            meta["initial_energy"] = self.initial_energy
        out["meta"] = meta
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "trajectory") -> Trajectory:
        """A trajectory from its JSON form (:meth:`to_dict`, ``flatbody simulate --out FILE``), validated.

        ``t`` (n,) strictly increasing finite times, ``state`` the eleven series of n finite numbers
        (:data:`~flatbody_env.physics.state.STATE_NAMES`); optional ``energy``, ``casimir``,
        ``p_theta`` (n,) (``casimir`` and ``p_theta`` are recomputed from the state when absent;
        H needs the body, so an absent ``energy`` is marked unknown: :attr:`has_energy` is False),
        ``rotation`` (n, 3, 3), ``initial_state`` and ``meta``. At most
        :data:`~flatbody_env.physics.validation.MAX_SAMPLES` rows.

        Raises
        ------
        ValueError
            Naming the field (``trajectory.state.mu``, ``trajectory.rotation``, …).
        """
        data = validation.mapping(where, data)
        validation.keys(where, data, _TRAJ_KEYS, ("t", "state"))
        t = validation.float_array(f"{where}.t", data["t"], shape=(None,))
        n = t.size
        if not 1 <= n <= validation.MAX_SAMPLES:
            raise ValueError(f"{where}.t: must hold 1 to {validation.MAX_SAMPLES} times, got {n}")
        if np.any(np.diff(t) <= 0):
            raise validation.refusal(f"{where}.t", "be strictly increasing")
        st = validation.mapping(f"{where}.state", data["state"])
        validation.keys(f"{where}.state", st, STATE_NAMES, STATE_NAMES)
        state = {name: validation.float_array(f"{where}.state.{name}", st[name], shape=(n,)) for name in STATE_NAMES}
        lo, hi = validation.STRETCH_RANGE
        for name in ("lambda", "mu", "rho"):  # the documented range (docs/reliability.md), as for a scene's state
            bad = np.flatnonzero((state[name] < lo) | (state[name] > hi))
            if bad.size:
                raise validation.refusal(
                    f"{where}.state.{name}",
                    f"lie in [{lo:g}, {hi:g}] (at t = {t[bad[0]]:g})",
                    float(state[name][bad[0]]),
                )
        series = {}
        for key in ("energy", "casimir", "p_theta"):
            if key in data:
                series[key] = validation.float_array(f"{where}.{key}", data[key], shape=(n,))
        rotation = (
            validation.float_array(f"{where}.rotation", data["rotation"], shape=(n, 3, 3))
            if data.get("rotation") is not None
            else None
        )
        initial = None
        if data.get("initial_state") is not None:
            initial_map = validation.mapping(f"{where}.initial_state", data["initial_state"])
            validate_state(initial_map, where=f"{where}.initial_state")
            initial = {name: float(initial_map[name]) for name in STATE_NAMES}
        meta = validation.mapping(f"{where}.meta", data.get("meta", {}))
        text = {k: validation.string(f"{where}.meta.{k}", meta.get(k, "")) for k in ("scene", "method", "model")}
        nfev = validation.integer(f"{where}.meta.nfev", meta.get("nfev", 0), low=0)
        wall = validation.number(f"{where}.meta.wall_time", meta.get("wall_time", 0.0), low=0.0)
        initial_energy = (
            validation.number(f"{where}.meta.initial_energy", meta["initial_energy"])
            if "initial_energy" in meta
            else None
        )
        extra = {
            k: v
            for k, v in meta.items()
            if k not in ("scene", "method", "model", "nfev", "wall_time", "initial_energy")
        }
        return cls(
            t=t,
            state=state,
            energy=series.get("energy", np.full(n, np.nan)),
            casimir=series.get("casimir", casimir(state["s1"], state["s2"], state["s3"])),
            p_theta=series.get("p_theta", state["p_theta"].copy()),
            rotation=rotation,
            method=text["method"],
            model=text["model"],
            nfev=nfev,
            wall_time=wall,
            scene=text["scene"],
            extra=extra,
            initial_state=initial,
            initial_energy=initial_energy,
        )

    @property
    def has_energy(self) -> bool:
        """False when the trajectory was read from JSON without an ``energy`` series."""
        return bool(np.all(np.isfinite(self.energy)))


_TRAJ_KEYS = ("t", "state", "energy", "casimir", "p_theta", "rotation", "initial_state", "meta")


def read_trajectory(path: str | Path) -> Trajectory:
    """Read a trajectory saved by ``flatbody simulate --out FILE`` (or ``json.dump(traj.to_dict())``).

    Raises
    ------
    ValueError
        A missing, unreadable or non-regular file, malformed JSON, or a malformed trajectory
        (naming the field).
    """
    return Trajectory.from_dict(validation.read_json("trajectory", path))


def _resolve_times(t_end: Any, times: Sequence[float] | np.ndarray | None) -> tuple[float, np.ndarray]:
    """Validated (t_end, output times): exactly the requested times (scipy's ``t_eval`` convention)."""
    t_end = validation.number("t_end", t_end, positive=True, high=validation.T_END_MAX)
    if times is None:
        return t_end, np.linspace(0.0, t_end, DEFAULT_SAMPLES)
    if isinstance(times, (int, float, np.integer, np.floating)) and not isinstance(times, bool):
        times = [times]
    arr = validation.float_array("times", times, shape=(None,))
    if arr.size == 0 or arr.size > validation.MAX_SAMPLES:
        raise ValueError(f"times: must hold 1 to {validation.MAX_SAMPLES} times in [0, t_end], got {arr.size}")
    outside = arr[(arr < 0) | (arr > t_end)]
    if outside.size:
        raise validation.refusal("times", f"each lie in [0, t_end] = [0, {t_end:g}]", float(outside[0]))
    if np.any(np.diff(arr) <= 0):
        raise validation.refusal("times", "be strictly increasing")
    return t_end, arr


def simulate(
    scene: Scene | Mapping[str, Any] | str,
    *,
    t_end: float,
    times: Sequence[float] | np.ndarray | None = None,
    method: str = "auto",
    rtol: float = 1e-10,
    atol: float = 1e-10,
    with_rotation: bool = False,
    step: float | None = None,
    model: str = "auto",
    energy_tol: float | None = None,
    max_nfev: int = DEFAULT_MAX_NFEV,
    max_wall_time: float = DEFAULT_MAX_WALL_TIME,
) -> Trajectory:
    """Integrate a scene from t = 0 to ``t_end``.

    Parameters
    ----------
    scene : Scene, dict or str
        A :class:`~flatbody_env.scene.Scene`, a scene dict, a JSON path or a built-in name.
    t_end : float
        Final time, > 0.
    times : sequence of float, optional
        Output times in [0, t_end], strictly increasing: the trajectory holds exactly these rows
        (scipy's ``t_eval`` convention; the state at t = 0 stays available as
        :attr:`Trajectory.initial_state`, or ask for ``times=[0, ...]``); default 101 even
        samples from 0 to t_end. At most 100 000 times.
    method : str
        Integrator name (``flatbody methods``) or ``"auto"`` (the default): the fastest registered
        method that meets rtol/atol in the chosen model (:mod:`flatbody_env.integrators.auto`:
        ``DOP853-numba`` in the two-polar chart, ``RATTLE-kahanli6`` with a step chosen to meet
        the tolerance in the regular chart; scipy's methods where the compiled ones do not
        apply). ``Trajectory.method`` names what ran, ``meta["method_requested"]`` and
        ``meta["method_reason"]`` why. Before this default, it was scipy ``DOP853``.
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
    max_nfev, max_wall_time : int, float
        The work budget (:class:`~flatbody_env.integrators.Tolerances`): right-hand-side
        evaluations (default 2·10⁷) and wall-clock seconds (default 120, scipy methods); past it
        the run stops with ``IntegrationError(kind="budget")``.

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
    sc = scene if isinstance(scene, Scene) else load_scene(scene)
    t_end, times_arr = _resolve_times(t_end, times)
    model = validation.string("model", model, choices=MODELS)
    method = validation.string("method", method)
    validation.boolean("with_rotation", with_rotation)
    if step is not None:  # bounded work: a fixed step below the floor is an error, never replaced
        step = validation.fixed_step("step", step)
    validation.number(
        "max_wall_time", max_wall_time, positive=True, high=validation.MAX_SECONDS
    )  # before the automatic choice runs anything
    body = sc.body
    y0 = pack(sc.state)
    if method == AUTO:
        if step is not None:
            raise ValueError(
                "step: method='auto' runs adaptive methods (or chooses RATTLE's step itself); "
                "give step= only with a fixed-step method named by method="
            )
        return _simulate_auto(sc, y0, times_arr, model, rtol, atol, energy_tol, with_rotation, max_nfev, max_wall_time)
    try:
        meth = get_method(method)
    except ValueError as exc:
        raise ValueError(str(exc).replace("(allowed: ", "(allowed: auto, ", 1)) from None
    if model in LADDER_RUNGS or (
        model == "auto" and meth.info.adaptive and meth.info.chart != "regular" and step is None
    ):
        low = check_rung(model, y0, body) if model != "auto" else choose_rung(y0, body)
        if low is not None:
            return _simulate_rung(
                sc, low, times_arr, rtol, atol, step, energy_tol, with_rotation, max_nfev, max_wall_time
            )
    chosen = model
    if model == "auto":
        choice = explain_model(y0, body, ladder=False)
        chosen = meth.info.chart if meth.info.chart == "regular" else choice.rung
        if body.spin_convention == "paper":
            chosen = "two-polar"
        if chosen != choice.rung:
            choice = RungChoice(
                rung=chosen, invariant=f"method {method!r} runs in the {chosen} chart", measured=choice.measured
            )
    else:
        choice = RungChoice(rung=chosen, invariant=f"model={model!r} was asked for")
    if chosen != meth.info.chart:
        twin = _twin(method, chosen)
        if twin is None and model != "auto":
            raise ValueError(
                f"method: {method!r} integrates the {meth.info.chart} chart, but model={chosen!r} was asked for"
            )
        if twin is not None:
            meth = get_method(twin)
        # model="auto" and no twin: the method asked for by name runs in its own chart; near
        # lambda = mu its failure is detected and reported (IntegrationError), never hidden.
        if twin is None:
            choice = RungChoice(
                rung=meth.info.chart,
                invariant=f"method {method!r} has no twin in the {chosen} chart and runs in its own",
                measured=choice.measured,
            )
    # rtol, atol, step, energy_tol and the budget are validated by Tolerances (one home), built once: the default
    # energy tolerance needs rtol and atol, checked first by the same rule
    H0 = hamiltonian(y0, body)
    if energy_tol is None:
        # fixed step: the tolerance only catches blow-ups (see docs/integrators.md)
        lo, hi = validation.TOL_RANGE
        checked = (validation.number(k, v, low=lo, high=hi) for k, v in (("rtol", rtol), ("atol", atol)))
        energy_tol = default_energy_tol(H0, *checked, adaptive=meth.info.adaptive)
    tol = Tolerances(
        rtol=rtol, atol=atol, step=step, energy_tol=energy_tol, max_nfev=max_nfev, max_wall_time=max_wall_time
    )
    check_step(meth.info, tol)
    # methods integrate from grid[0] = 0; a grid without 0 gets it prepended and its row dropped
    prepended = times_arr[0] != 0.0
    grid = np.concatenate([[0.0], times_arr]) if prepended else times_arr
    start = time.perf_counter()
    if grid.size == 1:  # only t = 0 asked for: the initial state, nothing to integrate
        sol = Solution(t=grid.copy(), Y=y0[:, None].copy(), rotation=np.eye(3)[None] if with_rotation else None, nfev=0)
    else:
        sol = meth.integrate(body, y0, grid, tol=tol, with_rotation=with_rotation)
    wall = time.perf_counter() - start
    keep = slice(1, None) if prepended else slice(None)
    Y = sol.Y[:, keep]
    state = unpack(Y)
    energy = sol.stats.get("energy")
    energy = hamiltonian_series(Y, body) if energy is None else np.asarray(energy, float)[keep]
    return Trajectory(
        t=np.asarray(sol.t, float)[keep],
        state=state,
        energy=energy,
        casimir=casimir(state["s1"], state["s2"], state["s3"]),
        p_theta=state["p_theta"].copy(),
        rotation=None if sol.rotation is None else sol.rotation[keep],
        method=meth.info.name,
        model=meth.info.chart,
        nfev=sol.nfev,
        wall_time=wall,
        scene=sc.name,
        initial_state=unpack(y0),
        initial_energy=float(H0),
        extra=choice.as_meta(),
    )


def _adaptive_energy_tol(energy_tol, rtol, atol, H0) -> float:
    return float(energy_tol) if energy_tol is not None else default_energy_tol(H0, rtol, atol)


def _simulate_auto(
    sc: Scene, y0, times_arr, model, rtol, atol, energy_tol, with_rotation, max_nfev, max_wall_time
) -> Trajectory:
    """``method="auto"``: the rung (``model``) decides the model, :mod:`flatbody_env.integrators.auto` the method."""
    body = sc.body
    if model in LADDER_RUNGS or model == "auto":
        low = check_rung(model, y0, body) if model != "auto" else choose_rung(y0, body)
        if low is not None:
            traj = _simulate_rung(
                sc, low, times_arr, rtol, atol, None, energy_tol, with_rotation, max_nfev, max_wall_time
            )
            traj.extra.update(
                {"method_requested": AUTO, "method_reason": f"auto: the {low.rung} rung's own solver ({traj.method})"}
            )
            return traj
    if model == "auto":
        choice = explain_model(y0, body, ladder=False)
        if body.spin_convention == "paper" and choice.rung != "two-polar":
            choice = RungChoice(
                rung="two-polar",
                invariant="spin_convention 'paper' exists in the two-polar chart only",
                measured=choice.measured,
            )
    else:
        choice = RungChoice(rung=model, invariant=f"model={model!r} was asked for")
    H0 = hamiltonian(y0, body)
    tol = Tolerances(
        rtol=rtol,
        atol=atol,
        energy_tol=_adaptive_energy_tol(energy_tol, rtol, atol, H0),
        max_nfev=max_nfev,
        max_wall_time=max_wall_time,
    )
    prepended = times_arr[0] != 0.0
    grid = np.concatenate([[0.0], times_arr]) if prepended else times_arr
    keep = slice(1, None) if prepended else slice(None)
    start = time.perf_counter()
    if grid.size == 1:
        name, meta = auto_method(choice.rung, body).method, auto_method(choice.rung, body).as_meta()
        sol = Solution(t=grid.copy(), Y=y0[:, None].copy(), rotation=np.eye(3)[None] if with_rotation else None, nfev=0)
    else:
        sol, name, meta = integrate_auto(choice.rung, body, y0, grid, tol, with_rotation=with_rotation)
    wall = time.perf_counter() - start
    Y = sol.Y[:, keep]
    state = unpack(Y)
    energy = sol.stats.get("energy")
    energy = hamiltonian_series(Y, body) if energy is None else np.asarray(energy, float)[keep]
    return Trajectory(
        t=np.asarray(sol.t, float)[keep],
        state=state,
        energy=energy,
        casimir=casimir(state["s1"], state["s2"], state["s3"]),
        p_theta=state["p_theta"].copy(),
        rotation=None if sol.rotation is None else sol.rotation[keep],
        method=name,
        model=choice.rung,
        nfev=sol.nfev,
        wall_time=wall,
        scene=sc.name,
        initial_state=unpack(y0),
        initial_energy=float(H0),
        extra={**choice.as_meta(), **meta},
    )


def _simulate_rung(
    sc: Scene, choice: RungChoice, times_arr, rtol, atol, step, energy_tol, with_rotation, max_nfev, max_wall_time
) -> Trajectory:
    """Integrate on a rung below the full models (:mod:`flatbody_env.integrators.ladder`)."""
    model = rung_model(choice.rung)
    y0 = pack(sc.state)
    H0 = hamiltonian(y0, sc.body)
    if energy_tol is None:
        energy_tol = default_energy_tol(H0, rtol, atol)
    tol = Tolerances(
        rtol=rtol, atol=atol, step=step, energy_tol=float(energy_tol), max_nfev=max_nfev, max_wall_time=max_wall_time
    )
    # rungs integrate from grid[0] = 0 as the full models do: a grid without 0 gets it prepended and its row dropped
    prepended = times_arr[0] != 0.0
    grid = np.concatenate([[0.0], times_arr]) if prepended else times_arr
    keep = slice(1, None) if prepended else slice(None)
    start = time.perf_counter()
    sol = model.integrate(sc.body, y0, grid, tol=tol, with_rotation=with_rotation)
    wall = time.perf_counter() - start
    state = unpack(sol.Y[:, keep])
    return Trajectory(
        t=np.asarray(sol.t, float)[keep],
        state=state,
        energy=np.asarray(sol.stats["energy"], float)[keep],
        casimir=casimir(state["s1"], state["s2"], state["s3"]),
        p_theta=state["p_theta"].copy(),
        rotation=None if sol.rotation is None else sol.rotation[keep],
        method=model.info.name,
        model=choice.rung,
        nfev=sol.nfev,
        wall_time=wall,
        scene=sc.name,
        extra=choice.as_meta(),
        initial_state=unpack(y0),
        initial_energy=float(H0),
    )


def _twin(method: str, chart: str) -> str | None:
    from flatbody_env.integrators import available_methods

    names = {m.name: m for m in available_methods()}
    base = method[: -len("-regular")] if method.endswith("-regular") else method
    candidate = base if chart == "two-polar" else f"{base}-regular"
    if candidate in names and names[candidate].chart == chart:
        return candidate
    return None


__all__ = [
    "GAP_MIN",
    "MODELS",
    "Trajectory",
    "read_trajectory",
    "simulate",
    "choose_model",
    "explain_model",
    "gap_lower_bound",
    "IntegrationError",
]

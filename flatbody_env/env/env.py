"""``FlatBody-v1`` (and the other ids of docs/tasks.md): steer a flat affinely-rigid body with thickness onto a
stationary ellipse — the single-environment face.

The environment composes three parts (dm_control's Environment/Task split): the body
(:class:`~flatbody_env.physics.body.Body`, physics of [1] with the corrections of [2]), an integrator
chosen by name through the seam :func:`flatbody_env.integrators.steppers.make_env_step`, and the task
(:mod:`flatbody_env.env.task`: draws, observation, reward, termination), resolved once by
:func:`~flatbody_env.env.core.configure`. A step is the transition of :mod:`flatbody_env.env.transition` for a
batch of one body (:class:`~flatbody_env.env.core.EnvCore`), as on every other face.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from flatbody_env.env import transition as tr
from flatbody_env.env.core import (
    DEFAULT_INTEGRATOR,
    DEFAULT_TOLERANCE,
    ROTATION_INTEGRATOR,
    EnvCore,
    configure,
    end_reason,
    target_of,
)
from flatbody_env.env.task import CONTROLS, OBSERVATION_NAMES, REWARD_TERMS, TARGET_NAMES, ReachStationaryEllipse
from flatbody_env.physics import validation
from flatbody_env.physics.body import Body
from flatbody_env.physics.state import unpack

_FLOATS = (np.dtype(np.float32), np.dtype(np.float64))


class FlatBodyEnv(gym.Env):
    """Steer a flat affinely-rigid body with thickness onto a stationary ellipse.

    ## Description

    The body of [1] (section 3): a plate whose configuration is Φ = R·diag(λ, μ, ϱ)·U(θ)⁻¹ —
    two in-plane stretches λ, μ, a thickness ϱ, a material rotation θ and an orientation R —
    moving under the Hamiltonian H = 𝒯 (eq. (32)) + V_λμ (eqs. (37)–(39)) + V_ϱ (eq. (40)) with the
    equations of motion (44)–(49) (spin bracket corrected per errata E3/E4 of [2]). A stationary
    ellipse (eqs. (50)–(54)) keeps λ, μ, ϱ and the angular velocities constant while G and C
    rotate. The agent applies a co-moving torque on the spin and/or a force on the thickness to
    bring the body onto a target stationary ellipse and keep it there.

    ## Action Space

    ``Box(-1, 1, (n,), float32)``; the actions are scaled inside by the documented limits:

    =======================  ===  ==============================  =========================  ============
    control                  n    entry                           effect                      unit
    =======================  ===  ==============================  =========================  ============
    ``"torque"``             3    a[0:3]                          τ = torque_limit · a on ṡ   J (torque)
    ``"dilatation"``         1    a[0]                            f = force_limit · a on ṗ_ϱ  N
    ``"torque+dilatation"``  4    a[0:3] torque, a[3] force       both                        —
    ``"none"``               1    a[0] (ignored)                  none                        —
    =======================  ===  ==============================  =========================  ============

    ## Observation Space

    ``Box(low, high, (16,), float32)`` with finite bounds (the physics state stays float64):

    ===  ================  ============================================  ================  ==========
    idx  name              meaning                                       bounds            unit
    ===  ================  ============================================  ================  ==========
    0-2  s1, s2, s3        co-moving spin                                ±momentum_bound   J·s
    3    p_theta           momentum of θ (conserved)                     ±momentum_bound   J·s
    4-6  p_lambda, p_mu,   momenta of λ, μ, ϱ                            ±momentum_bound   kg·m/s
         p_rho
    7-8  lambda, mu        in-plane stretches                            stretch_bounds    1
    9    rho               thickness                                     rho_bounds        1
    10   sin_theta         sin θ (material rotation angle)               [−1, 1]           1
    11   cos_theta         cos θ                                         [−1, 1]           1
    12   target_lambda     target λ*                                     stretch_bounds    1
    13   target_mu         target μ*                                     stretch_bounds    1
    14   target_rho        target ϱ*                                     rho_bounds        1
    15   target_s3         target s3*                                    ±momentum_bound   J·s
    ===  ================  ============================================  ================  ==========

    A task may append entries (the body's constants of ``FlatBodyAnyBody-v0``), and ``observe_time=True`` (a task
    keyword, off on every registered id) appends the episode's elapsed time last: steps / 400, in [0, 2500], 0 at a
    reset and 1 where the registered ids truncate (Gymnasium's ``TimeAwareObservation``, written by the transition).

    ## Rewards

    The reward is the sum of named terms, each returned in ``info["reward_terms"]``. The v1 ids
    (``FlatBody-v1`` …): a reward in [0, 1] per step on the task distance d alone (dm_control's ``tolerance``
    form, :mod:`flatbody_env.env.transition`): ``success`` = (1 − β) when d ≤ tol, ``proximity`` = β·g(d)
    with g = 1 within the tolerance and a Gaussian of the excess outside (β = ``w_proximity`` = 0.2,
    margin ``proximity_margin`` = 0.5); 0 on a step that ends the episode by failure. The v0 ids: terms ≤ 0
    (weights are keyword arguments, see :class:`~flatbody_env.env.task.ReachStationaryEllipse`):
    ``shape`` −w‖(Δλ, Δμ, Δϱ)‖, ``spin`` −w|Δs3|, ``tumble`` −w‖(ω1, ω2)‖, ``rest``
    −w‖(p_λ, p_μ, p_ϱ)‖, ``action`` −w‖a‖², ``failure`` −penalty when the step ends the episode by
    integrator failure or by leaving the domain.

    ``info["is_success"]`` is True when the distance d = ‖(Δλ, Δμ, Δϱ, Δs3, ω1, ω2, p_λ, p_μ, p_ϱ)‖
    is at most ``success_tolerance`` (0.05).

    ## Starting State

    A target is a spectrally stable stationary ellipse of the circulation family (|s3| < |p_θ|,
    [2]) with λ* ∈ [1.3, 2], λ*/μ* ∈ [1.5, 3.5] (default body) that the controls can reach
    within the episode: its settling rate r (the slowest closed-loop pole of the cheap-control LQR
    about the target, :func:`flatbody_env.physics.controllability.settling_rate`) is at least
    ``min_settling_rate`` = 0.15 s⁻¹, so that under such feedback the slowest mode shrinks
    e³ ≈ 20-fold or more in 20 s (``"torque+dilatation"``; see :mod:`flatbody_env.env.task`, "Reachable within the
    episode"); or the one given by ``reset(options={"target": {"lambda": ..., "mu": ...}})`` (not filtered). The
    initial state has the target's
    p_θ (conserved by every control), shape and spin within ``initial_noise`` (15 %) of the target,
    small momenta and a uniform θ; without torque |s| equals |s3*| (the Casimir is conserved).
    ``reset(options={"state": {...eleven names...}})`` sets the state exactly; without a target beside it, the target
    is the one the seed's episode draws (the v1 ids: the same as ``reset(seed=...)``'s; the v0 ids: drawn from the
    seed's generator).

    ## Info

    One schema on every face (this env, the vector envs, the torch env on the CPU and CUDA): ``t``,
    ``distance``, ``is_success``, ``energy`` (H, eq. (41)), ``casimir`` (|s|²), ``p_theta``,
    ``integrator`` ({"method": the method that really ran, "nfev": its right-hand-side evaluations in this
    step}), ``status`` (the integrator's status, 0 = success, :data:`flatbody_env.integrators.failure.KINDS`),
    ``domain_code`` (0 inside; what ended the episode otherwise: :data:`~flatbody_env.env.core.END_REASONS`,
    :func:`~flatbody_env.env.core.end_reason` says it in words) and (``step``) ``reward_terms``. The vector
    faces, which end episodes themselves, add Gymnasium-style episode statistics (``episode``, ``_episode``)
    and an rsl_rl-style ``log``.

    ## Episode End

    Termination: the integrator failed (``info["status"]`` says why: non-finite state,
    step-size collapse, chart singularity, energy error), or the state left the domain
    (``info["domain_code"]`` names the variable): λ, μ outside ``stretch_bounds``, ϱ outside
    ``rho_bounds``, a momentum beyond ``momentum_bound``, or |λ − μ|/(λ + μ) < ``gap_min`` for a
    two-polar-chart integrator. The returned observation is then the last valid state (never NaN).
    Truncation: after 400 steps (t = 20 at dt = 0.05) through ``TimeLimit`` (registration).

    ## Arguments

    ``gym.make("FlatBody-v0", control="torque+dilatation", task="reach", body=None, dt=0.05, integrator=...,
    rtol=1e-11, atol=1e-11, step=None, torque_limit=0.5, force_limit=1.0, render_mode=None,
    track_rotation=False, stretch_bounds=(0.2, 4.0), rho_bounds=(0.1, 4.0), momentum_bound=50.0,
    gap_min=1e-3, **task_kwargs)`` where ``body`` is a :class:`~flatbody_env.physics.body.Body` or a scene-like
    dict ``{"params", "potential", "thickness"}`` (default: J = J3 = 1, V3 with κ = 1 and V_ϱ with
    a = b = 1 — barriers against every collapse, erratum E10 of [2]), ``task`` names the task
    (:data:`~flatbody_env.env.registration.TASK_CLASSES`: ``"reach"`` — this docstring's —, ``"hold-unstable"``,
    ``"reach-witnessed"``, ``"any-body"``; ``docs/tasks.md``) or is a task instance, and ``task_kwargs`` are the
    weights and ranges of the task (:class:`~flatbody_env.env.task.ReachStationaryEllipse` and its subclasses).
    The other registered ids (``FlatBodySlow-v0``, ``FlatBodyHoldUnstable-v0``, ``FlatBodyTorque-v0``,
    ``FlatBodyDilatation-v0``, ``FlatBodyAnyBody-v0``) are this class with another task; a task may add reward
    terms, end episodes of its own accord and append observation entries (``observation_space``). ``integrator``
    is any name of
    ``flatbody methods``; the default :data:`DEFAULT_INTEGRATOR` is the fastest method measured to keep
    the episode state error ≤ 1e-8 (``docs/env.md``).

    ## Version History

    * v1: the tolerance reward in [0, 1] on the task distance; counter-based draws in the transition, the same
      episodes for a seed on every face and device (a shape the settling-rate table is unsure about is drawn
      again); the task suite's ladder (docs/tasks.md).
    * v0: initial version (the other tasks added with the same draws, numbers bit for bit; the settling-rate
      filter of ``FlatBody-v0`` was introduced without a version bump, before v1 existed). Deprecated: kept bit
      for bit so that saved reports reproduce.

    References
    ----------
    .. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
       degenerate dimension", arXiv:0902.3573 (2009).
    .. [2] ``docs/physics.md``: the corrected equations and the paper's errata.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(
        self,
        control: str = "torque+dilatation",
        task: str | ReachStationaryEllipse = "reach",
        body: Body | Mapping[str, Any] | None = None,
        dt: float = 0.05,
        integrator: str = DEFAULT_INTEGRATOR,
        rtol: float = DEFAULT_TOLERANCE,
        atol: float = DEFAULT_TOLERANCE,
        step: float | None = None,
        torque_limit: float = 0.5,
        force_limit: float = 1.0,
        render_mode: str | None = None,
        track_rotation: bool = False,
        stretch_bounds: tuple[float, float] = (0.2, 4.0),
        rho_bounds: tuple[float, float] = (0.1, 4.0),
        momentum_bound: float = 50.0,
        gap_min: float = 1e-3,
        **task_kwargs: Any,
    ) -> None:
        self.config = c = configure(
            control=control, task=task, body=body, dt=dt, integrator=integrator, rtol=rtol, atol=atol, step=step,
            torque_limit=torque_limit, force_limit=force_limit, render_mode=render_mode, track_rotation=track_rotation,
            stretch_bounds=stretch_bounds, rho_bounds=rho_bounds, momentum_bound=momentum_bound, gap_min=gap_min,
            **task_kwargs,
        )  # fmt: skip
        self.core = EnvCore(c, 1)
        """The batch of one body this env steps (:class:`~flatbody_env.env.core.EnvCore`)."""
        self.core.action_field = "action"
        self.render_mode = render_mode
        self.action_space = c.action_space
        self.observation_space = c.observation_space
        self.integrator = c.integrator
        self._names = c.reward_names
        self._terms = tuple((name, tr.R_TERMS + i) for i, name in enumerate(self._names))
        self._shape = (c.n_act,)
        self._A = np.zeros((1, c.n_act))
        self._method = c.stepper.method
        self._tol = c.task.success_tolerance
        self._started = False

    # --- composition (read only) -------------------------------------------------------------------
    body = property(lambda self: self.core.body_of(0), doc="The body (the episode's, for a task that draws one).")
    task = property(lambda self: self.config.task, doc="The task (:mod:`flatbody_env.env.task`).")
    control = property(lambda self: self.config.control)
    mask = property(lambda self: self.config.mask, doc="Which of (τ1, τ2, τ3, f_ϱ) the action drives (4,) bool.")
    limits = property(lambda self: self.config.limits, doc="(τ1, τ2, τ3, f_ϱ) limits (4,).")
    dt = property(lambda self: self.config.dt)
    stepper = property(lambda self: self.config.stepper, doc="The integrator's env stepper (the seam's).")
    tolerances = property(lambda self: self.config.tolerances)
    reward_names = property(lambda self: self._names, doc='The names of ``info["reward_terms"]`` (the task\'s).')
    stepping_integrator = property(lambda self: self._method, doc="The method that really integrates.")
    kernel_config = property(lambda self: self.config.kcfg, doc="The task's kernel configuration ``cfg`` (read only).")

    @property
    def kernel_params(self) -> np.ndarray:
        """The body's kernel parameters P (9,) (the episode's body)."""
        return self.core.S[tr.P0 : tr.P0 + 9, 0].copy()

    # --- state ---------------------------------------------------------------------------------------
    @property
    def state(self) -> dict[str, float]:
        """The body's state as the eleven named fields (float64)."""
        return unpack(self.core.S[:11, 0].copy())

    @property
    def physics_state(self) -> np.ndarray:
        """The body's packed state y (11,) float64 (a copy; layout :mod:`flatbody_env.physics.state`)."""
        return self.core.S[:11, 0].copy()

    @property
    def time(self) -> float:
        """Simulated time of the episode (steps × dt)."""
        return float(self.core.K[tr.K_CLOCK, 0]) * self.config.dt

    @property
    def rotation(self) -> np.ndarray | None:
        """R(t) (3×3) when tracked (``track_rotation`` or a render mode), else None."""
        return None if self.core.R is None else self.core.R.copy()

    @property
    def witness(self) -> np.ndarray | None:
        """The current episode's witness — actions (steps, n) that take the start into the success ball at the
        last step — for tasks that draw one (:class:`~flatbody_env.env.witness.ReachWithWitness`); else None."""
        if self.config.task.kind != tr.TASK_WITNESS or not self._started:
            return None
        from flatbody_env.env.witness import witness_actions

        return witness_actions(self.core.S[tr.W0 : tr.W0 + 9, 0], self.config.task.witness_steps, self.config.n_act)

    @property
    def target(self) -> dict[str, float]:
        """The target stationary ellipse: lambda, mu, rho, s3, p_theta, omega3, theta_dot, energy."""
        if not self._started:
            return {}
        t = target_of(self.core, 0)
        return {"lambda": t.lam, "mu": t.mu, "rho": t.rho, "s3": t.s3, "p_theta": t.p_theta, "omega3": t.omega3,
                "theta_dot": t.theta_dot, "energy": t.energy}  # fmt: skip

    @property
    def target_vector(self) -> np.ndarray:
        """The target entries of the observation (λ*, μ*, ϱ*, s3*) (4,) (a copy)."""
        return self.core.S[tr.TG0 : tr.TG0 + 4, 0].copy()

    def left_domain(self, y: np.ndarray) -> str | None:
        """None inside the documented domain, else what left it."""
        return self.config.left_domain(y)

    def controls(self, action) -> tuple[np.ndarray, np.ndarray]:
        """The clipped action a (n,) and the controls u = (τ1, τ2, τ3, f_ϱ) (4,) it applies. ValueError for a
        non-finite or wrong-sized action."""
        a = self._action(action)
        if not np.isfinite(a).all():
            raise validation.refusal("action", f"be {a.size} finite real numbers in [-1, 1]", action)
        clipped, u = self.config.controls(a[None])
        return clipped[0], u[0]

    def _action(self, action) -> np.ndarray:
        """``action`` as (n,) float64 real numbers, or ``ValueError`` naming ``action`` (finiteness is checked by the
        transition itself, before the body moves)."""
        n = self.config.n_act
        try:
            a = np.asarray(action)
            a = None if a.dtype.kind not in "fiu" or a.dtype == np.bool_ else a.astype(np.float64, copy=False)
        except (TypeError, ValueError, OverflowError):
            a = None
        if a is None or a.shape != (n,):  # the action space's shape (n,) only: (1, n), (n, 1) are batches or typos
            raise validation.refusal("action", f"be {n} finite real numbers in [-1, 1] (shape ({n},))", action)
        return a

    # --- gymnasium API ---------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if seed is not None:
            validation.integer("seed", seed, low=0, high=validation.MAX_SEED)
        self.core.reset(seeds=None if seed is None else [seed], options=options)
        self._started = True
        return self.core.OBS[0].copy(), self._info(False)

    def step(self, action):
        if not self._started:
            raise RuntimeError("FlatBodyEnv: call reset() before step()")
        if type(action) is np.ndarray and action.shape == self._shape and action.dtype in _FLOATS:
            self._A[0] = action  # the fast path of a well-formed action (finiteness: the transition checks it)
        else:
            self._A[0] = self._action(action)
        core = self.core
        core.step(self._A)
        s = core.S[:, 0].tolist()
        k = core.K[:, 0].tolist()
        info = self._info_of(s, k)
        info["reward_terms"] = {name: s[i] for name, i in self._terms}
        return core.OBS[0].copy(), s[tr.R_REWARD], k[tr.K_TERMINATED] != 0, False, info

    def _info(self, step: bool) -> dict[str, Any]:
        return self._info_of(self.core.S[:, 0].tolist(), self.core.K[:, 0].tolist())

    def _info_of(self, s: list, k: list) -> dict[str, Any]:
        d = s[tr.R_DISTANCE]
        return {
            "t": k[tr.K_CLOCK] * self.config.dt,
            "distance": d,
            "is_success": d <= self._tol and not k[tr.K_TERMINATED],
            "energy": s[tr.R_ENERGY],
            "casimir": s[tr.R_CASIMIR],
            "p_theta": s[3],
            "integrator": {"method": self._method, "nfev": k[tr.K_NFEV]},
            "status": k[tr.K_STATUS],
            "domain_code": k[tr.K_CODE],
        }

    def end_reason(self, info: Mapping[str, Any]) -> str:
        """What ended the episode of a step's ``info``, in words ("" when nothing did)."""
        return end_reason(int(info["status"]), int(info["domain_code"]), self._method)

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        from flatbody_env.env.rendering import frame_status, render_frame

        R = self.core.R if self.core.R is not None else np.eye(3)
        return render_frame(self.physics_state, R, self.target, self.time, status=frame_status(self))


__all__ = [
    "CONTROLS",
    "DEFAULT_INTEGRATOR",
    "FlatBodyEnv",
    "OBSERVATION_NAMES",
    "REWARD_TERMS",
    "ROTATION_INTEGRATOR",
    "TARGET_NAMES",
]

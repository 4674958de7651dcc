"""``FlatBody-v0``: steer a flat affinely-rigid body with thickness onto a stationary ellipse.

The environment only composes three parts (dm_control's Environment/Task split): the body
(:class:`~flatbody_env.physics.body.Body`, physics of [1] with the corrections of [2]), an integrator
chosen by name through the seam :func:`flatbody_env.integrators.make_stepper`, and the task
:class:`~flatbody_env.env.task.ReachStationaryEllipse`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from flatbody_env.physics.body import Body, default_body
from flatbody_env.physics.equilibria import StationaryEllipse
from flatbody_env.env.kernels import CFG_SIZE, domain_code, post_step
from flatbody_env.physics.hamiltonian import hamiltonian
from flatbody_env.integrators import Tolerances, get_method, make_stepper
from flatbody_env.physics.state import STATE_NAMES, pack, unpack, validate_state
from flatbody_env.env.task import CONTROLS, REWARD_TERMS, TARGET_NAMES, ReachStationaryEllipse, control_mask, target_vector

DEFAULT_INTEGRATOR = "DOP853-numba"
"""Default integrator: compiled DOP853 at rtol = atol = :data:`DEFAULT_TOLERANCE`, first step guessed
as one env step — the fastest method measured to keep the episode state error ≤ 1e-8 and to survive
close approaches to λ = μ. Measured against scipy DOP853 at 1e-13 restarted every step with the
same actions, 16 episodes × 400 random-action steps: max error 2.0e-9 (median 2e-11); at 1e-10 one
chaotic episode reached 1.0e-7, hence 1e-11. Through a close approach (|λ − μ| = 7.7e-3) the error
stays below 1e-9 while RK4 at h = dt fails ("under-resolved") and fixed-step methods of similar cost
err by 1e-4…1e-1. ``flatbody bench env`` re-measures the episode error."""

DEFAULT_TOLERANCE = 1e-11
"""rtol = atol of the default integrator (see :data:`DEFAULT_INTEGRATOR`)."""

ROTATION_INTEGRATOR = "DOP853"
"""Integrator used when R must be carried (rendering, recording) and the chosen one cannot."""

OBSERVATION_NAMES: tuple[str, ...] = (
    "s1", "s2", "s3", "p_theta", "p_lambda", "p_mu", "p_rho", "lambda", "mu", "rho", "sin_theta", "cos_theta",
    "target_lambda", "target_mu", "target_rho", "target_s3",
)


class FlatBodyEnv(gym.Env):
    """Steer a flat affinely-rigid body with thickness onto a stationary ellipse.

    ## Description

    The body of [1] (section 3): a plate whose configuration is Φ = R·diag(λ, μ, ϱ)·U(θ)⁻¹ —
    two in-plane stretches λ, μ, a thickness ϱ, a material rotation θ and an orientation R —
    moving under the Hamiltonian H = 𝒯 (eq. (32)) + V_λμ (eqs. (37)–(39)) + V_ϱ (eq. (40)) with the
    equations of motion (44)–(49) (spin bracket corrected per NOTES E3/E4 of [2]). A stationary
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

    ## Rewards

    The reward is the sum of named terms, each ≤ 0 and each returned in ``info["reward_terms"]``
    (weights are keyword arguments, see :class:`~flatbody_env.env.task.ReachStationaryEllipse`):
    ``shape`` −w‖(Δλ, Δμ, Δϱ)‖, ``spin`` −w|Δs3|, ``tumble`` −w‖(ω1, ω2)‖, ``rest``
    −w‖(p_λ, p_μ, p_ϱ)‖, ``action`` −w‖a‖², ``failure`` −penalty when the step ends the episode by
    integrator failure or by leaving the domain.

    ``info["is_success"]`` is True when the distance d = ‖(Δλ, Δμ, Δϱ, Δs3, ω1, ω2, p_λ, p_μ, p_ϱ)‖
    is at most ``success_tolerance`` (0.05).

    ## Starting State

    A target is a spectrally stable stationary ellipse of the circulation family (|s3| < |p_θ|,
    NOTES §7) with λ* ∈ [1.3, 2], λ*/μ* ∈ [1.5, 3.5] (default body) that the controls can reach
    within the episode: its settling rate r (the slowest closed-loop pole of the cheap-control LQR
    about the target, :func:`flatbody_env.physics.controllability.settling_rate`) is at least
    ``min_settling_rate`` = 0.15 s⁻¹, so that under such feedback the slowest mode shrinks
    e³ ≈ 20-fold or more in 20 s (``"torque+dilatation"``; see :mod:`flatbody_env.env.task`, "Reachable within the episode");
    or the one given by ``reset(options={"target": {"lambda": ..., "mu": ...}})`` (not filtered). The initial state has the target's
    p_θ (conserved by every control), shape and spin within ``initial_noise`` (15 %) of the target,
    small momenta and a uniform θ; without torque |s| equals |s3*| (the Casimir is conserved).
    ``reset(options={"state": {...eleven names...}})`` sets the state exactly.

    ## Episode End

    Termination: the integrator failed (``info["integrator_failure"]`` says why: non-finite state,
    step-size collapse, chart singularity, energy error), or the state left the domain
    (``info["left_domain"]`` names the variable): λ, μ outside ``stretch_bounds``, ϱ outside
    ``rho_bounds``, a momentum beyond ``momentum_bound``, or |λ − μ|/(λ + μ) < ``gap_min`` for a
    two-polar-chart integrator. The returned observation is then the last valid state (never NaN).
    Truncation: after 400 steps (t = 20 at dt = 0.05) through ``TimeLimit`` (registration).

    ## Arguments

    ``gym.make("FlatBody-v0", control="torque+dilatation", body=None, dt=0.05, integrator=...,
    rtol=1e-11, atol=1e-11, step=None, torque_limit=0.5, force_limit=1.0, render_mode=None,
    track_rotation=False, stretch_bounds=(0.2, 4.0), rho_bounds=(0.1, 4.0), momentum_bound=50.0,
    gap_min=1e-3, **task_kwargs)`` where ``body`` is a :class:`~flatbody_env.physics.body.Body` or a scene-like
    dict ``{"params", "potential", "thickness"}`` (default: J = J3 = 1, V3 with κ = 1 and V_ϱ with
    a = b = 1 — barriers against every collapse, NOTES E10) and ``task_kwargs`` are the weights and
    ranges of :class:`~flatbody_env.env.task.ReachStationaryEllipse`. ``integrator`` is any name of
    ``flatbody methods``; the default :data:`DEFAULT_INTEGRATOR` is the fastest method measured to keep
    the episode state error ≤ 1e-8 (README, "Environment").

    ## Version History

    * v0: initial version.

    References
    ----------
    .. [1] ``shared/paper/000_b5acfe912a09eb12.txt``.
    .. [2] ``shared/physics/NOTES.md``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(
        self,
        control: str = "torque+dilatation",
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
        self._mask = control_mask(control)
        self.control = control
        self.body = _as_body(body)
        if not self.body.inertia.is_isotropic:
            raise ValueError("body: the task's stationary ellipses need J1 = J2 (isotropic in the plane)")
        for name, value in (("dt", dt), ("torque_limit", torque_limit), ("force_limit", force_limit), ("momentum_bound", momentum_bound)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"{name}: must be a finite number > 0, got {value!r}")
        for name, (lo, hi) in (("stretch_bounds", stretch_bounds), ("rho_bounds", rho_bounds)):
            if not (0 < lo < hi and math.isfinite(hi)):
                raise ValueError(f"{name}: must be (lo, hi) with 0 < lo < hi, got {(lo, hi)!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode: must be None or 'rgb_array', got {render_mode!r}")
        self.dt = float(dt)
        self.integrator = integrator
        info = get_method(integrator).info  # ValueError for an unknown name
        self._chart = info.chart
        self.render_mode = render_mode
        self.track_rotation = bool(track_rotation or render_mode is not None)
        self._fixed_step = not info.adaptive
        if self._fixed_step and step is None:
            step = self.dt  # one fixed step per env step unless step= asks for sub-steps
        self.tolerances = Tolerances(rtol=rtol, atol=atol, step=step)
        self.stepping_integrator = integrator
        try:
            self._stepper = make_stepper(integrator, self.body, self.tolerances, with_rotation=self.track_rotation)
        except ValueError:
            if not self.track_rotation:
                raise
            # compiled two-polar methods do not carry R: drawing/recording integrates with the reference
            self.stepping_integrator = ROTATION_INTEGRATOR
            self._stepper = make_stepper(ROTATION_INTEGRATOR, self.body, Tolerances(rtol=rtol, atol=atol), with_rotation=True)
        self._fast = None
        if self.stepping_integrator == integrator and not self.track_rotation and self.body.compiled:
            self._fast = _fast_stepper(integrator)
        self.task = ReachStationaryEllipse(**task_kwargs)
        self.limits = np.array([torque_limit, torque_limit, torque_limit, force_limit])
        self.stretch_bounds = (float(stretch_bounds[0]), float(stretch_bounds[1]))
        self.rho_bounds = (float(rho_bounds[0]), float(rho_bounds[1]))
        self.momentum_bound = float(momentum_bound)
        self.gap_min = float(gap_min)
        t = self.task
        self._cfg = np.array(
            [t.w_shape, t.w_spin, t.w_tumble, t.w_rest, t.w_action, t.failure_penalty, t.success_tolerance,
             *self.stretch_bounds, *self.rho_bounds, self.momentum_bound, self.gap_min, 1.0 if self._chart == "two-polar" else 0.0],
            dtype=np.float64,
        )
        assert self._cfg.size == CFG_SIZE
        self._P = np.array(self.body.kernel_params(), dtype=np.float64)
        self._work = (np.empty(11), np.empty(6), np.empty(4), np.empty(7), np.empty(4))
        self._mask_u8 = self._mask.astype(np.uint8)
        self._a = np.zeros(max(int(self._mask.sum()), 1))
        self._zero_action = np.zeros_like(self._a)
        self._u = np.zeros(4)
        self._ynew = np.empty(11)
        self._h = float(self.tolerances.step) if self.tolerances.step is not None else 0.0
        # fixed-step methods: the sub-step; DOP853: the first step guessed as one whole env step
        # (accepted in one step at the default tolerance; rejected and halved where needed)
        self._h_guess = self._h if self._fixed_step else self.dt
        self._has_action = bool(self._mask.any())

        n_act = int(self._mask.sum()) or 1
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n_act,), dtype=np.float32)
        m, (slo, shi), (rlo, rhi) = self.momentum_bound, self.stretch_bounds, self.rho_bounds
        low = np.array([-m] * 7 + [slo, slo, rlo, -1.0, -1.0, slo, slo, rlo, -m], dtype=np.float32)
        high = np.array([m] * 7 + [shi, shi, rhi, 1.0, 1.0, shi, shi, rhi, m], dtype=np.float32)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)

        self._y = np.zeros(11)
        self._R: np.ndarray | None = np.eye(3) if self.track_rotation else None
        self._target: StationaryEllipse | None = None
        self._tvec = np.zeros(4)
        self.time = 0.0
        self._last_action = np.zeros(n_act)

    # --- public state -------------------------------------------------------------------------------
    @property
    def state(self) -> dict[str, float]:
        """The body's state as the eleven named fields (float64)."""
        return unpack(self._y)

    @property
    def rotation(self) -> np.ndarray | None:
        """R(t) (3×3) when tracked (``track_rotation`` or a render mode), else None."""
        return None if self._R is None else self._R.copy()

    @property
    def target(self) -> dict[str, float]:
        """The target stationary ellipse: lambda, mu, rho, s3, p_theta, omega3, theta_dot, energy."""
        t = self._target
        if t is None:
            return {}
        return {"lambda": t.lam, "mu": t.mu, "rho": t.rho, "s3": t.s3, "p_theta": t.p_theta, "omega3": t.omega3, "theta_dot": t.theta_dot, "energy": t.energy}

    # --- gymnasium API ---------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode; ``options``: ``{"target": {"lambda", "mu"[, "branch", "sign"]}, "state": {...}}``,
        each checked by :mod:`flatbody_env.physics.validation` (``ValueError`` naming ``options.…``)."""
        super().reset(seed=seed)
        options = _checked_options(options)
        if "target" in options:
            self._target = self.task.target_from(options["target"], self.body)
        else:
            self._target = self.task.sample_target(self.np_random, self.body, limits=self.limits, control=self.control)
        self._tvec = target_vector(self._target)
        if "state" in options:
            state = options["state"]
            try:
                validate_state(state, where="options.state")
            except ValueError as exc:
                raise ValueError(str(exc)) from None
            self._y = pack(state, validate=False)
        else:
            self._y = self.task.sample_initial_state(self.np_random, self._target, self.control)
        left = self._left_domain(self._y)
        if left:
            raise ValueError(f"options.state: starts outside the domain ({left})")
        self._R = np.eye(3) if self.track_rotation else None
        self.time = 0.0
        self._last_action = np.zeros(self.action_space.shape)
        return self._observation(), self._reset_info()

    def step(self, action):
        if self._target is None:
            raise RuntimeError("FlatBodyEnv: call reset() before step()")
        if self._fast is not None:
            return self._step_fast(action)
        a = np.asarray(action, dtype=np.float64).reshape(self.action_space.shape)
        if not np.all(np.isfinite(a)):
            raise ValueError("action: must be finite numbers in [-1, 1]")
        a = np.clip(a, -1.0, 1.0)
        u = np.zeros(4)
        if self._mask.any():
            u[self._mask] = a * self.limits[self._mask]
        result = self._stepper(self._y, self._R, u, self.dt)
        act = a if self._mask.any() else np.zeros_like(a)
        y_out, terms_arr, sc, vel, force = self._work
        obs = np.empty(16, dtype=np.float32)
        ended = post_step(self._y, result.y, 0 if result.ok else 1, act, act.size, self._tvec, self._cfg, self._P, y_out, obs, terms_arr, sc, vel, force)
        failure = None if result.ok else f"{result.kind}: {result.reason}"
        left = self._left_domain(result.y) if result.ok and ended else None
        if not ended:
            self._y = y_out.copy()
            if self.track_rotation:
                self._R = result.R
            self.time += self.dt
        terms = dict(zip(REWARD_TERMS, terms_arr.tolist()))
        info = self._step_info(terms, failure, left, result.nfev, sc)
        return obs, float(terms_arr.sum()), bool(ended), False, info

    def _step_fast(self, action):
        """One compiled integrator call and one compiled bookkeeping call (same results as the slow path)."""
        fast = self._fast
        ek = fast.kernels
        a = np.asarray(action, dtype=np.float64)
        if a.ndim != 1:
            a = a.ravel()
        if a.size != self._a.size or not ek.controls_kernel(a, self._mask_u8, self.limits, self._a, self._u):
            raise ValueError(f"action: must be {self._a.size} finite numbers in [-1, 1], got {action!r}")
        tol = self.tolerances
        y = self._y
        st = fast.stepper.step(y, self._u, self._P, self.dt, self._h_guess, tol.rtol, tol.atol, np.inf, self._ynew)
        y_out, terms_arr, sc, vel, force = self._work
        obs = np.empty(16, dtype=np.float32)
        act = self._a if self._has_action else self._zero_action
        ended = ek.post_step(y, self._ynew, st, act, act.size, self._tvec, self._cfg, self._P, y_out, obs, terms_arr, sc, vel, force)
        failure = left = None
        if ended:
            if st != 0:
                failure = f"{fast.kinds[st]}: {fast.reason(st)}"
            else:
                left = self._left_domain(self._ynew)
        else:
            y[:] = y_out
            self.time += self.dt
        tl = terms_arr.tolist()
        distance, energy, cas, _ = sc.tolist()
        info = {
            "t": self.time,
            "distance": distance,
            "is_success": distance <= self.task.success_tolerance and not ended,
            "energy": energy,
            "casimir": cas,
            "p_theta": float(y[3]),
            "integrator": {"method": self.integrator, "nfev": 0},
            "integrator_failure": failure,
            "left_domain": left,
            "reward_terms": dict(zip(REWARD_TERMS, tl)),
        }
        return obs, sum(tl), bool(ended), False, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        from flatbody_env.env.rendering import render_frame

        return render_frame(self._y, self._R if self._R is not None else np.eye(3), self.target, self.time)

    # --- helpers -----------------------------------------------------------------------------------------
    def _left_domain(self, y: np.ndarray) -> str | None:
        """None inside the documented domain, else what left it (the test itself is
        :func:`flatbody_env.env.kernels.domain_code`, shared with the compiled path)."""
        code = domain_code(y, self._cfg)
        if code == 0:
            return None
        if code == 1:
            return "non-finite state"
        lo, hi = self.stretch_bounds
        if code in (2, 3):
            name, k = ("lambda", 7) if code == 2 else ("mu", 8)
            return f"{name} = {y[k]:.4g} outside [{lo:g}, {hi:g}]"
        if code == 4:
            return f"rho = {y[9]:.4g} outside [{self.rho_bounds[0]:g}, {self.rho_bounds[1]:g}]"
        if code == 5:
            k = int(np.argmax(np.abs(y[:7]) > self.momentum_bound))
            return f"{STATE_NAMES[k]} = {y[k]:.4g} beyond the momentum bound {self.momentum_bound:g}"
        return f"|lambda - mu|/(lambda + mu) < gap_min = {self.gap_min:g} (two-polar chart singular at lambda = mu)"

    def _observation(self) -> np.ndarray:
        y = self._y
        obs = np.concatenate([y[:10], [math.sin(y[10]), math.cos(y[10])], self._tvec])
        return obs.astype(np.float32)

    def _step_info(self, terms, failure, left, nfev, sc) -> dict[str, Any]:
        distance = float(sc[0])
        return {
            "t": self.time,
            "distance": distance,
            "is_success": bool(distance <= self.task.success_tolerance and not failure and not left),
            "energy": float(sc[1]),
            "casimir": float(sc[2]),
            "p_theta": float(self._y[3]),
            "integrator": {"method": self.integrator, "nfev": int(nfev)},
            "integrator_failure": failure,
            "left_domain": left,
            "reward_terms": terms,
        }

    def _reset_info(self) -> dict[str, Any]:
        y = self._y
        distance = float(self.task.distance(y, self.body, self._tvec))
        return {
            "t": self.time,
            "distance": distance,
            "is_success": bool(distance <= self.task.success_tolerance),
            "energy": float(hamiltonian(y, self.body)),
            "casimir": float(y[0] ** 2 + y[1] ** 2 + y[2] ** 2),
            "p_theta": float(y[3]),
            "integrator": {"method": self.integrator, "nfev": 0},
            "integrator_failure": None,
            "left_domain": None,
        }


class _FastPath:
    """The compiled environment stepper of a method plus the compiled bookkeeping (picklable)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._load()

    def _load(self) -> None:
        from flatbody_env.env import compiled as env_compiled
        from flatbody_env.integrators.compiled_methods import env_stepper
        from flatbody_env.integrators.failure import KINDS, failure_reason

        self.stepper = env_stepper(self.name)
        self.kernels = env_compiled
        self.kinds = KINDS
        self.reason = failure_reason

    def __getstate__(self):
        return {"name": self.name}

    def __setstate__(self, state):
        self.name = state["name"]
        self._load()


def _fast_stepper(name: str) -> _FastPath | None:
    """The compiled fast path for ``name`` if it has a paper-state environment stepper, else None."""
    from flatbody_env.integrators.compiled_methods import ENV_METHODS, env_stepper

    if name not in ENV_METHODS or env_stepper(name).state != "paper":
        return None
    return _FastPath(name)


def _as_body(body: Body | Mapping[str, Any] | None) -> Body:
    if body is None:
        return default_body()
    if isinstance(body, Body):
        return body
    if isinstance(body, Mapping):
        return Body.from_dict(body, where="body")
    raise ValueError(f"body: expected a Body or a dict with params/potential/thickness, got {type(body).__name__}")


__all__ = ["FlatBodyEnv", "DEFAULT_INTEGRATOR", "OBSERVATION_NAMES", "CONTROLS", "REWARD_TERMS", "TARGET_NAMES"]


def _checked_options(options: Any) -> dict[str, Any]:
    """``reset(options=...)`` validated before use: types, finite numbers within the documented
    ranges (:mod:`flatbody_env.physics.validation`); ``ValueError`` naming ``options.…``."""
    from flatbody_env.physics import validation as v

    if options is None:
        return {}
    options = dict(v.mapping("options", options))
    v.keys("options", options, ("target", "state"))
    target = options.get("target")
    if target is not None and not isinstance(target, StationaryEllipse):
        target = v.mapping("options.target", target)
        v.keys("options.target", target, ("lambda", "mu", "branch", "sign", "rho", "s3", "p_theta"), ("lambda", "mu"))
        checked = {k: v.number(f"options.target.{k}", target[k], low=v.STRETCH_RANGE[0], high=v.STRETCH_RANGE[1]) for k in ("lambda", "mu")}
        if "branch" in target:
            checked["branch"] = v.string("options.target.branch", target["branch"], choices=("rotation", "circulation"))
        if "sign" in target:
            checked["sign"] = v.number("options.target.sign", target["sign"], low=-1.0, high=1.0)
            if checked["sign"] not in (-1.0, 1.0):
                raise ValueError(f"options.target.sign: must be +1 or -1, got {checked['sign']!r}")
        options["target"] = checked
    if "state" in options:
        options["state"] = v.mapping("options.state", options["state"])
    return options


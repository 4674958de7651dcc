"""``FlatBody-v0``: steer a flat affinely-rigid body with thickness onto a stationary ellipse.

The environment only composes three parts (dm_control's Environment/Task split): the body
(:class:`~flatbody_env.physics.body.Body`, physics of [1] with the corrections of [2]), an integrator
chosen by name through the seam :func:`flatbody_env.integrators.steppers.make_env_step`, and the task
:class:`~flatbody_env.env.task.ReachStationaryEllipse` (observation, reward terms, termination).
There is one step path: the seam's stepper (compiled where the method has a compiled environment
stepper, the generic one otherwise), then the bookkeeping kernel
:func:`flatbody_env.env.kernels.post_step` (its compiled twin when the stepper is compiled), then
:func:`build_info`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from flatbody_env.env import kernels as python_kernels
from flatbody_env.env.registration import TASK_CLASSES
from flatbody_env.env.task import (
    CONTROLS,
    OBSERVATION_NAMES,
    OBSERVATION_SIZE,
    REWARD_TERMS,
    TARGET_NAMES,
    Episode,
    ReachStationaryEllipse,
    control_mask,
    domain_code,
    target_row,
)
from flatbody_env.integrators import Tolerances, get_method
from flatbody_env.integrators.steppers import make_env_step
from flatbody_env.physics import validation
from flatbody_env.physics.body import Body, default_body
from flatbody_env.physics.equilibria import StationaryEllipse, stationary_from_shape
from flatbody_env.physics.potentials import KIND_CUSTOM
from flatbody_env.physics.state import STATE_NAMES, STATE_SIZE, pack, unpack, validate_state

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
"""Integrator used when R must be carried (rendering, recording) and the chosen method refuses to
step this body at all (e.g. a compiled method with a custom potential); ``info["integrator"]["method"]``
then names it. The compiled two-polar methods carry R themselves
(:mod:`flatbody_env.integrators.rotation_kernels`), so rendering and recording run the method asked for."""


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
    [2]) with λ* ∈ [1.3, 2], λ*/μ* ∈ [1.5, 3.5] (default body) that the controls can reach
    within the episode: its settling rate r (the slowest closed-loop pole of the cheap-control LQR
    about the target, :func:`flatbody_env.physics.controllability.settling_rate`) is at least
    ``min_settling_rate`` = 0.15 s⁻¹, so that under such feedback the slowest mode shrinks
    e³ ≈ 20-fold or more in 20 s (``"torque+dilatation"``; see :mod:`flatbody_env.env.task`, "Reachable within the episode");
    or the one given by ``reset(options={"target": {"lambda": ..., "mu": ...}})`` (not filtered). The initial state has the target's
    p_θ (conserved by every control), shape and spin within ``initial_noise`` (15 %) of the target,
    small momenta and a uniform θ; without torque |s| equals |s3*| (the Casimir is conserved).
    ``reset(options={"state": {...eleven names...}})`` sets the state exactly.

    ## Info

    Built in one place (:func:`build_info`) for ``reset``, ``step`` and the vector env: ``t``,
    ``distance``, ``is_success``, ``energy`` (H, eq. (41)), ``casimir`` (|s|²), ``p_theta``,
    ``integrator`` ({"method": the method that really ran, "nfev": its right-hand-side
    evaluations in this step}), ``integrator_failure``, ``left_domain`` and (``step``) ``reward_terms``.

    ## Episode End

    Termination: the integrator failed (``info["integrator_failure"]`` says why: non-finite state,
    step-size collapse, chart singularity, energy error), or the state left the domain
    (``info["left_domain"]`` names the variable): λ, μ outside ``stretch_bounds``, ϱ outside
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
    terms, end episodes of its own accord and append observation entries (:attr:`observation_size`). ``integrator`` is any name of
    ``flatbody methods``; the default :data:`DEFAULT_INTEGRATOR` is the fastest method measured to keep
    the episode state error ≤ 1e-8 (``docs/env.md``).

    ## Version History

    * v0: initial version (unchanged when the other tasks were added: same draws, numbers bit for bit).

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
        self.mask = control_mask(control)
        self.control = control
        self.task = _as_task(task, task_kwargs)
        if self.task.varies_body and body is not None:
            raise ValueError("body: this task draws its own body at every reset (leave body unset)")
        self.body = _as_body(body)
        self.custom_potential = (
            self.body.potential if getattr(self.body.potential, "kind", None) == KIND_CUSTOM else None
        )
        """The body's custom (Python) potential, whose part of H the bookkeeping kernels leave out
        (:meth:`energy_left_out`); None for a built-in potential."""
        if not self.body.inertia.is_isotropic:
            raise ValueError("body: the task's stationary ellipses need J1 = J2 (isotropic in the plane)")
        for name, value in (
            ("torque_limit", torque_limit),
            ("force_limit", force_limit),
            ("momentum_bound", momentum_bound),
        ):
            validation.number(name, value, low=validation.PARAM_RANGE[0], high=validation.MOMENTUM_MAX)
        for name, pair in (("stretch_bounds", stretch_bounds), ("rho_bounds", rho_bounds)):
            validation.interval(name, pair, low=validation.STRETCH_RANGE[0], high=validation.STRETCH_RANGE[1])
        validation.number("gap_min", gap_min, low=0.0, high=0.5)
        if render_mode is not None:
            validation.string("render_mode", render_mode, choices=self.metadata["render_modes"])
        validation.boolean("track_rotation", track_rotation)
        self.dt = validation.number("dt", dt, low=validation.ENV_DT_RANGE[0], high=validation.ENV_DT_RANGE[1])
        self.integrator = validation.string("integrator", integrator)
        info = get_method(integrator, where="integrator").info  # ValueError naming integrator for an unknown name
        self.render_mode = render_mode
        self.track_rotation = bool(track_rotation or render_mode is not None)
        if not info.adaptive and step is None:
            step = self.dt  # one fixed step per env step unless step= asks for sub-steps
        if (
            step is not None
        ):  # bounded work: a floor (never replaced) and at most ENV_MAX_SUBSTEPS sub-steps per env step
            step = validation.fixed_step("step", step, high=self.dt)
            if math.ceil(self.dt / step) > validation.ENV_MAX_SUBSTEPS:
                raise ValueError(
                    f"step: at most {validation.ENV_MAX_SUBSTEPS} sub-steps per env step (step >= dt / "
                    f"{validation.ENV_MAX_SUBSTEPS} = {self.dt / validation.ENV_MAX_SUBSTEPS:g}), got step = {step!r}"
                )
        # the per-step budget (docs/reliability.md): every env step stops within these
        self.tolerances = Tolerances(
            rtol=rtol,
            atol=atol,
            step=step,
            max_nfev=validation.ENV_STEP_MAX_NFEV,
            max_wall_time=validation.ENV_STEP_MAX_SECONDS,
        )
        # adaptive methods: the first step guessed as one whole env step (accepted in one step at
        # the default tolerance; rejected and halved where needed)
        first_step = 0.0 if not info.adaptive else self.dt
        try:
            self.stepper = make_env_step(
                integrator, self.body, self.tolerances, with_rotation=self.track_rotation, first_step=first_step
            )
        except ValueError:
            if not self.track_rotation:
                raise
            # methods that do not carry R: drawing/recording integrates with the reference (info names it)
            self.stepper = make_env_step(
                ROTATION_INTEGRATOR,
                self.body,
                Tolerances(
                    rtol=rtol,
                    atol=atol,
                    max_nfev=validation.ENV_STEP_MAX_NFEV,
                    max_wall_time=validation.ENV_STEP_MAX_SECONDS,
                ),
                with_rotation=True,
            )
        self.limits = np.array([torque_limit, torque_limit, torque_limit, force_limit])
        self.stretch_bounds = (float(stretch_bounds[0]), float(stretch_bounds[1]))
        self.rho_bounds = (float(rho_bounds[0]), float(rho_bounds[1]))
        self.momentum_bound = float(momentum_bound)
        self.gap_min = float(gap_min)
        self._cfg = self.task.kernel_config(
            stretch_bounds=self.stretch_bounds,
            rho_bounds=self.rho_bounds,
            momentum_bound=self.momentum_bound,
            gap_min=self.gap_min,
            check_gap=info.chart == "two-polar",
        )
        self._P = np.array(self.body.kernel_params(), dtype=np.float64)
        self._mask_u8 = self.mask.astype(np.uint8)

        n_act = int(self.mask.sum()) or 1
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n_act,), dtype=np.float32)
        m, (slo, shi), (rlo, rhi) = self.momentum_bound, self.stretch_bounds, self.rho_bounds
        xlo, xhi = self.task.observation_extra_bounds()
        low = np.array([-m] * 7 + [slo, slo, rlo, -1.0, -1.0, slo, slo, rlo, -m, *xlo], dtype=np.float32)
        high = np.array([m] * 7 + [shi, shi, rhi, 1.0, 1.0, shi, shi, rhi, m, *xhi], dtype=np.float32)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.observation_size = OBSERVATION_SIZE + len(self.task.observation_extra_names)
        """Entries of the observation: the 16 of :data:`~flatbody_env.env.task.OBSERVATION_NAMES` and the task's own."""
        self.reward_names = self.task.reward_names
        """The names of ``info["reward_terms"]`` (the task's)."""
        self._own_terms = bool(self.task.extra_reward_names)
        self._obs_extra = self.task.observation_extra(self.body).astype(np.float32)
        self._witness: np.ndarray | None = None

        # work arrays of the one step path
        self._a = np.zeros(n_act)
        self._u = np.zeros(4)
        self._views()
        self._ynew = np.empty(STATE_SIZE)
        self._yout = np.empty(STATE_SIZE)
        self._terms = np.empty(len(self.reward_names))
        self._sc = np.empty(4)
        self._vel = np.empty(7)
        self._force = np.empty(4)
        self._counters = np.zeros(4, np.int64)  # [nfev, steps, rejected, nfev budget of one env step (compiled DOP853)]
        self._counters[3] = validation.ENV_STEP_MAX_NFEV
        self._Rnew = np.eye(3)

        self._y = np.zeros(STATE_SIZE)
        self._R: np.ndarray | None = np.eye(3) if self.track_rotation else None
        self._target: StationaryEllipse | None = None
        self._target_shape: tuple[float, float, float] | None = (
            None  # (λ*, μ*, sign) of a target drawn by the sampler, built on demand
        )
        self._sampler = None
        self._tvec = np.zeros(4)
        self.time = 0.0

    # --- public state and configuration ---------------------------------------------------------------
    @property
    def state(self) -> dict[str, float]:
        """The body's state as the eleven named fields (float64)."""
        return unpack(self._y)

    @property
    def physics_state(self) -> np.ndarray:
        """The body's packed state y (11,) float64 (a copy; layout :mod:`flatbody_env.physics.state`)."""
        return self._y.copy()

    @property
    def rotation(self) -> np.ndarray | None:
        """R(t) (3×3) when tracked (``track_rotation`` or a render mode), else None."""
        return None if self._R is None else self._R.copy()

    @property
    def witness(self) -> np.ndarray | None:
        """The current episode's witness — actions (steps, n) that take the start into the success ball at the
        last step — for tasks that draw one (:class:`~flatbody_env.env.witness.ReachWithWitness`); else None."""
        return None if self._witness is None else self._witness.copy()

    @property
    def sampler(self):
        """The :class:`~flatbody_env.env.sampling.EpisodeSampler` of this configuration (compiled when the
        stepper is), which draws a reset's target and initial state without Python per draw."""
        if self._sampler is None:
            from flatbody_env.env import sampling
            from flatbody_env.env.sampling import EpisodeSampler

            self._sampler = EpisodeSampler(
                self.task, self.body, self.limits, self.control, self.kernels if self.stepper.compiled else sampling
            )
        return self._sampler

    @property
    def target(self) -> dict[str, float]:
        """The target stationary ellipse: lambda, mu, rho, s3, p_theta, omega3, theta_dot, energy."""
        if self._target is None and self._target_shape is not None:
            lam, mu, sign = self._target_shape
            self._target = stationary_from_shape(self.body, lam, mu, branch=self.task.target_branch, sign=sign)
        t = self._target
        if t is None:
            return {}
        return {
            "lambda": t.lam,
            "mu": t.mu,
            "rho": t.rho,
            "s3": t.s3,
            "p_theta": t.p_theta,
            "omega3": t.omega3,
            "theta_dot": t.theta_dot,
            "energy": t.energy,
        }

    @property
    def target_vector(self) -> np.ndarray:
        """The target entries of the observation (λ*, μ*, ϱ*, s3*) (4,) (a copy)."""
        return self._tvec.copy()

    @property
    def stepping_integrator(self) -> str:
        """The method that really integrates (``integrator``, or :data:`ROTATION_INTEGRATOR` when R
        must be carried and ``integrator`` cannot)."""
        return self.stepper.method

    @property
    def kernels(self):
        """The bookkeeping kernels matching the stepper: :mod:`flatbody_env.env.compiled` when the
        stepper runs compiled, else :mod:`flatbody_env.env.kernels` (same source)."""
        if self.stepper.compiled:
            from flatbody_env.env import compiled

            return compiled
        return python_kernels

    @property
    def kernel_params(self) -> np.ndarray:
        """The body's kernel parameters P (9,) as the kernels take them (read only)."""
        return self._P

    @property
    def kernel_config(self) -> np.ndarray:
        """The task/domain configuration vector ``cfg`` of the kernels (:mod:`flatbody_env.env.task`; read only)."""
        return self._cfg

    # --- gymnasium API ---------------------------------------------------------------------------------
    def sample_episode(
        self, rng: np.random.Generator, options: Mapping[str, Any] | None = None
    ) -> tuple[np.ndarray, StationaryEllipse]:
        """The initial state y (11,) and the target that :meth:`reset` draws from ``rng`` with ``options``
        (the env itself is not changed; ``rng`` advances exactly as in ``reset``). :meth:`draw_episodes`
        gives the task's whole draw (body and witness included)."""
        ep = self.draw_episodes([rng], options)[0]
        target = ep.ellipse
        if target is None:
            body = ep.body or self.body
            target = stationary_from_shape(
                body, float(ep.target[0]), float(ep.target[1]), branch=self.task.target_branch, sign=float(ep.target[5])
            )
        return ep.state, target

    def draw_episodes(self, rngs, options: Mapping[str, Any] | None = None) -> list[Episode]:
        """What :meth:`reset` draws for each generator in ``rngs`` with ``options`` — the task's draws
        (:meth:`~flatbody_env.env.task.ReachStationaryEllipse.draw_batch`; each generator advances exactly as
        in a reset of its own), or the target and state the options give. The env itself is not changed."""
        options = _checked_options(options)
        if not options:
            episodes = self.task.draw_batch(
                list(rngs), self.body, limits=self.limits, control=self.control, simulator=self
            )
        else:
            episodes = [self._draw_with_options(rng, options) for rng in rngs]
        for ep in episodes:
            self.check_start(ep.state, "options.state" if "state" in options else "initial_noise")
        return episodes

    def _draw_with_options(self, rng: np.random.Generator, options: Mapping[str, Any]) -> Episode:
        """The target and/or state that ``options`` give; what they do not give is drawn by the task for the env's
        current body (:meth:`~flatbody_env.env.task.ReachStationaryEllipse.sample_target`,
        :meth:`~flatbody_env.env.task.ReachStationaryEllipse.start_near`), without a witness."""
        if "target" in options:
            target = self.task.target_from(options["target"], self.body)
        else:
            target = self.task.sample_target(rng, self.body, limits=self.limits, control=self.control)
        if "state" in options:
            try:
                validate_state(options["state"], where="options.state")
            except ValueError as exc:
                raise ValueError(str(exc)) from None
            y = pack(options["state"], validate=False)
        else:
            y = self.task.start_near(rng, target, self.control, body=self.body)
        return Episode(state=y, target=target_row(target), ellipse=target)

    def rollout(self, Y: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Advance N bodies from the states ``Y`` (11, N) under the normalised actions ``actions`` (steps, N, n)
        with this env's integrator and body; returns the final states (11, N) and whether each body stayed
        inside the domain without an integrator failure (N,) bool (a failed body keeps its last valid state).
        The task's simulations at reset use it (:class:`~flatbody_env.env.witness.ReachWithWitness`)."""
        from flatbody_env.env import task as task_module

        Y = np.array(Y, dtype=np.float64, order="C")
        n = Y.shape[1]
        actions = np.asarray(actions, dtype=np.float64)
        if actions.ndim != 3 or actions.shape[1] != n or actions.shape[2] != self._a.size:
            raise ValueError(f"actions: expected shape (steps, {n}, {self._a.size}), got {actions.shape}")
        codes_of = self.kernels.domain_codes if self.stepper.compiled else task_module.domain_codes
        out, status, nfev, codes = np.empty_like(Y), np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64)
        U, A = np.empty((4, n)), np.empty((n, self._a.size))
        ok = np.ones(n, dtype=bool)
        for k in range(actions.shape[0]):
            if not self.kernels.controls_batch(np.ascontiguousarray(actions[k]), self._mask_u8, self.limits, A, U):
                raise ValueError("actions: must be finite numbers")
            self.stepper.advance_batch(Y, U, self.dt, out, status, nfev)
            codes_of(out, self._cfg, codes)
            ok &= (status == 0) & (codes == 0)
            np.copyto(Y, out, where=ok)
        return Y, ok

    def use_body(self, body: Body) -> None:
        """Make ``body`` the env's body (a task that draws its body per episode): the stepper, the kernel
        parameters and the observation's body entries follow."""
        if body is self.body:
            return
        self.body = body
        self.stepper = self.stepper.with_body(body)
        self._P = np.array(body.kernel_params(), dtype=np.float64)
        self._obs_extra = self.task.observation_extra(body).astype(np.float32)
        self._sampler = None

    def energy_left_out(self, Y: np.ndarray) -> np.ndarray | float:
        """The part of H (eq. (41)) that the bookkeeping kernels leave out of ``info["energy"]`` at the
        states ``Y`` (11,) or (11, N): a custom in-plane potential's value (the kernels know the
        built-in potentials only), 0 otherwise. The single and the batched env add it."""
        pot = self.custom_potential
        if pot is None:
            return 0.0
        if np.ndim(Y) == 1:
            return float(pot.value(float(Y[7]), float(Y[8]), float(Y[9])))
        return np.array([float(pot.value(float(a), float(b), float(c))) for a, b, c in zip(Y[7], Y[8], Y[9])])

    def check_start(self, y: np.ndarray, field: str) -> None:
        """ValueError naming ``field`` when the initial state ``y`` lies outside the domain."""
        left = self.left_domain(y)
        if left:
            raise ValueError(f"{field}: the initial state starts outside the domain ({left})")

    def observe(self, y: np.ndarray, target_vector: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
        """The observation (:attr:`observation_size`,) float32 and the reset ``info`` of state ``y`` with target
        (λ*, μ*, ϱ*, s3*) (the env's current body)."""
        obs = np.empty(self.observation_size, dtype=np.float32)
        self.kernels.post_step(
            y,
            y,
            0,
            self._a,
            0,
            target_vector,
            self._cfg,
            self._P,
            self._yout,
            obs,
            self._terms,
            self._sc,
            self._vel,
            self._force,
        )
        obs[OBSERVATION_SIZE:] = self._obs_extra
        if self.custom_potential is not None:
            self._sc[1] += self.energy_left_out(self._yout)
        return obs, build_info(
            t=0.0,
            scalars=self._sc,
            p_theta=y[3],
            ended=False,
            failure=None,
            left=None,
            method=self.stepper.method,
            nfev=0,
            terms=None,
            success_tolerance=self.task.success_tolerance,
        )

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if (
            not options and self.task.compiled_resets and self.sampler.applies
        ):  # the task's draws, through the sampler's kernels
            Y = np.empty((STATE_SIZE, 1))
            tg = self.sampler.sample([self.np_random], Y, [0])[0]
            y = Y[:, 0].copy()
            self.check_start(y, "initial_noise")
            self._y, self._target, self._target_shape = y, None, (float(tg[0]), float(tg[1]), float(tg[5]))
            self._tvec = tg[:4].copy()
            self._witness = None
        else:
            self.start_episode(self.draw_episodes([self.np_random], options)[0])
        self._R = np.eye(3) if self.track_rotation else None
        self.time = 0.0
        return self.observe(self._y, self._tvec)

    def start_episode(self, episode: Episode) -> None:
        """Set the state, target, body and witness of a drawn episode (:meth:`draw_episodes`)."""
        if episode.body is not None:
            self.use_body(episode.body)
        self._y = np.array(episode.state, dtype=np.float64)
        self._target = episode.ellipse
        tg = episode.target
        self._target_shape = (float(tg[0]), float(tg[1]), float(tg[5]))
        self._tvec = np.array(tg[:4], dtype=np.float64)
        self._witness = episode.witness

    def controls(self, action) -> tuple[np.ndarray, np.ndarray]:
        """The clipped action a (n,) and the controls u = (τ1, τ2, τ3, f_ϱ) (4,) it applies
        (:func:`flatbody_env.env.kernels.controls_batch`). ValueError for a non-finite or wrong-sized action."""
        self._set_controls(action)
        return self._a.copy(), self._u.copy()

    def _views(self) -> None:
        """``self._a`` and ``self._u`` as one body's (1, n) and (4, 1) arrays for controls_batch (views: rebuilt after unpickling)."""
        self._a_row, self._u_col = self._a.reshape(1, -1), self._u.reshape(4, 1)

    def __setstate__(self, state) -> None:
        self.__dict__.update(state)
        self._views()

    def _set_controls(self, action) -> None:
        """Clip and scale ``action`` into ``self._a``, ``self._u`` (the step's controls)."""
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            a = None
        if (
            a is None
            or a.size != self._a.size
            or not self.kernels.controls_batch(a.reshape(1, -1), self._mask_u8, self.limits, self._a_row, self._u_col)
        ):
            raise ValueError(f"action: must be {self._a.size} finite numbers in [-1, 1], got {action!r:.80}")

    def step(self, action):
        if self._target is None and self._target_shape is None:
            raise RuntimeError("FlatBodyEnv: call reset() before step()")
        k = self.kernels
        self._set_controls(action)
        y = self._y
        self._counters[:3] = 0
        st = self.stepper.advance(y, self._u, self.dt, self._ynew, self._counters, self._R, self._Rnew)
        obs = np.empty(self.observation_size, dtype=np.float32)
        terms = self._terms
        ended = k.post_step(
            y,
            self._ynew,
            st,
            self._a,
            self._a.size,
            self._tvec,
            self._cfg,
            self._P,
            self._yout,
            obs,
            terms,
            self._sc,
            self._vel,
            self._force,
        )
        obs[OBSERVATION_SIZE:] = self._obs_extra
        if self.custom_potential is not None:
            self._sc[1] += self.energy_left_out(self._yout)
        failure = left = None
        leaves = False
        if self._own_terms:  # the task's own termination and terms (e.g. leaving the tolerance of an unstable target)
            leaves = self.task.leaves(float(self._sc[0]), bool(ended))
            self.task.extra_terms(bool(ended or leaves), leaves, terms)
        if leaves:  # the new state is valid physics: kept, the episode ends
            left = self.describe_leaving(float(self._sc[0]))
            ended = 1
            y[:] = self._yout
            if self._R is not None:
                self._R = self._Rnew.copy()
            self.time += self.dt
        elif ended:
            if st != 0:
                failure = self.stepper.describe(st)
            else:
                left = self.left_domain(self._ynew)
        else:
            y[:] = self._yout
            if self._R is not None:
                self._R = self._Rnew.copy()
            self.time += self.dt
        tl = terms.tolist()
        info = build_info(
            t=self.time,
            scalars=self._sc,
            p_theta=y[3],
            ended=bool(ended),
            failure=failure,
            left=left,
            method=self.stepper.method,
            nfev=int(self._counters[0]),
            terms=dict(zip(self.reward_names, tl)),
            success_tolerance=self.task.success_tolerance,
        )
        return obs, sum(tl), bool(ended), False, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        from flatbody_env.env.rendering import render_frame

        return render_frame(self._y, self._R if self._R is not None else np.eye(3), self.target, self.time)

    def describe_leaving(self, distance: float) -> str:
        """``info["left_domain"]`` of a step the task ends because the body left the target's tolerance."""
        return f"distance = {distance:.4g} > success_tolerance = {self.task.success_tolerance:g} (left the target's neighbourhood)"

    def left_domain(self, y: np.ndarray) -> str | None:
        """None inside the documented domain, else what left it (the test itself is the task's
        :func:`~flatbody_env.env.task.domain_code`)."""
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


def build_info(
    *, t, scalars, p_theta, ended, failure, left, method: str, nfev, terms, success_tolerance: float
) -> dict[str, Any]:
    """The ``info`` of ``reset`` and ``step`` (the one builder; class docstring, "Info").

    One body: floats, ``failure``/``left`` a str or None, ``terms`` a dict of floats or None (reset).
    N bodies (the vector env): ``t``, ``scalars`` (4, N), ``p_theta``, ``ended``, ``nfev`` arrays,
    ``failure``/``left`` object arrays of str ("" for none), ``terms`` a dict of (N,) arrays.
    ``scalars``: distance, energy, |s|², (domain code) from :func:`flatbody_env.env.kernels.post_step`.
    """
    batched = np.ndim(scalars) == 2
    if batched:
        distance = scalars[0].copy()
        info: dict[str, Any] = {
            "t": np.asarray(t, dtype=np.float64).copy(),
            "distance": distance,
            "is_success": (distance <= success_tolerance) & ~np.asarray(ended, dtype=bool),
            "energy": scalars[1].copy(),
            "casimir": scalars[2].copy(),
            "p_theta": np.asarray(p_theta, dtype=np.float64).copy(),
            "integrator": {"method": method, "nfev": np.asarray(nfev, dtype=np.int64).copy()},
            "integrator_failure": failure,
            "left_domain": left,
        }
    else:
        distance = float(scalars[0])
        info = {
            "t": float(t),
            "distance": distance,
            "is_success": bool(distance <= success_tolerance and not ended),
            "energy": float(scalars[1]),
            "casimir": float(scalars[2]),
            "p_theta": float(p_theta),
            "integrator": {"method": method, "nfev": int(nfev)},
            "integrator_failure": failure,
            "left_domain": left,
        }
    if terms is not None:
        info["reward_terms"] = terms
    return info


def _as_task(task: str | ReachStationaryEllipse, task_kwargs: Mapping[str, Any]) -> ReachStationaryEllipse:
    """The task of ``task=`` (a name of :data:`~flatbody_env.env.registration.TASK_CLASSES` with its fields in
    ``task_kwargs``, or a task instance)."""
    if isinstance(task, ReachStationaryEllipse):
        if task_kwargs:
            raise ValueError(
                f"{sorted(task_kwargs)[0]}: give the task's fields to its constructor, not beside a task instance"
            )
        return task
    if not isinstance(task, str) or task not in TASK_CLASSES:
        raise ValueError(f"task: must be one of {', '.join(TASK_CLASSES)} or a task instance, got {task!r}")
    import importlib

    module, name = TASK_CLASSES[task].split(":")
    cls = getattr(importlib.import_module(module), name)
    try:
        return cls(**task_kwargs)
    except TypeError as exc:  # an unknown keyword: name it
        raise ValueError(f"task: {exc}") from None


def _as_body(body: Body | Mapping[str, Any] | None) -> Body:
    if body is None:
        return default_body()
    if isinstance(body, Body):
        return body
    if isinstance(body, Mapping):
        return Body.from_dict(body, where="body")
    raise ValueError(f"body: expected a Body or a dict with params/potential/thickness, got {type(body).__name__}")


__all__ = [
    "FlatBodyEnv",
    "DEFAULT_INTEGRATOR",
    "OBSERVATION_NAMES",
    "CONTROLS",
    "REWARD_TERMS",
    "TARGET_NAMES",
    "build_info",
]


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
        checked = {
            k: v.number(f"options.target.{k}", target[k], low=v.STRETCH_RANGE[0], high=v.STRETCH_RANGE[1])
            for k in ("lambda", "mu")
        }
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

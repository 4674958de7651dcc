"""The task: reach and hold a stationary ellipse (dm_control's Task half of the environment) — the task of
``FlatBody-v0`` and ``FlatBodySlow-v0`` and the base of the other tasks (:mod:`flatbody_env.env.hold`,
:mod:`flatbody_env.env.witness`, :mod:`flatbody_env.env.any_body`; ``docs/tasks.md``).

The task knows nothing of integrators: it samples a target and an initial state, scores a state
and decides success. :class:`~flatbody_env.env.env.FlatBodyEnv` composes it with a body and an
integrator.

Targets
-------
A target is a spectrally stable stationary ellipse of branch N (eqs. (50)–(54) of [1]) of the
"circulation" family |s3| < |p_θ| ([2] §7: q < 0 there), built from a shape (λ*, μ*) sampled
in :attr:`ReachStationaryEllipse.target_lambda` × aspect ratio :attr:`target_aspect` by the
inverse problem (:func:`flatbody_env.physics.equilibria.stationary_from_shape`); unstable,
non-existent and unreachable shapes (below) are re-drawn.

Reachability. Every control leaves p_θ conserved (ṗ_θ = 0, eq. (46) of [1]: a torque acts on s,
the dilatation force on p_ϱ), so the initial state gets the target's p_θ. Without torque the
Casimir |s|² is conserved too, so for ``control="dilatation"`` (and ``"none"``) the initial
spin is drawn on the sphere |s| = |s3*|; with torque |s| is free.

Reachable within the episode. The in-plane shape (λ, μ, p_λ, p_μ) is reached only through s3
(τ3), and one of its two oscillation modes only weakly: linearised about the target, optimal
linear feedback (LQR, equally weighted errors) settles that mode no faster than the target's
settling rate r however cheap the control (:func:`flatbody_env.physics.controllability.settling_rate`, the
slowest pole of the cheap-control LQR, a limit that more gain does not raise; the LQR of
``agents`` settles at 1.01–1.2 r). r depends on the shape alone (not on the sign of (s3, p_θ)):
it falls steeply away from the edge of existence of the family (λ*μ* → 1 for V3). Measured for
the default body over 200 targets of the earlier ranges λ* ∈ [1.25, 1.7], λ*/μ* ∈ [1.3, 2]: r from
0.006 to 0.27 s⁻¹, median 0.056 — an error in the slow mode shrinks by e^(−0.056·20) ≈ 0.33 over a
20 s episode, while the start is 0.2–0.35 away and success needs 0.05: most of those targets were
out of reach (the LQR controller reached 40 % of them). Rule: a target is sampled only if
r ≥ :attr:`min_settling_rate` (0.15 s⁻¹ by default), so that over the registered episode
(T = 20 s) the slowest mode shrinks under such feedback by e^(−r T) ≤ e^(−3) ≈ 1/20 — from the largest
initial distance ≈ 0.35 to ≈ 0.017, three times inside the tolerance (the bare requirement
r T ≥ ln(0.35/0.05) would be r ≥ 0.097 s⁻¹). The default ranges λ* ∈ [1.3, 2], λ*/μ* ∈ [1.5, 3.5]
contain the fast shapes near the edge of existence: of 400 draws, 264 are existing and stable and
81 of those pass (r ≥ 0.15). Measured: the LQR controller about the target (``agents``) reaches the
tolerance in 100 of 100 seeded episodes (largest final distance 0.019); with the filter at 0.1 it
still reaches all (largest 0.045). The filter applies where the controls stabilise targets at
linear order (``"torque+dilatation"``); with torque only ϱ, and with dilatation only the shape, is
not linearly controllable (r = 0 for every target), so for those modes it is not applied.
``min_settling_rate=0`` switches it off.

Reward terms (each ≤ 0; their sum is the reward; each weight is a keyword)
--------------------------------------------------------------------------
============  ====================================================  ==================
name          value                                                  weight (default)
============  ====================================================  ==================
``shape``     −w ‖(λ − λ*, μ − μ*, ϱ − ϱ*)‖                          ``w_shape`` (1.0)
``spin``      −w |s3 − s3*|                                          ``w_spin`` (0.5)
``tumble``    −w ‖(ω1, ω2)‖  (target: ω1 = ω2 = 0)                  ``w_tumble`` (0.5)
``rest``      −w ‖(p_λ, p_μ, p_ϱ)‖  (target: all 0)                  ``w_rest`` (0.5)
``action``    −w ‖a‖²  (a ∈ [−1, 1]ⁿ, before scaling)                ``w_action`` (0.05)
``failure``   −penalty on a step that ends the episode by failure    ``failure_penalty`` (10)
============  ====================================================  ==================

Success: the distance d = ‖(Δλ, Δμ, Δϱ, Δs3, ω1, ω2, p_λ, p_μ, p_ϱ)‖ to the target is at most
``success_tolerance`` (0.05).

Observation, scoring and termination as kernels
-----------------------------------------------
Each formula is written once, as a plain-float function of this module that numba compiles
unchanged (:func:`flatbody_env.integrators.jit.retarget`, see :mod:`flatbody_env.env.compiled`):
:func:`omega12_kernel` (ω1, ω2), :func:`score_kernel` (reward terms and distance),
:func:`observe_kernel` (the observation) and :func:`domain_code` (termination by leaving the
domain). ``omega12_kernel`` and ``score_kernel`` use arithmetic and numpy ufuncs only, so the same
function also scores N bodies at once on arrays in structure-of-arrays layout (``y`` of shape
(11, N)); :class:`ReachStationaryEllipse`'s vectorised methods call them that way.

Kernel configuration vector ``cfg`` (float64, :data:`CFG_SIZE`; built by
:meth:`ReachStationaryEllipse.kernel_config`)

=====  ==================  =================================================
index  name                meaning
=====  ==================  =================================================
0–5    weights             w_shape, w_spin, w_tumble, w_rest, w_action, failure_penalty
6      success_tolerance   distance at or below which ``is_success``
7–8    stretch_bounds      domain of λ and μ
9–10   rho_bounds          domain of ϱ
11     momentum_bound      domain of s and p (absolute value)
12     gap_min             smallest |λ − μ|/(λ + μ) (two-polar integrators only)
13     check_gap           1 for a two-polar integrator, else 0
=====  ==================  =================================================

Domain codes (:data:`DOMAIN_CODES`): 0 inside, 1 non-finite, 2 λ, 3 μ, 4 ϱ, 5 momentum, 6 gap.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md``: the corrected equations and the paper's errata (E1–E10).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from flatbody_env.env import targets as _targets
from flatbody_env.env.sampling import initial_state_kernel
from flatbody_env.physics import validation
from flatbody_env.physics.body import Body
from flatbody_env.physics.controllability import settling_rate, target_state
from flatbody_env.physics.equilibria import StationaryEllipse, stationary_from_shape

INITIAL_NOISE_MAX = 5.0
"""Largest ``initial_noise``: offsets d ∈ [−n, n] scale the stretches by e^d (e^5 ≈ 148), far outside any target's
neighbourhood; beyond it e^d overflows long before a start could lie in the domain."""
_TABLE_FOR: dict = {}
"""(id(body), limits, control, ranges) → (body, the settling-rate table or None): whether it applies, decided once."""
CONTROLS = ("none", "torque", "dilatation", "torque+dilatation")
REWARD_TERMS = ("shape", "spin", "tumble", "rest", "action", "failure")
TARGET_NAMES = ("lambda", "mu", "rho", "s3")
OBSERVATION_NAMES: tuple[str, ...] = (
    "s1",
    "s2",
    "s3",
    "p_theta",
    "p_lambda",
    "p_mu",
    "p_rho",
    "lambda",
    "mu",
    "rho",
    "sin_theta",
    "cos_theta",
    "target_lambda",
    "target_mu",
    "target_rho",
    "target_s3",
)
"""The observation layout: entries 0–9 are the state entries 0–9 (:data:`flatbody_env.physics.state.STATE_NAMES`),
10–11 (sin θ, cos θ), 12–15 the target (:data:`TARGET_NAMES`)."""
OBSERVATION_SIZE = len(OBSERVATION_NAMES)
OBS_STATE = slice(0, 10)
"""Observation entries that copy the state entries 0–9 (s1 … ϱ)."""
OBS_SIN_THETA = 10
OBS_COS_THETA = 11
OBS_TARGET = slice(12, 16)
"""Observation entries of the target (λ*, μ*, ϱ*, s3*)."""
CFG_SIZE = 14
DOMAIN_CODES = ("inside", "non-finite state", "lambda", "mu", "rho", "momentum", "gap")
TASK_REACH, TASK_HOLD, TASK_WITNESS = 0, 1, 2
"""Task kinds of the transition (:mod:`flatbody_env.env.transition`): reach a stable ellipse from a noisy start, hold
an unstable one (the episode ends outside the tolerance), reach from a witnessed start."""
REWARDS = ("terms", "tolerance")
"""``reward``: the named terms of the v0 ids (module docstring), or the v1 ids' tolerance reward in [0, 1]
(:mod:`flatbody_env.env.transition`, "Rewards")."""
TOLERANCE_TERMS = ("success", "proximity")
"""The named terms of the tolerance reward (:mod:`flatbody_env.env.transition`, "Rewards")."""
DRAWS = ("numpy", "philox")
"""``draws``: the v0 ids' numpy generators on the host, or the v1 ids' counter-based draws in the transition."""
DEFAULT_LIMITS = (0.5, 0.5, 0.5, 1.0)
"""(τ1, τ2, τ3, f_ϱ) limits of :class:`~flatbody_env.env.env.FlatBodyEnv`'s defaults (torque_limit, force_limit)."""


@dataclass(frozen=True, kw_only=True)
class Episode:
    """What a task draws at a reset: the initial state, the target and, where the task decides them,
    the episode's body and a witness."""

    state: np.ndarray
    """The initial state y (11,)."""
    target: np.ndarray
    """The target (λ*, μ*, ϱ*, s3*, p_θ*, sign of (s3*, p_θ*)) (6,) (:func:`target_row`)."""
    ellipse: StationaryEllipse | None = None
    """The target's full record where the draw built it (else the environment builds it from the shape when asked)."""
    body: Body | None = None
    """The episode's body when the task draws one (:class:`~flatbody_env.env.any_body.ReachAnyBody`); None: the env's."""
    witness_params: np.ndarray | None = None
    """The witness's parameters (9,) — amplitude, then half-period and phase per driven control — from which
    :func:`~flatbody_env.env.witness.witness_actions` gives the actions that take the initial state into the success
    ball at the last step (:class:`~flatbody_env.env.witness.ReachWithWitness`); None where the task has none."""


def control_mask(control: str) -> np.ndarray:
    """Which of (τ1, τ2, τ3, f_ϱ) an action drives, shape (4,) bool."""
    validation.string("control", control, choices=CONTROLS)
    torque = "torque" in control
    dil = "dilatation" in control
    return np.array([torque, torque, torque, dil])


@dataclass(frozen=True, kw_only=True)
class ReachStationaryEllipse:
    """Reach and hold a stationary ellipse (module docstring) — the task of ``FlatBody-v0`` and
    ``FlatBodySlow-v0``, and the base of the other tasks (``docs/tasks.md``).

    What a task owns and the environment asks it for: the draws of a reset (:meth:`draw`,
    :meth:`draw_batch`), the reward terms (:attr:`reward_names`), the entries the observation adds to the 16
    shared ones (:attr:`observation_extra_names`) and the configuration of the compiled reset
    (:meth:`sampler_settings`); the transition computes the task's own terms and termination from its
    :attr:`kind`.
    """

    target_branch: ClassVar[str] = "circulation"
    """The branch of the targets (:data:`flatbody_env.physics.equilibria.BRANCHES`)."""
    compiled_targets: ClassVar[bool] = True
    """Whether the compiled draws' kernels (:mod:`flatbody_env.env.sampling`) can draw its targets (the v1 ids)."""
    varies_body: ClassVar[bool] = False
    """Whether each episode draws its own body (:attr:`Episode.body`)."""
    extra_reward_names: ClassVar[tuple[str, ...]] = ()
    """Reward terms beyond the kernels' six (:data:`REWARD_TERMS`), computed by the transition for the task's
    :attr:`kind`."""
    body_observation_names: ClassVar[tuple[str, ...]] = ()
    """The body's constants the observation holds after the 16 of :data:`OBSERVATION_NAMES` (the transition writes
    them at a reset; :class:`~flatbody_env.env.any_body.ReachAnyBody`)."""
    kind: ClassVar[int] = TASK_REACH
    """The transition's task kind (:data:`TASK_REACH`, :data:`TASK_HOLD`, :data:`TASK_WITNESS`)."""

    w_shape: float = 1.0
    w_spin: float = 0.5
    w_tumble: float = 0.5
    w_rest: float = 0.5
    w_action: float = 0.05
    failure_penalty: float = 10.0
    success_tolerance: float = 0.05
    target_lambda: tuple[float, float] = (1.3, 2.0)
    """Range of the target λ*."""
    target_aspect: tuple[float, float] = (1.5, 3.5)
    """Range of λ*/μ*."""
    initial_noise: float = 0.15
    """Relative size of the initial offset from the target."""
    min_settling_rate: float = 0.15
    """Reachability filter: least :func:`~flatbody_env.physics.controllability.settling_rate` (s⁻¹) of a sampled target."""
    settling_table: bool = True
    """Decide the filter from the shipped settling-rate table where it applies
    (:mod:`flatbody_env.env.targets`: the same targets, without a Riccati solve per draw); False: always solve."""
    reward: str = "terms"
    """:data:`REWARDS`: ``"terms"`` (the v0 ids) or ``"tolerance"`` (the v1 ids)."""
    draws: str = "numpy"
    """:data:`DRAWS`: ``"numpy"`` (the v0 ids) or ``"philox"`` (the v1 ids)."""
    w_proximity: float = 0.2
    """β of the tolerance reward: the weight of its shaping term ``proximity`` (the ``success`` term has 1 − β)."""
    proximity_margin: float = 0.5
    """m of the tolerance reward: the excess distance beyond the tolerance where ``proximity`` falls to 0.1 β."""
    observe_time: bool = False
    """Append the episode's elapsed time to the observation (its last entry, ``time``): the steps since the reset over
    :data:`~flatbody_env.env.registration.MAX_EPISODE_STEPS` (0 at a reset, 1 where every registered id truncates),
    the information a time-limited task's policy lacks to be Markov (Pardo et al., ICML 2018; Gymnasium's
    ``TimeAwareObservation``). Off on every registered id (``env_kwargs`` turns it on: a variant)."""

    def __post_init__(self) -> None:
        validation.boolean("observe_time", self.observe_time)  # first: the observation's properties read it
        for name in (
            "w_shape",
            "w_spin",
            "w_tumble",
            "w_rest",
            "w_action",
            "failure_penalty",
            "success_tolerance",
            "min_settling_rate",
        ):
            validation.number(name, getattr(self, name), low=0.0, high=validation.PARAM_RANGE[1])
        validation.number("initial_noise", self.initial_noise, low=0.0, high=INITIAL_NOISE_MAX)
        for name in (
            "target_lambda",
            "target_aspect",
        ):  # kept as a tuple of floats whatever pair was given (an array too)
            object.__setattr__(
                self,
                name,
                validation.interval(
                    name,
                    getattr(self, name),
                    low=validation.STRETCH_RANGE[0],
                    high=validation.STRETCH_RANGE[1],
                    strict=False,
                ),
            )
        if self.target_aspect[0] <= 1.0:
            raise ValueError(f"target_aspect: must exceed 1 (λ* > μ*, away from λ = μ), got {self.target_aspect!r}")
        validation.boolean("settling_table", self.settling_table)
        validation.string("reward", self.reward, choices=REWARDS)
        validation.string("draws", self.draws, choices=DRAWS)
        validation.number("w_proximity", self.w_proximity, low=0.0, high=1.0)
        validation.number("proximity_margin", self.proximity_margin, low=1e-6, high=validation.PARAM_RANGE[1])

    # --- what the environment asks --------------------------------------------------------------
    @property
    def reward_names(self) -> tuple[str, ...]:
        """The names of the reward terms, in the order of ``info["reward_terms"]`` (their sum is the reward)."""
        if self.reward == "tolerance":
            return TOLERANCE_TERMS
        return REWARD_TERMS + self.extra_reward_names

    @property
    def no_witness_message(self) -> str:
        """The ``ValueError`` of a reset that finds no witnessed start (tasks with witnesses)."""
        return "start_distance: no witnessed start found (widen start_distance or witness_amplitude)"

    @property
    def no_target_message(self) -> str:
        """The ``ValueError`` of a reset that finds no target in the ranges."""
        return (
            "target_lambda/target_aspect: no stable stationary ellipse with settling rate >= min_settling_rate "
            "found for this body in the target ranges (the settling rate grows with torque_limit and force_limit: "
            "raise them, lower min_settling_rate, or widen the ranges)"
        )

    def accepts(self, target: StationaryEllipse) -> bool:
        """The stability class of a target: spectrally stable (q < 0, shape Hessian positive definite)."""
        return bool(target.stable)

    def sampler_settings(self) -> tuple[float, ...]:
        """Entries 9–15 of the episode sampler's configuration (:mod:`flatbody_env.env.sampling`):
        circulation branch, stable class, the noise start."""
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def observation_extra_names(self) -> tuple[str, ...]:
        """Observation entries after the 16 of :data:`OBSERVATION_NAMES`: :attr:`body_observation_names`, then ``time``
        where the task observes it (:attr:`observe_time`)."""
        return (*self.body_observation_names, *(("time",) if self.observe_time else ()))

    def body_observation_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds (low, high) of the entries of :attr:`body_observation_names`."""
        return np.zeros(0), np.zeros(0)

    def observation_extra_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds (low, high) of the entries of :attr:`observation_extra_names` (the time's: 0 to the longest episode
        a vector env allows, in :data:`~flatbody_env.env.registration.MAX_EPISODE_STEPS`)."""
        lo, hi = self.body_observation_bounds()
        if self.observe_time:
            from flatbody_env.env.registration import MAX_EPISODE_STEPS

            lo, hi = np.append(lo, 0.0), np.append(hi, validation.MAX_EPISODE_STEPS / MAX_EPISODE_STEPS)
        return lo, hi

    def start_near(
        self, rng: np.random.Generator, target: StationaryEllipse, control: str, *, body: Body
    ) -> np.ndarray:
        """The task's start near a given target (:meth:`sample_initial_state` here)."""
        return self.sample_initial_state(rng, target, control)

    def draw(
        self,
        rng: np.random.Generator,
        body: Body,
        *,
        limits=DEFAULT_LIMITS,
        control: str = "torque+dilatation",
        simulator: Any = None,
    ) -> Episode:
        """One reset's draws: a target (:meth:`sample_target`), then a start near it (:meth:`sample_initial_state`).

        ``simulator`` is the environment's (:meth:`flatbody_env.env.env.FlatBodyEnv.rollout`), for tasks
        that simulate while they draw; unused here.
        """
        target = self.sample_target(rng, body, limits=limits, control=control)
        return Episode(
            state=self.start_near(rng, target, control, body=body), target=target_row(target), ellipse=target
        )

    def draw_batch(
        self,
        rngs: Sequence[np.random.Generator],
        body: Body,
        *,
        limits=DEFAULT_LIMITS,
        control: str = "torque+dilatation",
        simulator: Any = None,
    ) -> list[Episode]:
        """:meth:`draw` for each generator (each draws exactly what it would alone)."""
        return [self.draw(rng, body, limits=limits, control=control, simulator=simulator) for rng in rngs]

    # --- targets --------------------------------------------------------------------------------
    def reachable(
        self, target: StationaryEllipse, body: Body, limits=DEFAULT_LIMITS, control: str = "torque+dilatation"
    ) -> bool:
        """Whether ``target`` passes the reachability filter (module docstring, "Reachability").

        True when the controls settle it at a rate ≥ :attr:`min_settling_rate`; also True for
        every target when the controls cannot stabilise any target at linear order (``control``
        without τ3 or without f_ϱ: the filter does not apply) or when the filter is off (0).
        """
        if not self.filter_applies(control):
            return True
        y = target_state(target.lam, target.mu, target.rho, target.s3, target.p_theta)
        return settling_rate(body, y, limits, control_mask(control)) >= self.min_settling_rate

    def sample_target(
        self, rng: np.random.Generator, body: Body, *, limits=DEFAULT_LIMITS, control: str = "torque+dilatation"
    ) -> StationaryEllipse:
        """A stable stationary ellipse of the circulation family that the controls can reach (module docstring).

        The draws and the test are those of :meth:`reachable`; where the shipped settling-rate
        table applies (:attr:`settling_table`, :mod:`flatbody_env.env.targets`) it answers the test
        without a Riccati solve, and the exact test runs only where the table is unsure.
        """
        table = self.table_for(body, limits, control)
        thr = self.min_settling_rate
        (l0, l1), (a0, a1) = self.target_lambda, self.target_aspect
        for _ in range(500):
            # one call for the three draws: the same stream and values as uniform, uniform, random
            # (numpy's uniform(lo, hi) is lo + (hi − lo)·next_double)
            u_lam, u_aspect, u_sign = rng.random(3).tolist()
            lam = l0 + (l1 - l0) * u_lam
            aspect = a0 + (a1 - a0) * u_aspect
            mu = lam / aspect
            sign = 1.0 if u_sign < 0.5 else -1.0
            code = _targets.UNSURE if table is None else table.decide(lam, aspect, thr)
            if code == _targets.REJECT:
                continue
            try:
                target = stationary_from_shape(body, lam, mu, branch=self.target_branch, sign=sign)
            except ValueError:
                continue
            if not self.accepts(target):
                continue
            if code == _targets.UNSURE and not self.reachable(target, body, limits, control):
                continue
            return target
        raise ValueError(self.no_target_message)

    def filter_applies(self, control: str) -> bool:
        """Whether the reachability filter applies (:meth:`reachable`): on, and both τ3 and f_ϱ driven."""
        mask = control_mask(control)
        return self.min_settling_rate != 0 and bool(mask[2] and mask[3])

    def table_for(self, body: Body, limits, control: str):
        """The settling-rate table when it answers the filter here, else None (every draw solves)."""
        if not self.settling_table or self.min_settling_rate == 0 or control != "torque+dilatation":
            return None
        key = (
            id(body),
            tuple(np.asarray(limits, dtype=float).tolist()),
            control,
            self.target_lambda,
            self.target_aspect,
        )
        hit = _TABLE_FOR.get(key)
        if hit is not None and hit[0] is body:
            return hit[1]
        table = _targets.shipped_table()
        if table is not None and not table.applies(body, limits, control, self.target_lambda, self.target_aspect):
            table = None
        if len(_TABLE_FOR) > 64:
            _TABLE_FOR.clear()
        _TABLE_FOR[key] = (body, table)
        return table

    def sample_initial_state(self, rng: np.random.Generator, target: StationaryEllipse, control: str) -> np.ndarray:
        """A state near the target from which the controls can reach it (module docstring)."""
        torque = "torque" in control
        # one call for all draws: the same stream and values as one uniform(−n, n) per draw
        # (numpy's uniform(lo, hi) is lo + (hi − lo)·next_double)
        y = np.empty(11)
        initial_state_kernel(
            rng.random(10 if torque else 9),
            self.initial_noise,
            torque,
            target.lam,
            target.mu,
            target.rho,
            target.s3,
            target.p_theta,
            y,
        )
        return y

    # --- kernel configuration ---------------------------------------------------------------------
    def kernel_config(
        self,
        *,
        stretch_bounds: tuple[float, float],
        rho_bounds: tuple[float, float],
        momentum_bound: float,
        gap_min: float,
        check_gap: bool,
    ) -> np.ndarray:
        """The configuration vector ``cfg`` (:data:`CFG_SIZE`) of the kernels (module docstring)."""
        cfg = np.array(
            [
                self.w_shape,
                self.w_spin,
                self.w_tumble,
                self.w_rest,
                self.w_action,
                self.failure_penalty,
                self.success_tolerance,
                *stretch_bounds,
                *rho_bounds,
                momentum_bound,
                gap_min,
                1.0 if check_gap else 0.0,
            ],
            dtype=np.float64,
        )
        assert cfg.size == CFG_SIZE
        return cfg

    def _weights(self) -> np.ndarray:
        return np.array([self.w_shape, self.w_spin, self.w_tumble, self.w_rest, self.w_action, self.failure_penalty])

    # --- scoring (vectorised: y of shape (11,) or (11, N)); the formulas are the kernels below -------
    @staticmethod
    def omega12(y: np.ndarray, body: Body) -> tuple[np.ndarray, np.ndarray]:
        """(ω1, ω2) of state(s) ``y`` (11,) or (11, N): :func:`omega12_kernel`."""
        return omega12_kernel(y, body.inertia.J1, body.inertia.J3)

    def distance(self, y: np.ndarray, body: Body, target: np.ndarray):
        """The task distance d = ‖(Δλ, Δμ, Δϱ, Δs3, ω1, ω2, p_λ, p_μ, p_ϱ)‖ (float, or shape (N,));
        ``target`` = (λ*, μ*, ϱ*, s3*), shape (4,) or (4, N)."""
        return self.reward_terms(y, body, target, np.zeros(1), False, _with_distance=True)[1]

    def reward_terms(
        self, y: np.ndarray, body: Body, target: np.ndarray, action: np.ndarray, failed, *, _with_distance: bool = False
    ):
        """The named terms (module docstring) by :func:`score_kernel`; floats for one body, arrays (N,) for N.

        ``action`` has shape (n,) or (N, n); ``failed`` is a bool or a bool array (N,).
        """
        y = np.asarray(y, dtype=np.float64)
        action = np.asarray(action, dtype=np.float64)
        act2 = np.sum(action * action, axis=-1)
        one = y.ndim == 1
        terms = np.empty(6) if one else np.empty((6, y.shape[1]))
        P = np.array([body.inertia.J1, 0.0, body.inertia.J3])
        d = score_kernel(y, np.asarray(target, dtype=np.float64), act2, np.asarray(failed), self._weights(), P, terms)
        out = dict(zip(REWARD_TERMS, terms.tolist() if one else terms))
        if _with_distance:
            return out, (float(d) if one else d)
        return out


def state_from_observation(obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The state y and the target (λ*, μ*, ϱ*, s3*) from observation(s): the inverse of
    :func:`observe_kernel` (θ = atan2(sin θ, cos θ), in (−π, π]).

    ``obs`` (16,) gives y (11,) and target (4,); ``obs`` (N, 16) gives y (11, N) and target (4, N). θ is the C
    library's atan2 (:mod:`flatbody_env.integrators.libm`: NumPy's differs in the last bit on AVX-512 machines, and the
    adaptive step of a motion started from y weighs θ too).
    """
    from flatbody_env.integrators.libm import arctan2

    obs = np.asarray(obs, dtype=np.float64)
    o = obs.T
    y = np.empty((11,) + o.shape[1:])
    y[0:10] = o[OBS_STATE]
    y[10] = arctan2(o[OBS_SIN_THETA], o[OBS_COS_THETA])
    return y, o[OBS_TARGET].copy()


def target_row(target: StationaryEllipse) -> np.ndarray:
    """(λ*, μ*, ϱ*, s3*, p_θ*, sign) (6,): the target as :class:`Episode` and the episode sampler hold it
    (sign: of σ₊ = s3* + p_θ*, the ``sign`` of :func:`~flatbody_env.physics.equilibria.stationary_from_shape`)."""
    return np.array(
        [target.lam, target.mu, target.rho, target.s3, target.p_theta, 1.0 if target.s3 + target.p_theta > 0 else -1.0]
    )


def target_vector(target: StationaryEllipse) -> np.ndarray:
    """(λ*, μ*, ϱ*, s3*) — the target entries of the observation (:data:`TARGET_NAMES`)."""
    return np.array([target.lam, target.mu, target.rho, target.s3])


# --------------------------------------------------------------------------------------------- kernels
def omega12_kernel(y, J, J3):
    """(ω1, ω2) = (s1/(Jμ² + J3ϱ²), s2/(Jλ² + J3ϱ²)): the inverse Legendre map after eq. (31) of [1]
    for J1 = J2 = J. Scalars (``y`` (11,)) or arrays (``y`` (11, N))."""
    j3r2 = J3 * y[9] * y[9]
    return y[0] / (J * y[8] * y[8] + j3r2), y[1] / (J * y[7] * y[7] + j3r2)


def score_kernel(y, tgt, act2, ended, cfg, P, terms):
    """Reward terms into ``terms`` (6,) and the task distance (returned) of state ``y``.

    Parameters
    ----------
    y : (11,) or (11, N)
        State(s).
    tgt : (4,) or (4, N)
        Target (λ*, μ*, ϱ*, s3*).
    act2 : float or (N,)
        ‖a‖² of the clipped action.
    ended : int/bool or (N,)
        1 when the step ends the episode by failure or by leaving the domain.
    cfg : (≥ 6,)
        Weights w_shape, w_spin, w_tumble, w_rest, w_action, failure_penalty (module docstring).
    P : (≥ 3,) or (≥ 3, N)
        J = P[0], J3 = P[2] (:meth:`flatbody_env.physics.body.Body.kernel_params`), one body's or each body's.
    terms : (6,) or (6, N), output
        shape, spin, tumble, rest, action, failure (:data:`REWARD_TERMS`).
    """
    w1, w2 = omega12_kernel(y, P[0], P[2])
    dl = y[7] - tgt[0]
    dm = y[8] - tgt[1]
    dr = y[9] - tgt[2]
    ds = y[2] - tgt[3]
    shape = np.sqrt(dl * dl + dm * dm + dr * dr)
    tumble = np.sqrt(w1 * w1 + w2 * w2)
    rest = np.sqrt(y[4] * y[4] + y[5] * y[5] + y[6] * y[6])
    terms[0] = -cfg[0] * shape
    terms[1] = -cfg[1] * np.abs(ds)
    terms[2] = -cfg[2] * tumble
    terms[3] = -cfg[3] * rest
    terms[4] = -cfg[4] * act2
    terms[5] = -cfg[5] * ended
    return np.sqrt(shape * shape + ds * ds + tumble * tumble + rest * rest)


def observe_kernel(y, tgt, obs):
    """The observation (:data:`OBSERVATION_NAMES`) of state ``y`` (11,) and target ``tgt`` (4,) into ``obs`` (16,)."""
    for i in range(10):
        obs[i] = y[i]
    obs[10] = math.sin(y[10])
    obs[11] = math.cos(y[10])
    for i in range(4):
        obs[12 + i] = tgt[i]


def domain_codes(Y, cfg, out):
    """:func:`domain_code` of each column of ``Y`` (11, N) into ``out`` (N,) int64."""
    for k in range(Y.shape[1]):
        out[k] = domain_code(Y[:, k], cfg)


def domain_code(y, cfg):
    """Termination by leaving the domain: 0 if ``y`` (11,) lies in it, else the code of the first
    violation (:data:`DOMAIN_CODES`; bounds in ``cfg``, module docstring)."""
    for i in range(11):
        if not math.isfinite(y[i]):
            return 1
    if y[7] < cfg[7] or y[7] > cfg[8]:
        return 2
    if y[8] < cfg[7] or y[8] > cfg[8]:
        return 3
    if y[9] < cfg[9] or y[9] > cfg[10]:
        return 4
    for i in range(7):
        if abs(y[i]) > cfg[11]:
            return 5
    if cfg[13] != 0.0 and abs(y[7] - y[8]) < cfg[12] * (y[7] + y[8]):
        return 6
    return 0

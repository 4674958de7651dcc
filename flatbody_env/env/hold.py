"""The task of ``FlatBodyHoldUnstable-v0``: keep the body at an unstable (hyperbolic) stationary ellipse.

Targets
-------
A target is a stationary ellipse of branch N (eqs. (50)–(54) of [1]) of the *rotation* family
|s3| > |p_θ| (a rigid rotation about the plate's normal, ω3 dominant), built from a shape
λ* ∈ :attr:`HoldUnstableEllipse.target_lambda`, λ*/μ* ∈ :attr:`~HoldUnstableEllipse.target_aspect`
by the inverse problem (:func:`flatbody_env.physics.equilibria.stationary_from_shape`), and kept only
when it is *hyperbolic*: the out-of-plane block of the linearisation, s̈1 = q s1 with
q = (s3/I2 − ω3)(ω3 − s3/I1) ([2] §7), has q > 0 — a saddle with growth rate γ = √q — with γ in
[:attr:`~HoldUnstableEllipse.min_growth_rate`, :attr:`~HoldUnstableEllipse.max_growth_rate`], while
the shape block stays stable (the Hessian of the effective potential W positive definite). For a rigid
rotation (θ̇ = 0) q > 0 exactly when Jμ*² < J3ϱ*² < Jλ*² — rotation about the intermediate principal
axis ([2] §7); the rotation family of V3 also circulates (0 < |θ̇| < |ω3|), and of the targets drawn
with the default body (J = J3 = 1, ϱ* = 1) 84 % have μ* < 1 < λ* (measured over 10⁴ draws; μ* up to
1.16). For the default ranges the shape block is always stable (these are the only hyperbolic
ellipses of branch N of the default body: its circulation family is stable everywhere), and the full
9 × 9 linearisation (:func:`flatbody_env.physics.controllability.linearize`) has exactly one eigenvalue
with positive real part, +γ (the tests check it).

Start and success
-----------------
The body starts *inside* the success ball: at task distance R ∈ [r_lo, r_hi] × ``success_tolerance``
(:attr:`~HoldUnstableEllipse.start_radius`, fractions of the tolerance) in a uniformly random direction
of the distance coordinates (Δλ, Δμ, Δϱ, Δs3, ω1, ω2, p_λ, p_μ, p_ϱ), with the target's p_θ
(conserved) and a uniform θ (:func:`flatbody_env.env.sampling.ball_state_kernel`). The episode
*terminates* as soon as the distance exceeds the tolerance (``info["left_domain"]`` says so), so
``info["is_success"]`` on the last step means: stayed within the tolerance for the whole episode.
Without control the instability grows like e^(γt) and the body leaves (``docs/tasks.md`` gives the
measured times).

Reward terms
------------
The six terms of :mod:`flatbody_env.env.task` (``failure`` also on the step that leaves the ball)
and ``alive`` = +:attr:`~HoldUnstableEllipse.w_alive` on every step that does not end the episode —
without it the shaping terms, all ≤ 0, would reward leaving early.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md``: the corrected equations, the stationary ellipses and their linear stability.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flatbody_env.env.sampling import BALL_DRAWS, HYPERBOLIC, START_BALL, ball_state_kernel
from flatbody_env.env.task import TASK_HOLD, ReachStationaryEllipse
from flatbody_env.physics import validation
from flatbody_env.physics.body import Body
from flatbody_env.physics.equilibria import StationaryEllipse


@dataclass(frozen=True, kw_only=True)
class HoldUnstableEllipse(ReachStationaryEllipse):
    """Stay within the tolerance of a hyperbolic stationary ellipse (module docstring)."""

    target_branch: ClassVar[str] = "rotation"
    extra_reward_names: ClassVar[tuple[str, ...]] = ("alive",)
    kind: ClassVar[int] = TASK_HOLD

    target_lambda: tuple[float, float] = (1.3, 2.5)
    target_aspect: tuple[float, float] = (1.5, 3.5)
    min_settling_rate: float = 0.0
    """Not used: the settling-rate filter is the reaching tasks' (0 switches it off)."""
    min_growth_rate: float = 0.15
    """Least growth rate γ = √q (s⁻¹) of a target: without control an offset grows e-fold in ≤ 6.7 s."""
    max_growth_rate: float = 10.0
    """Greatest γ (s⁻¹); the default ranges reach about 0.65."""
    start_radius: tuple[float, float] = (0.3, 0.9)
    """Range of the start's task distance, as fractions of ``success_tolerance``."""
    w_alive: float = 1.0
    """Reward per step that does not end the episode."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("min_growth_rate", "max_growth_rate", "w_alive"):
            validation.number(name, getattr(self, name), low=0.0, high=validation.PARAM_RANGE[1])
        validation.requirement(
            "max_growth_rate",
            self.max_growth_rate,
            self.max_growth_rate >= self.min_growth_rate,
            f"be >= min_growth_rate ({self.min_growth_rate})",
        )
        lo, hi = validation.interval("start_radius", self.start_radius, low=0.0, high=1.0, strict=False)
        object.__setattr__(self, "start_radius", (lo, hi))
        validation.requirement(
            "start_radius", (lo, hi), hi < 1.0, "be (lo, hi) with 0 <= lo <= hi < 1 (fractions of the tolerance)"
        )
        validation.requirement(
            "success_tolerance",
            self.success_tolerance,
            self.success_tolerance > 0,
            "be > 0 for a task that ends outside it",
        )

    @property
    def no_target_message(self) -> str:
        return (
            "target_lambda/target_aspect: no hyperbolic stationary ellipse of the rotation branch with growth rate in "
            "[min_growth_rate, max_growth_rate] found for this body in the target ranges"
        )

    def accepts(self, target: StationaryEllipse) -> bool:
        """Hyperbolic: q > 0 with √q in range, the shape Hessian positive definite (module docstring)."""
        if (
            target.q is None
            or target.shape_hessian_min is None
            or not (target.q > 0.0 and target.shape_hessian_min > 0.0)
        ):
            return False
        return self.min_growth_rate <= math.sqrt(target.q) <= self.max_growth_rate

    def sampler_settings(self) -> tuple[float, ...]:
        tol = self.success_tolerance
        return (
            1.0,
            HYPERBOLIC,
            self.min_growth_rate,
            self.max_growth_rate,
            START_BALL,
            self.start_radius[0] * tol,
            self.start_radius[1] * tol,
        )

    def sample_initial_state(
        self, rng: np.random.Generator, target: StationaryEllipse, control: str, *, body: Body
    ) -> np.ndarray:
        """The start inside the success ball (module docstring): :func:`~flatbody_env.env.sampling.ball_state_kernel`
        on :data:`~flatbody_env.env.sampling.BALL_DRAWS` uniforms (``body`` gives J and J3 for s1, s2 from ω1, ω2)."""
        tol = self.success_tolerance
        y = np.empty(11)
        ball_state_kernel(
            rng.random(BALL_DRAWS),
            self.start_radius[0] * tol,
            self.start_radius[1] * tol,
            target.lam,
            target.mu,
            target.rho,
            target.s3,
            target.p_theta,
            body.inertia.J1,
            body.inertia.J3,
            y,
        )
        return y

    def start_near(
        self, rng: np.random.Generator, target: StationaryEllipse, control: str, *, body: Body
    ) -> np.ndarray:
        return self.sample_initial_state(rng, target, control, body=body)


__all__ = ["HoldUnstableEllipse"]

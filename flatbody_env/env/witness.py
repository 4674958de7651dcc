"""The task of ``FlatBodyTorque-v0`` and ``FlatBodyDilatation-v0``: reach a stationary ellipse with
under-actuated controls, from starts that come with a witness.

With torque only the thickness (ϱ, p_ϱ), and with dilatation only the in-plane shape and the spin, are
not controllable at linear order: the linearisation about any target
(:func:`flatbody_env.physics.controllability.linearize`) has an uncontrollable pair of imaginary
modes, so no LQR exists (the Riccati equation has no stabilising solution) and the settling rate is 0
for every target. Whether a target can be reached is a question about the nonlinear system. This task
answers it episode by episode with a *witness*: a sequence of admissible actions that takes the start
into the success ball at the last step.

Time reversal
-------------
The equations of motion (eqs. (44)–(49) of [1], spin bracket per erratum E3 of [2]) are Hamiltonian
with H even in the momenta (s, p_θ, p_λ, p_μ, p_ϱ), and the controls enter as forces (τ on ṡ, f on
ṗ_ϱ). So with the reversal map 𝓡(y) = y with every momentum negated (:data:`REVERSAL`), if z(τ) solves
the equations under controls ũ(τ), then y(t) = 𝓡 z(T − t) solves them under u(t) = ũ(T − t):
q̇ = ∂H/∂p is odd in p, ṗ = −∂H/∂q + u is even, and ṡ = ω × s + τ is even under (s, ω) → (−s, −ω).

The draw
--------
1. A target as in ``FlatBody-v0`` (a spectrally stable ellipse of the circulation family in the same
   shape ranges), without the settling-rate filter (the rate is 0 for these controls).
2. A point y_b inside the success ball: task distance R ∈ :attr:`ReachWithWitness.witness_radius` ×
   ``success_tolerance`` in a random direction (:func:`flatbody_env.env.sampling.ball_state_kernel`).
3. From 𝓡(y_b), the environment's own integrator runs :attr:`~ReachWithWitness.witness_steps` steps
   of bang-bang actions: on each driven control a square wave ±α with its own half-period (uniform in
   :attr:`~ReachWithWitness.witness_half_period` steps) and phase, α uniform in
   :attr:`~ReachWithWitness.witness_amplitude` (periodic forcing reaches the resonances that random
   switching misses: the thickness responds to the spin only through s1², s2²).
4. The start is y0 = 𝓡(z(T)); the witness is the action sequence reversed. The draw is kept when the
   reversed run stayed in the domain, d(y0) lies in :attr:`~ReachWithWitness.start_distance`, and the
   start is off the target by at least :attr:`~ReachWithWitness.min_uncontrolled_offset` in the
   coordinates the controls do not drive at linear order (:meth:`~ReachWithWitness.uncontrolled_offset`:
   with torque only the thickness (Δϱ, p_ϱ); with dilatation only the shape and spin (Δλ, Δμ, Δs3, ω1,
   ω2, p_λ, p_μ)) — so that success needs the nonlinear coupling, not only linear feedback; otherwise
   step 2 is drawn again (a new y_b, new actions).

Replaying the witness from y0 with the environment's integrator reproduces y_b at the last step to
the integrator's accuracy (≈ 1e-10 measured; the tests replay witnesses and check the success), so
every episode has a solution: ``info["is_success"]`` at its end. The witness is available as
``env.unwrapped.witness`` (and ``FlatBodyVectorEnv.witnesses``); it is not in the observation.

What the witnesses show (measured, default body, 150 draws each): with torque, the square waves move
the body mainly in the spin and the in-plane shape, and the thickness through s1², s2² (start offsets
‖(Δϱ, p_ϱ)‖: median 0.03, 90th percentile 0.19); ``FlatBodyTorque-v0`` keeps the starts with at least
0.05 (the tolerance) there. With dilatation, breathing moves (ϱ, p_ϱ) and hardly anything else: on
s1 = s2 = 0 the thickness decouples from the shape and the spin exactly (ṗ_ϱ = −V_ϱ′ + J3ϱ(s1²/I1² +
s2²/I2²), and the potentials are separable), and from the success ball 20 s of periodic breathing moved
the shape and spin by 0.01 (median; 90th percentile 0.025) — no more than y_b itself. So no
``FlatBodyDilatation-v0`` start is off in the shape or spin by more than the tolerance
(``min_uncontrolled_offset`` = 0 there): reaching a different shape by breathing alone is out of reach
within an episode, and the task is to settle the thickness without disturbing the rest.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md``: the corrected equations and the paper's errata.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from flatbody_env.env.sampling import BALL_DRAWS, START_NONE, ball_state_kernel
from flatbody_env.env.task import (
    DEFAULT_LIMITS,
    TASK_WITNESS,
    Episode,
    ReachStationaryEllipse,
    control_mask,
    omega12_kernel,
    target_row,
)
from flatbody_env.physics import validation
from flatbody_env.physics.body import Body

REVERSAL = np.array([-1.0, -1.0, -1.0, -1.0, -1.0, -1.0, -1.0, 1.0, 1.0, 1.0, 1.0])
"""The reversal map 𝓡 on the packed state: the momenta s1, s2, s3, p_θ, p_λ, p_μ, p_ϱ negated (module docstring)."""


def square_wave(k, amplitude, half, phase):
    """The reversed run's action on one control at its step ``k``: ±amplitude, switching every ``half`` steps from
    ``phase`` (module docstring, "The draw", step 3)."""
    return amplitude if ((k + phase) // half) % 2 == 0 else -amplitude


def witness_actions(params, steps: int, n_act: int) -> np.ndarray:
    """The witness (steps, n) from its parameters (9,) — amplitude, then half-period and phase per driven control:
    the reversed run's square waves, reversed in time (module docstring, step 4)."""
    amp = float(params[0])
    out = np.empty((steps, n_act))
    for c in range(n_act):
        half, phase = int(params[1 + 2 * c]), int(params[2 + 2 * c])
        k = np.arange(steps)[::-1]  # the witness's step i is the reversed run's step steps - 1 - i
        out[:, c] = np.where(((k + phase) // half) % 2 == 0, amp, -amp)
    return out


def uncontrolled_offset(y, tg, J, J3, no_dilatation, no_torque):
    """The offset of state(s) ``y`` (11,) or (11, N) from the target (λ*, μ*, ϱ*, s3*) in the distance coordinates that
    the controls do not drive at linear order: ‖(Δϱ, p_ϱ)‖ without dilatation, ‖(Δλ, Δμ, Δs3, ω1, ω2, p_λ, p_μ)‖
    without torque (both without either, 0 with both); the flags are 0 or 1. Arithmetic and numpy ufuncs only: on
    scalars in the transition's draws, on arrays here."""
    w1, w2 = omega12_kernel(y, J, J3)
    dr = y[9] - tg[2]
    dl = y[7] - tg[0]
    dm = y[8] - tg[1]
    ds = y[2] - tg[3]
    thick = dr * dr + y[6] * y[6]
    shape = dl * dl + dm * dm + ds * ds + w1 * w1 + w2 * w2 + y[4] * y[4] + y[5] * y[5]
    return np.sqrt(no_dilatation * thick + no_torque * shape)


@dataclass(frozen=True, kw_only=True)
class ReachWithWitness(ReachStationaryEllipse):
    """Reach a stationary ellipse from a start that comes with a witness (module docstring)."""

    kind: ClassVar[int] = TASK_WITNESS

    min_settling_rate: float = 0.0
    """Off: under-actuated controls settle no target at linear order (r = 0)."""
    witness_radius: tuple[float, float] = (0.0, 0.5)
    """Range of the distance of y_b (where the witness ends) from the target, as fractions of ``success_tolerance``."""
    start_distance: tuple[float, float] = (0.1, 0.5)
    """Range of the start's task distance (the draw is repeated outside it)."""
    min_uncontrolled_offset: float = 0.0
    """Least offset of the start in the coordinates the controls do not drive at linear order (:meth:`uncontrolled_offset`)."""
    witness_amplitude: tuple[float, float] = (0.1, 0.6)
    """Range of the bang-bang amplitude α of the reversed run (normalised actions)."""
    witness_half_period: tuple[int, int] = (4, 80)
    """Range (steps, both included) of the half-period of each control's square wave."""
    witness_steps: int = 400
    """Length of the witness (the registered episode length)."""
    max_witness_attempts: int = 400
    """Draws of y_b per episode before the reset gives up."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for name, upper in (
            ("witness_radius", 1.0),
            ("witness_amplitude", 1.0),
            ("start_distance", validation.PARAM_RANGE[1]),
        ):
            object.__setattr__(
                self, name, validation.interval(name, getattr(self, name), low=0.0, high=upper, strict=False)
            )
        validation.integer("witness_steps", self.witness_steps, low=1, high=validation.WITNESS_MAX_STEPS)
        validation.integer("max_witness_attempts", self.max_witness_attempts, low=1, high=validation.RESET_MAX_STEPS)
        validation.requirement(
            "max_witness_attempts",
            self.max_witness_attempts,
            self.witness_steps * self.max_witness_attempts <= validation.RESET_MAX_STEPS,
            f"keep witness_steps × max_witness_attempts <= {validation.RESET_MAX_STEPS:,} env steps (a reset's work; "
            f"each step has its own budget; witness_steps = {self.witness_steps})",
        )
        pair = self.witness_half_period
        half_period_rule = "be integers (lo, hi) with 1 <= lo <= hi"
        if isinstance(pair, (str, bytes)) or not hasattr(pair, "__len__") or len(pair) != 2:
            raise validation.refusal("witness_half_period", half_period_rule, pair)
        lo, hi = (
            validation.integer(f"witness_half_period[{i}]", x, low=1, high=validation.MAX_EPISODE_STEPS)
            for i, x in enumerate(pair)
        )
        validation.requirement("witness_half_period", (lo, hi), lo <= hi, half_period_rule)
        object.__setattr__(self, "witness_half_period", (lo, hi))
        validation.number(
            "min_uncontrolled_offset", self.min_uncontrolled_offset, low=0.0, high=validation.PARAM_RANGE[1]
        )

    def sampler_settings(self) -> tuple[float, ...]:
        """The compiled draws draw the targets only (:data:`~flatbody_env.env.sampling.START_NONE`)."""
        return (0.0, 0.0, 0.0, 0.0, START_NONE, 0.0, 0.0)

    def draw_batch(
        self,
        rngs: Sequence[np.random.Generator],
        body: Body,
        *,
        limits=DEFAULT_LIMITS,
        control: str = "torque+dilatation",
        simulator: Any = None,
    ) -> list[Episode]:
        """Targets, then witnessed starts for all generators at once (module docstring, "The draw").

        ``simulator`` is the environment's batch (:meth:`flatbody_env.env.core.EnvCore.rollout` runs the reversed
        runs of all bodies as one batch). Each generator draws what it
        would draw alone: the targets' uniforms, then per attempt :meth:`attempt_draws` uniforms.
        """
        if simulator is None:
            raise ValueError("simulator: ReachWithWitness draws its starts by simulation; pass the environment")
        m = len(rngs)
        ellipses = [self.sample_target(rng, body, limits=limits, control=control) for rng in rngs]
        targets = np.array([target_row(t) for t in ellipses]).reshape(m, 6)
        mask = control_mask(control)
        n_act = max(int(mask.sum()), 1)
        steps = self.witness_steps
        tol = self.success_tolerance
        starts = np.empty((11, m))
        params = np.zeros((m, 9))
        pending = np.arange(m)
        attempts = 0
        J, J3 = body.inertia.J1, body.inertia.J3
        (a_lo, a_hi), (h_lo, h_hi) = self.witness_amplitude, self.witness_half_period
        k_steps = np.arange(steps)
        while pending.size:
            if attempts == self.max_witness_attempts:
                raise ValueError(
                    f"start_distance: no witnessed start in {self.start_distance} with an uncontrolled offset >= "
                    f"{self.min_uncontrolled_offset} after {attempts} draws (widen start_distance or witness_amplitude)"
                )
            attempts += 1
            k = pending.size
            YB = np.empty((11, k))
            actions = np.empty((steps, k, n_act))
            drawn = np.zeros((k, 9))
            for j, b in enumerate(pending):
                u = rngs[b].random(self.attempt_draws(n_act))
                tg = targets[b]
                ball_state_kernel(
                    u[:BALL_DRAWS],
                    self.witness_radius[0] * tol,
                    self.witness_radius[1] * tol,
                    tg[0],
                    tg[1],
                    tg[2],
                    tg[3],
                    tg[4],
                    J,
                    J3,
                    YB[:, j],
                )
                amplitude = a_lo + (a_hi - a_lo) * u[BALL_DRAWS]
                drawn[j, 0] = amplitude
                for c in range(n_act):
                    half = h_lo + min(int((h_hi - h_lo + 1) * u[BALL_DRAWS + 1 + 2 * c]), h_hi - h_lo)
                    phase = min(int(2 * half * u[BALL_DRAWS + 2 + 2 * c]), 2 * half - 1)
                    drawn[j, 1 + 2 * c], drawn[j, 2 + 2 * c] = half, phase
                    actions[:, j, c] = np.where(((k_steps + phase) // half) % 2 == 0, amplitude, -amplitude)
            Z, ok = simulator.rollout(REVERSAL[:, None] * YB, actions)
            Y0 = REVERSAL[:, None] * Z
            tv = targets[pending, :4].T
            d0 = self.distance(Y0, body, tv)
            keep = (
                ok
                & (d0 >= self.start_distance[0])
                & (d0 <= self.start_distance[1])
                & (self.uncontrolled_offset(Y0, body, tv, control) >= self.min_uncontrolled_offset)
            )
            for j in np.flatnonzero(keep):
                b = pending[j]
                starts[:, b] = Y0[:, j]
                params[b] = drawn[j]
            pending = pending[~keep]
        return [
            Episode(state=starts[:, b].copy(), target=targets[b].copy(), ellipse=ellipses[b], witness_params=params[b])
            for b in range(m)
        ]

    @staticmethod
    def uncontrolled_offset(Y: np.ndarray, body: Body, target: np.ndarray, control: str):
        """The offset of state(s) ``Y`` (11,) or (11, N) from the target (λ*, μ*, ϱ*, s3*) in the distance coordinates
        that ``control`` does not drive at linear order: ‖(Δϱ, p_ϱ)‖ without dilatation, ‖(Δλ, Δμ, Δs3, ω1, ω2,
        p_λ, p_μ)‖ without torque, both without either, 0 with both."""
        mask = control_mask(control)
        return uncontrolled_offset(
            np.asarray(Y, dtype=np.float64), np.asarray(target, dtype=np.float64), body.inertia.J1, body.inertia.J3,
            0.0 if mask[3] else 1.0, 0.0 if mask[2] else 1.0,
        )  # fmt: skip

    def attempt_draws(self, n_act: int) -> int:
        """Uniforms one attempt draws: y_b (:data:`~flatbody_env.env.sampling.BALL_DRAWS`), α, and a half-period and a
        phase per driven control."""
        return BALL_DRAWS + 1 + 2 * n_act


__all__ = ["REVERSAL", "ReachWithWitness", "square_wave", "uncontrolled_offset", "witness_actions"]

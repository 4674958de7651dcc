"""Hand-designed controllers for ``FlatBody-v0``: LQR about the target ellipse (the ``heuristic``
baseline) and a passivity-based damping law (:class:`PassivityController`, for comparison).

Dynamics both rely on (eqs. (44)–(49) of [1], spin bracket per errata E3/E4 of [2]; the controls
enter as in :mod:`flatbody_env.physics.equations`): with H = 𝒯 + V (eqs. (32), (37)–(40)),

.. math::

    \\dot s = s \\times \\omega + \\tau, \\quad \\omega = \\partial H/\\partial s \\quad (44)\\text{–}(45), \\qquad
    \\dot p_\\theta = 0 \\quad (46), \\qquad
    \\dot q = \\partial H/\\partial p, \\; \\dot p = -\\partial H/\\partial q + f\\,e_\\varrho \\quad (47)\\text{–}(49),

for q = (λ, μ, ϱ), p = (p_λ, p_μ, p_ϱ). θ is cyclic for J1 = J2 and p_θ is conserved by every
control, so the controlled state is x = (s1, s2, s3, p_λ, p_μ, p_ϱ, λ, μ, ϱ) ∈ ℝ⁹.

LQR (:class:`HeuristicController`)
---------------------------------
The target stationary ellipse x* (s1 = s2 = 0, p = 0, eqs. (50)–(54)) is an equilibrium of the
reduced system. Linearising eqs. (44)–(49) there (central differences of
:func:`flatbody_env.physics.equations.rhs`, :func:`flatbody_env.physics.controllability.linearize`) gives ẋ ≈ A δx + B a with the normalised action a (τ = τ_max a₁..₃,
f = f_max a₄). The shape block tells what the controls can do: at linear order the thickness
force moves only (ϱ, p_ϱ) and τ1, τ2 only (s1, s2); the in-plane shape (λ, μ, p_λ, p_μ) — two
oscillation modes of the effective potential W ([2]) — is reached *only through s3*: τ3
changes s3, and s3 enters the centrifugal forces −∂𝒯/∂(λ, μ) through σ± = s3 ± p_θ. One of
those modes is weakly controllable: its closed-loop pole saturates at a finite value whatever the
weights (:func:`flatbody_env.physics.controllability.settling_rate`), which sets how fast any linear
controller can settle the shape; the task samples only targets where that rate is ≥ 0.15 s⁻¹.
The gain K solves the continuous algebraic Riccati equation for weights Q (on x) and R (on a);
the action is a = clip(−K (x − x*), −1, 1). K is recomputed when the target changes.

Passivity (:class:`PassivityController`)
----------------------------------------
The gyroscopic term s × ω does no work, so the
power of the controls is

.. math:: \\dot H = \\omega \\cdot \\tau + \\dot\\varrho\\, f .

A target stationary ellipse (eqs. (50)–(54)) with s1 = s2 = 0, p = 0 is a critical point of the
energy–momentum function H − ω3* s3 at fixed p_θ (∂H/∂s3 = ω3, ∂H/∂q = 0 there), and a minimum
in the shape directions when it is spectrally stable ([2]: the Hessian of the effective
potential W is positive definite; the task samples only such targets). The controller makes

.. math::

    L = H - \\omega_3^* s_3 + \\tfrac{c}{2}(s_3 - s_3^*)^2 + \\tfrac{k_\\varrho}{2}(\\varrho - \\varrho^*)^2

decrease along motions (a Lyapunov function, energy–Casimir style):

.. math::

    \\dot L = \\omega_1\\tau_1 + \\omega_2\\tau_2 + \\big(\\omega_3 - \\omega_3^* + c(s_3 - s_3^*)\\big)\\tau_3
              + \\dot\\varrho\\,\\big(f + k_\\varrho(\\varrho - \\varrho^*)\\big) \\le 0

with

* **spin damping** τ_i = −k_ω ω_i (i = 1, 2), ω1 = s1/(Jμ² + J3ϱ²), ω2 = s2/(Jλ² + J3ϱ²): the
  tumbling decays (a torque changes s, and ω = I⁻¹ s);
* **spin regulation** τ3 = −k_3 (ω3 − ω3* + c (s3 − s3*)): proportional on s3 toward s3*, plus
  the term ω3 − ω3*, which is how the shape (λ, μ) is steered: ω3 = σ₊/(2Ju²) + σ₋/(2Jv²)
  (u = λ + μ, v = λ − μ, σ± = s3 ± p_θ) changes with the shape, so feeding it back through s3
  modulates the centrifugal forces −∂𝒯/∂(λ, μ) against the shape oscillation and damps it;
* **PD on the thickness** f = −k_ϱ (ϱ − ϱ*) − d_ϱ ϱ̇.

Each term is saturated at the action limits (a saturated damping term still has the sign that
makes L̇ ≤ 0). The velocities come from the inverse Legendre map
(:func:`flatbody_env.physics.hamiltonian.kinetic_kernel`).

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md``: the corrected equations and the paper's errata.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flatbody_env.physics.body import Body
from flatbody_env.physics.controllability import REDUCED_STATE, linearize  # noqa: F401  (re-exported: the LQR's model)
from flatbody_env.physics.hamiltonian import kinetic_kernel
from flatbody_env.env.task import control_mask, state_from_observation  # noqa: F401  (re-exported)


@dataclass(frozen=True, kw_only=True)
class HeuristicGains:
    """Gains of :class:`PassivityController` (physical units; see the module docstring)."""

    k_omega: float = 4.0
    """Spin damping τ_{1,2} = −k_ω ω_{1,2}."""
    k_s3: float = 4.0
    """τ3 = −k_3 (ω3 − ω3* + c (s3 − s3*))."""
    c_s3: float = 1.0
    """Weight c of the proportional s3 term."""
    k_rho: float = 4.0
    """Thickness stiffness k_ϱ."""
    d_rho: float = 3.0
    """Thickness damping d_ϱ."""


class PassivityController:
    """The passivity-based controller of the module docstring, with SB3's ``predict`` signature.

    Parameters
    ----------
    body : Body
        The environment's body (``env.unwrapped.body``).
    control : str
        The environment's control mode (which of τ1, τ2, τ3, f the action drives).
    limits : array of shape (4,)
        Torque and force limits (``env.unwrapped.limits``); actions are u / limit, clipped to [−1, 1].
    gains : HeuristicGains
    """

    def __init__(self, body: Body, control: str, limits: np.ndarray, gains: HeuristicGains | None = None) -> None:
        self.body = body
        self.mask = control_mask(control)
        self.limits = np.asarray(limits, dtype=np.float64)
        self.gains = gains or HeuristicGains()
        self._P = body.kernel_params()
        self._vel = np.empty(7)
        self._vel_t = np.empty(7)
        self._force = np.empty(4)

    @classmethod
    def for_env(cls, env, gains: HeuristicGains | None = None) -> "PassivityController":
        u = env.unwrapped
        return cls(u.body, u.control, u.limits, gains)

    def control(self, y: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Physical controls u = (τ1, τ2, τ3, f_ϱ) for state y (11,) and target (λ*, μ*, ϱ*, s3*)."""
        g = self.gains
        kinetic_kernel(y, self._P, self._vel, self._force)
        w1, w2, w3, _, _, _, rho_dot = self._vel
        yt = np.array([0.0, 0.0, target[3], y[3], 0.0, 0.0, 0.0, target[0], target[1], target[2], y[10]])
        kinetic_kernel(yt, self._P, self._vel_t, self._force)
        w3_star = self._vel_t[2]
        return np.array([
            -g.k_omega * w1,
            -g.k_omega * w2,
            -g.k_s3 * (w3 - w3_star + g.c_s3 * (y[2] - target[3])),
            -g.k_rho * (y[9] - target[2]) - g.d_rho * rho_dot,
        ])

    def action(self, obs: np.ndarray) -> np.ndarray:
        """Normalised action in [−1, 1]ⁿ for one observation (16,)."""
        y, target = state_from_observation(obs)
        u = self.control(y, target)
        if not self.mask.any():
            return np.zeros(1, dtype=np.float32)
        a = np.clip(u[self.mask] / self.limits[self.mask], -1.0, 1.0)
        return a.astype(np.float32)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3-style: a batch (N, 16) or one observation (16,) → (actions, None)."""
        obs = np.asarray(observation)
        if obs.ndim == 1:
            return self.action(obs), None
        return np.stack([self.action(o) for o in obs]), None


@dataclass(frozen=True, kw_only=True)
class LQRWeights:
    """Weights of :class:`HeuristicController`: Q = diag(q_spin ×3, q_momentum ×3, q_shape ×3), R = r·I."""

    q_spin: float = 1.0
    q_momentum: float = 10.0
    q_shape: float = 10.0
    r: float = 0.1


class HeuristicController:
    """LQR about the target ellipse (module docstring), with SB3's ``predict`` signature.

    Parameters
    ----------
    body : Body
        The environment's body (``env.unwrapped.body``), J1 = J2.
    control : str
        The environment's control mode (which of τ1, τ2, τ3, f the action drives).
    limits : array of shape (4,)
        Torque and force limits (``env.unwrapped.limits``).
    weights : LQRWeights
    """

    def __init__(self, body: Body, control: str, limits: np.ndarray, weights: LQRWeights | None = None) -> None:
        self.body = body
        self.mask = control_mask(control)
        self.limits = np.asarray(limits, dtype=np.float64)
        self.weights = weights or LQRWeights()
        self._cache: dict[tuple[float, ...], np.ndarray] = {}

    @classmethod
    def for_env(cls, env, weights: LQRWeights | None = None) -> "HeuristicController":
        u = env.unwrapped
        return cls(u.body, u.control, u.limits, weights)

    def gain(self, y_star: np.ndarray) -> np.ndarray:
        """K (k, 9) for the target state y_star (cached per target), k = the driven controls."""
        key = tuple(np.round(y_star[:10], 12))
        K = self._cache.get(key)
        if K is None:
            from scipy.linalg import solve_continuous_are

            A, B = linearize(self.body, y_star, self.limits)
            B = B[:, self.mask]
            w = self.weights
            Q = np.diag([w.q_spin] * 3 + [w.q_momentum] * 3 + [w.q_shape] * 3)
            R = w.r * np.eye(B.shape[1])
            P = solve_continuous_are(A, B, Q, R)
            K = np.linalg.solve(R, B.T @ P)
            if len(self._cache) > 1024:
                self._cache.clear()
            self._cache[key] = K
        return K

    def action(self, obs: np.ndarray) -> np.ndarray:
        """Normalised action in [−1, 1]ⁿ for one observation (16,)."""
        if not self.mask.any():
            return np.zeros(1, dtype=np.float32)
        y, target = state_from_observation(obs)
        y_star = np.array([0.0, 0.0, target[3], y[3], 0.0, 0.0, 0.0, target[0], target[1], target[2], 0.0])
        K = self.gain(y_star)
        dx = (y - y_star)[list(REDUCED_STATE)]
        return np.clip(-K @ dx, -1.0, 1.0).astype(np.float32)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3-style: a batch (N, 16) or one observation (16,) → (actions, None)."""
        obs = np.asarray(observation)
        if obs.ndim == 1:
            return self.action(obs), None
        return np.stack([self.action(o) for o in obs]), None


RESIDUAL_MODES = ("additive", "gain")


class ResidualAction:
    """The executed action of a residual agent on the LQR (:class:`HeuristicController`, a_LQR).

    * ``mode="additive"``: clip(a_LQR + scale · g(d) · a_policy, −1, 1), where
      g(d) = min(1, d / gate) fades the residual out near the target (d = the task's distance of
      the observed state; ``gate`` = 0: g = 1), so that the closed loop keeps the LQR's
      equilibrium at the target.
    * ``mode="gain"``: clip(a_LQR ⊙ (1 + scale · a_policy), −1, 1): the policy rescales each
      component of the LQR's action (state-dependent gain scheduling, factor in
      [1 − scale, 1 + scale]); the target stays an equilibrium (a_LQR = 0 there) whatever the
      policy outputs.

    Reads physical (unnormalised) observations (N, 16).
    """

    def __init__(self, env_kwargs=None, scale: float = 1.0, gate: float = 0.0, mode: str = "additive") -> None:
        from flatbody_env.env.env import FlatBodyEnv

        if not (math.isfinite(scale) and scale >= 0):
            raise ValueError(f"residual_scale: must be a finite number >= 0, got {scale!r}")
        if not (math.isfinite(gate) and gate >= 0):
            raise ValueError(f"residual_gate: must be a finite number >= 0, got {gate!r}")
        if mode not in RESIDUAL_MODES:
            raise ValueError(f"residual_mode: must be one of {', '.join(RESIDUAL_MODES)}, got {mode!r}")
        self.mode = mode
        proto = FlatBodyEnv(**(env_kwargs or {}))
        self.body, self.task = proto.body, proto.task
        self.controller = HeuristicController(proto.body, proto.control, proto.limits)
        self.scale, self.gate = float(scale), float(gate)

    def __call__(self, obs: np.ndarray, actions: np.ndarray) -> np.ndarray:
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
        base, _ = self.controller.predict(obs)
        a = self.scale * np.clip(np.asarray(actions, dtype=np.float64).reshape(base.shape), -1.0, 1.0)
        if self.mode == "gain":
            return np.clip(base * (1.0 + a), -1.0, 1.0).astype(np.float32)
        if self.gate > 0:
            y, target = state_from_observation(obs)
            d = self.task.distance(y, self.body, target)
            a = a * np.minimum(1.0, d / self.gate)[:, None]
        return np.clip(base + a, -1.0, 1.0).astype(np.float32)


def residual_vec_env(venv, env_kwargs=None, scale: float = 1.0, gate: float = 0.0, mode: str = "additive"):
    """Wrap an SB3 VecEnv over ``FlatBody-v0`` so that actions are residuals on the heuristic.

    The executed action is :class:`ResidualAction` (residual policy learning: the agent starts
    from the hand-designed controller and learns corrections). Must wrap the raw environment
    (inside ``VecNormalize``): the heuristic reads physical observations.
    """
    from stable_baselines3.common.vec_env import VecEnvWrapper

    residual = ResidualAction(env_kwargs, scale, gate, mode)

    class ResidualOnHeuristic(VecEnvWrapper):
        def reset(self):
            self._obs = self.venv.reset()
            return self._obs

        def step_async(self, actions):
            self.venv.step_async(residual(self._obs, actions))

        def step_wait(self):
            obs, rewards, dones, infos = self.venv.step_wait()
            self._obs = obs
            return obs, rewards, dones, infos

    return ResidualOnHeuristic(venv)

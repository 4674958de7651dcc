"""A causal sampling planner over the environment's own transition: the suite's model-predictive reference.

MuJoCo MPC's sampling planners are the anchor (Howell et al., "Predictive Sampling: Real-time Behaviour
Synthesis with MuJoCo", arXiv:2212.00541, 2022; Williams et al., MPPI, ICRA 2016): at every control step,
from the state the observation gives (the state entries and θ = atan2(sin θ, cos θ); the target from its
entries), K candidate action sequences over a horizon of H env steps are rolled out with the environment's
own batched transition (:class:`flatbody_env.env.core.EnvCore`: the same integrator, domain and reward —
no formula is restated), scored by ``objective`` (the env's own task distance or reward over the horizon; a body
whose episode ends by failure stops earning), and combined by MPPI's exponential weights (temperature ``temperature`` × the spread of
the returns); the plan's first action is applied, the plan is shifted by one step and warm-starts the next
(``warm_start``). The horizon recedes (H steps from every state) or, with ``to_end``, shrinks: it ends where the
episode does, on the state success is judged on (shrinking-horizon MPC; the env's clock tells the steps left), and
the first step of an episode may refine its plan more often than the others (``initial_iterations``).

Candidates are the nominal plan plus Gaussian noise on ``knots`` control points linearly interpolated over
the horizon (smooth actions, few dimensions), clipped to [−1, 1]; one candidate is the nominal plan itself
and one the all-zero plan. ``iterations`` refinements per control step (MPPI with iterations: a
cross-entropy flavour). The planner is causal: it sees the observation only (and, with ``to_end``, the episode's
clock) — never the episode's witness or future draws. It uses the true model of the episode's body (for ``FlatBodyAnyBody-v1``, whose constants
the observation hides, that is privileged: the row says "true model").

Compute per control step: ``samples`` × ``horizon`` × ``iterations`` body-steps (:attr:`PlannerSettings.body_steps`;
:attr:`Planner.body_steps` counts what was rolled out);
episodes are planned together (their candidates in one batch), so the Python overhead is paid once per
planning step for the whole batch.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatbody_env.env import transition as tr
from flatbody_env.env.core import EnvCore, configure
from flatbody_env.env.task import state_from_observation
from flatbody_env.integrators import libm


LOG_FLOOR = 1e-3
"""ε of the ``"distance"`` objective's log(d + ε): relative progress counts, so precision near the target pays."""
FAILED_DISTANCE = 10.0
"""The distance a candidate scores after its episode ended by failure (the ``"distance"`` objective)."""


LAW_OF_PRIOR = {"none": None, "lqr": "heuristic", "passivity": "passivity", "pumping": "pumping"}
"""Each value of :attr:`PlannerSettings.prior` and the law of :data:`agents.heuristic.LAWS` it names (None: no law)."""
PRIOR_LAWS = tuple(LAW_OF_PRIOR)
"""The values of :attr:`PlannerSettings.prior`."""


@dataclass(frozen=True, kw_only=True)
class PlannerSettings:
    """The planner's knobs (module docstring); defaults measured on the v1 suite (docs/tasks.md)."""

    samples: int = 48
    """Candidate action sequences per control step (K), the nominal and the zero plan among them."""
    horizon: int = 60
    """Env steps each candidate is rolled out (H; 3 s at dt = 0.05)."""
    knots: int = 4
    """Control points of a candidate's noise, interpolated linearly over the horizon."""
    noise: float = 0.3
    """Standard deviation of the noise on the knots (normalised actions), far from the target; it shrinks with the
    task distance d of the current state as min(1, max(``noise_floor``, d / ``noise_distance``)) (fine control near
    the target, where broad noise would only jitter the plan)."""
    noise_floor: float = 0.05
    noise_distance: float = 0.2
    temperature: float = 0.1
    """MPPI's temperature as a fraction of the spread (max − min) of the candidates' returns."""
    iterations: int = 1
    """Refinements of the plan per control step."""
    terminal: float = 0.0
    """Weight of the horizon's last state, in steps of the ``"distance"`` objective (with either objective): a stand-in
    for the cost beyond the horizon (without it a short horizon is myopic about the slow modes), or, with ``to_end``,
    what the episode's last state, which success is judged on, is worth."""
    prior: str = "none"
    """A feedback law the candidates perturb: ``"none"`` (open-loop action sequences), ``"lqr"``, ``"passivity"`` or
    ``"pumping"`` (the LQR with centrifugal pumping) — closed-loop rollouts: the action at each step is
    clip(law(observation) + the candidate's perturbation); :mod:`agents.heuristic`. The row's label names it."""
    warm_start: bool = True
    """Whether each control step starts from the previous step's plan shifted by one step (MPPI's warm start, which
    carries what the earlier steps found); ``False``: from the zero perturbation at every step, so the action is a
    function of the observation alone — what a network distilled from the planner can represent (docs/agents.md)."""
    to_end: bool = False
    """Whether the horizon ends where the episode does (shrinking-horizon MPC): at each control step the candidates are
    rolled out over the episode's remaining steps (at most ``horizon``; :meth:`Planner.act`'s ``steps_left``) and the
    terminal weight falls on the episode's last state, the one success is judged on. The plan's steps are then the
    episode's own, so what an earlier step found about the end carries over to the next (``warm_start``). ``False``: a
    receding horizon of ``horizon`` steps, which sees the end only in its last ``horizon`` steps."""
    initial_iterations: int = 0
    """Refinements of the plan at the first control step after :meth:`Planner.reset` (or its construction): a plan
    optimised over the whole horizon before the first action, which the later steps refine ``iterations`` at a time
    (0: ``iterations`` there as well)."""
    objective: str = "distance"
    """What a candidate scores: ``"distance"`` — minus log(d + :data:`LOG_FLOOR`) of the task distance d summed over
    the horizon (the env's own distance, so no formula is restated; a body whose episode ends scores
    :data:`FAILED_DISTANCE` for the rest of the horizon) — or ``"reward"``, the env's reward summed (with ``to_end``:
    the return to go); ``terminal`` adds the distance objective's term on the horizon's last state to either."""

    def __post_init__(self) -> None:
        from flatbody_env.physics import validation

        for name, hi in (("samples", 4096), ("horizon", 400), ("knots", 400), ("iterations", 16)):
            validation.integer(name, getattr(self, name), low=2 if name in ("samples", "knots") else 1, high=hi)
        validation.integer("initial_iterations", self.initial_iterations, low=0, high=64)
        validation.number("noise", self.noise, low=0.0, high=2.0)
        validation.number("noise_floor", self.noise_floor, low=0.0, high=1.0)
        validation.number("noise_distance", self.noise_distance, low=1e-6, high=1e6)
        validation.number("temperature", self.temperature, low=1e-6, high=1e6)
        validation.number("terminal", self.terminal, low=0.0, high=1e6)
        validation.string("objective", self.objective, choices=("distance", "reward"))
        validation.string("prior", self.prior, choices=PRIOR_LAWS)
        validation.boolean("warm_start", self.warm_start)
        validation.boolean("to_end", self.to_end)

    @property
    def body_steps(self) -> int:
        """Body-steps of simulation per control step and episode, at most (with ``to_end`` the horizon shrinks toward
        the episode's end, and the first step refines ``initial_iterations`` times: :attr:`Planner.body_steps` counts
        what was rolled out)."""
        return self.samples * self.horizon * self.iterations


class Planner:
    """Plans for B episodes of one configuration at once (module docstring).

    Parameters
    ----------
    env_kwargs : dict
        The id's keyword arguments (``agents.evaluate.env_kwargs_for``): the model the planner rolls out.
    episodes : int
        B, the episodes planned together.
    settings : PlannerSettings
    seed : int
        Of the planner's own noise.
    """

    def __init__(self, env_kwargs: dict, episodes: int, settings: PlannerSettings | None = None, seed: int = 0) -> None:
        self.settings = s = settings or PlannerSettings()
        self.config = configure(**env_kwargs)
        self.episodes = int(episodes)
        self.n_act = self.config.n_act
        self.core = EnvCore(self.config, self.episodes * s.samples, max_episode_steps=None, autoreset="none")
        self.rng = np.random.default_rng(seed)
        self.law = None
        if s.prior != "none":
            from agents.heuristic import LAWS

            law = LAWS[LAW_OF_PRIOR[s.prior]]
            self.law = law(self.config.body, self.config.control, self.config.limits)
        self.plan = np.zeros((self.episodes, s.horizon, self.n_act))
        t = np.linspace(0.0, 1.0, s.horizon)
        knots = np.linspace(0.0, 1.0, s.knots)
        # (H, knots): linear interpolation weights of the knots at each step of the horizon
        self._interp = np.stack([np.interp(t, knots, np.eye(s.knots)[k]) for k in range(s.knots)], axis=1)
        self.seconds = 0.0
        """Wall time spent planning (all calls)."""
        self.calls = 0
        self.body_steps = 0
        """Body-steps rolled out (all calls, all episodes)."""
        self._fresh = True

    def reset(self) -> None:
        """Forget the plans (new episodes): the next control step is a first one (``initial_iterations``)."""
        self.plan[:] = 0.0
        self._fresh = True

    def act(self, obs: np.ndarray, bodies_P: np.ndarray | None = None, steps_left=None) -> np.ndarray:
        """The next action (B, n) float32 of each episode from its observation (B, d); ``bodies_P`` (9, B): each
        episode's body (its kernel parameters; None: the configuration's body); ``steps_left`` (B,): each episode's
        steps to its time limit, counting this one (the env's ``max_episode_steps`` minus its ``episode_steps``; 0 after
        a truncation, before the autoreset), required with :attr:`PlannerSettings.to_end`."""
        t0 = time.perf_counter()
        s, B, K, n = self.settings, self.episodes, self.settings.samples, self.n_act
        self._obs = obs
        if not s.warm_start:
            self.plan[:] = 0.0
        horizons = np.full(B, s.horizon, dtype=np.int64)
        if s.to_end:
            from flatbody_env.physics import validation

            left = np.asarray(steps_left) if steps_left is not None else None
            validation.requirement(
                "steps_left",
                steps_left,
                left is not None and left.shape == (B,) and left.dtype.kind in "iu" and bool((left >= 0).all()),
                f"be {B} integers >= 0 (the planner plans to the episode's end: to_end)",
            )
            # 0: the episode has just ended, and the step that autoresets it ignores the action
            horizons = np.clip(left, 1, s.horizon)
        Y, T = state_from_observation(np.asarray(obs, dtype=np.float64)[:, :16])
        d = self._distance(Y, T, bodies_P)
        scale = (s.noise * np.clip(d / s.noise_distance, s.noise_floor, 1.0))[:, None, None, None]
        iterations = s.initial_iterations if self._fresh and s.initial_iterations else s.iterations
        for _ in range(iterations):
            noise = scale * self.rng.standard_normal((B, K, s.knots, n))
            noise[:, 0] = 0.0  # the nominal plan itself
            cand = self.plan[:, None] + np.einsum("hk,bjkn->bjhn", self._interp, noise)
            cand[:, 1] = 0.0  # the zero plan
            np.clip(cand, -1.0, 1.0, out=cand)
            returns = self._rollout(Y, T, bodies_P, cand, horizons)
            spread = returns.max(axis=1, keepdims=True) - returns.min(axis=1, keepdims=True)
            w = libm.exp((returns - returns.max(axis=1, keepdims=True)) / (s.temperature * np.maximum(spread, 1e-9)))
            w /= w.sum(axis=1, keepdims=True)
            self.plan = np.einsum("bj,bjhn->bhn", w, cand)
        self._fresh = False
        action = self.plan[:, 0].copy()
        if self.law is not None:
            action = np.clip(self.law.predict(np.asarray(obs))[0] + action, -1.0, 1.0)
        self.plan = np.concatenate([self.plan[:, 1:], self.plan[:, -1:]], axis=1)  # shift; hold the last action
        self.seconds += time.perf_counter() - t0
        self.calls += 1
        return action.astype(np.float32)

    def _distance(self, Y: np.ndarray, T: np.ndarray, bodies_P) -> np.ndarray:
        """The task distance (B,) of the states Y (11, B) to the targets T (4, B) (the task's own scoring kernel)."""
        if bodies_P is None:
            return np.asarray(self.config.task.distance(Y, self.config.body, T), dtype=float).reshape(-1)
        from flatbody_env.env.any_body import body_from_constants

        out = np.empty(Y.shape[1])
        for b in range(Y.shape[1]):
            body = body_from_constants(bodies_P[list(tr.P_CONSTANTS), b])
            out[b] = self.config.task.distance(Y[:, b], body, T[:, b])
        return out

    def _rollout(self, Y: np.ndarray, T: np.ndarray, bodies_P, cand: np.ndarray, horizons: np.ndarray) -> np.ndarray:
        """The returns (B, K) of the candidates (B, K, H, n) from the states Y (11, B) with targets T (4, B), each
        episode's rolled out over its first ``horizons[b]`` steps (B,) (the terminal weight on the last of them)."""
        s, B, K = self.settings, self.episodes, self.settings.samples
        core = self.core
        TG = np.zeros((6, B))
        TG[:4] = T
        TG[4] = Y[3]
        core.set_bodies(
            np.repeat(Y, K, axis=1),
            np.repeat(TG, K, axis=1),
            None if bodies_P is None else np.repeat(bodies_P, K, axis=1),
        )
        alive = np.ones(B * K, dtype=bool)
        total = np.zeros(B * K)
        steps = int(horizons.max())
        last = np.repeat(horizons, K) - 1  # each body's last step of its horizon
        ragged = bool((horizons < steps).any())  # episodes with fewer steps left than others: masked per body
        end = np.zeros(B * K)  # the distance there
        A = np.empty((B * K, self.n_act))
        reward = s.objective == "reward"
        obs0 = None
        if self.law is not None:
            obs0 = np.repeat(np.asarray(self._obs, dtype=np.float32), K, axis=0)
        for h in range(steps):
            A[:] = cand[:, :, h].reshape(B * K, self.n_act)
            if self.law is not None:
                A[:] = np.clip(self.law.predict(obs0 if h == 0 else core.OBS)[0] + A, -1.0, 1.0)
            core.step(A)
            within = (h <= last) if ragged else True
            if reward:
                total += np.where(alive & within, core.S[tr.R_REWARD], 0.0)
            else:
                score = libm.log(np.where(alive, core.S[tr.R_DISTANCE], FAILED_DISTANCE) + LOG_FLOOR)
                total -= np.where(within, score, 0.0) if ragged else score
            alive &= core.K[tr.K_TERMINATED] == 0
            if s.terminal > 0 and (ragged or h == steps - 1):
                # the horizon's last state; a body whose episode ended on it or before scores as failed
                here = np.where(alive, core.S[tr.R_DISTANCE], FAILED_DISTANCE)
                end = np.where(h == last, here, end) if ragged else here
        self.body_steps += B * K * steps
        if s.terminal > 0:  # where the horizon ends counts as ``terminal`` steps of the distance objective there
            total -= s.terminal * libm.log(end + LOG_FLOOR)
        return total.reshape(B, K)


AROUND_PUMPING = {"prior": "pumping", "terminal": 200.0, "horizon": 120, "knots": 8}
"""The planner of the reach tasks where the LQR is weak: around the LQR with centrifugal pumping, whose gains come over
10 s and more, a 6 s horizon with its last state weighted 200 steps (5,760 body-steps per control step, twice the
default): 96 % on ``FlatBodySlowHard-v1`` against the law's 84 %. Over the default 3 s horizon the plans undid what
the law gains (50 % on the first 20 episodes, the law 90 %; docs/tasks.md)."""
TO_THE_END = {
    **AROUND_PUMPING,
    "horizon": 400,
    "knots": 40,
    "to_end": True,
    "initial_iterations": 16,
    "objective": "reward",
    "terminal": 5.0,
}
"""Around the pumping law to the episode's end (``to_end``; 400 steps: the whole episode), the first step refined 16
times before the first action, the later ones once each, a knot every 10 steps, scored by the env's reward to the
episode's end (the return to go) and 5 steps of the distance objective on its last state (the one success is judged
on). On ``FlatBodyAnyBody-v1``, whose targets have no settling-rate floor, the 6 s horizon of :data:`AROUND_PUMPING`
reached 83 % and missed mostly the slowest targets; on the first 20 reference episodes (docs/tasks.md) it reached 70 %
(mean return 184.7), this planner 100 % (188.7); with the distance objective and the terminal weight 200 100 % as well
but with a mean return of 157.7 (it arrives later: its objective pays for precision inside the tolerance, which the
reward does not), with the reward alone 85 % (191.1). On the 100 reference episodes 98 % (the 6 s horizon 83 %), on
the held-out seeds 20000–20099 95 % (84 %); 10,344 body-steps per control step on average."""
PLANNERS: dict[str, dict[str, Any]] = {
    "FlatBodySlow-v1": AROUND_PUMPING,
    "FlatBodySlowHard-v1": AROUND_PUMPING,
    "FlatBodyTorque-v1": AROUND_PUMPING,
    "FlatBodyAnyBody-v1": TO_THE_END,
    "FlatBodyHoldUnstable-v1": {"prior": "passivity"},
}
"""Each v1 id's planner, as overrides of :class:`PlannerSettings` (the others, ``FlatBody-v1``: the LQR with a
terminal weight of 60 steps over 3 s): the passivity law on the unstable ellipse (it holds more starts than the LQR,
docs/tasks.md); :data:`AROUND_PUMPING` on the reach tasks where the LQR is weak (slow targets; under torque alone it
cannot move the thickness: 3 % against the pumping law's 53 %), planned :data:`TO_THE_END` of the episode on
``FlatBodyAnyBody-v1``."""


def settings_for(env_id: str, overrides: dict[str, Any] | None = None) -> PlannerSettings:
    """The planner of a registered id (:data:`PLANNERS`; the v0 ids: the LQR's, passivity where it cannot be built),
    with ``overrides`` (:func:`parse_overrides`: field → value) of its settings."""
    task = PLANNERS.get(env_id)
    if task is None:
        from flatbody_env.env.registration import task_spec

        control = task_spec(env_id).kwargs.get("control", "torque+dilatation")
        hold = task_spec(env_id).kwargs.get("task") == "hold-unstable"
        prior = "lqr" if control == "torque+dilatation" and not hold else "passivity"
        # around the LQR, a terminal weight: without it the 3 s horizon trades the slow modes for quick gains and the
        # plans did worse than the LQR alone (84 % against 100 % on FlatBody-v1; with it 100 %, docs/tasks.md)
        task = {"prior": prior, "terminal": 60.0 if prior == "lqr" else 0.0}
    return PlannerSettings(**{**task, **(overrides or {})})


def parse_overrides(items: list[str] | None, where: str = "planner") -> dict[str, Any]:
    """``["samples=256", "horizon=160", ...]`` → ``{"samples": 256, "horizon": 160, ...}``: each KEY a field of
    :class:`PlannerSettings`, each VALUE read as that field's type (int, float or str); the ranges are checked when the
    settings are built. ``ValueError`` naming ``where`` and the item otherwise."""
    from dataclasses import fields

    from flatbody_env.physics import validation

    kinds = {f.name: f.type for f in fields(PlannerSettings)}
    out: dict[str, Any] = {}
    for item in items or []:
        key, eq, text = str(item).partition("=")
        if not eq or key not in kinds:
            raise validation.refusal(where, f"be KEY=VALUE with KEY one of {', '.join(kinds)}", item)
        kind = {"int": int, "float": float, "bool": bool}.get(str(kinds[key]), str)
        if kind is bool:  # read as YAML, as --env-kwargs values are
            out[key] = validation.boolean(f"{where}.{key}", validation.parse_yaml(f"{where}.{key}", text))
            continue
        try:
            out[key] = kind(text)
        except ValueError:
            raise validation.refusal(
                f"{where}.{key}", f"be a{'n integer' if kind is int else ' number'}", text
            ) from None
    try:  # the ranges, before anything runs
        PlannerSettings(**out)
    except ValueError as exc:
        raise ValueError(f"{where}.{exc}") from None
    return out


PRIOR_NAMES = {"lqr": "the LQR", "pumping": "the LQR with pumping", "passivity": "the passivity law"}
"""How :func:`label` names each prior (the baselines' row names, docs/tasks.md)."""


def label(settings: PlannerSettings) -> str:
    """The report's name of the planner row: the law its plans perturb, and the model it rolls out."""
    fresh = ("" if settings.warm_start else ", no warm start") + (", to the episode's end" if settings.to_end else "")
    if settings.prior == "none":
        return f"planner (MPPI over open-loop plans{fresh}, true model)"
    return f"planner (MPPI around {PRIOR_NAMES.get(settings.prior, settings.prior)}{fresh}, true model)"


__all__ = [
    "LAW_OF_PRIOR",
    "PLANNERS",
    "PRIOR_LAWS",
    "AROUND_PUMPING",
    "TO_THE_END",
    "Planner",
    "PlannerSettings",
    "label",
    "parse_overrides",
    "settings_for",
]

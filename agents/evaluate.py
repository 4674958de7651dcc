"""Evaluate agents and baselines on the flatbody tasks (``FlatBody-v0`` and the others of
``docs/tasks.md``) over seeded episodes.

Episode i is reset with seed ``seed + i`` — the same target and initial state for every policy
(the batched :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv` reproduces single-env resets
seed for seed). Per episode:

* ``success``: ``info["is_success"]`` at the end of the episode (distance ≤ the task tolerance
  0.05 on the last step, no failure);
* ``final_distance``: the task distance d = ‖(Δλ, Δμ, Δϱ, Δs3, ω1, ω2, p_λ, p_μ, p_ϱ)‖ on the last step;
* ``time_to_reach``: sim time of the first step with d ≤ tolerance (None if never);
* ``energy_change``: H(end) − H(start) (the controls do work: Ḣ = ω·τ + ϱ̇ f);
* ``action_effort``: mean over steps of ‖a‖² (normalised actions in [−1, 1]ⁿ);
* ``return``, ``length``, ``failed`` (integrator failure, left the domain, or — on a task that ends
  there — left the target's tolerance).

Policies: the agent (an SB3 model, observations normalised by its frozen VecNormalize
statistics, deterministic actions; for a residual agent combined with the LQR action, :class:`agents.heuristic.ResidualAction`), and the
baselines ``zero`` (a = 0), ``random`` (uniform actions from a seeded generator), ``heuristic``
(LQR about the target, :class:`agents.heuristic.HeuristicController`) and ``passivity``
(:class:`agents.heuristic.PassivityController`), on the v1 reach tasks ``pumping`` (the LQR with the out-of-plane
spin's centrifugal force pumped against the thickness or the shape, :class:`agents.heuristic.PumpingController`), and on
the tasks whose starts come with a witness
(:class:`flatbody_env.env.witness.ReachWithWitness`) ``witness``: the witness replayed open loop. A
baseline that cannot be built for a task (the LQR where the controls are not linearly controllable)
is reported as such (:data:`CANNOT_BE_BUILT`).
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from agents.numpy_policy import (
    MODELS_DIR,
    shipped_model_dir,
)  # where shipped agents live (numpy_policy: no import back)

EVAL_SEED = 10_000
"""First evaluation episode seed (episode i is reset with seed ``EVAL_SEED + i``): the default of
:func:`evaluate_all`, :func:`evaluate_task`, ``flatbody evaluate --seed``, ``flatbody sweep seeds --eval-seed``
and the service's evaluate job — held apart from the training seeds (0, 1, …), far below."""
BASELINES = ("zero", "random", "heuristic", "passivity")
"""``heuristic``: LQR about the target (:class:`agents.heuristic.HeuristicController`);
``passivity``: the energy-based damping law (:class:`agents.heuristic.PassivityController`)."""
PLANNER = "planner"
"""The model-predictive reference of the v1 ids (:mod:`agents.planner`): MPPI over the env's own transition."""
WITNESS = "witness"
"""The baseline of the tasks with witnessed starts: each episode's witness replayed open loop."""
PUMPING = "pumping"
"""The classic baseline of the v1 reach tasks that uses the second-order channel: the LQR with the out-of-plane spin's
centrifugal force pumped against the thickness (torque alone) or the in-plane shape
(:class:`agents.heuristic.PumpingController`)."""
ALL_BASELINES = (*BASELINES, PUMPING, PLANNER, WITNESS)
"""Every baseline's name, in the order the reports and charts list them (:func:`baselines_for`: those of a task)."""
GROWTH_FLOOR = 1e-4
"""Growth rates (s⁻¹) below this count as 0 in :func:`target_features` (the finite-difference linearisation of a
spectrally stable target has eigenvalues within ~1e-6 of the imaginary axis)."""
CANNOT_BE_BUILT = "cannot be built"
"""The ``status`` of a baseline that does not exist for a task (its ``reason`` says why)."""
METRICS = (
    "success_rate",
    "final_distance",
    "final_distance_median",
    "reach_rate",
    "time_to_reach",
    "energy_change",
    "abs_energy_change",
    "action_effort",
    "return",
    "failure_rate",
)

Policy = Callable[[np.ndarray], np.ndarray]
"""Observations (N, 16) (or (N, 21) with the body's constants) → actions (N, n)."""


def shipped_agents(env_id: str) -> dict[str, Path]:
    """The shipped agents of a task: ``{algo: folder}`` for every ``MODELS_DIR/<algo>-<env_id>/model.zip`` (``algo``
    may hold a dash: ``rsl-ppo``; every task id starts with ``FlatBody``, so ``*-<env_id>`` matches that task only)."""
    found = {}
    for folder in sorted(MODELS_DIR.glob(f"*-{env_id}")):
        algo = folder.name[: -len(env_id) - 1]
        if (folder / "model.zip").exists() and algo:
            found[algo] = folder
    return found


def baselines_for(env_id: str) -> tuple[str, ...]:
    """The baselines evaluated on a task: :data:`BASELINES`; on the v1 ids :data:`PUMPING` where a target is reached
    (not held), then :data:`PLANNER`; and :data:`WITNESS` where its starts come with a witness."""
    from flatbody_env.env.registration import task_spec

    spec = task_spec(env_id)
    extra = ()
    if spec.version >= 1:
        extra = ((PUMPING,) if spec.kwargs.get("task") != "hold-unstable" else ()) + (PLANNER,)
    return BASELINES + extra + ((WITNESS,) if spec.kwargs.get("task") == "reach-witnessed" else ())


POLICY_BACKENDS = ("auto", "numpy", "sb3")
"""How :class:`Agent` evaluates the policy: ``numpy`` the exported ``policy.npz``
(:mod:`agents.numpy_policy`, no torch), ``sb3`` the SB3 model itself (imports torch), ``auto`` the
exported policy when it is there and current, else SB3 (a stale export is reported on stderr)."""


class Agent:
    """A trained agent as a batch policy: its deterministic policy with frozen VecNormalize statistics.

    Parameters
    ----------
    path : str or Path, optional
        A run folder (with ``model.zip``, ``config.yml`` and optionally ``vecnormalize.pkl`` and
        ``policy.npz``) or a ``model.zip`` (its folder is searched for the rest). Default: the
        shipped agent.
    backend : {"auto", "numpy", "sb3"}
        :data:`POLICY_BACKENDS`. With ``auto`` and a current ``policy.npz`` (the shipped agent's
        is), torch and SB3 are not imported.
    """

    def __init__(self, path: str | Path | None = None, *, backend: str = "auto") -> None:
        from flatbody_env.physics import validation

        validation.string("backend", backend, choices=POLICY_BACKENDS)
        p = Path(path) if path is not None else shipped_model_dir()
        folder = p if p.is_dir() else p.parent
        model_file = p if p.is_file() else folder / "model.zip"
        if not model_file.is_file():
            raise ValueError(f"model: no model at {str(p)!r} (expected a run folder with model.zip, or a .zip)")
        from agents.numpy_policy import read_run_config

        self.config: dict[str, Any] = read_run_config(folder)  # a mapping, or a ValueError naming config.yml
        from agents.numpy_policy import model_format_of
        from flatbody_env.physics import validation

        algo = model_format_of(self.config, model_file.name)
        self.algo = algo
        """The SB3 class of the model file (``ppo``, ``sac``, ``td3``; an rsl-ppo run's is ``ppo``)."""
        self.path = folder
        self.policy = None
        self.model = None
        self.vecnormalize = None
        if backend != "sb3":
            from agents.numpy_policy import StalePolicyError, load_policy

            try:
                self.policy = load_policy(model_file)
            except StalePolicyError as exc:
                if backend == "numpy":
                    raise
                if (folder / "policy.npz").exists():  # present but stale: say so (a missing one is the SB3 default)
                    import sys

                    sys.stderr.write(f"flatbody: {exc}; evaluating with Stable-Baselines3 instead\n")
            # a damaged policy.npz (DamagedPolicyError) is an error, never a silent fall-back to the pickle
        if self.policy is None:
            self._load_sb3(model_file, folder, algo)
        self.backend = "numpy" if self.policy is not None else "sb3"
        hp = self.config.get("hyperparams") or {}
        self.env_id: str = self.config.get("env_id") or "FlatBody-v0"
        self.env_kwargs: dict[str, Any] = dict(hp.get("env_kwargs") or {})
        if self.env_id != "FlatBody-v0":  # another task: its registered keywords (task, control, ...) come with it
            self.env_kwargs = env_kwargs_for(self.env_id, self.env_kwargs)
        self.residual = hp.get("residual") or None

        self.residual_scale = validation.number(
            "config.yml.hyperparams.residual_scale", hp.get("residual_scale", 1.0), low=0.0, high=1e6
        )
        self.residual_gate = validation.number(
            "config.yml.hyperparams.residual_gate", hp.get("residual_gate", 0.0), low=0.0, high=1e6
        )
        self._base = residual_action(self.env_kwargs, hp)

    def _load_sb3(self, model_file: Path, folder: Path, algo: str) -> None:
        from agents.numpy_policy import check_trusted, load_sb3, load_vecnormalize

        check_trusted(folder, "model.zip (a pickle-based SB3 file)")  # before torch is imported (docs/reliability.md)
        import torch
        from stable_baselines3 import PPO, SAC, TD3

        torch.set_num_threads(1)
        cls = {"ppo": PPO, "sac": SAC, "td3": TD3}[algo]
        self.model = load_sb3(cls, model_file)  # the one trust check again, on the file itself, and the reading door
        vn = folder / "vecnormalize.pkl"
        if vn.exists():
            self.vecnormalize = load_vecnormalize(vn)
            self.vecnormalize.training = False

    @property
    def residual_action(self):
        """The executed action's form (:class:`agents.heuristic.ResidualAction`: the LQR or the passivity law
        plus this policy's residual), or None for a policy that acts alone."""
        return self._base

    def policy_actions(self, obs: np.ndarray) -> np.ndarray:
        """The trained policy's deterministic actions (N, n) for raw observations (N, 16), before any residual."""
        if self.policy is not None:
            return self.policy(obs)
        o = self.vecnormalize.normalize_obs(obs) if self.vecnormalize is not None else obs
        actions, _ = self.model.predict(o, deterministic=True)
        return actions

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        actions = self.policy_actions(obs)
        if self._base is not None:  # residual on the hand-designed controller
            actions = self._base(obs, actions)
        return actions


def residual_action(env_kwargs: dict[str, Any], hp: dict[str, Any]):
    """The executed action's form of a run with hyperparameters ``hp`` on a task of ``env_kwargs``: a
    :class:`agents.heuristic.ResidualAction` (a classic law of ``RESIDUAL_BASES`` plus the policy's residual) where
    ``hp`` has a ``residual`` prior, else None (the policy's action is the control)."""
    from agents.heuristic import RESIDUAL_BASES

    kind = hp.get("residual") or None
    if kind not in RESIDUAL_BASES:
        return None
    from agents.heuristic import ResidualAction

    return ResidualAction(
        env_kwargs,
        float(hp.get("residual_scale", 1.0)),
        float(hp.get("residual_gate", 0.0)),
        str(hp.get("residual_mode", "additive")),
        kind,
    )


def sb3_policy(model, residual=None) -> Policy:
    """The deterministic action of an SB3 ``model`` as it trains, as a batch policy: its VecNormalize statistics
    applied as they are now, through ``residual`` (:func:`residual_action`) when the run has a prior."""
    vn = model.get_vec_normalize_env()

    def policy(obs: np.ndarray) -> np.ndarray:
        o = vn.normalize_obs(np.asarray(obs, dtype=np.float32)) if vn is not None else obs
        actions = model.predict(o, deterministic=True)[0]
        return residual(obs, actions) if residual is not None else actions

    return policy


EVAL_COLUMNS = ("env_steps", "train_seconds", "episodes", "success_rate", "success_lo", "success_hi", "return",
                "final_distance", "final_distance_median")  # fmt: skip
"""The columns of a run's ``evaluations.csv`` (:class:`HeldOutEvaluations`)."""


class HeldOutEvaluations:
    """Evaluations of a policy along its training on held-out episodes (seeds ``seed`` … ``seed + episodes − 1``, the
    table's, never trained on): the deterministic policy as it is when the run passes each step count of ``at``.

    ``flatbody train --eval-freq N`` (:meth:`every`) and the benchmark's learning curves (fractions of the budget) are
    both this. The trainers call :meth:`start` with the step count they start from (earlier marks are dropped: a
    resumed run does not evaluate again what it passed), :meth:`due` and :meth:`add` as they go (the time spent
    evaluating is left out of the run's wall time and of ``train_seconds``) and :meth:`close` at the end.

    Parameters
    ----------
    env_id : str
        The task (its registered keywords updated by ``env_kwargs``).
    at : sequence of int
        Env step counts, ascending.
    seed, episodes : int
        Episode i is reset with seed ``seed + i``; ``episodes`` per evaluation.
    then : callable, optional
        Called with each point; a return of False stops the run there (a pruner: ``flatbody tune``), which the trainer
        then ends as a completed run.
    """

    def __init__(self, env_id: str, at, *, seed: int = EVAL_SEED, episodes: int = 100,
                 env_kwargs: dict[str, Any] | None = None, then=None) -> None:  # fmt: skip
        from flatbody_env.physics import validation

        self.env_id = validation.string("env", env_id)
        self.seed = validation.integer("eval_seed", seed, low=0, high=validation.MAX_SEED)
        self.episodes = validation.integer("eval_episodes", episodes, low=1, high=validation.MAX_EPISODES)
        self.env_kwargs = dict(env_kwargs or {})
        self.at = sorted(int(a) for a in at)
        self.points: list[dict[str, Any]] = []
        self.t0 = time.perf_counter()
        self.eval_seconds = 0.0
        self.table = None
        self.say = False
        self.then = then
        self.stop = False
        """Whether ``then`` asked to stop the run."""

    @classmethod
    def every(cls, freq: int, total: int, env_id: str, **kwargs: Any) -> HeldOutEvaluations:
        """Evaluations every ``freq`` env steps up to ``total`` (``flatbody train --eval-freq``): at most
        ``MAX_REPEATS`` (1000) of them, so ``freq`` ≥ total / 1000."""
        from flatbody_env.physics import validation

        low = max(1, -(-int(total) // validation.MAX_REPEATS))
        validation.integer("eval_freq", freq, low=low, high=validation.MAX_TIMESTEPS)
        return cls(env_id, range(freq, int(total) + 1, freq), **kwargs)

    def start(self, steps: int, table=None, *, say: bool = False) -> None:
        """The run starts at ``steps`` (marks up to it dropped); ``table``: a :class:`agents.runs.ProgressTable` that
        gets a row per evaluation (:data:`EVAL_COLUMNS`); ``say``: a line per evaluation on stderr."""
        self.at = [a for a in self.at if a > steps]
        self.table, self.say = table, say

    def due(self, steps: int) -> bool:
        """Whether the run, at ``steps``, has passed the next mark."""
        return bool(self.at) and steps >= self.at[0]

    def train_seconds(self) -> float:
        """Seconds since this object was made (just before its run), less the time spent evaluating."""
        return time.perf_counter() - self.t0 - self.eval_seconds

    def figures(self, policy: Policy, episodes: int | None = None) -> dict[str, Any]:
        """``policy`` on the held-out episodes: success (with its 95 % interval), return, final distance."""
        s = summarize(run_episodes(policy, episodes=episodes or self.episodes, seed=self.seed, env_id=self.env_id,
                                   env_kwargs=self.env_kwargs or None))  # fmt: skip
        keep = ("episodes", "success_rate", "success_ci95", "return", "final_distance", "final_distance_median")
        return {k: s[k] for k in keep}

    def add(self, steps: int, policy: Policy, episodes: int | None = None) -> dict[str, Any]:
        """Evaluate ``policy`` now, at ``steps`` env steps (the marks passed dropped); the point, also in ``points``."""
        while self.at and steps >= self.at[0]:
            self.at.pop(0)
        train_s = self.train_seconds()
        t = time.perf_counter()
        figures = self.figures(policy, episodes)
        self.eval_seconds += time.perf_counter() - t
        point = {"env_steps": int(steps), "train_seconds": float(train_s), **figures}
        self.points.append(point)
        lo, hi = figures["success_ci95"]
        if self.table is not None:
            self.table.add({k: point.get(k, {"success_lo": lo, "success_hi": hi}.get(k)) for k in EVAL_COLUMNS})
        if self.say:
            print(
                f"flatbody: evaluation at {steps:,} steps: success {figures['success_rate']:.0%} ({lo:.0%}-{hi:.0%}) "
                f"on {figures['episodes']} held-out episodes (seeds {self.seed}+), final distance "
                f"{figures['final_distance']:.3g}",
                file=sys.stderr,
            )
        if self.then is not None and self.then(point) is False:
            self.stop = True
        return point

    def sb3_callback(self, residual=None):
        """An SB3 callback that evaluates the model (:func:`sb3_policy`) whenever :meth:`due`."""
        from stable_baselines3.common.callbacks import BaseCallback

        evaluations = self

        class Evaluations(BaseCallback):
            def _on_step(self) -> bool:
                if evaluations.due(self.num_timesteps):
                    evaluations.add(self.num_timesteps, sb3_policy(self.model, residual))
                return not evaluations.stop

        return Evaluations()

    def close(self) -> None:
        """The last write of the table."""
        if self.table is not None:
            self.table.close()


def zero_policy(action_dim: int) -> Policy:
    return lambda obs: np.zeros((obs.shape[0], action_dim), dtype=np.float32)


def random_policy(action_dim: int, seed: int) -> Policy:
    rng = np.random.default_rng(seed)
    return lambda obs: rng.uniform(-1.0, 1.0, size=(obs.shape[0], action_dim)).astype(np.float32)


def heuristic_policy(env, kind: str = "heuristic") -> Policy:
    """The classic law ``kind`` (``heuristic``: the LQR, ``passivity``, :data:`PUMPING`) of ``env``'s body as a batch
    policy."""
    from agents.heuristic import LAWS

    ctl = LAWS[kind](env.body, env.control, env.limits)
    return lambda obs: ctl.predict(obs)[0]


def env_kwargs_for(env_id: str, env_kwargs: dict[str, Any] | None = None) -> dict[str, Any]:
    """The keyword arguments of a registered id (``docs/tasks.md``) updated by ``env_kwargs``."""
    from flatbody_env.env.registration import task_spec

    return {**task_spec(env_id).kwargs, **(env_kwargs or {})}


def run_episodes(
    policy: Policy | str,
    *,
    episodes: int,
    seed: int,
    env_kwargs: dict[str, Any] | None = None,
    env_id: str = "FlatBody-v0",
    batch: int = 50,
    progress: bool = False,
    label: str = "",
    compute: dict | None = None,
    planner: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """Roll out ``episodes`` seeded episodes of ``env_id`` (batched ``batch`` at a time); one record per episode.

    ``policy`` is a batch policy or a baseline name (:data:`BASELINES`, :data:`PUMPING`, :data:`PLANNER`,
    :data:`WITNESS`; ``planner``:
    overrides of the planner's settings, :func:`agents.planner.parse_overrides`); ``env_kwargs``
    update the id's registered keywords.

    Raises
    ------
    numpy.linalg.LinAlgError
        When the LQR baseline cannot be built for the task's targets (:func:`evaluate_policies` reports it).
    """
    from flatbody_env.env.registration import task_spec
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    from flatbody_env.physics import validation

    validation.integer("episodes", episodes, low=1)
    steps = task_spec(env_id).max_episode_steps
    kwargs = env_kwargs_for(env_id, env_kwargs)
    records: list[dict[str, Any]] = []
    bar = None
    if progress:
        from flatbody_env.progress import progress_bar

        bar = progress_bar(total=episodes * steps, desc=label or "evaluate", unit="step", leave=False)
    for start in range(0, episodes, batch):
        n = min(batch, episodes - start)
        env = FlatBodyVectorEnv(num_envs=n, max_episode_steps=steps, **kwargs)
        adim = env.single_action_space.shape[0]
        step_index = [0]
        if isinstance(policy, str):
            if policy == "zero":
                pol = zero_policy(adim)
            elif policy == "random":
                pol = random_policy(adim, seed + start)
            elif policy in ("heuristic", "passivity", PUMPING):
                pol = heuristic_policy(env, policy)
            elif policy == WITNESS:
                pol = None  # after the reset, which draws the witnesses
            elif policy == PLANNER:
                pol = _planner_policy(env, env_id, kwargs, n, seed + start, compute, planner)
            else:
                raise validation.refusal("baseline", f"be one of {', '.join(ALL_BASELINES)}", policy)
        else:
            pol = policy
        tol = env.task.success_tolerance
        obs, info = env.reset(seed=seed + start)
        if pol is None:
            pol = _witness_policy(env, step_index)
        e0 = np.asarray(info["energy"], dtype=float).copy()
        active = np.ones(n, dtype=bool)
        ret = np.zeros(n)
        effort = np.zeros(n)
        length = np.zeros(n, dtype=int)
        reach = np.full(n, np.nan)
        final_d = np.full(n, np.nan)
        success = np.zeros(n, dtype=bool)
        failed = np.zeros(n, dtype=bool)
        e_end = e0.copy()
        while active.any():
            a = np.asarray(pol(obs), dtype=np.float32).reshape(n, adim)
            obs, r, term, trunc, info = env.step(a)
            step_index[0] += 1
            act = active
            ac = np.clip(a.astype(np.float64), -1.0, 1.0)
            ret[act] += r[act]
            effort[act] += np.sum(ac * ac, axis=1)[act]
            length[act] += 1
            d = np.asarray(info["distance"])
            t = np.asarray(info["t"], dtype=float)
            newly = act & np.isnan(reach) & (d <= tol) & ~term
            reach[newly] = t[newly]
            e_end[act] = np.asarray(info["energy"])[act]
            done = act & (term | trunc)
            final_d[done] = d[done]
            success[done] = np.asarray(info["is_success"])[done]
            failed[done] = term[done]
            active = active & ~done
            if bar is not None:
                bar.update(int(act.sum()))
        env.close()
        for i in range(n):
            records.append(
                {
                    "seed": seed + start + i,
                    "success": bool(success[i]),
                    "final_distance": float(final_d[i]),
                    "time_to_reach": None if math.isnan(reach[i]) else float(reach[i]),
                    "energy_change": float(e_end[i] - e0[i]),
                    "action_effort": float(effort[i] / max(length[i], 1)),
                    "return": float(ret[i]),
                    "length": int(length[i]),
                    "failed": bool(failed[i]),
                }
            )
    if bar is not None:
        bar.close()
    return records


def _planner_policy(
    env, env_id: str, kwargs: dict[str, Any], n: int, seed: int, compute: dict | None, overrides: dict | None = None
) -> Policy:
    """The planner (:mod:`agents.planner`) of ``env_id`` (its settings with ``overrides``) for the ``n`` episodes of
    ``env``, which it reads each body's kernel parameters from (the true model, also where the observation hides them);
    its compute into ``compute``."""
    from agents.planner import Planner, label, settings_for

    planner = Planner(kwargs, n, settings_for(env_id, overrides), seed=seed)

    def act(obs):
        a = planner.act(obs, env.body_params, env.max_episode_steps - env.episode_steps)
        if compute is not None:
            compute["seconds"] = compute.get("seconds", 0.0) + planner.seconds
            compute["episode_steps"] = compute.get("episode_steps", 0) + n
            compute["body_steps"] = compute.get("body_steps", 0) + planner.body_steps
            # as rolled out: a horizon to the episode's end shrinks, and its first step refines more often
            compute["body_steps_per_step"] = round(compute["body_steps"] / compute["episode_steps"])
            compute["label"] = label(planner.settings)
            compute["settings"] = dataclasses.asdict(planner.settings)
            planner.seconds = 0.0
            planner.body_steps = 0
        return a

    return act


def _witness_policy(env, step_index: list[int]) -> Policy:
    """Each body's witness (``env.witnesses``, drawn at the reset) replayed open loop: step k plays row k."""
    witnesses = env.witnesses
    if any(w is None for w in witnesses):
        raise ValueError(
            "baseline: witness needs a task whose starts come with a witness (FlatBodyTorque-v0, FlatBodyDilatation-v0)"
        )
    W = np.stack(witnesses)
    return lambda obs: W[:, min(step_index[0], W.shape[1] - 1)].astype(np.float32)


def success_interval(successes: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The 95 % Wilson score interval of a success rate k/n (E. B. Wilson, J. Am. Stat. Assoc. 22, 209 (1927)):
    (p̂ + z²/2n ∓ z √(p̂(1 − p̂)/n + z²/4n²)) / (1 + z²/n), z = Φ⁻¹(0.975)."""
    from flatbody_env.physics import validation

    validation.requirement("episodes", n, n >= 1, "be >= 1")
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # at 0 and n successes the ends are exactly 0 and 1 (the formula's rounding left 1e-17 above the rate)
    return (0.0 if successes == 0 else max(0.0, centre - half)), (1.0 if successes == n else min(1.0, centre + half))


def summarize(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Means over episodes (``time_to_reach`` over the episodes that reached the target)."""
    fd = np.array([r["final_distance"] for r in records])
    ttr = [r["time_to_reach"] for r in records if r["time_to_reach"] is not None]
    de = np.array([r["energy_change"] for r in records])
    wins = int(sum(r["success"] for r in records))
    lengths = np.array([r["length"] for r in records])
    return {
        "episodes": len(records),
        "success_rate": float(np.mean([r["success"] for r in records])),
        "success_ci95": list(success_interval(wins, len(records))),
        "length_mean": float(np.mean(lengths)),
        "length_median": float(np.median(lengths)),
        "final_distance": float(np.mean(fd)),
        "final_distance_median": float(np.median(fd)),
        "reach_rate": float(len(ttr) / len(records)),
        "time_to_reach": float(np.mean(ttr)) if ttr else None,
        "energy_change": float(np.mean(de)),
        "abs_energy_change": float(np.mean(np.abs(de))),
        "action_effort": float(np.mean([r["action_effort"] for r in records])),
        "return": float(np.mean([r["return"] for r in records])),
        "failure_rate": float(np.mean([r["failed"] for r in records])),
    }


def evaluate_all(
    model: str | Path | None = None,
    *,
    episodes: int = 100,
    seed: int = EVAL_SEED,
    baselines: bool = True,
    progress: bool = False,
    backend: str = "auto",
) -> dict[str, Any]:
    """The evaluation report of an agent on its task (``FlatBody-v1`` for the shipped one):
    ``{"agent": {...}, "baselines": {"zero", "random", "heuristic", "passivity"}, ...}``;
    ``policy_backend`` says how the agent's policy ran (``numpy`` or ``sb3``, :class:`Agent`)."""
    agent = Agent(model, backend=backend)
    env_id = agent.config.get("env_id") or "FlatBody-v0"
    env_kwargs = agent.env_kwargs
    report: dict[str, Any] = {
        "env_id": env_id,
        "episodes": episodes,
        "seed": seed,
        "model": str(agent.path),
        "policy_backend": agent.backend,
        "agent": summarize(
            run_episodes(
                agent,
                episodes=episodes,
                seed=seed,
                env_kwargs=env_kwargs,
                env_id=env_id,
                progress=progress,
                label="agent",
            )
        ),
    }
    if baselines:
        report["baselines"] = {
            name: _summary_or_status(
                name, episodes=episodes, seed=seed, env_kwargs=env_kwargs, env_id=env_id, progress=progress
            )[0]
            for name in baselines_for(env_id)
        }
    return report


def _summary_or_status(name: str, **kwargs) -> tuple[dict[str, Any], list[dict[str, Any]] | None]:
    """A baseline's summary and records, or ``{"status": CANNOT_BE_BUILT, "reason": ...}`` (and no records)
    where it does not exist for the task (the LQR where the Riccati equation has no stabilising solution)."""
    compute: dict = {}
    try:
        records = run_episodes(name, label=name, compute=compute, **kwargs)
    except np.linalg.LinAlgError as exc:
        return {"status": CANNOT_BE_BUILT, "reason": f"LinAlgError: {' '.join(str(exc).split())}"}, None
    summary = summarize(records)
    if compute:  # the planner: what each of its control steps cost (the batch's wall time shared by its episodes)
        summary["compute"] = {
            "label": compute["label"],
            "body_steps_per_step": compute["body_steps_per_step"],
            "seconds_per_step": compute["seconds"] / max(compute["episode_steps"], 1),
            "settings": compute["settings"],
        }
    return summary, records


def evaluate_task(
    env_id: str,
    *,
    episodes: int = 100,
    seed: int = EVAL_SEED,
    model: str | Path | None = None,
    baselines: bool = True,
    with_agents: bool = True,
    progress: bool = False,
    backend: str = "auto",
    only: tuple[str, ...] | None = None,
    planner: dict[str, Any] | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The reference report of one registered task: every baseline (:func:`baselines_for`; ``only``: those named)
    and agent — the one in ``model``, else the task's shipped agents (:func:`shipped_agents`) — over ``episodes``
    seeded episodes, with each episode's target features (:func:`target_features`) and per-episode results.
    ``planner``: overrides of the planner's settings (:func:`agents.planner.parse_overrides`; the report's planner
    summary holds the settings that ran). ``env_kwargs``: the task's registered keywords changed (a variant: every
    policy, the targets and the planner's model run on it; an agent on its own keywords updated by these); the report
    holds them in ``env_kwargs`` (all of them) and ``variant`` (the changed ones).

    ``{"env_id", "episodes", "seed", "targets": {"seed", "settling_rate", "growth_rate"}, "policies": {name:
    {"kind", "summary", "episodes": {"success", "final_distance", "return", "length"}}}}``; for ``FlatBody-v0``
    also the keys of :func:`evaluate_all` (``agent``, ``baselines``).
    """
    from flatbody_env.env.registration import task_spec

    spec = task_spec(env_id)
    report: dict[str, Any] = {
        "env_id": env_id,
        "episodes": episodes,
        "seed": seed,
        "max_episode_steps": spec.max_episode_steps,
        "dt": float(spec.kwargs.get("dt", 0.05)),
        "env_kwargs": env_kwargs_for(env_id, env_kwargs),
        "summary": spec.summary,
        "targets": target_features(env_id, episodes=episodes, seed=seed, env_kwargs=env_kwargs),
        "policies": {},
    }
    if env_kwargs:
        report["variant"] = dict(env_kwargs)
    policies = report["policies"]
    columns = ("success", "final_distance", "return", "length")
    if baselines:
        names = baselines_for(env_id)
        if only is not None:
            from flatbody_env.physics import validation

            for name in only:
                validation.string("baselines", name, choices=names)
            names = tuple(n for n in names if n in only)
        for name in names:
            extra = {"planner": planner} if name == PLANNER else {}
            summary, records = _summary_or_status(
                name, episodes=episodes, seed=seed, env_id=env_id, env_kwargs=env_kwargs, progress=progress, **extra
            )
            entry: dict[str, Any] = {"kind": "baseline", "summary": summary}
            if records is not None:
                entry["episodes"] = {c: [r[c] for r in records] for c in columns}
            policies[name] = entry
    found = {"agent": Path(model)} if model is not None else (shipped_agents(env_id) if with_agents else {})
    from flatbody_env.output import shown_path

    for name, folder in found.items():
        agent = Agent(folder, backend=backend)
        records = run_episodes(
            agent,
            episodes=episodes,
            seed=seed,
            env_kwargs={**agent.env_kwargs, **(env_kwargs or {})},
            env_id=env_id,
            progress=progress,
            label=name,
        )
        policies[name] = {
            "kind": "agent",
            "model": shown_path(folder, MODELS_DIR.parent.parent),  # agents/models/... wherever the checkout lies
            "policy_backend": agent.backend,
            "summary": summarize(records),
            "episodes": {c: [r[c] for r in records] for c in columns},
        }
    agents_found = [k for k, v in policies.items() if v["kind"] == "agent"]
    if agents_found:
        report["agent"] = policies[agents_found[0]]["summary"]
        report["policy_backend"] = policies[agents_found[0]]["policy_backend"]
    report["baselines"] = {k: v["summary"] for k, v in policies.items() if v["kind"] == "baseline"}
    return report


def target_features(
    env_id: str, *, episodes: int, seed: int, env_kwargs: dict[str, Any] | None = None
) -> dict[str, list]:
    """Each seeded episode's target: its settling rate r under the task's controls
    (:func:`flatbody_env.physics.controllability.settling_rate`; 0 where the controls stabilise no target
    at linear order) and its instability growth rate γ = max(0, max Re eig A) of the linearisation
    (:func:`flatbody_env.physics.controllability.linearize`; below :data:`GROWTH_FLOOR` — the finite
    differences' noise on the imaginary axis of a spectrally stable target — it counts as 0), of the
    episode's own body."""
    from flatbody_env.env.vector_env import FlatBodyVectorEnv
    from flatbody_env.env.task import control_mask
    from flatbody_env.physics.controllability import linearize, settling_rate

    env = FlatBodyVectorEnv(num_envs=episodes, **env_kwargs_for(env_id, env_kwargs))
    obs, _ = env.reset(seed=seed)
    mask = control_mask(env.control)
    rates, growth = [], []
    for i, body in enumerate(env.bodies):
        t = env.target_vectors[i]
        y_star = np.array([0.0, 0.0, t[3], env.states[i, 3], 0.0, 0.0, 0.0, t[0], t[1], t[2], 0.0])
        rates.append(settling_rate(body, y_star, env.limits, mask))
        A, _ = linearize(body, y_star, env.limits)
        g = float(np.max(np.linalg.eigvals(A).real))
        growth.append(g if g > GROWTH_FLOOR else 0.0)
    env.close()
    return {"seed": [seed + i for i in range(episodes)], "settling_rate": rates, "growth_rate": growth}


def format_table(report: dict[str, Any]) -> str:
    """A Markdown table of the report (one row per policy; a baseline that cannot be built says why)."""
    rows = ([("agent", report["agent"])] if "agent" in report else []) + list((report.get("baselines") or {}).items())
    head = (
        "| policy | success rate (95 % interval) | final distance (mean) | final distance (median) | time to reach (mean, s) "
        "| ΔH (mean) | action effort ‖a‖² | return |"
    )
    env_id = report.get("env_id", "FlatBody-v0")
    lines = [
        f"{env_id}, {report['episodes']} episodes, seeds {report['seed']}..{report['seed'] + report['episodes'] - 1}",
        "",
        head,
        "|" + "---|" * 8,
    ]
    for name, s in rows:
        if s.get("status"):
            lines.append(f"| {name} | {s['status']}: {s['reason']} | | | | | | |")
            continue
        ttr = "—" if s["time_to_reach"] is None else f"{s['time_to_reach']:.2f} ({s['reach_rate']:.0%} reach)"
        lo, hi = s.get("success_ci95", (float("nan"), float("nan")))
        lines.append(
            f"| {name} | {s['success_rate']:.0%} ({lo:.0%}–{hi:.0%}) | {s['final_distance']:.4f} | {s['final_distance_median']:.4f} | {ttr} | "
            f"{s['energy_change']:+.3f} | {s['action_effort']:.3f} | {s['return']:.1f} |"
        )
    return "\n".join(lines)

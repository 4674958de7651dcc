"""Imitation: cross-entropy plans of open-loop residuals cloned into a residual agent's policy; the planner distilled.

Used for ``FlatBodySlow-v0`` (docs/agents.md), where the LQR fails on the slowest targets and PPO alone
found only part of the strategy that reaches them (tumbling the body, s1, s2 ≠ 0, moves the slow
in-plane shape through the centrifugal terms; zero at linear order, so the LQR never uses it). Three
steps, each a command:

1. :func:`plan` (``flatbody imitate plan``): for each seeded training episode, a cross-entropy
   search over an open-loop residual u(t) — piecewise constant on ``knots`` equal intervals of the
   episode, every action component — executed exactly as the agent's own residual is
   (:class:`agents.heuristic.ResidualAction` of the run folder it will be cloned into: the LQR plus the
   gated residual). The cost of a plan is 10·max(d_T − ``reach``, 0) + 0.05·mean ‖u‖² (d_T the task
   distance on the last step, 10 if the episode ended early): reach within ``reach`` of the target,
   then spend as little residual as possible; an episode the LQR alone ends within ``reach`` costs 0
   with the zero plan, the least possible, and is not searched. All seeds × samples of a chunk run as one batch of :class:`FlatBodyVectorEnv` (every
   sample of a seed is reset with that seed: the same target and start).
2. :func:`clone` (``flatbody imitate clone``): the successful plans are replayed, their
   (observation, residual) pairs recorded, and the policy mean of an SB3 PPO run (its weights as the
   start, its ``vecnormalize.pkl`` observation statistics) is fitted to them by least squares (Adam,
   minibatches). The result is a run folder (:class:`agents.runs.RunFolder`: ``config.yml`` naming the start run and
   the plans as its prior, ``run.json``, ``progress.csv`` of the fit, ``vecnormalize.pkl``, ``model.zip``,
   ``policy.npz``).
3. PPO fine-tunes it on the task (``flatbody train --trained-agent`` or ``flatbody curriculum
   --trained-agent``): the clone alone is worse than its start (an open-loop plan is a function of time,
   the policy of the state), but it starts PPO where the nonlinear strategy is used.

A second round plans *corrections* of the fine-tuned run's own policy (``on_policy``: the executed
residual is clip(policy(obs) + u(t), −1, 1), u = 0 being the run alone), clones them into that run and
fine-tunes again (expert iteration).

Plans are saved as ``.npz`` without pickles (:class:`Plans`).

**Distilling the planner** (:func:`distill`, ``flatbody imitate distill``): the v1 tasks' model-predictive reference
(:mod:`agents.planner`) is the expert of a DAgger loop — it labels the states the policy reaches with what it would do
there, and the policy's mean action is fitted to every label so far (:func:`fit_policy_mean`, the fit ``clone`` makes
too). The result is a PPO run folder that acts from the observation alone at the cost of one forward pass, where the
planner rolls out thousands of body-steps per control step with the true model.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flatbody_env.physics import validation

REACH_COST = 10.0
"""Weight of the final distance beyond ``reach`` in a plan's cost."""
EFFORT_COST = 0.05
"""Weight of the residual's mean squared size in a plan's cost."""
ENDED_DISTANCE = 10.0
"""The final distance charged to an episode that ended before its last step (left the domain, failed)."""


@dataclass(frozen=True, kw_only=True)
class PlanSettings:
    """The cross-entropy search of :func:`plan`.

    knots : int
        Piecewise-constant intervals of the open-loop residual over the episode.
    samples : int
        Plans drawn per seed and iteration.
    iterations : int
        Cross-entropy iterations.
    elite : int
        Best plans per seed whose mean and spread the next draws use (smoothed 0.7 new / 0.3 old).
    init_std : float
        Initial spread of every knot (the mean starts at 0: the LQR alone).
    reach : float
        Final distance below which a plan only spends less (the cost's knee; ≤ the task's tolerance).
    chunk : int
        Seeds planned in one batch (``chunk × samples`` bodies).
    seed : int
        Seed of the draws.
    """

    knots: int = 16
    samples: int = 64
    iterations: int = 40
    elite: int = 8
    init_std: float = 0.5
    reach: float = 0.02
    chunk: int = 32
    seed: int = 0

    def __post_init__(self) -> None:
        validation.integer("knots", self.knots, low=1, high=400)
        validation.integer("samples", self.samples, low=2, high=4096)
        validation.integer("iterations", self.iterations, low=1, high=10_000)
        validation.integer("elite", self.elite, low=1, high=self.samples)
        validation.number("init_std", self.init_std, low=0.0, high=10.0)
        validation.number("reach", self.reach, low=0.0, high=10.0)
        validation.integer("chunk", self.chunk, low=1, high=4096)
        validation.integer("seed", self.seed, low=0, high=validation.MAX_SEED)
        if self.chunk * self.samples > 1 << 17:
            raise ValueError(
                f"chunk, samples: at most {1 << 17} bodies in one batch, got {self.chunk} x {self.samples}"
            )


@dataclass(frozen=True, kw_only=True)
class Plans:
    """Plans of :func:`plan`: ``seeds`` (S,), ``final_distance`` (S,) of each best plan, ``knots`` (S, K, n)
    (the residual's value on each of the K intervals, n action components), the ``env_id`` and the run
    folder whose residual form executed them (``model``)."""

    env_id: str
    model: str
    seeds: np.ndarray
    final_distance: np.ndarray
    knots: np.ndarray
    on_policy: bool = False
    """The plans correct ``model``'s own policy (executed residual: policy + plan) instead of replacing it."""

    def save(self, path: str | Path) -> None:
        from flatbody_env.output import atomic_path

        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez(
                fh,
                env_id=np.str_(self.env_id),
                model=np.str_(self.model),
                seeds=self.seeds,
                final_distance=self.final_distance,
                knots=self.knots,
                on_policy=np.bool_(self.on_policy),
            )

    @classmethod
    def load(cls, path: str | Path) -> Plans:
        """Plans saved by :meth:`save`, read through the one reading door (:func:`validation.read_npz`: a regular file,
        every array's declared shape checked before it is read, no pickles); ``ValueError`` naming ``plans``."""
        d = validation.read_npz("plans", path)
        try:
            return cls(
                env_id=str(d["env_id"]),
                model=str(d["model"]),
                seeds=d["seeds"].astype(np.int64),
                final_distance=d["final_distance"].astype(np.float64),
                knots=d["knots"].astype(np.float64),
                on_policy=bool(d["on_policy"]) if "on_policy" in d else False,
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(
                f"plans: cannot read {str(path)[:80]!r} as plans ({type(exc).__name__}: {str(exc)[:80]})"
            ) from None

    def __add__(self, other: Plans) -> Plans:
        if (self.env_id, self.model, self.on_policy) != (
            other.env_id,
            other.model,
            other.on_policy,
        ) or self.knots.shape[1:] != other.knots.shape[1:]:
            raise ValueError("plans: can only join plans of the same task, run folder, kind and shape")
        return Plans(
            env_id=self.env_id,
            model=self.model,
            seeds=np.concatenate([self.seeds, other.seeds]),
            final_distance=np.concatenate([self.final_distance, other.final_distance]),
            knots=np.concatenate([self.knots, other.knots]),
            on_policy=self.on_policy,
        )


def _residual_agent(model: str | Path, backend: str = "auto"):
    """The run folder's :class:`agents.evaluate.Agent` (for its task and residual form); refuses a run
    without an LQR/passivity residual in additive mode (the plan is an additive residual)."""
    from agents.evaluate import Agent

    agent = Agent(model, backend=backend)
    if agent.residual_action is None or agent.residual_action.mode != "additive":
        raise ValueError(f"model: {str(model)[:80]!r} is not an additive residual agent (residual_mode: additive)")
    return agent


def rollout(venv, residual, seeds: np.ndarray, knots: np.ndarray, *, record: bool = False, policy=None):
    """Run one episode per row of ``knots`` (B, K, n) from the seeds (B,) under the LQR plus the open-loop
    residual (plus ``policy(obs)``, the agent's own residual, when given: the plan corrects it); returns the
    final distances (B,), the mean squared plan (B,) and, with ``record``, the observations (T, B, obs) and
    executed residuals (T, B, n) of every step."""
    steps = venv.max_episode_steps
    b, k = knots.shape[:2]
    obs, _ = venv.reset(seed=[int(s) for s in seeds])
    alive = np.ones(b, dtype=bool)
    final = np.full(b, ENDED_DISTANCE)
    effort = np.zeros(b)
    seen_o, seen_a = [], []
    for t in range(steps):
        u = knots[:, t * k // steps, :]
        effort += np.sum(u * u, axis=1)
        if policy is not None:
            u = np.clip(policy(obs) + u, -1.0, 1.0)
        if record:
            seen_o.append(obs.copy())
            seen_a.append(u.copy())
        obs, _, term, trunc, info = venv.step(residual(obs, u))
        ended = alive & (term | trunc)
        final = np.where(ended, np.where(term, ENDED_DISTANCE, info["distance"]), final)
        alive &= ~(term | trunc)
    recorded = (np.array(seen_o), np.array(seen_a)) if record else None
    return final, effort / steps, recorded


def plan(
    model: str | Path, seeds, settings: PlanSettings | None = None, *, on_policy: bool = False, progress: bool = True
) -> Plans:
    """Cross-entropy plans (module docstring, step 1) for the seeded episodes of ``model``'s task.

    Parameters
    ----------
    model : str or Path
        A run folder of an additive residual agent: its task (``env_id``, keywords) and residual form
        (:class:`agents.heuristic.ResidualAction`) execute the plans.
    seeds : sequence of int
        Episode seeds (keep them apart from the evaluation seeds).
    settings : PlanSettings, optional
    on_policy : bool
        Plan corrections of ``model``'s own policy (executed residual: clip(policy + plan, −1, 1)) — a
        second round after a fine-tuned run — instead of residuals that replace it.

    Returns
    -------
    Plans
        The best plan of every seed (by cost) and its final distance.
    """
    from flatbody_env.env.vector_env import FlatBodyVectorEnv
    from flatbody_env.progress import progress_bar

    s = settings or PlanSettings()
    agent = _residual_agent(model)
    seeds = np.asarray(
        [validation.integer("seeds", int(x), low=0, high=validation.MAX_SEED) for x in seeds], dtype=np.int64
    )
    if seeds.size == 0:
        raise ValueError("seeds: give at least one seed")
    policy = agent.policy_actions if on_policy else None
    # The zero plan (the LQR alone, or the run alone with on_policy) first, for every seed: where it ends
    # within ``reach`` its cost is 0, the least any plan can cost, so that seed is not searched.
    venv = FlatBodyVectorEnv(num_envs=seeds.size, autoreset_mode="SameStep", **agent.env_kwargs)
    n = venv.single_action_space.shape[0]
    zero_d, _, _ = rollout(venv, agent.residual_action, seeds, np.zeros((seeds.size, s.knots, n)), policy=policy)
    venv.close()
    final_d, final_u = zero_d.copy(), np.zeros((seeds.size, s.knots, n))
    todo = np.flatnonzero(zero_d > s.reach)
    rng = np.random.default_rng(s.seed)
    bar = progress_bar(
        total=int(np.ceil(todo.size / s.chunk)) * s.iterations, desc="plans", unit="iteration", enabled=progress
    )
    for lo in range(0, todo.size, s.chunk):
        rows_todo = todo[lo : lo + s.chunk]
        chunk = seeds[rows_todo]
        m = chunk.size
        venv = FlatBodyVectorEnv(num_envs=m * s.samples, autoreset_mode="SameStep", **agent.env_kwargs)
        mean = np.zeros((m, s.knots, n))
        std = np.full((m, s.knots, n), s.init_std)
        best_cost = REACH_COST * (zero_d[rows_todo] - s.reach)
        best_d, best_u = zero_d[rows_todo].copy(), np.zeros((m, s.knots, n))
        batch_seeds = np.repeat(chunk, s.samples)
        for _ in range(s.iterations):
            u = np.clip(mean[:, None] + std[:, None] * rng.standard_normal((m, s.samples, s.knots, n)), -1.0, 1.0)
            u[:, 0] = best_u  # the best so far stays in the draw
            d, effort, _ = rollout(
                venv, agent.residual_action, batch_seeds, u.reshape(m * s.samples, s.knots, n), policy=policy
            )
            cost = (REACH_COST * np.maximum(d - s.reach, 0.0) + EFFORT_COST * effort).reshape(m, s.samples)
            order = np.argsort(cost, axis=1)[:, : s.elite]
            elite = np.take_along_axis(u, order[:, :, None, None], axis=1)
            mean = 0.7 * elite.mean(axis=1) + 0.3 * mean
            std = np.maximum(0.7 * elite.std(axis=1) + 0.3 * std, 0.02)
            rows = np.arange(m)
            c0, d0 = cost[rows, order[:, 0]], d.reshape(m, s.samples)[rows, order[:, 0]]
            better = c0 < best_cost
            best_cost[better], best_d[better] = c0[better], d0[better]
            best_u[better] = u[rows, order[:, 0]][better]
            bar.update(1)
        venv.close()
        final_d[rows_todo], final_u[rows_todo] = best_d, best_u
    bar.close()
    return Plans(
        env_id=agent.env_id, model=str(model), seeds=seeds, final_distance=final_d, knots=final_u, on_policy=on_policy
    )


def clone(
    plans: Plans,
    model: str | Path,
    out: str | Path,
    *,
    tolerance: float | None = None,
    epochs: int = 20,
    batch_size: int = 1024,
    learning_rate: float = 3e-4,
    seed: int = 0,
    progress: bool = True,
    force: bool = False,
    command: list[str] | None = None,
    plans_files: list[str] | None = None,
) -> dict:
    """Fit ``model``'s policy mean to the successful plans (module docstring, step 2); write the run folder ``out``.

    Parameters
    ----------
    plans : Plans
        Plans made for ``model``'s residual form (:func:`plan`).
    model : str or Path
        The SB3 PPO run folder to start from (weights, ``vecnormalize.pkl``, ``config.yml``).
    out : str or Path
        The new run folder (refused if it holds a run unless ``force``, as ``flatbody train`` refuses:
        :meth:`agents.runs.RunFolder.new`).
    plans_files : list of str, optional
        The files the plans came from (recorded in ``config.yml``).
    tolerance : float, optional
        Plans whose final distance is at most this are cloned (default: the task's success tolerance).

    Returns
    -------
    dict
        ``plans`` (cloned), ``pairs`` (observation, residual), ``replayed_success`` (the replayed plans
        that end within the tolerance: 1.0 unless the environment changed), ``mse_start`` and ``mse_end``
        (the policy mean's squared error against the residuals before and after the fit).
    """
    from agents.config import RunConfig
    from agents.runs import RunFolder
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    validation.integer("epochs", epochs, low=1, high=10_000)
    validation.integer("batch_size", batch_size, low=1, high=1 << 20)
    validation.number("learning_rate", learning_rate, low=1e-8, high=1.0)
    run = RunFolder.new(out, force=force)  # before any work: never a folder holding a run, /, or the home folder
    folder = Path(model)
    start = RunConfig.read(folder, where="model")  # the start run's configuration, checked
    agent = _residual_agent(model, backend="sb3")  # SB3's own model and VecNormalize (pickles: a trusted folder only)
    if agent.algo != "ppo" or agent.vecnormalize is None:
        raise ValueError(f"model: {str(model)[:80]!r} is not a PPO run with normalised observations (vecnormalize.pkl)")
    if plans.env_id != agent.env_id:
        raise ValueError(f"plans: made for {plans.env_id}, the model is a {agent.env_id} run")
    tol = (
        agent.residual_action.task.success_tolerance
        if tolerance is None
        else validation.number("tolerance", tolerance, low=0.0, high=10.0)
    )
    keep = plans.final_distance <= tol
    if not keep.any():
        raise ValueError(f"plans: none ends within {tol:g}; nothing to clone")
    venv = FlatBodyVectorEnv(num_envs=int(keep.sum()), autoreset_mode="SameStep", **agent.env_kwargs)
    if plans.on_policy and Path(plans.model).resolve() != folder.resolve():
        raise ValueError(
            f"plans: corrections of {plans.model!r}'s policy replay only on that run, not {str(model)[:80]!r}"
        )
    final, _, (obs, act) = rollout(
        venv,
        agent.residual_action,
        plans.seeds[keep],
        plans.knots[keep],
        record=True,
        policy=agent.policy_actions if plans.on_policy else None,
    )
    venv.close()
    obs = obs.reshape(-1, obs.shape[-1]).astype(np.float32)
    act = act.reshape(-1, act.shape[-1]).astype(np.float32)

    t0 = time.perf_counter()
    ppo = agent.model
    x = agent.vecnormalize.normalize_obs(obs)
    mse_start, rows = fit_policy_mean(
        ppo.policy,
        x,
        act,
        epochs=epochs,
        batch_size=batch_size,
        learning_rate=learning_rate,
        seed=seed,
        progress=progress,
        desc="clone",
    )
    mse_end = rows[-1]["mse"]
    wall = time.perf_counter() - t0
    from agents.numpy_policy import read_pickled
    from flatbody_env.output import atomic_write

    imitation = {
        "plans": list(plans_files or []),
        "plans_cloned": int(keep.sum()),
        "pairs": int(len(x)),
        "tolerance": float(tol),
        "epochs": int(epochs),
        "batch_size": int(batch_size),
        "learning_rate": float(learning_rate),
        "seed": int(seed),
    }
    config = start.replace(trained_agent=str(model), curriculum=None, imitation=imitation)
    # every file through the run folder (atomic, no planted link followed); the folder is trusted once config.yml is in
    # place; the start run's statistics copied byte for byte through the reading door
    run.start(config, force=force)
    atomic_write(run.path / "vecnormalize.pkl", read_pickled(folder / "vecnormalize.pkl", "vecnormalize.pkl"))
    run.save("model.zip", lambda tmp: ppo.save(str(tmp)))
    run.write_progress(rows)
    run.write_run(config, timesteps=0, wall_time_s=wall, command=command, mse_start=mse_start, mse_end=mse_end)
    run.export_policy()
    return {
        "plans": int(keep.sum()),
        "pairs": int(len(x)),
        "replayed_success": float(np.mean(final <= tol)),
        "mse_start": mse_start,
        "mse_end": mse_end,
    }


def fit_policy_mean(
    pol,
    x: np.ndarray,
    y: np.ndarray,
    *,
    epochs: int,
    batch_size: int,
    learning_rate: float,
    seed: int,
    anneal: bool = False,
    progress: bool = True,
    desc: str = "fit",
) -> tuple[float, list[dict[str, Any]]]:
    """Fit the mean action of an SB3 actor-critic policy ``pol`` (its actor's layers) to ``y`` (M, n) at the normalised
    observations ``x`` (M, d) by least squares: Adam on shuffled minibatches, the rate constant or, with ``anneal``,
    brought to 0 over the epochs along a cosine. Returns the squared error before the fit and one row per epoch
    (``epoch``, ``mse`` over all pairs)."""
    import torch

    from flatbody_env.progress import progress_bar

    torch.manual_seed(seed)
    xt = torch.as_tensor(x, dtype=torch.float32)
    yt = torch.as_tensor(y, dtype=torch.float32)

    def mean_action(xb):
        return pol.action_net(pol.mlp_extractor.forward_actor(pol.extract_features(xb, pol.pi_features_extractor)))

    with torch.no_grad():
        mse_start = float(((mean_action(xt) - yt) ** 2).mean())
    from agents.train import actor_parameters

    params = [p for p in actor_parameters(pol) if p is not pol.log_std]  # the mean's: the fit leaves the noise alone
    opt = torch.optim.Adam(params, lr=learning_rate)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(opt, epochs) if anneal else None
    rows = []
    for epoch in progress_bar(range(epochs), desc=desc, unit="epoch", enabled=progress):
        perm = torch.randperm(len(xt))
        for i in range(0, len(xt), batch_size):
            b = perm[i : i + batch_size]
            loss = ((mean_action(xt[b]) - yt[b]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
        if schedule is not None:
            schedule.step()
        with torch.no_grad():
            rows.append({"epoch": epoch + 1, "mse": float(((mean_action(xt) - yt) ** 2).mean())})
    return mse_start, rows


# -- distilling the planner (DAgger) ------------------------------------------------------------------------------

MAX_ROUND_EPISODES = 2048
"""Episodes one round of :func:`distill` plans at most (the planner rolls out ``samples`` bodies for each)."""


@dataclass(frozen=True, kw_only=True)
class DistillSettings:
    """DAgger of the task's planner (:func:`distill`).

    rounds : int
        Collections of demonstrations: the first executes the planner, each later one the policy fitted so far (the
        planner labels the states that policy visits: Ross, Gordon and Bagnell's DAgger, AISTATS 2011).
    epochs, batch_size, learning_rate : int, int, float
        The fit after each round (:func:`fit_policy_mean` on every pair so far, from the initial weights, the rate
        annealed to 0 along a cosine).
    """

    rounds: int = 5
    epochs: int = 30
    batch_size: int = 512
    learning_rate: float = 1e-3

    def __post_init__(self) -> None:
        validation.integer("rounds", self.rounds, low=1, high=100)
        validation.integer("epochs", self.epochs, low=1, high=10_000)
        validation.integer("batch_size", self.batch_size, low=1, high=1 << 20)
        validation.number("learning_rate", self.learning_rate, low=1e-8, high=1.0)


def distill_config(env_id: str, *, seed: int = 0, overrides: list[str] | None = None, planner: dict | None = None):
    """The run configuration of a policy distilled from ``env_id``'s planner: SB3's PPO entry of the task (its network
    and observation normalisation; :func:`agents.config.resolve`) acting as an additive residual on the law the planner
    perturbs (:data:`agents.planner.LAW_OF_PRIOR`; a planner around no law: the policy acts alone), then ``overrides``:
    the policy learns what the planner adds to the law, as the planner plans it."""
    from agents.config import resolve
    from agents.planner import LAW_OF_PRIOR, settings_for

    residual = LAW_OF_PRIOR[settings_for(env_id, planner).prior]
    form = ["residual=null"] if residual is None else [f"residual={residual}", "residual_mode=additive"]
    return resolve("ppo", env_id, seed=seed, overrides=[*form, *(overrides or [])])


def _demonstrations(env_id, env_kwargs, seeds, planner_settings, planner_seed, label, execute, bar):
    """One round of :func:`distill`: the seeded episodes run together, the planner consulted at every step; returns the
    observations (M, d) of the steps of running episodes, the planner's labels there (``label(obs, action)``, (M, n))
    and the share of episodes that end in success. ``execute(obs)`` acts (None: the planner's own actions)."""
    from agents.planner import Planner
    from flatbody_env.env.registration import task_spec
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    steps = task_spec(env_id).max_episode_steps
    n = len(seeds)
    venv = FlatBodyVectorEnv(num_envs=n, max_episode_steps=steps, **env_kwargs)
    planner = Planner(env_kwargs, n, planner_settings, seed=planner_seed)
    obs, _ = venv.reset(seed=[int(s) for s in seeds])
    seen, labels = [], []
    alive = np.ones(n, dtype=bool)
    success = np.zeros(n, dtype=bool)
    for _ in range(steps):
        a = planner.act(obs, venv.body_params, venv.max_episode_steps - venv.episode_steps)
        seen.append(obs[alive].copy())
        labels.append(label(obs, a)[alive])
        if execute is not None:
            a = execute(obs)
        obs, _, term, trunc, info = venv.step(a)
        done = alive & (term | trunc)
        success[done] = np.asarray(info["is_success"])[done]
        alive &= ~(term | trunc)
        bar.update(1)
        if not alive.any():
            break
    venv.close()
    return np.concatenate(seen), np.concatenate(labels).astype(np.float32), float(success.mean())


def distill(
    config,
    out: str | Path,
    *,
    seeds: tuple[int, int],
    settings: DistillSettings | None = None,
    planner: dict[str, Any] | None = None,
    progress: bool = True,
    force: bool = False,
    command: list[str] | None = None,
) -> dict:
    """Distil the task's planner (:mod:`agents.planner`) into ``config``'s policy by DAgger; write the run folder ``out``.

    The planner plans from the observed state with the true model (on ``FlatBodyAnyBody-v1`` the body's constants the
    policy does not see): a privileged, slow expert — 5,760 body-steps per control step — whose choices a network
    learns to make from the observation alone, at the cost of one forward pass. Round 0 runs the planner on the first
    share of the training episodes (``seeds`` LO:HI split evenly over the rounds); each later round runs the policy
    fitted so far and records what the planner would have done in the states the policy reaches; after each round the
    policy's mean action is fitted to every pair so far (:class:`DistillSettings`). A label is the residual the
    planner adds to the run's law (clip((a_planner − law(obs)) / residual_scale, −1, 1); the policy's action itself
    where the run has no residual), so the run executes the law plus the policy, as the planner does.

    Parameters
    ----------
    config : agents.config.RunConfig
        A PPO run (:func:`distill_config`; or a distilled run's ``config.yml``, which repeats it): its task, network,
        seed (weights, fit, the planner's noise) and residual form (additive, ungated).
    seeds : (int, int)
        LO, HI: the training episodes LO … HI − 1, below the evaluation seeds (:data:`agents.evaluate.EVAL_SEED`).
    planner : dict, optional
        Overrides of the task's planner settings (:func:`agents.planner.parse_overrides`).

    Returns
    -------
    dict
        ``rounds``: one row per round (``round``, ``episodes``, ``executed`` — planner or policy —,
        ``executed_success``, ``pairs`` so far, ``mse`` after the fit); ``pairs``; ``wall_time_s``.
    """
    import copy

    from agents.config import RunConfig
    from agents.evaluate import EVAL_SEED, env_kwargs_for, residual_action
    from agents.planner import label as planner_label
    from agents.planner import settings_for
    from agents.runs import RunFolder
    from agents.train import new_model
    from flatbody_env.env.registration import task_spec
    from flatbody_env.progress import progress_bar

    s = settings or DistillSettings()
    if not isinstance(config, RunConfig) or config.algo != "ppo":
        raise ValueError("config: distil into a PPO run's configuration (agents.imitation.distill_config)")
    lo, hi = (validation.integer("seeds", int(v), low=0, high=EVAL_SEED) for v in seeds)
    if not lo < hi or not s.rounds <= hi - lo <= MAX_ROUND_EPISODES * s.rounds:
        raise ValueError(
            f"seeds: give LO:HI below {EVAL_SEED} with 1 to {MAX_ROUND_EPISODES} episodes per round ({s.rounds} rounds)"
        )
    hp = config.hyperparams
    if hp.get("residual") and (hp.get("residual_mode", "additive") != "additive" or hp.get("residual_gate", 0.0)):
        raise ValueError("hyperparams.residual_mode: distil into an additive, ungated residual (residual_gate 0)")
    scale = float(hp.get("residual_scale", 1.0))
    validation.requirement(
        "hyperparams.residual_scale",
        scale,
        not hp.get("residual") or scale > 0,
        "be > 0 to distil (it scales the label)",
    )
    planner_settings = settings_for(config.env_id, planner)
    run = RunFolder.new(out, force=force)  # before any work: never a folder holding a run, /, or the home folder
    env_kwargs = env_kwargs_for(config.env_id, config.env_kwargs)
    form = residual_action(env_kwargs, hp)

    def label(obs, action):
        if form is None:
            return np.asarray(action, dtype=np.float64)
        law = form.controller.predict(np.asarray(obs, dtype=np.float64))[0]
        return np.clip((np.asarray(action, dtype=np.float64) - law) / scale, -1.0, 1.0)

    import torch

    torch.set_num_threads(1)
    model, venv = new_model(config)
    vecnorm = venv if hasattr(venv, "obs_rms") else None
    initial = copy.deepcopy(model.policy.state_dict())

    def normalised(obs):
        return vecnorm.normalize_obs(obs) if vecnorm is not None and vecnorm.norm_obs else obs

    def execute(obs):
        actions, _ = model.predict(normalised(np.asarray(obs, dtype=np.float32)), deterministic=True)
        return actions if form is None else form(obs, actions)

    steps = task_spec(config.env_id).max_episode_steps
    chunks = np.array_split(np.arange(lo, hi), s.rounds)
    bar = progress_bar(total=s.rounds * steps, desc="distill", unit="step", enabled=progress)
    seen, labels, rows = [], [], []
    t0 = time.perf_counter()
    for r, chunk in enumerate(chunks):
        o, u, ok = _demonstrations(
            config.env_id,
            env_kwargs,
            chunk,
            planner_settings,
            config.seed + r,
            label,
            None if r == 0 else execute,
            bar,
        )
        if r == 0 and vecnorm is not None and vecnorm.norm_obs:
            # the normalisation the network sees: the demonstrations' own statistics (VecNormalize's running ones)
            vecnorm.obs_rms.mean = o.mean(axis=0).astype(np.float64)
            vecnorm.obs_rms.var = o.var(axis=0).astype(np.float64)
            vecnorm.obs_rms.count = float(len(o))
        seen.append(o)
        labels.append(u)
        model.policy.load_state_dict(initial)
        x, y = np.concatenate(seen), np.concatenate(labels)
        _, fit = fit_policy_mean(
            model.policy,
            normalised(x),
            y,
            epochs=s.epochs,
            batch_size=s.batch_size,
            learning_rate=s.learning_rate,
            seed=config.seed,
            anneal=True,
            progress=False,
        )
        rows.append(
            {
                "round": r,
                "episodes": len(chunk),
                "executed": "planner" if r == 0 else "policy",
                "executed_success": ok,
                "pairs": len(x),
                "mse": fit[-1]["mse"],
            }
        )
    bar.close()
    wall = time.perf_counter() - t0
    imitation = {
        "method": "distill",
        "expert": planner_label(planner_settings),
        "planner": asdict(planner_settings),  # every setting, so a later change of the task's planner
        # (agents.planner.PLANNERS) does not change what this config repeats
        "seeds": [lo, hi],
        "rounds": s.rounds,
        "epochs": s.epochs,
        "batch_size": s.batch_size,
        "learning_rate": s.learning_rate,
    }
    config = config.replace(trained_agent=None, curriculum=None, imitation=imitation)
    run.start(config, force=force)  # config.yml, the first file: the folder is trusted from here on
    run.save("model.zip", lambda tmp: model.save(str(tmp)))
    if vecnorm is not None:
        run.save("vecnormalize.pkl", lambda tmp: vecnorm.save(str(tmp)))
    run.write_progress(rows)
    run.write_run(config, timesteps=0, wall_time_s=wall, command=command, pairs=int(len(x)))
    run.export_policy()
    venv.close()
    return {"rounds": rows, "pairs": int(len(x)), "wall_time_s": wall}


def distill_settings_of(config) -> tuple[DistillSettings, dict[str, Any], tuple[int, int]]:
    """What a distilled run's ``config.yml`` says to repeat it (its ``prior.imitation``): the settings, the planner's
    settings (every one, as :func:`agents.planner.settings_for` overrides) and the seeds; ``ValueError`` naming
    ``config.yml`` for any other run."""
    from agents.planner import parse_overrides

    im = config.imitation or {}
    if im.get("method") != "distill":
        raise ValueError("config.yml: not a policy distilled from the planner (prior.imitation.method: distill)")
    try:
        settings = DistillSettings(**{k: im[k] for k in ("rounds", "epochs", "batch_size", "learning_rate")})
        lo, hi = (int(v) for v in im["seeds"])
        planner = parse_overrides([f"{k}={v}" for k, v in dict(im.get("planner") or {}).items()], "planner")
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"config.yml: prior.imitation: {type(exc).__name__}: {str(exc)[:80]}") from None
    return settings, planner, (lo, hi)

"""Train Stable-Baselines3's PPO, SAC and TD3 (and, through :mod:`agents.rsl`, rsl_rl's PPO) on any flatbody task.

``flatbody train --algo ppo|sac|td3|rsl-ppo --env ID`` resolves the run's configuration
(:func:`agents.config.resolve`: the entry of ``ID`` in ``agents/hyperparams/<algo>.yml``, the overrides, each
hyperparameter checked) and trains it into one run folder (:class:`agents.runs.RunFolder`: ``config.yml``,
``run.json``, ``progress.csv``, ``model.zip``, ``vecnormalize.pkl``, ``policy.npz``, rotated checkpoints).
``--resume`` continues a run from its newest checkpoint that loads, with the configuration its ``config.yml`` holds;
``--config FOLDER/config.yml`` trains that configuration again (:func:`train_config`).

Training uses :class:`agents.vec_env.FlatBodySB3VecEnv` (the natively batched env) wrapped in ``VecMonitor`` and
``VecNormalize``; nothing integrator-specific is passed: the env's default integrator runs. The SB3 algorithms train
on the CPU. ``torch.set_num_threads(1)`` by default (``--threads N``; more threads made no run faster and many slower
on a loaded machine: measured figures in docs/agents.md, "One torch thread"). A run is deterministic for a given
seed, configuration and versions on one thread (``--config`` reproduces it bit for bit, tested).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from agents.config import DEFAULT_ENV_ID, SB3_ALGOS, RunConfig, resolve
from agents.runs import RunFolder, TrainResult, stopped

ENV_ID = DEFAULT_ENV_ID
"""The task of :func:`train` when none is named."""
ALGOS = SB3_ALGOS
"""The algorithms this module trains itself (rsl-ppo: :mod:`agents.rsl`)."""
_META_KEYS = (
    "n_timesteps",
    "n_envs",
    "policy",
    "normalize",
    "env_kwargs",
    "residual",
    "residual_scale",
    "residual_gate",
    "residual_mode",
    "success_bonus",
    "precision_bonus",
    "noise_type",
    "noise_std",
    "fine_tune_log_std",
    "critic_warmup",
)
"""Keys of a hyperparameter entry that are not SB3 constructor keywords."""


def _policy_kwargs(raw: dict[str, Any] | None) -> dict[str, Any]:
    import torch

    kw = dict(raw or {})
    act = kw.get("activation_fn")
    if isinstance(act, str):  # checked by agents.config (one of ACTIVATIONS)
        kw["activation_fn"] = {
            "tanh": torch.nn.Tanh,
            "relu": torch.nn.ReLU,
            "elu": torch.nn.ELU,
            "leaky_relu": torch.nn.LeakyReLU,
        }[act]
    return kw


def algo_kwargs_of(hp: dict[str, Any]) -> dict[str, Any]:
    """The SB3 constructor keywords of a checked hyperparameter entry (:func:`agents.config.check_hyperparams`): its
    meta keys removed, the activation's name made a torch module, ``train_freq`` a tuple."""
    algo_kwargs = {k: v for k, v in hp.items() if k not in _META_KEYS}
    algo_kwargs["policy_kwargs"] = _policy_kwargs(algo_kwargs.get("policy_kwargs"))
    if isinstance(algo_kwargs.get("train_freq"), list):
        algo_kwargs["train_freq"] = tuple(algo_kwargs["train_freq"])
    return algo_kwargs


def normalize_of(hp: dict[str, Any]) -> dict[str, Any] | None:
    """The ``VecNormalize`` keywords of a hyperparameter entry's ``normalize`` (``true``: observations and rewards; a
    mapping as given), or None where the run does not normalise."""
    norm = hp.get("normalize") or None
    return {"norm_obs": True, "norm_reward": True} if norm is True else norm


def action_noise(hp: dict[str, Any], action_space):
    """The exploration noise added to SAC's or TD3's actions (``noise_type``: ``normal`` or ``ornstein-uhlenbeck``,
    of standard deviation ``noise_std``, default 0.1), as RL Zoo builds it; None without ``noise_type``."""
    kind = hp.get("noise_type")
    if kind is None:
        return None
    from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

    n = action_space.shape[0]
    std = float(hp.get("noise_std", 0.1)) * np.ones(n)
    cls = NormalActionNoise if kind == "normal" else OrnsteinUhlenbeckActionNoise
    return cls(mean=np.zeros(n), sigma=std)


def make_vec_env(
    n_envs: int,
    seed: int | None,
    env_kwargs: dict[str, Any] | None = None,
    residual: str | None = None,
    success_bonus: float = 0.0,
    residual_scale: float = 1.0,
    residual_gate: float = 0.0,
    precision_bonus: float = 0.0,
    residual_mode: str = "additive",
    env_id: str = ENV_ID,
):
    """``VecMonitor(FlatBodySB3VecEnv(n_envs, seed))`` (the natively batched env) of the task ``env_id``
    (any registered flatbody id, docs/tasks.md: its registered keywords updated by ``env_kwargs``).

    ``residual="heuristic"`` (the LQR; on ``FlatBodyAnyBody-v0`` re-solved for each episode's body from the
    observed constants), ``"passivity"`` (the passivity law) or ``"pumping"`` (the LQR with centrifugal pumping): the policy's actions are residuals added to the hand-designed
    controller's, scaled by ``residual_scale`` and faded out within ``residual_gate`` of the target,
    or (``residual_mode="gain"``) rescale its components (:class:`agents.heuristic.ResidualAction`). ``success_bonus`` > 0: training
    reward + bonus on every step with ``info["is_success"]`` (the task's distance ≤ tolerance), so
    that reaching the target pays; ``precision_bonus`` > 0: training reward
    + precision_bonus · max(0, ln(tolerance / max(d, 1e-6))), so that precision inside the tolerance
    pays too (relative precision: halving d pays the same at every scale);
    VecMonitor sits inside, so logged returns are the task's.
    """
    from stable_baselines3.common.vec_env import VecMonitor

    from agents.vec_env import FlatBodySB3VecEnv

    from agents.evaluate import env_kwargs_for

    env_kwargs = env_kwargs_for(env_id, env_kwargs)
    venv = FlatBodySB3VecEnv(n_envs, seed=seed, **env_kwargs)
    if residual:
        from agents.heuristic import RESIDUAL_BASES, residual_vec_env
        from flatbody_env.physics import validation

        validation.string("residual", residual, choices=RESIDUAL_BASES)

        venv = residual_vec_env(venv, env_kwargs, residual_scale, residual_gate, residual_mode, residual)
    venv = VecMonitor(venv)
    if success_bonus or precision_bonus:
        from flatbody_env.env.env import FlatBodyEnv

        tol = FlatBodyEnv(**(env_kwargs or {})).task.success_tolerance
        venv = _success_bonus(venv, float(success_bonus), float(precision_bonus), tol)
    return venv


def _success_bonus(venv, bonus: float, precision: float = 0.0, tol: float = 0.05):
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class SuccessBonus(VecEnvWrapper):
        """reward + bonus · 1[success] + precision · max(0, ln(tol / distance)) (training only)."""

        def reset(self):
            return self.venv.reset()

        def step_wait(self):
            obs, rewards, dones, infos = self.venv.step_wait()
            rewards = rewards + bonus * np.array([bool(i.get("is_success")) for i in infos], dtype=np.float32)
            if precision:
                d = np.array([i.get("distance", np.inf) for i in infos], dtype=np.float64)
                rewards = rewards + (precision * np.maximum(0.0, np.log(tol / np.maximum(d, 1e-6)))).astype(np.float32)
            return obs, rewards, dones, infos

    return SuccessBonus(venv)


def _algo_class(algo: str):
    from stable_baselines3 import PPO, SAC, TD3

    return {"ppo": PPO, "sac": SAC, "td3": TD3}[algo]


def _load_saved(
    cls,
    model_path: Path,
    vn_path: Path | None,
    env,
    norm,
    where: str,
    custom_objects: dict[str, Any] | None = None,
):
    """A saved model on ``env`` (wrapped in its saved VecNormalize statistics when the run normalises, in training
    mode): the one loading of a resumed checkpoint and of a fine-tuned run, through the one trust check and reading
    door (:func:`agents.numpy_policy.load_sb3`, :func:`~agents.numpy_policy.load_vecnormalize`). ``ValueError``
    naming ``where`` for a file that is missing or cannot be loaded."""
    from agents.numpy_policy import load_sb3, load_vecnormalize

    if norm:
        if vn_path is None or not vn_path.is_file():
            raise ValueError(
                f"{where}: {str(model_path)[:80]!r} has no VecNormalize statistics beside it (this run normalises)"
            )
        env = load_vecnormalize(vn_path, env, where=where)
        env.training = True
    return load_sb3(cls, model_path, where=where, env=env, custom_objects=custom_objects), env


def _load_trained_agent(cls, folder: Path, env, norm, hp: dict[str, Any], algo_kwargs: dict[str, Any], seed: int):
    """The model and (normalised) env of a fine-tuning run (:func:`train`'s ``trained_agent``): the run's weights,
    optimiser state and statistics; this run's rollout and update settings (not its network); with
    ``fine_tune_log_std``, every entry of the policy's log standard deviation (PPO's ``log_std``, gSDE's matrix too)
    set to that value."""
    keep = {k: v for k, v in algo_kwargs.items() if k != "policy_kwargs"}  # the network is the loaded one's
    model, env = _load_saved(
        cls, folder / "model.zip", folder / "vecnormalize.pkl", env, norm, "trained_agent", custom_objects=keep
    )
    if norm:
        env.norm_reward, env.gamma = bool(norm.get("norm_reward", True)), float(hp.get("gamma", 0.99))
    if "fine_tune_log_std" in hp:
        import torch

        with torch.no_grad():
            model.policy.log_std.fill_(float(hp["fine_tune_log_std"]))
    model.set_random_seed(seed)
    return model, env


def actor_parameters(policy) -> list:
    """The parameters of an SB3 actor-critic policy that shape its actions (the actor's layers, the action head and the
    log standard deviation), not the value function's."""
    return [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters(), policy.log_std]


def _critic_warmup_callback(until: int):
    """Hold the actor (:func:`actor_parameters`) fixed while fewer than ``until`` env steps are trained, so that PPO's
    first updates fit the value function to the policy it starts from (a fine-tuned policy is not moved by the
    advantages of an untrained critic); the whole policy trains from the first rollout at or past ``until``."""
    from stable_baselines3.common.callbacks import BaseCallback

    class CriticWarmup(BaseCallback):
        held = False

        def _hold(self, held: bool) -> None:
            for p in actor_parameters(self.model.policy):
                p.requires_grad_(not held)
            self.held = held

        def _on_training_start(self) -> None:
            self._hold(self.model.num_timesteps < until)

        def _on_rollout_start(self) -> None:
            if self.held and self.model.num_timesteps >= until:
                self._hold(False)

        def _on_training_end(self) -> None:
            self._hold(False)

        def _on_step(self) -> bool:
            return True

    return CriticWarmup()


def _progress_callback(total: int, start: int, enabled: bool):
    from stable_baselines3.common.callbacks import BaseCallback

    from flatbody_env.progress import progress_bar

    class TqdmCallback(BaseCallback):
        """A progress bar over environment steps (:func:`flatbody_env.progress.progress_bar`: tqdm on a
        terminal, a line every few seconds otherwise), showing the recent return and success rate."""

        bar = None

        def _on_training_start(self) -> None:
            self.bar = progress_bar(total=total, initial=start, unit="step", enabled=enabled, desc="train")

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs)
            if self.n_calls % 50 == 0:
                buf = self.model.ep_info_buffer
                succ = self.model.ep_success_buffer
                post = {}
                if buf:
                    post["ret"] = f"{sum(e['r'] for e in buf) / len(buf):.1f}"
                if succ:
                    post["succ"] = f"{sum(succ) / len(succ):.2f}"
                self.bar.set_postfix(post, refresh=False)
            return True

        def _on_training_end(self) -> None:
            self.close()

        def close(self) -> None:
            if self.bar is not None:
                self.bar.close()

    return TqdmCallback()


def rollout_steps(algo: str, hp: dict[str, Any]) -> int | None:
    """Environment steps SB3 collects between two looks at the step budget, so the steps trained are
    a multiple of it: PPO's rollout of ``n_envs × n_steps``; SAC's and TD3's ``n_envs × train_freq`` (``train_freq``
    in steps). None where it is not a fixed number of steps (``train_freq`` in episodes)."""
    nenv = int(hp.get("n_envs", 1))
    if algo == "ppo":
        return nenv * int(hp.get("n_steps", 2048))
    freq = hp.get("train_freq", 1)
    if isinstance(freq, (list, tuple)):
        if len(freq) != 2 or str(freq[1]) != "step":
            return None
        freq = freq[0]
    return nenv * int(freq)


def _checkpoint_writers(model, env, norm: bool, algo: str, state: dict | None) -> dict:
    """The files of an SB3 checkpoint (:meth:`agents.runs.RunFolder.save_checkpoint`): VecNormalize statistics, the
    replay buffer of SAC and TD3, a trainer's state (the curriculum's), the model."""
    writers: dict[str, Any] = {}
    if norm:
        writers["vecnormalize"] = lambda tmp: env.save(str(tmp))
    if algo in ("sac", "td3"):
        writers["replay_buffer"] = lambda tmp: model.save_replay_buffer(str(tmp))
    if state is not None:
        writers["state"] = lambda tmp: Path(tmp).write_text(json.dumps(state), encoding="utf-8")
    writers["model"] = lambda tmp: model.save(str(tmp))
    return writers


def _checkpoint_callback(every: int, folder: RunFolder, norm: bool, algo: str, state=None):
    """Save a checkpoint (atomic, through the run folder) every ``every`` calls of the callback (``every × n_envs``
    steps), the newest :data:`agents.runs.KEEP_CHECKPOINTS` kept; ``state()`` (optional) is saved beside it."""
    from stable_baselines3.common.callbacks import BaseCallback

    class AtomicCheckpoints(BaseCallback):
        def _on_step(self) -> bool:
            if self.n_calls % every == 0:
                env = self.model.get_vec_normalize_env()
                writers = _checkpoint_writers(self.model, env, norm, algo, state() if state else None)
                folder.save_checkpoint(int(self.model.num_timesteps), writers)
            return True

    return AtomicCheckpoints()


def _resume_from(cls, candidates: list, env, norm):
    """(model, env, steps, state) of the newest checkpoint of ``candidates`` (:meth:`agents.runs.RunFolder.checkpoints`)
    that loads; a newer one that does not (truncated by a crash, unreadable) is passed over with a one-line note on
    stderr. ``ValueError`` naming ``resume`` when none loads."""
    from agents.numpy_policy import load_replay_buffer
    from flatbody_env.physics import validation

    for k, ckpt in enumerate(candidates):
        try:
            model, wrapped = _load_saved(cls, ckpt.model, ckpt.vecnormalize, env, norm, "resume")
            if ckpt.replay_buffer is not None and hasattr(model, "load_replay_buffer"):
                load_replay_buffer(model, ckpt.replay_buffer)
            state = validation.read_json("resume", ckpt.state) if ckpt.state is not None else None
        except ValueError as exc:
            if k + 1 == len(candidates):
                why = str(exc).removeprefix("resume: ")
                raise ValueError(f"resume: no checkpoint in {ckpt.model.parent} loads (the oldest: {why})") from None
            print(
                f"flatbody: note: checkpoint {ckpt.model.name} cannot be loaded "
                f"({' '.join(str(exc).split())[:160]}); resuming from {candidates[k + 1].model.name}",
                file=sys.stderr,
            )
            continue
        return model, wrapped, ckpt.steps, state
    raise ValueError("resume: no checkpoint")  # unreachable: candidates is not empty


def check_resumed(
    config: RunConfig, folder: RunFolder, *, algo: str | None, env_id: str | None, flag: str = ""
) -> None:
    """Refuse to resume the run in ``folder`` as another algorithm or on another task than its ``config.yml`` says
    (``ValueError`` naming ``{flag}algo`` / ``{flag}env``: ``--env`` on the command line)."""
    from flatbody_env.physics import validation

    for name, given, recorded in (("algo", algo, config.algo), ("env", env_id, config.env_id)):
        validation.requirement(
            f"{flag}{name}",
            given,
            given is None or given == recorded,
            f"be {recorded}, the run in {str(folder.path)[:80]} trains {config.algo} on {config.env_id} "
            f"(leave {flag}{name} out: --resume reads it from config.yml)",
        )


def train(
    algo: str | None,
    out: str | Path,
    *,
    seed: int = 0,
    n_timesteps: int | None = None,
    n_envs: int | None = None,
    overrides: list[str] | None = None,
    hyperparams_file: str | Path | None = None,
    env_id: str | None = None,
    resume: bool = False,
    checkpoint_freq: int = 50_000,
    keep_checkpoints: bool = False,
    threads: int = 1,
    progress: bool = True,
    command: list[str] | None = None,
    extra_callbacks: list | None = None,
    force: bool = False,
    notes: bool = True,
    trained_agent: str | Path | None = None,
    device: str = "cpu",
    curriculum: dict[str, Any] | None = None,
    callback=None,
    evaluations=None,
) -> TrainResult:
    """Train ``algo`` on ``env_id`` (default :data:`ENV_ID`) with its file's hyperparameters and write the run folder
    ``out`` (:func:`agents.config.resolve`, then :func:`train_config`).

    With ``resume``, continue the run in ``out`` from its newest checkpoint instead: its ``config.yml`` says the
    algorithm, task, seed and hyperparameters (``algo`` and ``env_id``, when given, must agree: ``ValueError`` naming
    ``algo`` / ``env``); ``n_timesteps`` may raise the budget. ``trained_agent``: fine-tune from that run folder's
    model (weights, optimiser state, VecNormalize statistics; a trusted folder). ``curriculum``: the settings of
    :func:`agents.curriculum.curriculum_callback`. The other keywords: :func:`train_config`.
    """
    if resume:
        folder = RunFolder.existing(out, where="resume")
        config = folder.config()
        check_resumed(config, folder, algo=algo, env_id=env_id)
        if n_timesteps is not None:
            hp = {**config.hyperparams, "n_timesteps": n_timesteps}
            from agents.config import check_hyperparams

            config = config.replace(hyperparams=check_hyperparams(config.algo, hp, config.env_id))
    else:
        folder = RunFolder.new(out, force=force)  # before anything heavy: a refusal is immediate, nothing written
        config = resolve(
            algo,
            env_id or ENV_ID,
            seed=seed,
            n_timesteps=n_timesteps,
            n_envs=n_envs,
            overrides=overrides,
            hyperparams_file=hyperparams_file,
            device=device,
            trained_agent=trained_agent,
            curriculum=curriculum,
        )
    return train_config(
        config,
        folder,
        resume=resume,
        checkpoint_freq=checkpoint_freq,
        keep_checkpoints=keep_checkpoints,
        threads=threads,
        progress=progress,
        command=command,
        extra_callbacks=extra_callbacks,
        force=force,
        notes=notes,
        callback=callback,
        evaluations=evaluations,
    )


def train_config(
    config: RunConfig,
    folder: RunFolder,
    *,
    resume: bool = False,
    checkpoint_freq: int = 50_000,
    keep_checkpoints: bool = False,
    threads: int = 1,
    progress: bool = True,
    command: list[str] | None = None,
    extra_callbacks: list | None = None,
    force: bool = False,
    notes: bool = True,
    callback=None,
    evaluations=None,
) -> TrainResult:
    """Train the run ``config`` into ``folder`` (rsl-ppo: :func:`agents.rsl.train_rsl`).

    Parameters
    ----------
    checkpoint_freq : int
        Environment steps between checkpoints (0: none). With checkpoints on, a run stopped by Ctrl-C saves one at the
        step it reached and its message names the command that continues it.
    keep_checkpoints : bool
        Keep ``checkpoints/`` after a completed run.
    extra_callbacks : list, optional
        SB3 callbacks added to the run (e.g. the intermediate evaluations of :mod:`agents.tune`).
    callback : callable, optional
        rsl-ppo's per-iteration callback (:func:`agents.rsl.train_rsl`).
    notes : bool
        Say on stderr when ``n_timesteps`` rounds up, and each evaluation's result (False for the many runs of a search
        or sweep).
    evaluations : agents.evaluate.HeldOutEvaluations, optional
        Evaluations of the policy on held-out episodes along the run (``flatbody train --eval-freq``, the benchmark's
        curves), each a row of ``evaluations.csv`` in the run folder (``evaluations-resumed-N.csv`` after a resume);
        their time is left out of the run's wall time.

    Raises
    ------
    KeyboardInterrupt
        Ctrl-C; its message says where the checkpoint was kept and the command that continues the run.
    """
    from flatbody_env.physics import validation

    validation.integer("threads", threads, low=1, high=validation.MAX_WORKERS)
    validation.integer("checkpoint_freq", checkpoint_freq, low=0, high=validation.MAX_TIMESTEPS)
    if not resume:
        from agents.config import fine_tuning

        config = fine_tuning(config)  # the trained agent's policy form; before anything is written
    if config.algo == "rsl-ppo":
        if extra_callbacks:
            raise ValueError("extra_callbacks: SB3 callbacks do not run in rsl-ppo (give callback)")
        from agents.rsl import train_rsl

        return train_rsl(
            config,
            folder,
            resume=resume,
            checkpoint_freq=checkpoint_freq,
            keep_checkpoints=keep_checkpoints,
            threads=threads,
            progress=progress,
            command=command,
            force=force,
            callback=callback,
            evaluations=evaluations,
            notes=notes,
        )
    return _train_sb3(
        config,
        folder,
        resume=resume,
        checkpoint_freq=checkpoint_freq,
        keep_checkpoints=keep_checkpoints,
        threads=threads,
        progress=progress,
        command=command,
        extra_callbacks=extra_callbacks,
        force=force,
        notes=notes,
        evaluations=evaluations,
    )


def _train_sb3(
    config: RunConfig,
    folder: RunFolder,
    *,
    resume: bool,
    checkpoint_freq: int,
    keep_checkpoints: bool,
    threads: int,
    progress: bool,
    command: list[str] | None,
    extra_callbacks: list | None,
    force: bool,
    notes: bool,
    evaluations=None,
) -> TrainResult:
    from flatbody_env.physics import validation

    validation.requirement(
        "device",
        config.device,
        config.device == "cpu",
        f"be cpu for {config.algo} (Stable-Baselines3 trains on the CPU here; rsl-ppo on cuda)",
    )
    from agents.numpy_policy import check_trusted

    hp, algo = config.hyperparams, config.algo
    candidates = []
    if resume:  # the checkpoints are pickles: only from one of your runs, or with --trust
        check_trusted(folder.checkpoint_dir, "the checkpoints (pickle-based SB3 files)", where="resume")
        candidates = folder.checkpoints()
        if not candidates:
            raise ValueError(
                f"resume: no checkpoint in {folder.checkpoint_dir} (a run that completed keeps its checkpoints only "
                "when trained with --keep-checkpoints; train a longer run with a larger --n-timesteps)"
            )
    earlier = folder.previous_wall_time() if resume else 0.0  # the run so far, read up front
    if not resume and config.trained_agent is not None:
        if not (Path(config.trained_agent) / "model.zip").is_file():
            raise ValueError(f"trained_agent: {str(config.trained_agent)[:80]!r} holds no model.zip")
        check_trusted(config.trained_agent, "model.zip and vecnormalize.pkl (pickles)", where="trained_agent")

    import torch

    torch.set_num_threads(threads)
    total, nenv, seed = config.n_timesteps, config.n_envs, config.seed
    norm = normalize_of(hp)
    algo_kwargs = algo_kwargs_of(hp)
    unit = rollout_steps(algo, {**hp, "n_envs": nenv, **algo_kwargs})
    if not resume:
        folder.start(config, force=force)  # config.yml, the first file: the folder is trusted from here on
    env = _vec_env_of(config)
    cls = _algo_class(algo)
    start, resumed_from, state = 0, None, None
    if resume:
        model, env, start, state = _resume_from(cls, candidates, env, norm)
        resumed_from = start
    elif config.trained_agent is not None:
        model, env = _load_trained_agent(cls, Path(config.trained_agent), env, norm, hp, algo_kwargs, seed)
    else:
        model, env = new_model(config, env)
    planned = start + -(-(total - start) // unit) * unit if unit and total > start else max(total, start)
    if planned > total and notes:
        what = "rollouts of n_envs x n_steps" if algo == "ppo" else "collections of n_envs x train_freq"
        print(
            f"flatbody: note: n_timesteps {total} rounds up to {planned} ({algo.upper()} trains whole {what} = "
            f"{nenv} x {unit // nenv} = {unit} steps)",
            file=sys.stderr,
        )
    model.set_logger(folder.progress_logger(f"resumed-{start}" if resume else ""))

    callbacks = [_progress_callback(planned, start, progress), *(extra_callbacks or [])]
    if int(hp.get("critic_warmup", 0)) > start:
        callbacks.append(_critic_warmup_callback(int(hp["critic_warmup"])))
    curriculum = None
    if config.curriculum is not None:
        from agents.curriculum import curriculum_callback

        curriculum = curriculum_callback(
            config.env_id, seed=seed, env_kwargs=config.env_kwargs, **_curriculum_settings(config.curriculum)
        )
        if state is not None:
            curriculum.restore(state)
        callbacks.append(curriculum)
    if checkpoint_freq:
        snapshot = curriculum.state if curriculum is not None else None
        callbacks.append(_checkpoint_callback(max(checkpoint_freq // nenv, 1), folder, bool(norm), algo, snapshot))
    if evaluations is not None:
        from agents.evaluate import env_kwargs_for, residual_action

        evaluations.start(start, folder.evaluations_table(start if resume else None), say=notes)
        callbacks.append(
            evaluations.sb3_callback(residual_action(env_kwargs_for(config.env_id, config.env_kwargs), hp))
        )
    evaluated = evaluations.eval_seconds if evaluations is not None else 0.0
    t0 = time.perf_counter()
    try:
        try:
            model.learn(
                total_timesteps=max(total - start, 0),
                callback=callbacks,
                reset_num_timesteps=not resume,
                progress_bar=False,
            )
        finally:
            model.logger.close()  # progress.csv rewritten with every row (the one writing door)
            if evaluations is not None:
                evaluations.close()
    except KeyboardInterrupt:
        callbacks[0].close()
        steps = int(model.num_timesteps)
        if checkpoint_freq and steps > start:
            writers = _checkpoint_writers(
                model, env, bool(norm), algo, curriculum.state() if curriculum is not None else None
            )
            raise stopped(config, folder, steps, folder.save_checkpoint(steps, writers)) from None
        why = "no step trained yet" if steps <= start else "--checkpoint-freq 0"
        raise stopped(config, folder, steps, None, why) from None
    wall = time.perf_counter() - t0 - ((evaluations.eval_seconds - evaluated) if evaluations is not None else 0.0)

    folder.save("model.zip", lambda tmp: model.save(str(tmp)))  # a killed run leaves the previous model
    if norm:
        folder.save("vecnormalize.pkl", lambda tmp: env.save(str(tmp)))
    if curriculum is not None:  # the stages the run went through, beside its settings
        folder.write_config(config.replace(curriculum={**config.curriculum, "history": curriculum.history}))
    elif resume:  # the budget it was continued to
        folder.write_config(config)
    folder.write_run(
        config,
        timesteps=int(model.num_timesteps),
        wall_time_s=wall + earlier,
        command=command,
        resumed_from=resumed_from,
        threads=threads,
    )
    folder.export_policy()  # policy.npz beside the model: evaluate/demo run it without torch
    folder.finish(keep_checkpoints=keep_checkpoints)
    env.close()
    return TrainResult(out=folder.path, timesteps=int(model.num_timesteps), wall_time_s=wall, resumed_from=resumed_from)


def _vec_env_of(config: RunConfig):
    """The run's training environments (:func:`make_vec_env` with its hyperparameters), before ``VecNormalize``."""
    hp = config.hyperparams
    return make_vec_env(
        config.n_envs,
        config.seed,
        hp.get("env_kwargs"),
        hp.get("residual"),
        float(hp.get("success_bonus", 0.0)),
        float(hp.get("residual_scale", 1.0)),
        float(hp.get("residual_gate", 0.0)),
        float(hp.get("precision_bonus", 0.0)),
        str(hp.get("residual_mode", "additive")),
        env_id=config.env_id,
    )


def new_model(config: RunConfig, env=None):
    """A fresh SB3 model of the run ``config`` (its algorithm and hyperparameters, weights drawn from its seed) and its
    vectorised environment (``env``, or :func:`make_vec_env` of the run's), inside ``VecNormalize`` where the run
    normalises; returns ``(model, env)``. What :func:`train` starts from without a prior, and what
    :func:`agents.imitation.distill` fits."""
    from stable_baselines3.common.vec_env import VecNormalize

    hp = config.hyperparams
    if env is None:
        env = _vec_env_of(config)
    norm = normalize_of(hp)
    if norm:
        env = VecNormalize(env, gamma=float(hp.get("gamma", 0.99)), **norm)
    algo_kwargs = algo_kwargs_of(hp)
    noise = action_noise(hp, env.action_space)
    if noise is not None:
        algo_kwargs["action_noise"] = noise
    model = _algo_class(config.algo)(
        hp.get("policy", "MlpPolicy"), env, seed=config.seed, device="cpu", verbose=0, **algo_kwargs
    )
    return model, env


def _curriculum_settings(curriculum: dict[str, Any]) -> dict[str, Any]:
    """The keywords of :func:`agents.curriculum.curriculum_callback` from a run's ``curriculum`` (its ``history`` left
    out: what a run did, not what it is told)."""
    c = curriculum
    return {
        "key": c["key"],
        "stages": list(c["stages"]),
        "advance_at": c.get("advance_at", 0.8),
        "min_steps": c.get("min_stage_steps", 100_000),
        "max_steps": c.get("max_stage_steps", 500_000),
        "window": c.get("window", 2),
        "train_env_kwargs": c.get("train_env_kwargs") or {},
        "log_std_per_action": c.get("log_std_per_action"),
    }


__all__ = [
    "ALGOS",
    "ENV_ID",
    "action_noise",
    "actor_parameters",
    "algo_kwargs_of",
    "check_resumed",
    "make_vec_env",
    "new_model",
    "normalize_of",
    "rollout_steps",
    "train",
    "train_config",
]

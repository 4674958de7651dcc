"""Train SB3 agents on the flatbody tasks (``FlatBody-v0`` and every id of docs/tasks.md) in the RL-Zoo spirit.

Hyperparameters live in ``agents/hyperparams/<algo>.yml`` keyed by environment id; a run writes,
beside the model::

    OUT/model.zip          the SB3 model
    OUT/vecnormalize.pkl   VecNormalize statistics (when ``normalize`` is set; frozen at evaluation)
    OUT/config.yml         the hyperparameters actually used (after overrides), env id, algo, seed
    OUT/run.json           command line, git hash, versions, wall time, timesteps
    OUT/progress.csv       SB3's training log (episode return, success rate, losses)
    OUT/checkpoints/       periodic checkpoints (model + VecNormalize), the newest KEEP_CHECKPOINTS kept, for
                           ``--resume``; removed after a completed run unless ``--keep-checkpoints``

Every file is written through :mod:`flatbody_env.output` (atomic, no planted link followed): SB3's own writers
are given a temporary name (``model.save``), ``progress.csv`` comes from a logger format of ours and the
checkpoints from a callback of ours. The folder becomes trusted (its pickles load without ``--trust``) once
``config.yml``, the run's first file, is written. Every file read goes through
:mod:`flatbody_env.physics.validation`'s reading door, every pickle through :func:`agents.numpy_policy.read_pickled`.

Training uses :class:`agents.vec_env.FlatBodySB3VecEnv` (the natively batched env) wrapped in
``VecMonitor`` and ``VecNormalize``; nothing integrator-specific is passed: the env's default
integrator runs. ``torch.set_num_threads(1)`` by default (``--threads N``; more threads made no run faster and
many slower on a loaded machine: measured figures in docs/agents.md, "One torch thread").
"""

from __future__ import annotations

import copy
import json
import math
import os
import platform
import re
import shlex
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from flatbody_env.output import atomic_path, atomic_write
from flatbody_env.provenance import git_hash

ENV_ID = "FlatBody-v0"
ALGOS = ("ppo", "sac")
HYPERPARAMS_DIR = Path(__file__).resolve().parent / "hyperparams"
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
)
_ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu")


def load_hyperparams(algo: str, env_id: str = ENV_ID, path: str | Path | None = None) -> dict[str, Any]:
    """The YAML entry of ``env_id`` in ``hyperparams/<algo>.yml`` (or ``path``), deep-copied."""
    if algo not in ALGOS:
        raise ValueError(f"algo: must be one of {', '.join(ALGOS)}, got {algo!r}")
    from flatbody_env.physics import validation

    file = Path(path) if path else HYPERPARAMS_DIR / f"{algo}.yml"
    where = "hyperparams_file" if path else "hyperparams"
    data = validation.read_yaml(where, file) or {}  # the one reading door: bounded, no alias bombs
    if not isinstance(data, dict):
        raise ValueError(f"{where}: {str(file)!r} must hold a mapping of environment ids, got a {type(data).__name__}")
    if not isinstance(data.get(env_id, {}), dict):
        raise ValueError(
            f"{where}: the entry {env_id!r} in {file} must be a mapping, got a {type(data[env_id]).__name__}"
        )
    if env_id not in data:
        raise ValueError(f"env: no hyperparameters for {env_id!r} in {file} (has: {', '.join(data) or 'none'})")
    return copy.deepcopy(data[env_id])


def apply_overrides(hp: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """``key=value`` overrides (value parsed as YAML; dotted keys reach into mappings)."""
    hp = copy.deepcopy(hp)
    for item in overrides:
        if "=" not in item:
            raise ValueError(f"hyperparams: expected key=value, got {item!r}")
        key, text = item.split("=", 1)
        from flatbody_env.physics import validation

        value = validation.parse_yaml(f"hyperparams.{key.strip()[:60]}", text)  # no alias bombs in a value either
        node = hp
        parts = key.strip().split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise ValueError(f"hyperparams: {key!r} reaches into a non-mapping")
        node[parts[-1]] = value
    return hp


def _policy_kwargs(raw: dict[str, Any] | None) -> dict[str, Any]:
    import torch

    kw = dict(raw or {})
    act = kw.get("activation_fn")
    if isinstance(act, str):
        if act not in _ACTIVATIONS:
            raise ValueError(f"policy_kwargs.activation_fn: must be one of {', '.join(_ACTIVATIONS)}, got {act!r}")
        kw["activation_fn"] = {
            "tanh": torch.nn.Tanh,
            "relu": torch.nn.ReLU,
            "elu": torch.nn.ELU,
            "leaky_relu": torch.nn.LeakyReLU,
        }[act]
    return kw


def algo_kwargs_of(hp: dict[str, Any]) -> dict[str, Any]:
    """The SB3 constructor keywords of a hyperparameter entry (its meta keys removed, types fixed)."""
    algo_kwargs = {k: v for k, v in hp.items() if k not in _META_KEYS}
    algo_kwargs["policy_kwargs"] = _policy_kwargs(algo_kwargs.get("policy_kwargs"))
    for key in ("learning_rate", "buffer_size", "learning_starts", "batch_size"):
        if isinstance(algo_kwargs.get(key), str):
            algo_kwargs[key] = float(algo_kwargs[key])
    for key in ("buffer_size", "learning_starts", "batch_size", "n_steps", "n_epochs", "train_freq", "gradient_steps"):
        if key in algo_kwargs and not isinstance(algo_kwargs[key], (list, tuple)):
            algo_kwargs[key] = int(algo_kwargs[key])
    return algo_kwargs


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
    observed constants) or ``"passivity"`` (the passivity law): the policy's actions are residuals added to the hand-designed
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
        if residual not in ("heuristic", "passivity"):
            raise ValueError(f"residual: must be 'heuristic', 'passivity' or empty, got {residual!r}")
        from agents.heuristic import residual_vec_env

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
    from stable_baselines3 import PPO, SAC

    return {"ppo": PPO, "sac": SAC}[algo]


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
    optimiser state and statistics; this run's rollout and update settings (not its network)."""
    keep = {k: v for k, v in algo_kwargs.items() if k != "policy_kwargs"}  # the network is the loaded one's
    model, env = _load_saved(
        cls, folder / "model.zip", folder / "vecnormalize.pkl", env, norm, "trained_agent", custom_objects=keep
    )
    if norm:
        env.norm_reward, env.gamma = bool(norm.get("norm_reward", True)), float(hp.get("gamma", 0.99))
    model.set_random_seed(seed)
    return model, env


KEEP_CHECKPOINTS = 3
"""Checkpoints kept during a run (the newest; older ones are removed as new ones are written): enough that a newest
one damaged by a crash leaves a good one to ``--resume`` from."""


def checkpoints(folder: Path) -> list[tuple[Path, Path | None, Path | None, int]]:
    """(model.zip, vecnormalize.pkl or None, replay_buffer.pkl or None, timesteps) of every checkpoint in ``folder``,
    the newest first (names as :func:`_save_checkpoint` writes them; temporary files are never listed)."""
    if not folder.is_dir():
        return []
    found = []
    for f in folder.glob("rl_model_*_steps.zip"):
        m = re.fullmatch(r"rl_model_(\d+)_steps\.zip", f.name)
        if m:
            steps = int(m.group(1))
            vn = folder / f"rl_model_vecnormalize_{steps}_steps.pkl"
            rb = folder / f"rl_model_replay_buffer_{steps}_steps.pkl"
            found.append((f, (vn if vn.exists() else None), (rb if rb.exists() else None), steps))
    return sorted(found, key=lambda c: -c[3])


@dataclass
class TrainResult:
    out: Path
    timesteps: int
    wall_time_s: float
    resumed_from: int | None


def _csv_logger(folder: Path):
    """SB3's logger writing ``folder/progress.csv`` through the one writing door (:func:`flatbody_env.output.write_csv`:
    atomic, no planted link followed) instead of SB3's own CSV format, which writes into the final name as it goes.

    The table is kept in memory and the file rewritten after a dump once the last rewrite is a while ago (at least
    2 s, and ten times as long as the rewrite took, so the cost stays a small share of the run however long it is),
    and when the logger is closed: a killed run leaves the table of its last rewrite, never a half-written file.
    Columns are added, in sorted order, as they appear; earlier rows leave them empty (as SB3's format does)."""
    from stable_baselines3.common.logger import KVWriter, Logger, filter_excluded_keys

    from flatbody_env.output import write_csv

    class AtomicCSV(KVWriter):
        def __init__(self, path: Path) -> None:
            self.path, self.keys, self.rows = path, [], []
            self.written, self.cost, self.dirty = -math.inf, 0.0, False

        def write(self, key_values, key_excluded, step: int = 0) -> None:
            values = filter_excluded_keys(key_values, key_excluded, "csv")
            self.keys.extend(sorted(k for k in values if k not in self.keys))
            self.rows.append({k: v for k, v in values.items() if v is not None})
            self.dirty = True
            if time.monotonic() - self.written >= max(2.0, 10.0 * self.cost):
                self.flush()

        def flush(self) -> None:
            if not self.dirty:
                return
            t0 = time.monotonic()
            write_csv(self.path, self.keys, ([row.get(k, "") for k in self.keys] for row in self.rows))
            self.written, self.dirty = time.monotonic(), False
            self.cost = self.written - t0

        def close(self) -> None:
            self.flush()

    folder.mkdir(parents=True, exist_ok=True)
    return Logger(folder=str(folder), output_formats=[AtomicCSV(folder / "progress.csv")])


def _checkpoint_callback(every: int, folder: Path, norm: bool, algo: str, keep: int = KEEP_CHECKPOINTS):
    """Save a checkpoint (:func:`_save_checkpoint`: atomic, through the one writing door) every ``every`` calls of the
    callback (``every × n_envs`` steps) and keep the ``keep`` newest (SB3's ``CheckpointCallback`` wrote into the final
    names, so a run killed mid-write left a truncated newest checkpoint)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class AtomicCheckpoints(BaseCallback):
        def _on_step(self) -> bool:
            if self.n_calls % every == 0:
                _save_checkpoint(self.model, self.model.get_vec_normalize_env(), folder, norm, algo)
                _rotate_checkpoints(folder, keep)
            return True

    return AtomicCheckpoints()


def _rotate_checkpoints(folder: Path, keep: int) -> None:
    """Remove all but the ``keep`` newest checkpoints in ``folder``: every file of a checkpoint (SB3's model, statistics
    and replay buffer ``rl_model_[KIND_]N_steps.*``, rsl-ppo's ``rsl_model_N_steps.pt``), grouped by its step count N."""
    steps: dict[int, list[Path]] = {}
    for f in folder.glob("*_steps.*") if folder.is_dir() else ():
        m = re.fullmatch(r"rs?l_model_(?:[a-z_]+_)?(\d+)_steps\.(?:zip|pkl|pt)", f.name)
        if m:
            steps.setdefault(int(m.group(1)), []).append(f)
    for n in sorted(steps, reverse=True)[keep:]:
        for f in steps[n]:
            f.unlink(missing_ok=True)


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
    a multiple of it: PPO's rollout of ``n_envs × n_steps``; SAC's ``n_envs × train_freq`` (``train_freq``
    in steps). None where it is not a fixed number of steps (SAC with ``train_freq`` in episodes)."""
    nenv = int(hp.get("n_envs", 1))
    if algo == "ppo":
        return nenv * int(hp.get("n_steps", 2048))
    freq = hp.get("train_freq", 1)
    if isinstance(freq, (list, tuple)):
        if len(freq) != 2 or str(freq[1]) != "step":
            return None
        freq = freq[0]
    return nenv * int(freq)


def check_out(out: str | Path, *, force: bool = False) -> Path:
    """``out`` as a Path when a new training run may be written there.

    Raises
    ------
    ValueError
        ``out`` can never be trusted (:func:`agents.numpy_policy.trust_refusal`: ``/``, the home folder or a folder
        above it), or ``out`` is the shipped agent's folder (``agents/models/…``), or already holds a run (its
        ``model.zip``, ``config.yml``, ``run.json`` or ``checkpoints/``), and ``force`` is False: one
        line naming the folder and saying that ``--force`` overwrites it.
    """
    from agents.numpy_policy import trust_refusal

    out = Path(out)
    reason = trust_refusal(out)
    if reason is not None:  # the run would make the folder trusted (agents.numpy_policy.remember_run)
        raise ValueError(
            f"out: {str(out)[:80]!r} {reason}; a run's folder becomes trusted (its pickles load without --trust), "
            "so give the run a folder of its own, e.g. runs/ppo"
        )
    shipped = Path(__file__).resolve().parent / "models"
    if not force:
        if out.resolve().is_relative_to(shipped):
            raise ValueError(
                f"out: {str(out)!r} is the shipped agent's folder; --force overwrites it "
                "(or give another --out, e.g. runs/ppo)"
            )
        held = [name for name in ("model.zip", "config.yml", "run.json", "checkpoints") if (out / name).exists()]
        if held:
            raise ValueError(
                f"out: {str(out)!r} already holds a training run ({', '.join(held)}); --force overwrites it "
                "(--resume continues it)"
            )
    return out


def _save_checkpoint(model, env, folder: Path, norm: bool, algo: str) -> Path:
    """Save ``model`` (and its VecNormalize statistics, SAC's replay buffer) as the checkpoint of its
    current step count in ``folder``, under the names :func:`checkpoints` reads, each file atomically
    (:func:`flatbody_env.output.atomic_path`) and the model last: a checkpoint whose model is there is whole."""
    steps = int(model.num_timesteps)
    folder.mkdir(parents=True, exist_ok=True)
    if norm:
        with atomic_path(folder / f"rl_model_vecnormalize_{steps}_steps.pkl") as tmp:
            env.save(str(tmp))
    if algo == "sac" and hasattr(model, "save_replay_buffer"):
        with atomic_path(folder / f"rl_model_replay_buffer_{steps}_steps.pkl") as tmp:
            model.save_replay_buffer(str(tmp))
    with atomic_path(folder / f"rl_model_{steps}_steps.zip") as tmp:
        model.save(str(tmp))
    return folder / f"rl_model_{steps}_steps.zip"


def _wall_time(run: dict) -> float:
    """The ``wall_time_s`` of an earlier ``run.json`` (0 when it has none that is a finite number >= 0)."""
    value = run.get("wall_time_s", 0.0)
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value >= 0
    return float(value) if ok else 0.0


def _resume_from(cls, candidates: list, env, norm):
    """(model, env, steps) of the newest checkpoint of ``candidates`` (:func:`checkpoints`) that loads; a newer one that
    does not (truncated by a crash, unreadable) is passed over with a one-line note on stderr. ``ValueError`` naming
    ``resume`` when none loads."""
    from agents.numpy_policy import load_replay_buffer

    for k, (model_path, vn_path, rb_path, steps) in enumerate(candidates):
        try:
            model, wrapped = _load_saved(cls, model_path, vn_path, env, norm, "resume")
            if rb_path is not None and hasattr(model, "load_replay_buffer"):
                load_replay_buffer(model, rb_path)
        except ValueError as exc:
            if k + 1 == len(candidates):
                why = str(exc).removeprefix("resume: ")
                raise ValueError(f"resume: no checkpoint in {model_path.parent} loads (the oldest: {why})") from None
            print(
                f"flatbody: note: checkpoint {model_path.name} cannot be loaded "
                f"({' '.join(str(exc).split())[:160]}); resuming from {candidates[k + 1][0].name}",
                file=sys.stderr,
            )
            continue
        return model, wrapped, steps
    raise ValueError("resume: no checkpoint")  # unreachable: candidates is not empty


def train(
    algo: str,
    out: str | Path,
    *,
    seed: int = 0,
    n_timesteps: int | None = None,
    n_envs: int | None = None,
    overrides: list[str] | None = None,
    hyperparams_file: str | Path | None = None,
    env_id: str = ENV_ID,
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
) -> TrainResult:
    """Train ``algo`` on ``env_id`` with the YAML hyperparameters and save everything in ``out``.

    Parameters
    ----------
    n_timesteps : int, optional
        Environment steps; SB3 trains a whole number of :func:`rollout_steps`, so it rounds up
        (one line on stderr says so, unless ``notes`` is False).
    checkpoint_freq : int
        Environment steps between checkpoints (0: none). With checkpoints on, a run stopped by
        Ctrl-C saves one at the step it reached (``--resume`` continues from it).
    resume : bool
        Continue from the newest checkpoint in ``out/checkpoints`` (same hyperparameters: the
        saved ``config.yml`` is used) up to the total ``n_timesteps``.
    extra_callbacks : list, optional
        SB3 callbacks added to the run (e.g. the intermediate evaluations of :mod:`agents.tune`).
    trained_agent : str or Path, optional
        Fine-tune: start from this run folder's ``model.zip`` (weights and optimiser state) and its
        ``vecnormalize.pkl`` instead of a fresh policy (RL Zoo's ``--trained-agent``); the rollout
        and update settings are this run's hyperparameters. Unpickles, so the folder must be trusted
        (:func:`agents.numpy_policy.check_trusted`). Not with ``resume``.
    force : bool
        Train into ``out`` even if it holds a run or is the shipped agent (:func:`check_out`); the
        old run's checkpoints are removed first.
    notes : bool
        Say on stderr when ``n_timesteps`` rounds up (False for the many runs of a search or sweep).

    Raises
    ------
    KeyboardInterrupt
        Ctrl-C; its message says where the checkpoint was kept.
    """
    from flatbody_env.env.registration import task_spec

    task_spec(env_id)  # ValueError naming env for an id that is not a registered flatbody task
    out = Path(out) if resume else check_out(out, force=force)  # before the heavy imports: a refusal is immediate
    from agents.numpy_policy import check_trusted, read_run_config, remember_run

    ckpt_dir = out / "checkpoints"
    if resume:  # the checkpoints are pickles: only from one of your runs, or with --trust
        check_trusted(ckpt_dir, "the checkpoints (pickle-based SB3 files)", where="resume")
    elif trained_agent is not None:
        if not (Path(trained_agent) / "model.zip").is_file():
            raise ValueError(f"trained_agent: {str(trained_agent)[:80]!r} holds no model.zip")
        check_trusted(trained_agent, "model.zip and vecnormalize.pkl (pickles)", where="trained_agent")

    import torch
    from stable_baselines3.common.vec_env import VecNormalize

    if not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads: must be an integer >= 1, got {threads!r}")
    torch.set_num_threads(threads)
    resumed_from = None
    previous: dict[str, Any] = {}
    if resume:
        candidates = checkpoints(ckpt_dir)
        if not candidates:
            raise ValueError(f"resume: no checkpoint in {ckpt_dir}")
        cfg = read_run_config(out)  # the one reading door (config.yml: bounded, no alias bombs)
        if not cfg:
            raise ValueError(f"resume: {str(out)[:80]!r} holds no config.yml (the run's hyperparameters)")
        if cfg.get("algo") != algo:
            raise ValueError(f"algo: the run in {out} was trained with {cfg.get('algo')!r}, not {algo!r}")
        hp = cfg.get("hyperparams")
        if not isinstance(hp, dict):
            raise ValueError("config.yml.hyperparams: missing (the run's hyperparameters)")
        from flatbody_env.physics import validation

        seed = validation.integer("config.yml.seed", cfg.get("seed"), low=0, high=validation.MAX_SEED)
        if n_timesteps is not None:
            hp["n_timesteps"] = int(n_timesteps)
        if (out / "run.json").exists():  # the run so far (its wall time adds up), read through the door up front
            previous = validation.read_json("run.json", out / "run.json")
            previous = previous if isinstance(previous, dict) else {}
    else:
        hp = apply_overrides(load_hyperparams(algo, env_id, hyperparams_file), overrides or [])
        if n_timesteps is not None:
            hp["n_timesteps"] = int(n_timesteps)
        if n_envs is not None:
            hp["n_envs"] = int(n_envs)
    total = int(float(hp["n_timesteps"]))
    nenv = int(hp.get("n_envs", 1))
    if total < 1 or nenv < 1:
        raise ValueError(f"n_timesteps, n_envs: must be >= 1, got {total}, {nenv}")
    norm = hp.get("normalize") or None
    if norm is True:
        norm = {"norm_obs": True, "norm_reward": True}
    algo_kwargs = algo_kwargs_of(hp)
    unit = rollout_steps(algo, {**hp, "n_envs": nenv, **algo_kwargs})

    if force and not resume and ckpt_dir.exists():
        shutil.rmtree(ckpt_dir)  # an old run's checkpoints would be what a later --resume continues
    out.mkdir(parents=True, exist_ok=True)
    env = make_vec_env(
        nenv,
        seed,
        hp.get("env_kwargs"),
        hp.get("residual"),
        float(hp.get("success_bonus", 0.0)),
        float(hp.get("residual_scale", 1.0)),
        float(hp.get("residual_gate", 0.0)),
        float(hp.get("precision_bonus", 0.0)),
        str(hp.get("residual_mode", "additive")),
        env_id=env_id,
    )
    cls = _algo_class(algo)
    start = 0
    if resume:
        model, env, start = _resume_from(cls, candidates, env, norm)
        resumed_from = start
    else:
        if trained_agent is not None:
            model, env = _load_trained_agent(cls, Path(trained_agent), env, norm, hp, algo_kwargs, seed)
            cfg = {"env_id": env_id, "algo": algo, "seed": seed, "hyperparams": hp, "trained_agent": str(trained_agent)}
        else:
            if norm:
                env = VecNormalize(env, gamma=float(hp.get("gamma", 0.99)), **norm)
            model = cls(hp.get("policy", "MlpPolicy"), env, seed=seed, device="cpu", verbose=0, **algo_kwargs)
            cfg = {"env_id": env_id, "algo": algo, "seed": seed, "hyperparams": hp}
        atomic_write(out / "config.yml", yaml.safe_dump(cfg, sort_keys=False))
        remember_run(out)  # the run's first file is in place: its folder is this user's (docs/reliability.md)
    planned = (
        start + -(-(total - start) // unit) * unit if unit and total > start else max(total, start)
    )  # what SB3 will train
    if planned > total and notes:
        what = "rollouts of n_envs x n_steps" if algo == "ppo" else "collections of n_envs x train_freq"
        print(
            f"flatbody: note: n_timesteps {total} rounds up to {planned} ({algo.upper()} trains whole {what} = "
            f"{nenv} x {unit // nenv} = {unit} steps)",
            file=sys.stderr,
        )
    model.set_logger(_csv_logger(out if not resume else out / f"resumed-{start}"))

    bar = _progress_callback(planned, start, progress)
    callbacks = [bar, *(extra_callbacks or [])]
    if checkpoint_freq and checkpoint_freq > 0:
        callbacks.append(_checkpoint_callback(max(checkpoint_freq // nenv, 1), ckpt_dir, bool(norm), algo))
    t0 = time.perf_counter()
    remaining = max(total - start, 0)
    try:
        try:
            model.learn(
                total_timesteps=remaining, callback=callbacks, reset_num_timesteps=not resume, progress_bar=False
            )
        finally:
            model.logger.close()  # progress.csv rewritten with every row (the one writing door)
    except KeyboardInterrupt:
        bar.close()
        steps = int(model.num_timesteps)
        if checkpoint_freq and checkpoint_freq > 0 and steps > start:
            kept = _save_checkpoint(model, env, ckpt_dir, bool(norm), algo)
            _rotate_checkpoints(ckpt_dir, KEEP_CHECKPOINTS)
            raise KeyboardInterrupt(
                f"training stopped at {steps} steps; checkpoint {kept}: "
                f"flatbody train --algo {algo} --out {out} --resume continues"
            ) from None
        why = "no step trained yet" if steps <= start else "--checkpoint-freq 0"
        raise KeyboardInterrupt(f"training stopped at {steps} steps; no checkpoint saved ({why})") from None
    wall = time.perf_counter() - t0

    with atomic_path(out / "model.zip") as tmp:  # a killed run leaves the previous model, never half of one
        model.save(str(tmp))
    if norm:
        with atomic_path(out / "vecnormalize.pkl") as tmp:
            env.save(str(tmp))
    import gymnasium
    import numpy
    import stable_baselines3

    run = {
        "command": command if command is not None else [sys.executable, *sys.argv],
        "command_line": shlex.join(command if command is not None else sys.argv),
        "git_hash": git_hash(),
        "env_id": env_id,
        "algo": algo,
        "seed": seed,
        "n_timesteps": int(model.num_timesteps),
        "n_envs": nenv,
        "torch_threads": threads,
        "wall_time_s": round(wall + _wall_time(previous), 1),
        "resumed_from": resumed_from,
        "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "versions": {
            "python": platform.python_version(),
            "numpy": numpy.__version__,
            "gymnasium": gymnasium.__version__,
            "stable_baselines3": stable_baselines3.__version__,
            "torch": torch.__version__,
        },
        "cpu_count": os.cpu_count(),
    }
    atomic_write(out / "run.json", json.dumps(run, indent=2) + "\n")
    from agents.numpy_policy import export_policy

    try:
        export_policy(out)  # policy.npz beside the model: evaluate/demo run it without torch
    except ValueError as exc:  # a policy the numpy evaluator cannot run: evaluate/demo fall back to SB3
        print(f"note: no numpy policy exported ({exc}); evaluate and demo will use SB3", file=sys.stderr)
    if ckpt_dir.exists() and not keep_checkpoints:
        shutil.rmtree(ckpt_dir)
    env.close()
    return TrainResult(out=out, timesteps=int(model.num_timesteps), wall_time_s=wall, resumed_from=resumed_from)

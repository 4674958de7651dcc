"""Train SB3 agents on ``FlatBody-v0`` in the RL-Zoo spirit.

Hyperparameters live in ``agents/hyperparams/<algo>.yml`` keyed by environment id; a run writes,
beside the model::

    OUT/model.zip          the SB3 model
    OUT/vecnormalize.pkl   VecNormalize statistics (when ``normalize`` is set; frozen at evaluation)
    OUT/config.yml         the hyperparameters actually used (after overrides), env id, algo, seed
    OUT/run.json           command line, git hash, versions, wall time, timesteps
    OUT/progress.csv       SB3's training log (episode return, success rate, losses)
    OUT/checkpoints/       periodic checkpoints (model + VecNormalize) for ``--resume``;
                           removed after a completed run unless ``--keep-checkpoints``

Training uses :class:`agents.vec_env.FlatBodySB3VecEnv` (the natively batched env) wrapped in
``VecMonitor`` and ``VecNormalize``; nothing integrator-specific is passed: the env's default
integrator runs. ``torch.set_num_threads(1)`` by default (ECOSYSTEM.md: more threads are slower
on a loaded 2-core machine).
"""

from __future__ import annotations

import copy
import json
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from flatbody_env.output import atomic_path, atomic_write

ENV_ID = "FlatBody-v0"
ALGOS = ("ppo", "sac")
HYPERPARAMS_DIR = Path(__file__).resolve().parent / "hyperparams"
_META_KEYS = ("n_timesteps", "n_envs", "policy", "normalize", "env_kwargs", "residual", "residual_scale", "residual_gate", "residual_mode", "success_bonus", "precision_bonus")
_ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu")


def load_hyperparams(algo: str, env_id: str = ENV_ID, path: str | Path | None = None) -> dict[str, Any]:
    """The YAML entry of ``env_id`` in ``hyperparams/<algo>.yml`` (or ``path``), deep-copied."""
    if algo not in ALGOS:
        raise ValueError(f"algo: must be one of {', '.join(ALGOS)}, got {algo!r}")
    file = Path(path) if path else HYPERPARAMS_DIR / f"{algo}.yml"
    if not file.exists():
        raise ValueError(f"hyperparams: no file {str(file)!r}")
    data = yaml.safe_load(file.read_text(encoding="utf-8")) or {}
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
        value = yaml.safe_load(text)
        node = hp
        parts = key.strip().split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise ValueError(f"hyperparams: {key!r} reaches into a non-mapping")
        node[parts[-1]] = value
    return hp


def git_hash(where: Path | None = None) -> str:
    """``git rev-parse HEAD`` of the source tree ("unknown" outside a repository)."""
    cwd = where or Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() if out.returncode == 0 and out.stdout.strip() else "unknown"


def _policy_kwargs(raw: dict[str, Any] | None) -> dict[str, Any]:
    import torch

    kw = dict(raw or {})
    act = kw.get("activation_fn")
    if isinstance(act, str):
        if act not in _ACTIVATIONS:
            raise ValueError(f"policy_kwargs.activation_fn: must be one of {', '.join(_ACTIVATIONS)}, got {act!r}")
        kw["activation_fn"] = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU, "leaky_relu": torch.nn.LeakyReLU}[act]
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


def make_vec_env(n_envs: int, seed: int | None, env_kwargs: dict[str, Any] | None = None, residual: str | None = None,
                 success_bonus: float = 0.0, residual_scale: float = 1.0, residual_gate: float = 0.0,
                 precision_bonus: float = 0.0, residual_mode: str = "additive"):
    """``VecMonitor(FlatBodySB3VecEnv(n_envs, seed))`` (the natively batched env).

    ``residual="heuristic"``: the policy's actions are residuals added to the hand-designed
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

    venv = FlatBodySB3VecEnv(n_envs, seed=seed, **(env_kwargs or {}))
    if residual:
        if residual != "heuristic":
            raise ValueError(f"residual: must be 'heuristic' or empty, got {residual!r}")
        from agents.heuristic import residual_vec_env

        venv = residual_vec_env(venv, env_kwargs, residual_scale, residual_gate, residual_mode)
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


def latest_checkpoint(folder: Path) -> tuple[Path, Path | None, Path | None, int] | None:
    """(model.zip, vecnormalize.pkl or None, replay_buffer.pkl or None, timesteps) of the newest checkpoint."""
    if not folder.is_dir():
        return None
    best = None
    for f in folder.glob("rl_model_*_steps.zip"):
        m = re.fullmatch(r"rl_model_(\d+)_steps\.zip", f.name)
        if m and (best is None or int(m.group(1)) > best[1]):
            best = (f, int(m.group(1)))
    if best is None:
        return None
    f, steps = best
    vn = folder / f"rl_model_vecnormalize_{steps}_steps.pkl"
    rb = folder / f"rl_model_replay_buffer_{steps}_steps.pkl"
    return f, (vn if vn.exists() else None), (rb if rb.exists() else None), steps


@dataclass
class TrainResult:
    out: Path
    timesteps: int
    wall_time_s: float
    resumed_from: int | None


def _progress_callback(total: int, start: int, enabled: bool):
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm.auto import tqdm

    class TqdmCallback(BaseCallback):
        """tqdm over environment steps, showing the recent return and success rate."""

        def _on_training_start(self) -> None:
            self.bar = tqdm(total=total, initial=start, unit="step", disable=not enabled, dynamic_ncols=True, desc="train")

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
            self.bar.close()

    return TqdmCallback()


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
) -> TrainResult:
    """Train ``algo`` on ``env_id`` with the YAML hyperparameters and save everything in ``out``.

    Parameters
    ----------
    checkpoint_freq : int
        Environment steps between checkpoints (0: none).
    resume : bool
        Continue from the newest checkpoint in ``out/checkpoints`` (same hyperparameters: the
        saved ``config.yml`` is used) up to the total ``n_timesteps``.
    extra_callbacks : list, optional
        SB3 callbacks added to the run (e.g. the intermediate evaluations of :mod:`agents.tune`).
    """
    import torch
    from stable_baselines3.common.callbacks import CheckpointCallback
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import VecNormalize

    if env_id != ENV_ID:
        raise ValueError(f"env: only {ENV_ID} is supported, got {env_id!r}")
    if not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads: must be an integer >= 1, got {threads!r}")
    torch.set_num_threads(threads)
    out = Path(out)
    ckpt_dir = out / "checkpoints"
    resumed_from = None
    if resume:
        found = latest_checkpoint(ckpt_dir)
        if found is None:
            raise ValueError(f"resume: no checkpoint in {ckpt_dir}")
        cfg = yaml.safe_load((out / "config.yml").read_text(encoding="utf-8"))
        if cfg["algo"] != algo:
            raise ValueError(f"algo: the run in {out} was trained with {cfg['algo']!r}, not {algo!r}")
        hp = cfg["hyperparams"]
        seed = cfg["seed"]
        if n_timesteps is not None:
            hp["n_timesteps"] = int(n_timesteps)
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

    out.mkdir(parents=True, exist_ok=True)
    env = make_vec_env(nenv, seed, hp.get("env_kwargs"), hp.get("residual"), float(hp.get("success_bonus", 0.0)), float(hp.get("residual_scale", 1.0)),
                         float(hp.get("residual_gate", 0.0)), float(hp.get("precision_bonus", 0.0)),
                         str(hp.get("residual_mode", "additive")))
    cls = _algo_class(algo)
    start = 0
    if resume:
        model_path, vn_path, rb_path, start = found
        if norm:
            if vn_path is None:
                raise ValueError(f"resume: checkpoint {model_path.name} has no VecNormalize statistics beside it")
            env = VecNormalize.load(str(vn_path), env)
            env.training = True
        model = cls.load(str(model_path), env=env, device="cpu")
        if rb_path is not None and hasattr(model, "load_replay_buffer"):
            model.load_replay_buffer(str(rb_path))
        resumed_from = start
    else:
        if norm:
            env = VecNormalize(env, gamma=float(hp.get("gamma", 0.99)), **norm)
        model = cls(hp.get("policy", "MlpPolicy"), env, seed=seed, device="cpu", verbose=0, **algo_kwargs)
        cfg = {"env_id": env_id, "algo": algo, "seed": seed, "hyperparams": hp}
        atomic_write(out / "config.yml", yaml.safe_dump(cfg, sort_keys=False))
    model.set_logger(configure(str(out), ["csv"]) if not resume else configure(str(out / f"resumed-{start}"), ["csv"]))

    callbacks = [_progress_callback(total, start, progress), *(extra_callbacks or [])]
    if checkpoint_freq and checkpoint_freq > 0:
        callbacks.append(
            CheckpointCallback(
                save_freq=max(checkpoint_freq // nenv, 1),
                save_path=str(ckpt_dir),
                name_prefix="rl_model",
                save_vecnormalize=bool(norm),
                save_replay_buffer=algo == "sac",
            )
        )
    t0 = time.perf_counter()
    remaining = max(total - start, 0)
    model.learn(total_timesteps=remaining, callback=callbacks, reset_num_timesteps=not resume, progress_bar=False)
    wall = time.perf_counter() - t0

    with atomic_path(out / "model.zip") as tmp:  # a killed run leaves the previous model, never half of one
        model.save(str(tmp))
    if norm:
        with atomic_path(out / "vecnormalize.pkl") as tmp:
            env.save(str(tmp))
    previous = {}
    if resume and (out / "run.json").exists():
        previous = json.loads((out / "run.json").read_text(encoding="utf-8"))
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
        "wall_time_s": round(wall + float(previous.get("wall_time_s", 0.0)), 1),
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

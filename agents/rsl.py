"""PPO from rsl_rl (Isaac Lab's trainer) on :class:`~flatbody_env.env.torch_vector_env.FlatBodyTorchVectorEnv`.

``flatbody train --algo rsl-ppo`` (:func:`train_rsl`): the same residual policy learning on the LQR as the SB3
path (:class:`agents.heuristic.ResidualAction`, ``residual_mode`` ``gain`` or ``additive``), with the env, the
LQR residual and the policy's tensors on one torch device, and no hand-written PPO. Pieces:

* :class:`TorchResidual` — the executed action of a residual agent, batched in torch on the env's device:
  a_LQR = clip(−K (x − x*), −1, 1) with the gain K (N, k, 9) of each body's target, then
  clip(a_LQR (1 + s·a)) (gain mode) or clip(a_LQR + s·a) (additive). K is refreshed only for the bodies
  whose target changed (a reset), from :meth:`agents.heuristic.HeuristicController.gains` (the shipped
  table); the control law of every step runs on the device. Equal to ``ResidualAction`` to float32 round-off (tested).
* :class:`RslVecEnv` — rsl_rl's ``VecEnv`` contract over the torch vector env (SAME_STEP autoreset, so
  ``dones`` never hides a fake transition; ``extras["time_outs"]`` = the truncations, for rsl_rl's
  bootstrapping; ``episode_length_buf`` is the env's episode clocks, so rsl_rl's ``init_at_random_ep_len``
  staggers them).
* :class:`HeldGaussianDistribution` — rsl_rl's Gaussian action distribution with the exploration noise held for
  ``noise_hold_steps`` rollout steps (temporally correlated exploration, as SB3's gSDE); ``normalize_reward``
  divides the training rewards by the running std of the discounted returns (SB3's ``VecNormalize``).
* :func:`live_policy` — the training actor as a batch policy of :func:`agents.evaluate.run_episodes` (the
  evaluations of ``flatbody bench train --to-goal``, through ``train_rsl``'s ``callback``).
* ``residual: null`` (:data:`FROM_SCRATCH`): no LQR — the policy's output clipped to [−1, 1] is the control;
  :func:`from_scratch_curve` trains it for a wall-time budget and writes its held-out success and final distance
  against wall time, :func:`plot_curve` draws that table (docs/agents.md, "From scratch").
* :func:`export_sb3` — the trained actor as an SB3 ``PPO`` ``model.zip`` (same MLP; rsl_rl's observation
  normaliser folded into the first layer, exactly), so ``flatbody evaluate`` and ``demo`` run it unchanged
  (``config.yml`` says ``algo: ppo``, the format of the model file, and ``trainer: rsl-ppo``).

The run folder is the SB3 path's (agents/train.py): ``model.zip``, ``config.yml`` (env id, algo, seed,
hyperparameters, trainer), ``run.json`` (command, git hash, versions, wall time), ``progress.csv`` (one row per
PPO iteration), ``policy.npz`` (the numpy policy), plus ``rsl_model.pt`` (rsl_rl's own checkpoint) and, while the
run goes on, ``checkpoints/rsl_model_N_steps.pt`` every ``checkpoint_freq`` steps (the newest kept; every file
written atomically through :mod:`flatbody_env.output`).
"""

from __future__ import annotations

import json
import math
import os
import platform
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

RSL_RL_VERSION = "5.5.1"
"""The rsl_rl release this trainer is written against (pinned in pyproject.toml: ``rsl-rl-lib``)."""
ALGO = "rsl-ppo"
DEVICES = ("cpu", "cuda")

DEFAULTS: dict[str, Any] = {
    "n_timesteps": 1_000_000,
    "n_envs": 256,
    # the executed action: the LQR's, scheduled by the policy (agents/heuristic.py ResidualAction; as the SB3 agent)
    "residual": "heuristic",
    "residual_mode": "gain",
    "residual_scale": 1.0,
    "env_kwargs": {},
    # rsl_rl's runner and PPO (its names), but for noise_hold_steps, learn_std and normalize_reward
    "num_steps_per_env": 64,  # 256 x 64 = 16,384 transitions per update
    "stagger": True,  # init_at_random_ep_len: the bodies' episode clocks start spread over an episode
    "hidden_dims": [64, 64],
    "activation": "tanh",
    "init_std": 1.5,  # wide exploration: the executed gain factor 1 + clip(a) spans [0, 2]
    "learn_std": True,
    "noise_hold_steps": 4,  # the exploration noise held for 4 rollout steps (HeldGaussianDistribution; SB3's gSDE)
    "obs_normalization": True,
    "normalize_reward": True,  # rewards / std of the discounted returns (SB3's VecNormalize norm_reward), training only
    "num_learning_epochs": 5,
    "num_mini_batches": 8,
    "clip_param": 0.1,
    "use_clipped_value_loss": False,
    "gamma": 0.995,
    "lam": 0.95,
    "value_loss_coef": 1.0,
    "entropy_coef": 0.0,
    "learning_rate": 3.0e-4,  # the start: the adaptive schedule raises it to rsl_rl's cap 1e-2 within a few iterations
    "max_grad_norm": 1.0,
    "schedule": "adaptive",
    "desired_kl": 0.01,
}
"""Default hyperparameters (docs/agents.md, "rsl_rl": how they were chosen — with them the residual policy beats the LQR
on held-out seeds in 10^6 steps); ``--hyperparams KEY=VALUE`` overrides."""
_FLOAT_KEYS = (
    "residual_scale",
    "init_std",
    "clip_param",
    "gamma",
    "lam",
    "value_loss_coef",
    "entropy_coef",
    "learning_rate",
    "max_grad_norm",
    "desired_kl",
)


# --- the LQR residual on the device ---------------------------------------------------------------------------
class TorchResidual:
    """:class:`agents.heuristic.ResidualAction` batched in torch (module docstring).

    Parameters
    ----------
    env_kwargs : dict
    scale : float
    mode : {"gain", "additive"}
    device : torch.device
    gate : float
        Must be 0 (the fade-out near the target is not built on this path).
    """

    def __init__(self, env_kwargs: dict | None, scale: float, mode: str, device, gate: float = 0.0) -> None:
        import torch

        from agents.heuristic import _KEY_COLUMNS, _REDUCED_OBS, RESIDUAL_MODES, HeuristicController
        from flatbody_env.env.env import FlatBodyEnv
        from flatbody_env.env.task import OBS_TARGET

        if mode not in RESIDUAL_MODES:
            raise ValueError(f"residual_mode: must be one of {', '.join(RESIDUAL_MODES)}, got {mode!r}")
        if not (math.isfinite(scale) and scale >= 0):
            raise ValueError(f"residual_scale: must be a finite number >= 0, got {scale!r}")
        if gate:
            raise ValueError(
                "residual_gate: not supported by rsl-ppo (use residual_mode=gain, which keeps the target an equilibrium)"
            )
        proto = FlatBodyEnv(**(env_kwargs or {}))
        self.controller = HeuristicController(proto.body, proto.control, proto.limits)
        if not self.controller.mask.all():
            raise ValueError("residual: the LQR residual needs all four controls")
        self.scale, self.mode, self.device = float(scale), mode, torch.device(device)
        self._key_cols = torch.as_tensor(_KEY_COLUMNS, device=self.device)
        self._red_cols = torch.as_tensor(_REDUCED_OBS, device=self.device)
        self._t0 = OBS_TARGET.start
        self._keys: torch.Tensor | None = None
        self._minus_K: torch.Tensor | None = None
        self.refreshed = 0
        """Gains refreshed so far (one per reset body; a diagnostic)."""

    def lqr(self, obs):
        """a_LQR (N, 4) float32 for observations (N, 16) (:meth:`agents.heuristic.HeuristicController.act`)."""
        import torch

        o = obs.to(self.device, torch.float64)
        keys = o[:, self._key_cols]
        if self._keys is None or self._keys.shape != keys.shape:
            self._keys = torch.full_like(keys, float("nan"))
            self._minus_K = torch.empty((keys.shape[0], 4, 9), dtype=torch.float64, device=self.device)
        changed = (keys != self._keys).any(dim=1)
        if bool(changed.any()):
            rows = changed.nonzero()[:, 0]
            k = keys[rows].cpu().numpy()
            K = self.controller.gains(k[:, :4], k[:, 4])
            self._minus_K[rows] = -torch.from_numpy(K).to(self.device)
            self._keys[rows] = keys[rows]
            self.refreshed += int(rows.numel())
        dx = o[:, self._red_cols]
        t0 = self._t0
        dx[:, 2] -= o[:, t0 + 3]
        dx[:, 6:9] -= o[:, t0 : t0 + 3]
        a = torch.bmm(self._minus_K, dx[:, :, None])[:, :, 0].clamp_(-1.0, 1.0)
        return a.to(torch.float32)

    def __call__(self, obs, actions):
        """The executed actions (N, 4) float32 for the policy's ``actions`` at observations ``obs``."""
        import torch

        base = self.lqr(obs).to(torch.float64)
        a = self.scale * actions.to(self.device, torch.float64).reshape(base.shape).clamp(-1.0, 1.0)
        out = base * (1.0 + a) if self.mode == "gain" else base + a
        return out.clamp_(-1.0, 1.0).to(torch.float32)


# --- rsl_rl's VecEnv -------------------------------------------------------------------------------------------
def _vec_env_base():
    from rsl_rl.env import VecEnv

    return VecEnv


class RslVecEnv(_vec_env_base()):
    """rsl_rl's ``VecEnv`` over a :class:`~flatbody_env.env.torch_vector_env.FlatBodyTorchVectorEnv` (module docstring).

    The observation group is ``"policy"`` (actor and critic both read it). ``extras["log"]`` carries, over the
    episodes that ended in the step, ``/episode/final_distance`` and ``/episode/success``.
    """

    def __init__(
        self,
        env,
        residual: TorchResidual | None = None,
        seed: int | None = None,
        progress: list | None = None,
        reward_gamma: float | None = None,
    ) -> None:
        import torch

        self.env = env
        self.num_envs = env.num_envs
        self.num_actions = int(env.single_action_space.shape[0])
        self.max_episode_length = int(env.max_episode_steps)
        self.device = env.device
        self.cfg = {"env": "FlatBodyTorchVectorEnv", "num_envs": env.num_envs, "residual": residual is not None}
        self.residual = residual
        obs, _ = env.reset(seed=seed)
        self._obs = obs.to(self.device)
        self._return = torch.zeros(self.num_envs, dtype=torch.float64, device=self.device)
        self.reward_gamma = reward_gamma
        if reward_gamma is not None and not (0.0 < reward_gamma <= 1.0):
            raise ValueError(f"gamma: must be in (0, 1] for the reward normalisation, got {reward_gamma!r}")
        self._disc = torch.zeros(self.num_envs, dtype=torch.float64, device=self.device)
        from stable_baselines3.common.running_mean_std import RunningMeanStd

        self._ret_rms = RunningMeanStd(
            shape=()
        )  # the discounted returns' running statistics, as SB3's VecNormalize keeps them
        self.episodes: list[tuple[float, float, bool]] = []
        """(return, final distance, success) of every finished episode, in order."""

    @property
    def episode_length_buf(self):
        return self.env.episode_steps

    @episode_length_buf.setter
    def episode_length_buf(self, value) -> None:
        import torch

        v = torch.as_tensor(value).to("cpu", torch.int64).clamp(0, self.max_episode_length - 1)
        self.env.set_episode_steps(v.numpy())

    def _obs_dict(self, obs):
        from tensordict import TensorDict

        return TensorDict({"policy": obs}, batch_size=[self.num_envs], device=self.device)

    def get_observations(self):
        return self._obs_dict(self._obs)

    def step(self, actions):
        import torch

        a = (
            self.residual(self._obs, actions)
            if self.residual is not None
            else actions.clamp(-1.0, 1.0).to(torch.float32)
        )
        obs, rewards, terminated, truncated, info = self.env.step(a)
        self._obs = obs
        dones = terminated | truncated
        self._return += rewards
        extras: dict[str, Any] = {"time_outs": truncated.to(torch.float32)}
        if self.reward_gamma is not None:  # the training signal only: episodes are logged with the raw rewards
            self._disc = self._disc * self.reward_gamma + rewards.double()
            self._ret_rms.update(self._disc.cpu().numpy())
            self._disc[dones] = 0.0
            rewards = (
                (rewards.double() / math.sqrt(float(self._ret_rms.var) + 1e-8)).clamp(-10.0, 10.0).to(rewards.dtype)
            )
        if bool(dones.any()):
            d = info["distance"][dones]
            s = info["is_success"][dones]
            for r, dist, ok in zip(self._return[dones].tolist(), d.tolist(), s.tolist()):
                self.episodes.append((r, dist, bool(ok)))
            self._return[dones] = 0.0
            extras["log"] = {"/episode/final_distance": d.double().mean(), "/episode/success": s.double().mean()}
        return self._obs_dict(obs), rewards, dones.to(torch.long), extras


# --- temporally correlated exploration ------------------------------------------------------------------------
def _held_gaussian_base():
    from rsl_rl.modules.distribution import GaussianDistribution

    return GaussianDistribution


class HeldGaussianDistribution(_held_gaussian_base()):
    """rsl_rl's ``GaussianDistribution`` whose exploration noise is held for ``hold_steps`` consecutive rollout steps.

    While collecting (rsl_rl runs the rollout under ``torch.inference_mode``) :meth:`sample` returns
    mean + σ·ε with the same standard normal ε (one per body and action component) for ``hold_steps`` calls
    in a row, then draws a new one; outside inference mode (the PPO update's forward pass, whose sample is
    discarded) and whenever the batch shape changes it draws afresh. Each held sample is still a draw of
    N(mean, σ²), so the log-probabilities, entropy and KL of the parent are unchanged; the correlation in time
    is what SB3's gSDE (``sde_sample_freq``) gives the shipped SB3 agent. ``hold_steps: 1`` is the parent.
    """

    def __init__(self, output_dim: int, hold_steps: int = 1, **kwargs) -> None:
        super().__init__(output_dim, **kwargs)
        if not isinstance(hold_steps, int) or isinstance(hold_steps, bool) or hold_steps < 1:
            raise ValueError(f"noise_hold_steps: must be an integer >= 1, got {hold_steps!r}")
        self.hold_steps = hold_steps
        self._eps = None
        self._age = 0

    def sample(self):
        import torch

        mean, std = self._distribution.mean, self._distribution.stddev
        if self.hold_steps == 1 or not torch.is_inference_mode_enabled():
            return self._distribution.sample()
        if self._eps is None or self._eps.shape != mean.shape or self._age >= self.hold_steps:
            self._eps = torch.randn_like(mean)
            self._age = 0
        self._age += 1
        return mean + std * self._eps


def live_policy(actor, residual: TorchResidual | None, device: str = "cpu"):
    """The deterministic executed action of the training ``actor`` (mean, clipped, through ``residual``) as a batch
    policy of :func:`agents.evaluate.run_episodes` (numpy observations in, actions out): evaluations during training.
    ``residual`` None (a from-scratch agent, ``residual: null``): the mean clipped to [−1, 1] is the action, on ``device``."""
    import torch
    from tensordict import TensorDict

    dev = residual.device if residual is not None else torch.device(device)

    def policy(obs: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            o = torch.as_tensor(np.asarray(obs, dtype=np.float32), device=dev)
            mean = actor(TensorDict({"policy": o}, batch_size=[o.shape[0]], device=dev))
            if residual is None:
                return mean.clamp(-1.0, 1.0).cpu().numpy()
            return residual(o, mean).cpu().numpy()

    return policy


# --- export to SB3's format ------------------------------------------------------------------------------------
def export_sb3(actor, critic, path: Path, hp: dict[str, Any], seed: int) -> None:
    """Write the rsl_rl ``actor`` (and ``critic``) as an SB3 ``PPO`` model file at ``path``: the same MLPs, with
    rsl_rl's observation normaliser (x − m)/(s + ε) folded into each first layer, and log σ."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    from flatbody_env.env.env import FlatBodyEnv

    acts = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU}
    hidden = [int(h) for h in hp["hidden_dims"]]
    venv = DummyVecEnv([lambda: FlatBodyEnv(**(hp.get("env_kwargs") or {}))])
    model = PPO(
        "MlpPolicy",
        venv,
        seed=seed,
        device="cpu",
        verbose=0,
        policy_kwargs={"net_arch": {"pi": hidden, "vf": hidden}, "activation_fn": acts[hp["activation"]]},
    )
    pol = model.policy

    def linears(module):
        return [m for m in module.modules() if isinstance(m, torch.nn.Linear)]

    def folded(net, trunk, head):
        src = linears(net.mlp)
        dst = linears(trunk) + linears(head)
        assert len(src) == len(dst)
        norm = net.obs_normalizer
        with torch.no_grad():
            for k, (s, d) in enumerate(zip(src, dst)):
                W, b = s.weight.detach().double().cpu(), s.bias.detach().double().cpu()
                if k == 0 and not isinstance(norm, torch.nn.Identity):
                    m = norm._mean.detach().double().cpu()[0]
                    scale = norm._std.detach().double().cpu()[0] + norm.eps
                    W = W / scale
                    b = b - W @ m
                d.weight.copy_(W.to(d.weight.dtype))
                d.bias.copy_(b.to(d.bias.dtype))

    folded(actor, pol.mlp_extractor.policy_net, pol.action_net)
    folded(critic, pol.mlp_extractor.value_net, pol.value_net)
    with torch.no_grad():
        dist = actor.distribution
        log_std = dist.log_std_param if dist.std_type == "log" else torch.log(dist.std_param.clamp_min(1e-6))
        pol.log_std.copy_(log_std.detach().cpu().to(pol.log_std.dtype))
    model.save(str(path))
    venv.close()


# --- the trainer -----------------------------------------------------------------------------------------------
def runner_config(hp: dict[str, Any]) -> dict[str, Any]:
    """rsl_rl's ``OnPolicyRunner`` configuration from the hyperparameters."""
    net = {
        "class_name": "MLPModel",
        "hidden_dims": list(hp["hidden_dims"]),
        "activation": hp["activation"],
        "obs_normalization": bool(hp["obs_normalization"]),
    }
    alg_keys = (
        "num_learning_epochs",
        "num_mini_batches",
        "clip_param",
        "gamma",
        "lam",
        "value_loss_coef",
        "entropy_coef",
        "learning_rate",
        "max_grad_norm",
        "schedule",
        "desired_kl",
        "use_clipped_value_loss",
    )
    return {
        "num_steps_per_env": int(hp["num_steps_per_env"]),
        "save_interval": 10**9,
        "obs_groups": {"actor": ["policy"], "critic": ["policy"]},
        "actor": {
            **net,
            "distribution_cfg": {
                "class_name": "agents.rsl:HeldGaussianDistribution",
                "init_std": float(hp["init_std"]),
                "std_type": "scalar",
                "learn_std": bool(hp["learn_std"]),
                "hold_steps": hp["noise_hold_steps"],
            },
        },
        "critic": dict(net),
        "algorithm": {"class_name": "PPO", **{k: hp[k] for k in alg_keys}},
        "check_for_nan": True,
    }


def train_rsl(
    out: str | Path,
    *,
    seed: int = 0,
    n_timesteps: int | None = None,
    n_envs: int | None = None,
    device: str = "cpu",
    overrides: list[str] | None = None,
    env_id: str | None = None,
    threads: int = 1,
    progress: bool = True,
    command: list[str] | None = None,
    force: bool = False,
    callback=None,
    checkpoint_freq: int = 50_000,
    keep_checkpoints: bool = False,
):
    """Train rsl_rl's PPO on ``FlatBody-v0`` with the LQR residual and write the run folder ``out`` (module docstring).

    Every ``checkpoint_freq`` environment steps (rounded up to whole iterations; 0: never) rsl_rl's state (actor,
    critic, optimiser, iterations) is saved as ``out/checkpoints/rsl_model_N_steps.pt``, atomically through the one
    writing door; the newest :data:`agents.train.KEEP_CHECKPOINTS` are kept, and the folder is removed after a
    completed run unless ``keep_checkpoints``. ``n_timesteps`` rounds up to whole PPO iterations of ``n_envs`` x
    ``num_steps_per_env`` steps. ``callback``
    (optional) is called after each iteration as ``callback(runner, row)`` (``row``: the progress row); a true return
    value stops the training there, and the time spent in it is left out of the wall time (a benchmark's evaluations).
    Returns :class:`agents.train.TrainResult`.
    """
    import yaml

    from agents.numpy_policy import remember_run
    from agents.train import ENV_ID, KEEP_CHECKPOINTS, TrainResult, _rotate_checkpoints, apply_overrides, check_out
    from flatbody_env.output import atomic_path, atomic_write, write_csv
    from flatbody_env.physics import validation
    from flatbody_env.provenance import git_hash

    env_id = env_id or ENV_ID
    if env_id != ENV_ID:
        raise ValueError(f"env: only {ENV_ID} is supported, got {env_id!r}")
    if device not in DEVICES:
        raise ValueError(f"device: must be one of {', '.join(DEVICES)}, got {device!r}")
    if not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads: must be an integer >= 1, got {threads!r}")
    validation.integer("checkpoint_freq", checkpoint_freq, low=0, high=validation.MAX_TIMESTEPS)
    out = check_out(out, force=force)
    hp = apply_overrides(json.loads(json.dumps(DEFAULTS)), overrides or [])
    unknown = sorted(set(hp) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"hyperparams: unknown for rsl-ppo: {', '.join(unknown)} (known: {', '.join(DEFAULTS)})")
    for key in _FLOAT_KEYS:  # YAML reads 3e-4 (no dot) as a string
        try:
            hp[key] = float(hp[key])
        except (TypeError, ValueError):
            raise ValueError(f"{key}: must be a number, got {hp[key]!r}") from None
    hold = hp["noise_hold_steps"]
    if not isinstance(hold, int) or isinstance(hold, bool) or hold < 1:
        raise ValueError(f"noise_hold_steps: must be an integer >= 1, got {hold!r}")
    if n_timesteps is not None:
        hp["n_timesteps"] = int(n_timesteps)
    if n_envs is not None:
        hp["n_envs"] = int(n_envs)
    nenv, total, steps = int(hp["n_envs"]), int(float(hp["n_timesteps"])), int(hp["num_steps_per_env"])
    if nenv < 1 or total < 1 or steps < 1:
        raise ValueError(f"n_envs, n_timesteps, num_steps_per_env: must be >= 1, got {nenv}, {total}, {steps}")
    iterations = -(-total // (nenv * steps))

    import rsl_rl
    import torch
    from importlib.metadata import version
    from rsl_rl.runners import OnPolicyRunner

    from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv

    torch.set_num_threads(threads)
    torch.manual_seed(seed)
    np.random.seed(seed)
    env = FlatBodyTorchVectorEnv(
        nenv, device=device, **(hp.get("env_kwargs") or {})
    )  # cuda: raises until the device env exists
    residual = None
    if hp.get("residual"):
        if hp["residual"] != "heuristic":
            raise ValueError(f"residual: must be 'heuristic' or empty, got {hp['residual']!r}")
        residual = TorchResidual(
            hp.get("env_kwargs"), float(hp["residual_scale"]), str(hp["residual_mode"]), env.device
        )
    venv = RslVecEnv(env, residual, seed=seed, reward_gamma=float(hp["gamma"]) if hp["normalize_reward"] else None)
    cfg = {
        "env_id": env_id,
        "algo": "ppo",
        "seed": seed,
        "hyperparams": hp,
        "trainer": {"name": ALGO, "library": "rsl_rl", "version": version("rsl-rl-lib"), "device": device},
    }
    out.mkdir(parents=True, exist_ok=True)
    ckpt_dir = out / "checkpoints"
    if force and ckpt_dir.exists():
        import shutil

        shutil.rmtree(ckpt_dir)  # an old run's checkpoints are not this run's
    atomic_write(out / "config.yml", yaml.safe_dump(cfg, sort_keys=False))
    remember_run(out)  # the run's first file is in place: its folder is this user's (docs/reliability.md)
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):  # rsl_rl prints the models
        runner = OnPolicyRunner(venv, runner_config(hp), log_dir=None, device=device)
    rows: list[dict[str, Any]] = []
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=iterations * nenv * steps, unit="step", desc=f"rsl-ppo {env_id}", file=sys.stderr)
    t0 = time.perf_counter()
    for it in range(iterations):  # one PPO iteration at a time: a progress row each
        seen = len(venv.episodes)
        ti = time.perf_counter()
        runner.learn(1, init_at_random_ep_len=bool(hp["stagger"]) and it == 0)
        new = venv.episodes[seen:]
        rows.append(
            {
                "iteration": it + 1,
                "timesteps": (it + 1) * nenv * steps,
                "time_s": round(time.perf_counter() - t0, 3),
                "fps": round(nenv * steps / (time.perf_counter() - ti), 1),
                "episodes": len(new),
                "ep_rew_mean": float(np.mean([e[0] for e in new])) if new else "",
                "final_distance_mean": float(np.mean([e[1] for e in new])) if new else "",
                "success_rate": float(np.mean([e[2] for e in new])) if new else "",
                "action_std": float(runner.alg.get_policy().output_std.detach().mean()),
                "learning_rate": float(runner.alg.learning_rate),
            }
        )
        if bar is not None:
            bar.update(nenv * steps)
        done = (it + 1) * nenv * steps
        if checkpoint_freq and done // checkpoint_freq > it * nenv * steps // checkpoint_freq:
            ckpt_dir.mkdir(exist_ok=True)
            with atomic_path(ckpt_dir / f"rsl_model_{done}_steps.pt") as tmp:
                torch.save(_rsl_state(runner, hp, len(rows)), str(tmp))
            _rotate_checkpoints(ckpt_dir, KEEP_CHECKPOINTS)
        if callback is not None:
            tc = time.perf_counter()
            stop = callback(runner, rows[-1])
            t0 += time.perf_counter() - tc
            if stop:
                break
    wall = time.perf_counter() - t0
    if bar is not None:
        bar.close()
    write_csv(out / "progress.csv", list(rows[0]), ([r[k] for k in rows[0]] for r in rows))
    with atomic_path(out / "rsl_model.pt") as tmp:
        torch.save(_rsl_state(runner, hp, len(rows), optimizer=False), str(tmp))
    with atomic_path(out / "model.zip") as tmp:
        export_sb3(runner.alg.actor, runner.alg.critic, Path(str(tmp)), hp, seed)
    import gymnasium
    import stable_baselines3

    run = {
        "command": command if command is not None else [sys.executable, *sys.argv],
        "command_line": shlex.join(command if command is not None else sys.argv),
        "git_hash": git_hash(),
        "env_id": env_id,
        "algo": ALGO,
        "seed": seed,
        "n_timesteps": len(rows) * nenv * steps,
        "n_envs": nenv,
        "device": device,
        "torch_threads": threads,
        "wall_time_s": round(wall, 1),
        "resumed_from": None,
        "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "versions": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "gymnasium": gymnasium.__version__,
            "rsl_rl": version("rsl-rl-lib"),
            "stable_baselines3": stable_baselines3.__version__,
            "torch": torch.__version__,
        },
        "cpu_count": os.cpu_count(),
    }
    del rsl_rl
    atomic_write(out / "run.json", json.dumps(run, indent=2) + "\n")
    from agents.numpy_policy import export_policy

    export_policy(out)
    if ckpt_dir.exists() and not keep_checkpoints:
        import shutil

        shutil.rmtree(ckpt_dir)
    env.close()
    return TrainResult(out=out, timesteps=len(rows) * nenv * steps, wall_time_s=wall, resumed_from=None)


def _rsl_state(runner, hp: dict[str, Any], iterations: int, *, optimizer: bool = True) -> dict[str, Any]:
    """rsl_rl's state as saved in ``rsl_model.pt`` and the checkpoints (these with the optimiser's state)."""
    state = {
        "actor": runner.alg.actor.state_dict(),
        "critic": runner.alg.critic.state_dict(),
        "iterations": iterations,
        "runner_cfg": runner_config(hp),
    }
    if optimizer:
        state["optimizer"] = runner.alg.optimizer.state_dict()
    return state


# --- from scratch (no LQR prior): success and final distance against wall time -------------------------------
FROM_SCRATCH: list[str] = ["residual=null", "init_std=0.5", "hidden_dims=[128,128]"]
"""``--hyperparams`` of the from-scratch agent (docs/agents.md, "From scratch": how they were chosen): no LQR, the
policy's clipped output is the control."""
CURVE_HEADER = ("timesteps", "wall_s", "success", "final_distance")


def from_scratch_curve(
    out: str | Path,
    csv_path: str | Path,
    *,
    seed: int = 0,
    overrides: list[str] | None = None,
    budget_s: float = 600.0,
    eval_every_s: float = 30.0,
    episodes: int = 100,
    eval_seed: int = 10_000,
    device: str = "cpu",
    force: bool = False,
):
    """Train rsl-ppo with :data:`FROM_SCRATCH` (then ``overrides``) for ``budget_s`` seconds of training wall time and write the curve.

    After the first iteration that ends ``eval_every_s`` or more after the previous evaluation, and at the end, the
    deterministic policy (:func:`live_policy`, no residual) runs ``episodes`` held-out episodes (seeds ``eval_seed`` …);
    the evaluation time is left out of the wall time (``train_rsl``'s ``callback``). The training stops at the first
    evaluation at or past ``budget_s``, so the run folder ``out`` holds the last evaluated policy. ``csv_path``: one row
    per evaluation (:data:`CURVE_HEADER`), rewritten after each. ``device``: the torch device of env and policy
    (``"cuda"``: the torch env and the policy on the GPU, the evaluations' policy too). Returns the rows.
    """
    from agents.evaluate import run_episodes
    from flatbody_env.output import write_csv

    if not (budget_s > 0 and eval_every_s > 0):
        raise ValueError(f"budget_s, eval_every_s: must be > 0, got {budget_s!r}, {eval_every_s!r}")
    rows: list[tuple[int, float, float, float]] = []
    due = [float(eval_every_s)]

    def callback(runner, row) -> bool:
        if row["time_s"] < min(due[0], budget_s):
            return False
        due[0] = row["time_s"] + eval_every_s
        recs = run_episodes(live_policy(runner.alg.actor, None, device), episodes=episodes, seed=eval_seed)
        rows.append(
            (
                int(row["timesteps"]),
                round(float(row["time_s"]), 2),
                float(np.mean([r["success"] for r in recs])),
                float(np.mean([r["final_distance"] for r in recs])),
            )
        )
        write_csv(csv_path, CURVE_HEADER, [(t, f"{w:.2f}", f"{s_:.3f}", f"{d:.6f}") for t, w, s_, d in rows])
        return row["time_s"] >= budget_s

    train_rsl(
        out,
        seed=seed,
        n_timesteps=10**12,
        progress=False,
        overrides=[*FROM_SCRATCH, *(overrides or [])],
        callback=callback,
        device=device,
        force=force,
    )
    return rows


SCRATCH_CAPTION = (
    "Each point: the training policy at that moment (deterministic, no LQR) on {episodes} held-out episodes; wall time: training only\n"
    "(the evaluations left out), one torch thread on a shared 2-core machine. Dotted: the goal, success ≥ {success:.0%} and mean\n"
    "final distance ≤ {distance:g}, within {budget:g} s (vertical line). {note}"
)


def plot_curve(
    csv_path: str | Path,
    png_path: str | Path,
    *,
    success_goal: float = 0.95,
    distance_goal: float = 0.01,
    budget_s: float = 600.0,
    episodes: int = 100,
    note: str = "",
    title: str = "rsl-ppo from scratch (no LQR prior)",
) -> None:
    """Success and mean final distance against wall time, drawn from the saved curve ``csv_path`` (:func:`from_scratch_curve`)."""
    from flatbody_env.figures import PALETTE, chart, fraction_axis
    from flatbody_env.physics import validation

    data = validation.read_csv("csv", csv_path)  # the one reading door
    w = [float(r["wall_s"]) for r in data]
    with chart(png_path, size=(9.0, 4.4), ncols=2) as c:
        ax_d, ax_s = c.axes[0]
        ax_d.plot(
            w, [float(r["final_distance"]) for r in data], "o-", ms=3, color="tab:orange", label="rsl-ppo, from scratch"
        )
        ax_s.plot(w, [float(r["success"]) for r in data], "o-", ms=3, color="tab:orange")
        ax_d.axhline(distance_goal, color=PALETTE["goal"], ls=":", lw=1, label="goal (and the time budget)")
        ax_s.axhline(success_goal, color=PALETTE["goal"], ls=":", lw=1)
        for ax in (ax_d, ax_s):
            ax.axvline(budget_s, color=PALETTE["goal"], ls=":", lw=1)
            ax.set_xlabel("wall time (s)")
        ax_d.set_yscale("log")
        ax_d.set_ylabel("mean final distance")
        fraction_axis(ax_s, "success rate")
        c.legend(where="below", ncol=2)
        c.title(title)
        c.caption(
            SCRATCH_CAPTION.format(
                episodes=episodes, success=success_goal, distance=distance_goal, budget=budget_s, note=note
            ),
            fontsize=7,
        )


__all__ = [
    "ALGO",
    "CURVE_HEADER",
    "DEFAULTS",
    "FROM_SCRATCH",
    "HeldGaussianDistribution",
    "RSL_RL_VERSION",
    "RslVecEnv",
    "TorchResidual",
    "export_sb3",
    "from_scratch_curve",
    "live_policy",
    "plot_curve",
    "runner_config",
    "train_rsl",
]

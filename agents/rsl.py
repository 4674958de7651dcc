"""PPO from rsl_rl (Isaac Lab's trainer) on :class:`~flatbody_env.env.torch_vector_env.FlatBodyTorchVectorEnv`.

``flatbody train --algo rsl-ppo --env ID`` (:func:`train_rsl`): rsl_rl's PPO, with the env, the policy's tensors (and,
on the prior track, the LQR residual) on one torch device, and no hand-written PPO. The hyperparameters are the entry
of ``ID`` in ``agents/hyperparams/rsl-ppo.yml`` (the keys it leaves out: :data:`agents.config.RSL_DEFAULTS`); the
v1 ids train from scratch, ``FlatBody-v0``'s entry is the residual agent of docs/agents.md. Pieces:

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
* ``residual: null``: no LQR — the policy's output clipped to [−1, 1] is the control; :func:`from_scratch_curve`
  trains ``FlatBody-v0``'s entry so (:data:`FROM_SCRATCH`) for a wall-time budget and writes its held-out success and
  final distance against wall time, :func:`plot_curve` draws that table (docs/agents.md, "From scratch").
* :func:`export_sb3` — the trained actor as an SB3 ``PPO`` ``model.zip`` (same MLP; rsl_rl's observation
  normaliser folded into the first layer, exactly), so ``flatbody evaluate`` and ``demo`` run it unchanged
  (``config.yml`` says ``algo: rsl-ppo`` and ``model_format: ppo``).

The run folder is every trainer's (:class:`agents.runs.RunFolder`): ``model.zip``, ``config.yml``, ``run.json``,
``progress.csv`` (one row per PPO iteration), ``policy.npz``, plus ``rsl_model.pt`` (rsl_rl's own actor and critic)
and, while the run goes on, ``checkpoints/rsl_model_N_steps.pt`` every ``checkpoint_freq`` steps (actor, critic,
optimiser, learning rate, reward normaliser: what ``--resume`` continues from; the newest kept).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from agents.config import RunConfig
from agents.runs import RunFolder, TrainResult, stopped

RSL_RL_VERSION = "5.5.1"
"""The rsl_rl release this trainer is written against (pinned in pyproject.toml: ``rsl-rl-lib``)."""
ALGO = "rsl-ppo"


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
        from flatbody_env.physics import validation

        validation.string("residual_mode", mode, choices=RESIDUAL_MODES)
        validation.number("residual_scale", scale, low=0.0)
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
        if reward_gamma is not None:
            from flatbody_env.physics import validation

            validation.requirement(
                "gamma", reward_gamma, 0.0 < reward_gamma <= 1.0, "lie in (0, 1] for the reward normalisation"
            )
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
        self._obs = self.env.observations.to(self.device)  # an observed time (observe_time) follows the clocks

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
        from flatbody_env.physics import validation

        validation.integer("noise_hold_steps", hold_steps, low=1)
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
def export_sb3(
    actor, critic, path: Path, hp: dict[str, Any], seed: int, env_kwargs: dict[str, Any] | None = None
) -> None:
    """Write the rsl_rl ``actor`` (and ``critic``) as an SB3 ``PPO`` model file at ``path``: the same MLPs, with
    rsl_rl's observation normaliser (x − m)/(s + ε) folded into each first layer, and log σ. ``env_kwargs``: the
    keywords of the task the actor acts in (its spaces; default ``hp["env_kwargs"]``)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    from flatbody_env.env.env import FlatBodyEnv

    acts = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU}
    hidden = [int(h) for h in hp["hidden_dims"]]
    kwargs = env_kwargs if env_kwargs is not None else (hp.get("env_kwargs") or {})
    venv = DummyVecEnv([lambda: FlatBodyEnv(**kwargs)])
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
    config: RunConfig,
    folder: RunFolder,
    *,
    resume: bool = False,
    checkpoint_freq: int = 50_000,
    keep_checkpoints: bool = False,
    threads: int = 1,
    progress: bool = True,
    command: list[str] | None = None,
    force: bool = False,
    callback=None,
    evaluations=None,
    notes: bool = True,
) -> TrainResult:
    """Train rsl_rl's PPO with the configuration ``config`` (``algo: rsl-ppo``) into the run folder ``folder`` (module
    docstring); :func:`agents.train.train` and ``flatbody train --algo rsl-ppo`` come here.

    ``n_timesteps`` rounds up to whole PPO iterations of ``n_envs`` x ``num_steps_per_env`` steps. Every
    ``checkpoint_freq`` environment steps (rounded up to whole iterations; 0: never) rsl_rl's state (actor, critic,
    optimiser, iterations, learning rate, the reward normaliser) is saved as ``checkpoints/rsl_model_N_steps.pt``
    through the run folder; Ctrl-C saves one too and names the command that continues the run. ``resume``: continue
    from the newest checkpoint that loads (the environments restart from the seed, so a resumed run is not bit-identical
    to an uninterrupted one). ``callback`` (optional) is called after each iteration as ``callback(runner, row)``
    (``row``: the progress row); a true return value stops the training there, and the time spent in it is left out of
    the wall time. ``evaluations`` (optional, :class:`agents.evaluate.HeldOutEvaluations`): the deterministic policy
    (:func:`live_policy`, through the run's prior) on held-out episodes whenever due, a row each in the run folder's
    ``evaluations.csv``, their time left out of the wall time too (``notes``: a line on stderr each).
    """
    from agents.config import check_device
    from agents.numpy_policy import check_trusted

    check_device(config.device)
    hp, seed, device = config.hyperparams, config.seed, config.device
    nenv, total, steps = config.n_envs, config.n_timesteps, int(hp["num_steps_per_env"])
    iterations = -(-total // (nenv * steps))
    candidates = []
    if resume:  # the checkpoints are pickles (torch's); read only from one of your runs, or with --trust
        check_trusted(folder.checkpoint_dir, "the checkpoints (torch files)", where="resume")
        candidates = folder.checkpoints()
        if not candidates:
            raise ValueError(
                f"resume: no checkpoint in {folder.checkpoint_dir} (a run that completed keeps its checkpoints only "
                "when trained with --keep-checkpoints; train a longer run with a larger --n-timesteps)"
            )
    earlier = folder.previous_wall_time() if resume else 0.0  # the run so far, read up front

    import torch
    from rsl_rl.runners import OnPolicyRunner

    from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv

    torch.set_num_threads(threads)
    torch.manual_seed(seed)
    np.random.seed(seed)
    from agents.evaluate import env_kwargs_for

    env_kwargs = env_kwargs_for(config.env_id, config.env_kwargs)
    if not resume:
        folder.start(config, force=force)  # config.yml, the first file: the folder is trusted from here on
    env = FlatBodyTorchVectorEnv(nenv, device=device, **env_kwargs)
    residual = None
    if hp.get("residual"):
        residual = TorchResidual(env_kwargs, float(hp["residual_scale"]), str(hp["residual_mode"]), env.device)
    venv = RslVecEnv(env, residual, seed=seed, reward_gamma=float(hp["gamma"]) if hp["normalize_reward"] else None)
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):  # rsl_rl prints the models
        runner = OnPolicyRunner(venv, runner_config(hp), log_dir=None, device=device)
    done_it, resumed_from, rows = 0, None, []
    if resume:
        done_it = _load_rsl_state(runner, venv, candidates)
        resumed_from = done_it * nenv * steps
    bar = None
    if progress:
        from flatbody_env.progress import progress_bar

        bar = progress_bar(
            total=iterations * nenv * steps,
            initial=done_it * nenv * steps,
            unit="step",
            desc=f"rsl-ppo {config.env_id}",
        )
    table = folder.progress_table("progress.csv" if not resume else f"progress-resumed-{resumed_from}.csv")
    if evaluations is not None:
        evaluations.start(done_it * nenv * steps, folder.evaluations_table(resumed_from), say=notes)
    t0 = time.perf_counter()
    it = done_it
    try:
        for it in range(done_it, iterations):  # one PPO iteration at a time: a progress row each
            seen = len(venv.episodes)
            ti = time.perf_counter()
            runner.learn(1, init_at_random_ep_len=bool(hp["stagger"]) and it == done_it)
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
            table.add(rows[-1])  # written as it grows (a while apart): a long run shows its progress
            if bar is not None:
                bar.update(nenv * steps)
            done = (it + 1) * nenv * steps
            if checkpoint_freq and done // checkpoint_freq > it * nenv * steps // checkpoint_freq:
                _save_rsl_checkpoint(folder, runner, venv, hp, it + 1, done)
            if evaluations is not None and evaluations.due(done):
                tc = time.perf_counter()
                evaluations.add(done, live_policy(runner.alg.actor, residual, device))
                t0 += time.perf_counter() - tc
                if evaluations.stop:
                    break
            if callback is not None:
                tc = time.perf_counter()
                stop = callback(runner, rows[-1])
                t0 += time.perf_counter() - tc
                if stop:
                    break
    except KeyboardInterrupt:
        if bar is not None:
            bar.close()
        table.close()
        if evaluations is not None:
            evaluations.close()
        reached = len(rows) + done_it
        if checkpoint_freq and rows:
            kept = _save_rsl_checkpoint(folder, runner, venv, hp, reached, reached * nenv * steps)
            raise stopped(config, folder, reached * nenv * steps, kept) from None
        why = "no iteration trained yet" if not rows else "--checkpoint-freq 0"
        raise stopped(config, folder, reached * nenv * steps, None, why) from None
    wall = time.perf_counter() - t0
    if bar is not None:
        bar.close()
    trained = (done_it + len(rows)) * nenv * steps
    table.close()
    if evaluations is not None:
        evaluations.close()
    folder.save(
        "rsl_model.pt",
        lambda tmp: torch.save(_rsl_state(runner, venv, hp, done_it + len(rows), optimizer=False), str(tmp)),
    )
    folder.save(
        "model.zip", lambda tmp: export_sb3(runner.alg.actor, runner.alg.critic, Path(str(tmp)), hp, seed, env_kwargs)
    )
    if resume:  # the budget it was continued to
        folder.write_config(config)
    folder.write_run(
        config,
        timesteps=trained,
        wall_time_s=wall + earlier,
        command=command,
        resumed_from=resumed_from,
        threads=threads,
    )
    folder.export_policy()
    folder.finish(keep_checkpoints=keep_checkpoints)
    env.close()
    return TrainResult(out=folder.path, timesteps=trained, wall_time_s=wall, resumed_from=resumed_from)


def _save_rsl_checkpoint(folder: RunFolder, runner, venv, hp: dict[str, Any], iterations: int, steps: int) -> Path:
    import torch

    state = _rsl_state(runner, venv, hp, iterations)
    return folder.save_checkpoint(steps, {"model": lambda tmp: torch.save(state, str(tmp))}, prefix="rsl_model")


def _rsl_state(runner, venv, hp: dict[str, Any], iterations: int, *, optimizer: bool = True) -> dict[str, Any]:
    """rsl_rl's state as saved in ``rsl_model.pt`` and the checkpoints (these with the optimiser's state, the
    adaptive learning rate and the reward normaliser's statistics, what ``--resume`` needs)."""
    state = {
        "actor": runner.alg.actor.state_dict(),
        "critic": runner.alg.critic.state_dict(),
        "iterations": iterations,
        "runner_cfg": runner_config(hp),
    }
    if optimizer:
        rms = venv._ret_rms
        state["optimizer"] = runner.alg.optimizer.state_dict()
        state["learning_rate"] = float(runner.alg.learning_rate)
        state["return_rms"] = [float(rms.mean), float(rms.var), float(rms.count)]
    return state


def _load_rsl_state(runner, venv, candidates: list) -> int:
    """Load the newest checkpoint of ``candidates`` that loads into ``runner`` (read through the one trust check and
    reading door, unpickled by torch's weights-only loader: tensors and plain data only); a newer one that does
    not is passed over with a note on stderr. Returns the iterations it had trained."""
    from agents.numpy_policy import load_torch_state

    for k, ckpt in enumerate(candidates):
        try:
            state = load_torch_state(ckpt.model, where="resume", map_location=runner.device)
            try:
                runner.alg.actor.load_state_dict(state["actor"])
                runner.alg.critic.load_state_dict(state["critic"])
                runner.alg.optimizer.load_state_dict(state["optimizer"])
                runner.alg.learning_rate = float(state["learning_rate"])
                mean, var, count = (float(x) for x in state["return_rms"])
                iterations = int(state["iterations"])
            except Exception as exc:  # noqa: BLE001 - another network's weights, missing entries
                raise ValueError(
                    f"resume: cannot load {str(ckpt.model)[:80]!r} ({type(exc).__name__}: "
                    f"{' '.join(str(exc).split())[:120]})"
                ) from None
        except ValueError as exc:
            if k + 1 == len(candidates):
                raise ValueError(f"resume: no checkpoint in {ckpt.model.parent} loads (the oldest: {exc})") from None
            print(
                f"flatbody: note: checkpoint {ckpt.model.name} cannot be loaded "
                f"({' '.join(str(exc).split())[:160]}); resuming from {candidates[k + 1].model.name}",
                file=sys.stderr,
            )
            continue
        venv._ret_rms.mean, venv._ret_rms.var, venv._ret_rms.count = mean, var, count
        return iterations
    raise ValueError("resume: no checkpoint")  # unreachable: candidates is not empty


# --- from scratch (no LQR prior): success and final distance against wall time -------------------------------
FROM_SCRATCH: list[str] = ["residual=null", "init_std=0.5", "hidden_dims=[128,128]"]
"""``--hyperparams`` over ``FlatBody-v0``'s entry of the from-scratch agent of docs/agents.md ("From scratch": how they
were chosen): no LQR, the policy's clipped output is the control."""
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
    force: bool = False,
):
    """Train rsl-ppo with :data:`FROM_SCRATCH` (then ``overrides``) for ``budget_s`` seconds of training wall time and write the curve.

    After the first iteration that ends ``eval_every_s`` or more after the previous evaluation, and at the end, the
    deterministic policy (:func:`live_policy`, no residual) runs ``episodes`` held-out episodes (seeds ``eval_seed`` …,
    through :class:`agents.evaluate.HeldOutEvaluations`); the evaluation time is left out of the wall time
    (``train_rsl``'s ``callback``). The training stops at the first
    evaluation at or past ``budget_s``, so the run folder ``out`` holds the last evaluated policy. ``csv_path``: one row
    per evaluation (:data:`CURVE_HEADER`), rewritten after each. On the CPU: ``FlatBody-v0`` draws its episodes on
    the host, so it runs on the CPU faces only (a v1 id trains on a GPU with ``flatbody train --device cuda``).
    Returns the rows.
    """
    from agents.evaluate import HeldOutEvaluations
    from flatbody_env.output import write_csv

    from flatbody_env.physics import validation

    validation.requirement(
        "budget_s, eval_every_s", (budget_s, eval_every_s), budget_s > 0 and eval_every_s > 0, "be > 0"
    )
    rows: list[tuple[int, float, float, float]] = []
    due = [float(eval_every_s)]
    # the evaluations along every training run, here on a wall-time schedule (no step marks: added when due below)
    evaluations = HeldOutEvaluations("FlatBody-v0", [], seed=eval_seed, episodes=episodes)

    def callback(runner, row) -> bool:
        if row["time_s"] < min(due[0], budget_s):
            return False
        due[0] = row["time_s"] + eval_every_s
        point = evaluations.add(int(row["timesteps"]), live_policy(runner.alg.actor, None))
        rows.append(
            (
                point["env_steps"],
                round(float(row["time_s"]), 2),
                float(point["success_rate"]),
                float(point["final_distance"]),
            )
        )
        write_csv(csv_path, CURVE_HEADER, [(t, f"{w:.2f}", f"{s_:.3f}", f"{d:.6f}") for t, w, s_, d in rows])
        return row["time_s"] >= budget_s

    from agents.config import resolve
    from flatbody_env.physics.validation import MAX_TIMESTEPS

    folder = RunFolder.new(out, force=force)
    config = resolve(
        ALGO,
        "FlatBody-v0",
        seed=seed,
        n_timesteps=MAX_TIMESTEPS,
        overrides=[*FROM_SCRATCH, *(overrides or [])],
    )
    train_rsl(config, folder, progress=False, callback=callback, force=force)
    return rows


def curve_from_run(run: str | Path, csv_path: str | Path) -> list[tuple[int, float, float, float]]:
    """The curve of :func:`plot_curve` (:data:`CURVE_HEADER`) from a run folder trained with ``--eval-freq`` (its
    ``evaluations.csv`` and ``progress.csv``): each evaluation's env steps, success and mean final distance, and its
    wall time — the training time of the run's ``progress.csv`` at that step (the evaluations left out), counted from
    the end of the first PPO iteration, which on a GPU includes compiling the env's kernels. Writes ``csv_path`` and
    returns the rows; ``ValueError`` naming ``run`` when an evaluation's step is not an iteration of the run."""
    from flatbody_env.output import write_csv
    from flatbody_env.physics import validation

    folder = Path(run)
    progress = validation.read_csv("run", folder / "progress.csv")
    evaluations = validation.read_csv("run", folder / "evaluations.csv")
    if not progress or not evaluations:
        raise ValueError(f"run: {folder} holds no iterations or no evaluations (train it with --eval-freq)")
    at = {int(r["timesteps"]): float(r["time_s"]) for r in progress}
    first = float(progress[0]["time_s"])
    rows = []
    for r in evaluations:
        steps = int(r["env_steps"])
        if steps not in at:
            raise ValueError(f"run: the evaluation at {steps} steps is not at an iteration of {folder}")
        rows.append((steps, round(at[steps] - first, 2), float(r["success_rate"]), float(r["final_distance"])))
    write_csv(csv_path, CURVE_HEADER, [(t, f"{w:.2f}", f"{s_:.3f}", f"{d:.6f}") for t, w, s_, d in rows])
    return rows


SCRATCH_CAPTION = (
    "Each point: the training policy at that moment (deterministic, no LQR) on {episodes} held-out episodes; wall time: training only\n"
    "(the evaluations left out), {machine}. Dotted: the goal, success ≥ {success:.0%} and mean\n"
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
    machine: str = "one torch thread on a shared 2-core machine",
) -> None:
    """Success and mean final distance against wall time, drawn from the saved curve ``csv_path`` (:func:`from_scratch_curve`;
    ``machine`` names where it trained in the caption)."""
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
                episodes=episodes,
                success=success_goal,
                distance=distance_goal,
                budget=budget_s,
                note=note,
                machine=machine,
            ),
            fontsize=7,
        )


__all__ = [
    "ALGO",
    "CURVE_HEADER",
    "FROM_SCRATCH",
    "HeldGaussianDistribution",
    "RSL_RL_VERSION",
    "RslVecEnv",
    "TorchResidual",
    "export_sb3",
    "curve_from_run",
    "from_scratch_curve",
    "live_policy",
    "plot_curve",
    "runner_config",
    "train_rsl",
]

"""Evaluate agents and baselines on ``FlatBody-v0`` over seeded episodes.

Episode i is reset with seed ``seed + i`` — the same target and initial state for every policy
(the batched :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv` reproduces single-env resets
seed for seed). Per episode:

* ``success``: ``info["is_success"]`` at the end of the episode (distance ≤ the task tolerance
  0.05 on the last step, no failure);
* ``final_distance``: the task distance d = ‖(Δλ, Δμ, Δϱ, Δs3, ω1, ω2, p_λ, p_μ, p_ϱ)‖ on the last step;
* ``time_to_reach``: sim time of the first step with d ≤ tolerance (None if never);
* ``energy_change``: H(end) − H(start) (the controls do work: Ḣ = ω·τ + ϱ̇ f);
* ``action_effort``: mean over steps of ‖a‖² (normalised actions in [−1, 1]ⁿ);
* ``return``, ``length``, ``failed`` (integrator failure or left the domain).

Policies: the agent (an SB3 model, observations normalised by its frozen VecNormalize
statistics, deterministic actions; for a residual agent combined with the LQR action, :class:`agents.heuristic.ResidualAction`), and the
baselines ``zero`` (a = 0), ``random`` (uniform actions from a seeded generator), ``heuristic``
(LQR about the target, :class:`agents.heuristic.HeuristicController`) and ``passivity``
(:class:`agents.heuristic.PassivityController`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

BASELINES = ("zero", "random", "heuristic", "passivity")
"""``heuristic``: LQR about the target (:class:`agents.heuristic.HeuristicController`);
``passivity``: the energy-based damping law (:class:`agents.heuristic.PassivityController`)."""
METRICS = ("success_rate", "final_distance", "final_distance_median", "reach_rate", "time_to_reach", "energy_change",
           "abs_energy_change", "action_effort", "return", "failure_rate")

Policy = Callable[[np.ndarray], np.ndarray]
"""Observations (N, 16) → actions (N, n)."""


def shipped_model_dir() -> Path:
    """The folder of the agent shipped in the package (``agents/models/ppo-FlatBody-v0``)."""
    return Path(__file__).resolve().parent / "models" / "ppo-FlatBody-v0"


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
        import yaml

        if backend not in POLICY_BACKENDS:
            raise ValueError(f"backend: must be one of {', '.join(POLICY_BACKENDS)}, got {backend!r}")
        p = Path(path) if path is not None else shipped_model_dir()
        folder = p if p.is_dir() else p.parent
        model_file = p if p.is_file() else folder / "model.zip"
        if not model_file.exists():
            raise ValueError(f"model: no model at {str(p)!r} (expected a run folder with model.zip, or a .zip)")
        cfg_file = folder / "config.yml"
        self.config: dict[str, Any] = yaml.safe_load(cfg_file.read_text(encoding="utf-8")) if cfg_file.exists() else {}
        algo = self.config.get("algo") or ("sac" if "sac" in model_file.name.lower() else "ppo")
        self.algo = algo
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
            except ValueError:
                if backend == "numpy":
                    raise
        if self.policy is None:
            self._load_sb3(model_file, folder, algo)
        self.backend = "numpy" if self.policy is not None else "sb3"
        hp = self.config.get("hyperparams") or {}
        self.env_kwargs: dict[str, Any] = dict(hp.get("env_kwargs") or {})
        self.residual = hp.get("residual") or None
        self.residual_scale = float(hp.get("residual_scale", 1.0))
        self.residual_gate = float(hp.get("residual_gate", 0.0))
        self._base = None
        if self.residual == "heuristic":
            from agents.heuristic import ResidualAction

            self._base = ResidualAction(self.env_kwargs, self.residual_scale, self.residual_gate,
                                        str(hp.get("residual_mode", "additive")))

    def _load_sb3(self, model_file: Path, folder: Path, algo: str) -> None:
        import pickle

        import torch
        from stable_baselines3 import PPO, SAC

        torch.set_num_threads(1)
        cls = {"ppo": PPO, "sac": SAC}[algo]
        self.model = cls.load(str(model_file), device="cpu")
        vn = folder / "vecnormalize.pkl"
        if vn.exists():
            with vn.open("rb") as fh:
                self.vecnormalize = pickle.load(fh)
            self.vecnormalize.training = False

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


def zero_policy(action_dim: int) -> Policy:
    return lambda obs: np.zeros((obs.shape[0], action_dim), dtype=np.float32)


def random_policy(action_dim: int, seed: int) -> Policy:
    rng = np.random.default_rng(seed)
    return lambda obs: rng.uniform(-1.0, 1.0, size=(obs.shape[0], action_dim)).astype(np.float32)


def heuristic_policy(env, kind: str = "heuristic") -> Policy:
    from agents.heuristic import HeuristicController, PassivityController

    cls = HeuristicController if kind == "heuristic" else PassivityController
    ctl = cls(env.body, env.control, env.limits)
    return lambda obs: ctl.predict(obs)[0]


def run_episodes(policy: Policy | str, *, episodes: int, seed: int, env_kwargs: dict[str, Any] | None = None,
                 batch: int = 50, progress: bool = False, label: str = "") -> list[dict[str, Any]]:
    """Roll out ``episodes`` seeded episodes (batched ``batch`` at a time); one record per episode.

    ``policy`` is a batch policy or a baseline name (:data:`BASELINES`).
    """
    from flatbody_env.env.registration import MAX_EPISODE_STEPS
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    if not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes: must be an integer >= 1, got {episodes!r}")
    records: list[dict[str, Any]] = []
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=episodes * MAX_EPISODE_STEPS, desc=label or "evaluate", unit="step", leave=False, dynamic_ncols=True)
    for start in range(0, episodes, batch):
        n = min(batch, episodes - start)
        env = FlatBodyVectorEnv(num_envs=n, **(env_kwargs or {}))
        adim = env.single_action_space.shape[0]
        if isinstance(policy, str):
            if policy == "zero":
                pol = zero_policy(adim)
            elif policy == "random":
                pol = random_policy(adim, seed + start)
            elif policy in ("heuristic", "passivity"):
                pol = heuristic_policy(env, policy)
            else:
                raise ValueError(f"baseline: must be one of {', '.join(BASELINES)}, got {policy!r}")
        else:
            pol = policy
        tol = env.task.success_tolerance
        obs, info = env.reset(seed=seed + start)
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
            records.append({
                "seed": seed + start + i,
                "success": bool(success[i]),
                "final_distance": float(final_d[i]),
                "time_to_reach": None if math.isnan(reach[i]) else float(reach[i]),
                "energy_change": float(e_end[i] - e0[i]),
                "action_effort": float(effort[i] / max(length[i], 1)),
                "return": float(ret[i]),
                "length": int(length[i]),
                "failed": bool(failed[i]),
            })
    if bar is not None:
        bar.close()
    return records


def summarize(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Means over episodes (``time_to_reach`` over the episodes that reached the target)."""
    fd = np.array([r["final_distance"] for r in records])
    ttr = [r["time_to_reach"] for r in records if r["time_to_reach"] is not None]
    de = np.array([r["energy_change"] for r in records])
    return {
        "episodes": len(records),
        "success_rate": float(np.mean([r["success"] for r in records])),
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


def evaluate_all(model: str | Path | None = None, *, episodes: int = 100, seed: int = 10_000, baselines: bool = True,
                 progress: bool = False, backend: str = "auto") -> dict[str, Any]:
    """The evaluation report: ``{"agent": {...}, "baselines": {"zero", "random", "heuristic"}, ...}``;
    ``policy_backend`` says how the agent's policy ran (``numpy`` or ``sb3``, :class:`Agent`)."""
    agent = Agent(model, backend=backend)
    env_kwargs = agent.env_kwargs
    report: dict[str, Any] = {
        "env_id": "FlatBody-v0",
        "episodes": episodes,
        "seed": seed,
        "model": str(agent.path),
        "policy_backend": agent.backend,
        "agent": summarize(run_episodes(agent, episodes=episodes, seed=seed, env_kwargs=env_kwargs, progress=progress, label="agent")),
    }
    if baselines:
        report["baselines"] = {
            name: summarize(run_episodes(name, episodes=episodes, seed=seed, env_kwargs=env_kwargs, progress=progress, label=name))
            for name in BASELINES
        }
    return report


def format_table(report: dict[str, Any]) -> str:
    """A Markdown table of the report (one row per policy)."""
    rows = [("agent", report["agent"])] + list((report.get("baselines") or {}).items())
    head = "| policy | success rate | final distance (mean) | final distance (median) | time to reach (mean, s) | ΔH (mean) | action effort ‖a‖² | return |"
    lines = [f"FlatBody-v0, {report['episodes']} episodes, seeds {report['seed']}..{report['seed'] + report['episodes'] - 1}", "",
             head, "|" + "---|" * 8]
    for name, s in rows:
        ttr = "—" if s["time_to_reach"] is None else f"{s['time_to_reach']:.2f} ({s['reach_rate']:.0%} reach)"
        lines.append(
            f"| {name} | {s['success_rate']:.0%} | {s['final_distance']:.4f} | {s['final_distance_median']:.4f} | {ttr} | "
            f"{s['energy_change']:+.3f} | {s['action_effort']:.3f} | {s['return']:.1f} |"
        )
    return "\n".join(lines)

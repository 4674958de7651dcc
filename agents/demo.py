"""``flatbody demo``: the README's main job.

The shipped agent steers the body from a seeded off-equilibrium state onto a stable stationary
ellipse (``FlatBody-v1``, its task) for one 400-step episode; the command prints the target,
the distance over time and whether the episode ended on the target, and writes a rerun recording
through :class:`flatbody_env.recording.wrapper.RerunRecorder` (the one way an env episode is recorded).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np


def rollout(
    agent,
    *,
    seed: int,
    env_kwargs: dict[str, Any] | None = None,
    record_to: str | Path | None = None,
    title: str | None = None,
    env_id: str = "FlatBody-v0",
) -> dict[str, Any]:
    """One seeded episode of ``agent`` (a batch policy) with the rotation tracked.

    With ``record_to`` the episode is also written to that ``.rrd`` file through
    :class:`flatbody_env.recording.wrapper.RerunRecorder` — the one way an env episode is recorded —
    atomically (:func:`flatbody_env.output.atomic_path`): a run that fails leaves no half-written file.

    Returns t (n,), states (11, n), actions (n, k) (row j: the action applied on [t_j, t_{j+1});
    the last row is zero), reward_terms (dict of (n,) arrays; entry j: the reward received on
    arriving at t_j, zero at t = 0), distance (n,), energy (n,), target, success, tolerance,
    body, ``env_id`` (the task recorded) and ``path`` (the recording, or None). Only the env's public surface is read
    (``state``, ``target``, ``info``).
    """
    if record_to is not None:
        from flatbody_env.output import atomic_path
        from flatbody_env.recording.wrapper import episode_file

        target = episode_file(record_to, 0)  # the one episode's file
        target.parent.mkdir(parents=True, exist_ok=True)  # as the recorder itself does
        with atomic_path(target) as tmp:
            ep = _rollout(agent, seed=seed, env_kwargs=env_kwargs, record_to=tmp, title=title, env_id=env_id)
        return {**ep, "path": target}
    return _rollout(agent, seed=seed, env_kwargs=env_kwargs, record_to=None, title=title, env_id=env_id)


def _rollout(agent, *, seed, env_kwargs, record_to, title, env_id) -> dict[str, Any]:
    import gymnasium as gym

    import flatbody_env  # noqa: F401  (registers the ids)
    from flatbody_env.env.core import end_reason

    with warnings.catch_warnings():  # a v0 id (the prior track's agents) is deprecated: the summary says so, once
        warnings.simplefilter("ignore", DeprecationWarning)
        env = gym.make(env_id, track_rotation=True, **(env_kwargs or {}))
    wrapper = None
    if record_to is not None:
        from flatbody_env.recording.wrapper import RerunRecorder

        env = wrapper = RerunRecorder(env, record_to, title=title)
    u = env.unwrapped

    obs, info = env.reset(seed=seed)
    k = env.action_space.shape[0]
    t, states, acts, dist, energy = [0.0], [u.physics_state], [], [info["distance"]], [info["energy"]]
    terms: dict[str, list[float]] = {}
    done = False
    while not done:
        a = np.asarray(agent(obs[None, :]), dtype=np.float32).reshape(k)
        obs, _, term, trunc, info = env.step(a)
        done = term or trunc
        t.append(info["t"])
        states.append(u.physics_state)
        acts.append(np.clip(a, -1, 1).astype(np.float64))
        dist.append(info["distance"])
        energy.append(info["energy"])
        for name, v in info["reward_terms"].items():
            terms.setdefault(name, [0.0]).append(v)
    target = u.target
    env.close()
    return {
        "t": np.array(t),
        "states": np.array(states).T,
        "actions": np.array(acts + [np.zeros(k)]),
        "reward_terms": {n: np.array(v) for n, v in terms.items()},
        "distance": np.array(dist),
        "energy": np.array(energy),
        "target": target,
        "success": bool(info["is_success"]),
        "failure": end_reason(int(info["status"]), int(info["domain_code"]), info["integrator"]["method"]) or None,
        "tolerance": u.task.success_tolerance,
        "body": u.body,
        "env_id": env_id,
        "path": wrapper.recorded_paths[0] if wrapper is not None and wrapper.recorded_paths else None,
    }


def _task(env_id: str) -> str:
    """The task's id, marked when it is a deprecated v0 id (kept for the agents trained on it)."""
    return f"{env_id} (deprecated v0 id)" if env_id.endswith("-v0") else env_id


def outcome(ep: dict[str, Any]) -> str:
    """How the episode ended, in words: on the target or not, when it first came within the tolerance, and what
    ended it early (an integrator failure, leaving the domain or the tolerance)."""
    t, d, tol = ep["t"], ep["distance"], ep["tolerance"]
    reached = np.flatnonzero(d <= tol)
    first = (
        f"first within tolerance {tol:g} at t = {t[reached[0]]:.2f}"
        if reached.size
        else f"never within tolerance {tol:g}"
    )
    if ep["success"]:
        text = f"SUCCESS: on the target ellipse at t = {t[-1]:.2f} ({first})"
    else:
        text = f"MISSED: not on the target at t = {t[-1]:.2f} ({first}; distance {d[0]:.4f} -> {d[-1]:.4f})"
    if ep["failure"]:
        text += f"; the episode ended early at t = {t[-1]:.2f}: {ep['failure']}"
    return text


def format_demo(ep: dict[str, Any], *, seed: int, label: str, rows: int = 9, command: str = "flatbody demo") -> str:
    """The short summary printed by ``flatbody demo`` (and ``flatbody record --agent``, ``command``): a first line
    that says who steered which task and how it ended (:func:`outcome`), the target, a table of the distance and the
    state over time, and the distance's first and last values."""
    tg = ep["target"]
    t, d, y = ep["t"], ep["distance"], ep["states"]
    tol = ep["tolerance"]
    reached = np.flatnonzero(d <= tol)
    lines = [
        f"{command}: {label} on {_task(ep.get('env_id', 'FlatBody-v0'))}, seed {seed}: {outcome(ep)}",
        f"target: lambda* = {tg['lambda']:.4f}, mu* = {tg['mu']:.4f}, rho* = {tg['rho']:.4f}, s3* = {tg['s3']:+.4f}, "
        f"p_theta = {tg['p_theta']:+.4f} (omega3* = {tg['omega3']:+.4f}, theta_dot* = {tg['theta_dot']:+.4f})",
        "",
        f"{'t':>7} {'distance':>9} {'lambda':>8} {'mu':>8} {'rho':>8} {'s3':>8} {'|(w1,w2)|':>9} {'energy':>9}",
    ]
    from flatbody_env.env.task import ReachStationaryEllipse

    w1, w2 = ReachStationaryEllipse.omega12(y, ep["body"])
    for k in np.unique(np.linspace(0, t.size - 1, rows).round().astype(int)):
        lines.append(
            f"{t[k]:7.2f} {d[k]:9.4f} {y[7, k]:8.4f} {y[8, k]:8.4f} {y[9, k]:8.4f} {y[2, k]:+8.4f} "
            f"{math.hypot(w1[k], w2[k]):9.4f} {ep['energy'][k]:9.4f}"
        )
    lines.append("")
    first = f"first within tolerance at t = {t[reached[0]]:.2f}" if reached.size else "never within tolerance"
    verdict = "SUCCESS: on the target ellipse" if ep["success"] else "not on the target at the end"
    if ep["failure"]:
        verdict += f" (episode ended early: {ep['failure']})"
    lines.append(f"distance {d[0]:.4f} -> {d[-1]:.4f} (tolerance {tol:g}); {first}; {verdict}")
    return "\n".join(lines)


def run_demo(
    *,
    model: str | Path | None = None,
    seed: int = 7,
    out: str | None = "demo.rrd",
    backend: str = "auto",
    docs: str | Path | None = None,
    command: str = "flatbody demo",
) -> int:
    """Run the demo; returns the exit code (0 also when the agent misses: the summary says so).

    With ``docs`` (a Markdown page) the printed summary also replaces the transcript between the
    page's ``<!-- demo:transcript -->`` markers: a ``text`` block of ``$ COMMAND`` and the output,
    so the README's transcript is regenerated by the demo itself and never typed
    (:func:`flatbody_env.output.replace_marked_block`).

    The policy runs as exported numpy (``policy.npz``, :mod:`agents.numpy_policy`) when it is
    current, so the demo imports neither torch nor SB3 (``backend``: :data:`agents.evaluate.POLICY_BACKENDS`)."""
    from agents.evaluate import Agent

    agent = Agent(model, backend=backend)
    ep = rollout(
        agent,
        seed=seed,
        env_kwargs=agent.env_kwargs,
        record_to=out or None,
        title=f"flatbody demo (seed {seed})",
        env_id=agent.env_id,
    )
    label = "the shipped agent" if model is None else f"agent {agent.path}"
    lines = [format_demo(ep, seed=seed, label=label)]
    if ep["path"] is not None:
        lines.append(f"wrote {ep['path']} (open with: rerun {ep['path']})")
    output = "\n".join(lines)
    print(output)
    if docs:
        from flatbody_env.output import replace_marked_block

        replace_marked_block(docs, "transcript", f"```text\n$ {command}\n{output}\n```", kind="demo")
        print(f"updated the transcript in {docs}")
    return 0

"""The timing worker of ``flatbody bench compare``: run as a script (``python -P compare_worker.py``) with one source
tree first on ``PYTHONPATH``, it times the core figures of *that* tree's code on request.

It runs against any revision, old or new, so it imports nothing of the bench wing (an older tree has no harness, or
another one) and uses only the public faces every revision has: ``gym.make`` of a FlatBody id,
``FlatBodyVectorEnv``, ``simulate``, the ``flatbody record-env`` command, stable-baselines3's PPO, the task's planner
(``agents.planner``: a revision before it reports that figure as not timed). It times its own
blocks (the clock is in the process that runs the code) and answers the parent, which alternates the two trees'
workers (:func:`flatbody_env.bench.compare.run`), one JSON line per request on its own pipe; everything the code
prints goes to stderr.

Requests: ``{"do": "hello"}`` → the tree's package path and the FlatBody ids it registers; ``{"do": "setup",
"figure": F, "env": ID}`` → builds the figure's state and runs one untimed block (compiling, caches); ``{"do":
"time", "figure": F}`` → ``{"seconds": s, "count": n}``, one timed block of n units; ``{"do": "quit"}``.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import tempfile
import time
import traceback
import warnings

CANDIDATE_IDS = ("FlatBody-v1", "FlatBody-v0")
"""The single-env ids a figure may run on, newest first (the parent picks the first both trees register)."""

ENV_STEPS = 1000
VECTOR_N = 1024
VECTOR_STEPS = 20
SIMULATE_CALLS = 10
RECORD_STEPS = 100
PPO_ENVS = 8
PPO_STEPS = 512
PLANNER_EPISODES = 8
PLANNER_STEPS = 5
"""The sizes of a timed block (module docstring of :mod:`flatbody_env.bench.compare`)."""

_state: dict = {}


def _env_step(env_id: str):
    import gymnasium as gym
    import numpy as np

    env = gym.make(env_id)
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)

    def block() -> int:
        for _ in range(ENV_STEPS):
            _, _, term, trunc, _ = env.step(action)
            if term or trunc:
                env.reset()
        return ENV_STEPS

    return block


def _vector_step(env_id: str):
    import gymnasium as gym
    import numpy as np

    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    env = FlatBodyVectorEnv(num_envs=VECTOR_N, **dict(gym.spec(env_id).kwargs))
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, env.action_space.shape).astype(np.float32)

    def block() -> int:
        for _ in range(VECTOR_STEPS):
            env.step(actions)
        return VECTOR_STEPS * VECTOR_N

    return block


def _simulate(env_id: str):
    from flatbody_env.simulation import simulate

    def block() -> int:
        for _ in range(SIMULATE_CALLS):
            simulate("planar-v3", t_end=100.0, method="DOP853-numba", model="two-polar")
        return SIMULATE_CALLS

    return block


def _recording(env_id: str):
    from flatbody_env.cli.main import main

    folder = tempfile.mkdtemp(prefix="flatbody-compare-rec-")
    path = os.path.join(folder, "episode.rrd")
    argv = ["record-env", "--env-id", env_id, "--max-steps", str(RECORD_STEPS), "--out", path]

    def block() -> int:
        if main(argv) != 0:
            raise RuntimeError(f"flatbody {' '.join(argv)} failed")
        return 1

    return block


def _ppo(env_id: str):
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    torch.set_num_threads(1)
    venv = make_vec_env(env_id, n_envs=PPO_ENVS, seed=0)
    model = PPO("MlpPolicy", venv, n_steps=PPO_STEPS, batch_size=256, n_epochs=4, seed=0, device="cpu", verbose=0)

    def block() -> int:
        model.learn(total_timesteps=PPO_ENVS * PPO_STEPS, reset_num_timesteps=False, progress_bar=False)
        return 1

    return block


def _planner(env_id: str):
    from agents.evaluate import env_kwargs_for
    from agents.planner import Planner, settings_for
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    kwargs = env_kwargs_for(env_id)
    env = FlatBodyVectorEnv(num_envs=PLANNER_EPISODES, **kwargs)
    obs = [env.reset(seed=10000)[0]]
    settings = settings_for(env_id)
    planner = Planner(kwargs, PLANNER_EPISODES, settings, seed=0)
    to_end = getattr(settings, "to_end", False)  # a tree whose planner has no horizon to the episode's end: False

    def block() -> int:
        for _ in range(PLANNER_STEPS):
            left = (env.max_episode_steps - env.episode_steps,) if to_end else ()
            obs[0] = env.step(planner.act(obs[0], env.body_params, *left))[0]
        return PLANNER_STEPS * PLANNER_EPISODES

    return block


FIGURES = {
    "env-step": _env_step,
    "vector-step": _vector_step,
    "simulate": _simulate,
    "recording": _recording,
    "ppo": _ppo,
    "planner": _planner,
}


def _answer(request: dict) -> dict:
    do = request.get("do")
    if do == "hello":
        import gymnasium as gym

        import flatbody_env

        asked = request.get("env")
        registered = [e for e in ((asked,) if asked else CANDIDATE_IDS) if e in gym.registry]
        return {"package": os.path.dirname(os.path.abspath(flatbody_env.__file__)), "envs": registered}
    if do == "setup":
        block = FIGURES[request["figure"]](request["env"])
        block()  # untimed: compiling, caches, the first episode
        _state[request["figure"]] = block
        return {"ready": True}
    if do == "time":
        block = _state[request["figure"]]
        start = time.perf_counter()
        count = block()
        return {"seconds": time.perf_counter() - start, "count": count}
    raise ValueError(f"unknown request {do!r}")


def serve() -> None:
    """Answer requests from stdin until ``quit`` (module docstring)."""
    answers = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # anything the code prints goes to stderr, not into the answers
    warnings.simplefilter("ignore")
    os.environ.setdefault("RUST_LOG", "off")
    for line in sys.stdin:
        request = json.loads(line)
        if request.get("do") == "quit":
            break
        try:
            with contextlib.redirect_stdout(sys.stderr):
                reply = _answer(request)
        except Exception as exc:  # the parent reports it with the worker's stderr
            traceback.print_exc()
            reply = {"error": f"{type(exc).__name__}: {exc}"}
        answers.write(json.dumps(reply) + "\n")


if __name__ == "__main__":
    serve()

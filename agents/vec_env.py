"""An SB3 ``VecEnv`` over :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv`.

Stable-Baselines3 2.x cannot consume a ``gymnasium.vector.VectorEnv``: it expects SAME_STEP
autoreset (a finished sub-environment is reset inside the same ``step``, its last observation
kept in ``infos[i]["terminal_observation"]``) and ``infos[i]["TimeLimit.truncated"]``. This
adapter runs the native batch in its SAME_STEP autoreset mode and translates the infos; it uses
the vector env's public API only.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from flatbody_env.env.vector_env import FlatBodyVectorEnv


class FlatBodySB3VecEnv(VecEnv):
    """SB3 view of N batched bodies of any id of docs/tasks.md (``FlatBody-v1`` by default).

    Parameters
    ----------
    num_envs : int
    seed : int, optional
        Seeds sub-environment i with ``seed + i`` on the first reset.
    **kwargs
        Passed to :class:`FlatBodyVectorEnv` (``max_episode_steps`` and the env's keywords).
    """

    def __init__(self, num_envs: int, seed: int | None = None, **kwargs: Any) -> None:
        self.venv = FlatBodyVectorEnv(num_envs=num_envs, autoreset_mode=AutoresetMode.SAME_STEP, **kwargs)
        super().__init__(num_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self._seed = seed
        self._actions: np.ndarray | None = None

    def reset(self):
        obs, _ = self.venv.reset(seed=self._seed)
        self._seed = None
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self):
        obs, rewards, terminated, truncated, info = self.venv.step(self._actions)
        dones = terminated | truncated
        infos: list[dict[str, Any]] = []
        for i in range(self.num_envs):
            d = {
                "distance": float(info["distance"][i]),
                "is_success": bool(info["is_success"][i]),
                "energy": float(info["energy"][i]),
                "reward_terms": {k: float(x[i]) for k, x in info["reward_terms"].items()},
                "status": int(info["status"][i]),
                "domain_code": int(info["domain_code"][i]),
                "TimeLimit.truncated": bool(truncated[i] and not terminated[i]),
            }
            if dones[i]:
                d["terminal_observation"] = info["final_obs"][i].copy()
            infos.append(d)
        return obs, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self.venv, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        return [getattr(self.venv, method_name)(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def seed(self, seed: int | None = None):
        self._seed = seed
        return [None if seed is None else seed + i for i in range(self.num_envs)]

    def get_images(self):
        return [None for _ in range(self.num_envs)]

"""The Gymnasium environment ``FlatBody-v0`` and the other tasks of ``docs/tasks.md``: body + integrator + task.

Importing this package registers every task id with Gymnasium (:mod:`flatbody_env.env.registration`).
"""

from __future__ import annotations

from flatbody_env.env.registration import ENV_ID, MAX_EPISODE_STEPS, register_envs

register_envs()


def __getattr__(name: str):
    """Lazy access to the environment classes."""
    if name == "FlatBodyEnv":
        from flatbody_env.env.env import FlatBodyEnv

        return FlatBodyEnv
    if name == "FlatBodyVectorEnv":
        from flatbody_env.env.vector_env import FlatBodyVectorEnv

        return FlatBodyVectorEnv
    if name == "FlatBodyTorchVectorEnv":  # imports torch
        from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv

        return FlatBodyTorchVectorEnv
    raise AttributeError(f"module 'flatbody_env.env' has no attribute {name!r}")


__all__ = ["ENV_ID", "FlatBodyEnv", "FlatBodyTorchVectorEnv", "FlatBodyVectorEnv", "MAX_EPISODE_STEPS", "register_envs"]

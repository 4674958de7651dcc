"""Registers ``FlatBody-v0`` with Gymnasium when :mod:`flatbody_env` is imported.

``gym.make("FlatBody-v0")`` (or ``gym.make("flatbody_env:FlatBody-v0")``, which imports the
package first) builds :class:`~flatbody_env.env.env.FlatBodyEnv` inside PassiveEnvChecker,
OrderEnforcing and a TimeLimit of 400 steps; ``gym.make_vec("FlatBody-v0", num_envs,
vectorization_mode="vector_entry_point")`` builds the natively batched
:class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv` (it truncates by itself).
"""

from __future__ import annotations

ENV_ID = "FlatBody-v0"
MAX_EPISODE_STEPS = 400


def register_envs() -> None:
    import gymnasium

    if ENV_ID in gymnasium.registry:
        return
    gymnasium.register(
        id=ENV_ID,
        entry_point="flatbody_env.env.env:FlatBodyEnv",
        vector_entry_point="flatbody_env.env.vector_env:FlatBodyVectorEnv",
        max_episode_steps=MAX_EPISODE_STEPS,
    )

"""The vector entry point of every registered id: ``gym.make_vec(ID, n, vectorization_mode="vector_entry_point")``
builds the natively batched numpy env, and with ``device=`` the torch one (the faces of the one transition, on top of
them all)."""

from __future__ import annotations

from typing import Any


def make_vector_env(num_envs: int = 1, device=None, **kwargs: Any) -> Any:
    """The vector entry point of every registered id (``gym.make_vec(ID, n, vectorization_mode="vector_entry_point",
    device=...)``): :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv` (numpy) without ``device``, else
    :class:`~flatbody_env.env.torch_vector_env.FlatBodyTorchVectorEnv` on that device (``"cpu"`` or ``"cuda"``; torch
    tensors, SAME_STEP autoreset unless ``autoreset_mode`` says otherwise)."""
    if device is None:
        from flatbody_env.env.vector_env import FlatBodyVectorEnv

        return FlatBodyVectorEnv(num_envs, **kwargs)
    from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv  # torch only when a device is asked for

    return FlatBodyTorchVectorEnv(num_envs, device=device, **kwargs)


__all__ = ["make_vector_env"]

"""flatbody_env — a flat affinely-rigid body with thickness: physics, simulation, environment.

The model is the paper's (``shared/paper/000_b5acfe912a09eb12.txt``, sections 3–3.4) with the
corrections of ``shared/physics/NOTES.md``. Scripting entry points::

    from flatbody_env import load_scene, simulate
    traj = simulate(load_scene("default"), t_end=20.0)
"""

from __future__ import annotations

from .body import Body, Inertia, default_body
from .integrators import IntegrationError, available_methods, get_method
from .potentials import CustomPotential, ThicknessPotential, V1, V2, V3
from .scene import Scene, SceneError, builtin_scenes, load_scene
from .simulation import Trajectory, simulate
from .state import STATE_NAMES, pack, unpack

__version__ = "0.1.0"

from .registration import register_envs as _register_envs

_register_envs()


def __getattr__(name: str):
    """Lazy access to the environment classes (they import gymnasium's spaces)."""
    if name == "FlatBodyEnv":
        from .env import FlatBodyEnv

        return FlatBodyEnv
    if name == "FlatBodyVectorEnv":
        from .vector_env import FlatBodyVectorEnv

        return FlatBodyVectorEnv
    raise AttributeError(f"module 'flatbody_env' has no attribute {name!r}")

__all__ = [
    "Body",
    "FlatBodyEnv",
    "FlatBodyVectorEnv",
    "CustomPotential",
    "Inertia",
    "IntegrationError",
    "STATE_NAMES",
    "Scene",
    "SceneError",
    "ThicknessPotential",
    "Trajectory",
    "V1",
    "V2",
    "V3",
    "available_methods",
    "builtin_scenes",
    "default_body",
    "get_method",
    "load_scene",
    "pack",
    "simulate",
    "unpack",
]

"""flatbody_env — a flat affinely-rigid body with thickness: physics, simulation, environment.

Scripting entry points (importing them loads numpy and scipy only)::

    from flatbody_env import load_scene, simulate
    traj = simulate(load_scene("default"), t_end=20.0)

The wings: :mod:`flatbody_env.physics` (the model), :mod:`flatbody_env.integrators`,
:mod:`flatbody_env.env` (``FlatBody-v0``), :mod:`flatbody_env.recording` (rerun files) and
:mod:`flatbody_env.cli` (the ``flatbody`` command). ``FlatBody-v0`` is registered with Gymnasium
as soon as both this package and ``gymnasium`` are imported, in either order, without this
package importing gymnasium itself.
"""

from __future__ import annotations

import sys

from flatbody_env.integrators import IntegrationError, available_methods, get_method
from flatbody_env.physics.body import Body, Inertia, default_body
from flatbody_env.physics.potentials import CustomPotential, ThicknessPotential, V1, V2, V3
from flatbody_env.physics.state import STATE_NAMES, pack, unpack
from flatbody_env.scene import Scene, SceneError, builtin_scenes, load_scene
from flatbody_env.simulation import Trajectory, simulate
from flatbody_env.batch import BatchTrajectory, simulate_batch

__version__ = "0.1.0"


def _register_when_gymnasium_is_imported() -> None:
    """Register ``FlatBody-v0`` now if gymnasium is loaded, else right after it is first imported."""
    if "gymnasium" in sys.modules:
        import flatbody_env.env  # noqa: F401  (registers on import)

        return
    import importlib.abc
    import importlib.machinery

    class _AfterGymnasium(importlib.abc.MetaPathFinder):
        def find_spec(self, fullname, path, target=None):
            if fullname != "gymnasium":
                return None
            spec = importlib.machinery.PathFinder.find_spec(fullname, path)
            if spec is None or spec.loader is None:
                return None
            exec_module = spec.loader.exec_module

            def exec_then_register(module):
                exec_module(module)
                sys.meta_path[:] = [f for f in sys.meta_path if not isinstance(f, _AfterGymnasium)]
                import flatbody_env.env  # noqa: F401  (registers on import)

            spec.loader.exec_module = exec_then_register
            return spec

    if not any(type(f).__name__ == "_AfterGymnasium" for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterGymnasium())


_register_when_gymnasium_is_imported()


def __getattr__(name: str):
    """Lazy access to the environment classes (they import gymnasium)."""
    if name in ("FlatBodyEnv", "FlatBodyVectorEnv", "FlatBodyTorchVectorEnv"):
        import flatbody_env.env as env

        return getattr(env, name)
    raise AttributeError(f"module 'flatbody_env' has no attribute {name!r}")


__all__ = [
    "BatchTrajectory",
    "Body",
    "CustomPotential",
    "FlatBodyEnv",
    "FlatBodyTorchVectorEnv",
    "FlatBodyVectorEnv",
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
    "simulate_batch",
    "unpack",
]

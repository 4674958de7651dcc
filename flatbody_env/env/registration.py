"""Registers the flatbody tasks with Gymnasium when :mod:`flatbody_env` is imported.

Every id builds :class:`~flatbody_env.env.env.FlatBodyEnv` (body + integrator + task) with the task
and keyword arguments of its :class:`TaskSpec` (:data:`TASKS`): ``gym.make(ID)`` (or
``gym.make("flatbody_env:ID")``, which imports the package first) wraps it in PassiveEnvChecker,
OrderEnforcing and a TimeLimit of ``max_episode_steps``; ``gym.make_vec(ID, num_envs,
vectorization_mode="vector_entry_point")`` builds the natively batched
:class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv` with the same keywords (it truncates by
itself). Keywords given to ``gym.make`` override the registered ones. ``docs/tasks.md`` is the
page of each task.

This module stays light (no numpy, no task classes): the task classes are named by dotted path
(:data:`TASK_CLASSES`) and imported by the environment.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

ENV_ID = "FlatBody-v1"
MAX_EPISODE_STEPS = 400
"""Steps of every registered task (t = 20 at dt = 0.05)."""

TASK_CLASSES = {
    "reach": "flatbody_env.env.task:ReachStationaryEllipse",
    "hold-unstable": "flatbody_env.env.hold:HoldUnstableEllipse",
    "reach-witnessed": "flatbody_env.env.witness:ReachWithWitness",
    "any-body": "flatbody_env.env.any_body:ReachAnyBody",
}
"""The tasks :class:`~flatbody_env.env.env.FlatBodyEnv` composes (``task=NAME``), by module path."""


@dataclass(frozen=True, kw_only=True)
class TaskSpec:
    """A registered id: which task, with which keywords, and what it is for (``docs/tasks.md``)."""

    env_id: str
    kwargs: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments of :class:`~flatbody_env.env.env.FlatBodyEnv` (``task``, ``control`` and the task's fields)."""
    max_episode_steps: int = MAX_EPISODE_STEPS
    summary: str = ""
    rung: str = ""
    """The v1 suite's ladder: ``"easy"``, ``"medium"`` or ``"hard"`` (docs/tasks.md says why); "" for the v0 ids."""

    @property
    def version(self) -> int:
        """The id's version (``-vN``)."""
        return int(self.env_id.rsplit("-v", 1)[1])


V1 = {"reward": "tolerance", "draws": "philox"}
"""What every v1 id adds to its task: the tolerance reward and the transition's counter-based draws."""

TASKS = (
    TaskSpec(
        env_id="FlatBody-v1",
        kwargs={"task": "reach", **V1},
        rung="easy",
        summary="reach a stable stationary ellipse that linear feedback settles fast (settling rate r >= 0.15/s)",
    ),
    TaskSpec(
        env_id="FlatBodySlow-v1",
        kwargs={"task": "reach", "min_settling_rate": 0.05, **V1},
        rung="easy",  # a classic law reaches 91 % (the LQR with centrifugal pumping, docs/tasks.md)
        summary="reach a stable ellipse whose slowest mode settles at r >= 0.05/s under linear feedback",
    ),
    TaskSpec(
        env_id="FlatBodySlowHard-v1",
        kwargs={"task": "reach", "min_settling_rate": 0.0, **V1},
        rung="hard",
        summary="reach any stable ellipse of the circulation family in the same shapes (no settling-rate floor)",
    ),
    TaskSpec(
        env_id="FlatBodyHoldUnstable-v1",
        kwargs={"task": "hold-unstable", "min_growth_rate": 0.25, "start_radius": (0.5, 0.9), **V1},
        rung="medium",
        summary="stay within the tolerance of a hyperbolic (unstable) stationary ellipse for the whole episode",
    ),
    TaskSpec(
        env_id="FlatBodyTorque-v1",
        kwargs={
            "task": "reach-witnessed",
            "control": "torque",
            "min_uncontrolled_offset": 0.05,
            "max_witness_attempts": 400,  # 400 witness runs of 400 steps at most: the reset bound
            **V1,
        },
        rung="hard",
        summary="reach a stable ellipse with torque only, from witnessed starts off in the uncontrolled thickness",
    ),
    TaskSpec(
        env_id="FlatBodyAnyBody-v1",
        kwargs={"task": "any-body", "observe_body": False, "min_settling_rate": 0.0, **V1},
        rung="hard",
        summary="reach a stable ellipse of a body drawn per episode whose constants are not observed",
    ),
    TaskSpec(env_id="FlatBody-v0", kwargs={"task": "reach"}, summary="deprecated: FlatBody-v1"),
    TaskSpec(
        env_id="FlatBodySlow-v0",
        kwargs={"task": "reach", "min_settling_rate": 0.0},
        summary="deprecated: FlatBodySlowHard-v1",
    ),
    TaskSpec(
        env_id="FlatBodyHoldUnstable-v0",
        kwargs={"task": "hold-unstable"},
        summary="deprecated: FlatBodyHoldUnstable-v1",
    ),
    TaskSpec(
        env_id="FlatBodyTorque-v0",
        kwargs={"task": "reach-witnessed", "control": "torque", "min_uncontrolled_offset": 0.05},
        summary="deprecated: FlatBodyTorque-v1",
    ),
    TaskSpec(
        env_id="FlatBodyDilatation-v0",
        kwargs={"task": "reach-witnessed", "control": "dilatation"},
        summary="retired in v1 (breathing cannot move the shape within an episode: the passivity law solves it)",
    ),
    TaskSpec(env_id="FlatBodyAnyBody-v0", kwargs={"task": "any-body"}, summary="deprecated: FlatBodyAnyBody-v1"),
)
"""The registered tasks, in the order of ``docs/tasks.md``."""

TASK_IDS = tuple(spec.env_id for spec in TASKS)
V1_IDS = tuple(spec.env_id for spec in TASKS if spec.version == 1)
"""The v1 suite, in the order of its ladder (docs/tasks.md)."""


def task_spec(env_id: str) -> TaskSpec:
    """The :class:`TaskSpec` of a registered id; ``ValueError`` naming ``env`` otherwise."""
    for spec in TASKS:
        if spec.env_id == env_id:
            return spec
    from flatbody_env.physics import validation

    raise validation.refusal("env", f"be one of {', '.join(TASK_IDS)}", env_id)


def register_envs() -> None:
    import gymnasium

    for spec in TASKS:
        if spec.env_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=spec.env_id,
            entry_point="flatbody_env.env.env:FlatBodyEnv",
            vector_entry_point="flatbody_env.env.vector_entry:make_vector_env",
            max_episode_steps=spec.max_episode_steps,
            kwargs=dict(spec.kwargs),
        )

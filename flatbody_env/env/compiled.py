"""Compiled twins of the task's kernels (:mod:`flatbody_env.env.task`) and of the bookkeeping
(:mod:`flatbody_env.env.kernels`) (numba, on-disk cache).

The same plain-float code, compiled by :func:`flatbody_env.integrators.jit.retarget` with every
function it calls (the physics kernels included) re-bound to its compiled copy, recursively — no
formula is restated, no callee listed by hand. Used by the v0 ids' host draws (the episode sampler,
:mod:`flatbody_env.env.sampling`) and by :meth:`flatbody_env.env.core.EnvCore.rollout`; the transition's own loops
are compiled by :func:`flatbody_env.env.transition.cpu`.
"""

from __future__ import annotations

from flatbody_env.env import kernels as _ek
from flatbody_env.env import sampling as _sampling
from flatbody_env.env import task as _task
from flatbody_env.integrators.jit import retarget

omega12_kernel = retarget(_task.omega12_kernel)
score_kernel = retarget(_task.score_kernel)
observe_kernel = retarget(_task.observe_kernel)
domain_code = retarget(_task.domain_code)
domain_codes = retarget(_task.domain_codes)
post_step = retarget(_ek.post_step)
post_step_lanes = retarget(_ek.post_step_lanes)
controls_batch = retarget(_ek.controls_batch)
ball_state_kernel = retarget(_sampling.ball_state_kernel)
sample_episodes = retarget(_sampling.sample_episodes)  # the reset's draws (:mod:`flatbody_env.env.sampling`)

__all__ = [
    "ball_state_kernel",
    "controls_batch",
    "domain_code",
    "domain_codes",
    "observe_kernel",
    "omega12_kernel",
    "post_step",
    "post_step_lanes",
    "sample_episodes",
    "score_kernel",
]

"""Compiled twins of the task's kernels (:mod:`flatbody_env.env.task`) and of the bookkeeping
(:mod:`flatbody_env.env.kernels`) (numba, on-disk cache).

The same plain-float code, compiled by :func:`flatbody_env.integrators.jit.retarget` with every
function it calls (the physics kernels included) re-bound to its compiled copy, recursively — no
formula is restated, no callee listed by hand. Used by :meth:`flatbody_env.env.core.EnvCore.rollout` (the v0
ids' witnessed starts) and by the tests; the transition's own loops are compiled by
:func:`flatbody_env.env.transition.cpu`.
"""

from __future__ import annotations

from flatbody_env.env import kernels as _ek
from flatbody_env.env import task as _task
from flatbody_env.integrators.jit import retarget

domain_codes = retarget(_task.domain_codes)
post_step = retarget(_ek.post_step)
post_step_lanes = retarget(_ek.post_step_lanes)

__all__ = [
    "domain_codes",
    "post_step",
    "post_step_lanes",
]

"""Compiled twins of the task's kernels (:mod:`flatbody_env.env.task`) and of the bookkeeping
(:mod:`flatbody_env.env.kernels`) (numba, on-disk cache).

The same plain-float code is re-bound to the integrators' jitted physics kernels with
:func:`flatbody_env.integrators.jit.jit_copy` — no formula is restated. Used by
:class:`~flatbody_env.env.env.FlatBodyEnv` and :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv`
whenever the integrator runs compiled (:attr:`flatbody_env.integrators.steppers.EnvStepper.compiled`).
"""

from __future__ import annotations

from flatbody_env.env import kernels as _ek
from flatbody_env.env import task as _task
from flatbody_env.integrators.jit import jit_copy, kinetic_kernel, potential_kernel

omega12_kernel = jit_copy(_task.omega12_kernel)
score_kernel = jit_copy(_task.score_kernel, omega12_kernel=omega12_kernel)
observe_kernel = jit_copy(_task.observe_kernel)
domain_code = jit_copy(_task.domain_code)
post_step = jit_copy(_ek.post_step, domain_code=domain_code, score_kernel=score_kernel, observe_kernel=observe_kernel,
                     kinetic_kernel=kinetic_kernel, potential_kernel=potential_kernel)
post_step_batch = jit_copy(_ek.post_step_batch, post_step=post_step)
controls_kernel = jit_copy(_ek.controls_kernel)
controls_batch = jit_copy(_ek.controls_batch, controls_kernel=controls_kernel)

__all__ = ["controls_batch", "controls_kernel", "domain_code", "observe_kernel", "omega12_kernel", "post_step", "post_step_batch", "score_kernel"]

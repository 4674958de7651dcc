"""Compiled twins of the task's kernels (:mod:`flatbody_env.env.task`) and of the bookkeeping
(:mod:`flatbody_env.env.kernels`) (numba, on-disk cache).

The same plain-float code is re-bound to the integrators' jitted physics kernels with
:func:`flatbody_env.integrators.jit.jit_copy` — no formula is restated. Used by
:class:`~flatbody_env.env.env.FlatBodyEnv` and :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv`
whenever the integrator runs compiled (:attr:`flatbody_env.integrators.steppers.EnvStepper.compiled`).
"""

from __future__ import annotations

from flatbody_env.env import kernels as _ek
from flatbody_env.env import sampling as _sampling
from flatbody_env.env import targets as _targets
from flatbody_env.env import task as _task
from flatbody_env.integrators.jit import jit_copy, kinetic_iso, kinetic_kernel, potential_kernel
from flatbody_env.physics import equilibria as _eq

omega12_kernel = jit_copy(_task.omega12_kernel)
score_kernel = jit_copy(_task.score_kernel, omega12_kernel=omega12_kernel)
observe_kernel = jit_copy(_task.observe_kernel)
domain_code = jit_copy(_task.domain_code)
post_step = jit_copy(_ek.post_step, domain_code=domain_code, score_kernel=score_kernel, observe_kernel=observe_kernel,
                     kinetic_kernel=kinetic_kernel, potential_kernel=potential_kernel)
post_step_lanes = jit_copy(_ek.post_step_lanes, domain_code=domain_code, score_kernel=score_kernel, observe_kernel=observe_kernel,
                           kinetic_kernel=kinetic_kernel, kinetic_iso=kinetic_iso, potential_kernel=potential_kernel)
controls_batch = jit_copy(_ek.controls_batch)
# the reset's draws (:mod:`flatbody_env.env.sampling`)
_stencil_step = jit_copy(_eq.stencil_step)
_stationary_shape_kernel = jit_copy(_eq.stationary_shape_kernel, squared_sigmas_kernel=jit_copy(_eq.squared_sigmas_kernel),
                                    stencil_step=_stencil_step, smallest_eigenvalue_sym3=jit_copy(_eq.smallest_eigenvalue_sym3))
_candidate_kernel = jit_copy(_sampling.candidate_kernel, decide_kernel=jit_copy(_targets.decide_kernel),
                             potential_stencil_kernel=jit_copy(_sampling.potential_stencil_kernel, stencil_step=_stencil_step,
                                                               potential_kernel=potential_kernel),
                             stationary_shape_kernel=_stationary_shape_kernel)
sample_episodes = jit_copy(_sampling.sample_episodes, sample_episode_kernel=jit_copy(
    _sampling.sample_episode_kernel, candidate_kernel=_candidate_kernel, initial_state_kernel=jit_copy(_sampling.initial_state_kernel)))

__all__ = ["controls_batch", "domain_code", "observe_kernel", "omega12_kernel", "post_step", "post_step_lanes", "sample_episodes", "score_kernel"]

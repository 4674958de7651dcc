"""Compiled twins of :mod:`flatbody_env.env.kernels` (numba, on-disk cache).

The same plain-float code is re-bound to the integrators' jitted physics kernels with
:func:`flatbody_env.integrators.jit.jit_copy` — no formula is restated. Used by
:class:`~flatbody_env.env.env.FlatBodyEnv` and :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv`
whenever the integrator has a compiled environment stepper.
"""

from __future__ import annotations

from flatbody_env.env import kernels as _ek
from flatbody_env.integrators.jit import jit_copy, kinetic_kernel, potential_kernel

domain_code = jit_copy(_ek.domain_code)
post_step = jit_copy(_ek.post_step, domain_code=domain_code, kinetic_kernel=kinetic_kernel, potential_kernel=potential_kernel)
post_step_batch = jit_copy(_ek.post_step_batch, post_step=post_step)
controls_kernel = jit_copy(_ek.controls_kernel)

__all__ = ["domain_code", "post_step", "post_step_batch", "controls_kernel"]

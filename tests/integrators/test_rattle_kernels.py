"""RATTLE's kernels run the physics layer's own kernels (compiled by :func:`~flatbody_env.integrators.jit.retarget`), restating none."""

from __future__ import annotations

import types

import numba

from flatbody_env.integrators import rattle_kernels as rk
from flatbody_env.integrators.jit import _names
from flatbody_env.physics import kinematics, potentials, regular

PHYSICS = {
    "column_dot": kinematics.column_dot,
    "decompose_kernel": kinematics.decompose_kernel,
    "invariant_gradient_kernel": potentials.invariant_gradient_kernel,
    "forces": regular.regular_forces_kernel,
    "stretches": kinematics.stretches_kernel,
    "regular_energy_kernel": regular.regular_energy_kernel,
}


def test_rattle_compiles_the_physics_code():
    for name, kernel in PHYSICS.items():
        assert getattr(rk, name).py_func.__code__ is kernel.__code__, name


def test_every_function_of_the_module_is_compiled_or_physics():
    """No formula function is defined here beside the physics' ones: each compiled function's code comes from this
    module (the RATTLE step, the chart following, the drivers) or from a physics kernel, and every callee it reads
    is compiled."""
    physics_codes = {k.__code__ for k in PHYSICS.values()} | {potentials.potential_kernel.__code__}
    todo = [v for v in vars(rk).values() if isinstance(v, numba.core.dispatcher.Dispatcher)]
    seen = set()
    while todo:
        py = todo.pop().py_func
        if py.__code__ in seen:
            continue
        seen.add(py.__code__)
        assert py.__module__ == rk.__name__ or py.__code__ in physics_codes, py.__qualname__
        for name in _names(py.__code__):
            value = py.__globals__.get(name)
            assert not isinstance(value, types.FunctionType), f"{py.__name__} calls plain-Python {name}"
            if isinstance(value, numba.core.dispatcher.Dispatcher):
                todo.append(value)

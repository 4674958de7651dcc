"""One way to compile a kernel (:func:`flatbody_env.integrators.jit.retarget`): callees re-bound recursively, none listed by hand.

The CUDA target is checked under the simulator (test_cuda_simulator.py); the on-disk cache in test_jit_cache.py."""

from __future__ import annotations

import types

import numba
import numpy as np

from flatbody_env.integrators import ladder_kernels as lk
from flatbody_env.integrators import twopolar_kernels as tk
from flatbody_env.integrators.jit import _names, retarget


def _reached(func) -> tuple[list, list]:
    """(compiled functions, plain-Python functions) read by ``func``'s code and, recursively, by its compiled callees."""
    seen, plain, todo = {}, [], [func]
    while todo:
        py = todo.pop().py_func
        for name in _names(py.__code__):
            value = py.__globals__.get(name)
            if isinstance(value, numba.core.dispatcher.Dispatcher) and id(value) not in seen:
                seen[id(value)] = value
                todo.append(value)
            elif isinstance(value, types.FunctionType):
                plain.append(f"{py.__name__}.{name}")
    return list(seen.values()), plain


def test_env_kernels_reach_only_compiled_code():
    """env/compiled.py lists no callee: every function beneath its kernels (the task's, the sampler's, the physics') is compiled."""
    from flatbody_env.env import compiled

    for name in compiled.__all__:
        reached, plain = _reached(getattr(compiled, name))
        assert plain == [], name
    reached, _ = _reached(compiled.post_step)
    assert {"score_kernel", "omega12_kernel", "kinetic_kernel", "potential_kernel"} <= {
        f.py_func.__name__ for f in reached
    }


def test_the_ladder_runs_the_two_polar_dop853():
    """One DOP853 step control: the ladder's systems run :func:`~.twopolar_kernels.dop853_advance`'s own code with N re-bound."""
    for solve, n in ((lk.dop853_inplane, 6), (lk.dop853_thickness, 2)):
        glob = solve.py_func.__globals__
        assert glob["N"] == n and glob["rhs_kernel"] is lk.subsystem_rhs
        for name in ("dop853_advance", "dop853_initial_step_into"):
            assert glob[name].py_func.__code__ is getattr(tk, name).py_func.__code__
        stages = glob["dop853_advance"].py_func.__globals__["_dop853_stages"].py_func
        assert stages.__code__ is tk._dop853_stages.py_func.__code__ and stages.__globals__["N"] == n


_K = 3.0


def _scale(x):
    return _K * x


def _inner(x):
    return _scale(x)


def _outer(x):
    return _inner(x) + 1.0


def _twice(x):
    return 2.0 * x


def test_constants_rebind_recursively_and_plain_substitutes_are_compiled():
    assert retarget(_outer)(2.0) == 7.0
    assert retarget(_outer, _K=5.0)(2.0) == 11.0  # a constant read two calls down
    assert retarget(_outer, _inner=_twice)(2.0) == 5.0  # a plain function given as a constant: compiled as the callee
    assert retarget(_outer, _K=5.0) is retarget(_outer, _K=5.0)  # memoised
    assert isinstance(retarget(_outer, _inner=_twice), numba.core.dispatcher.Dispatcher)


def test_subsystem_rhs_is_sub_rhs():
    y = np.array([0.0, 0.0, 1.6, 1.1, 0.2, -0.3, 0.3, 1.5, 0.8, 1.1, 0.2])
    P = np.array([1.0, 1.0, 0.8, 3.0, 1.0, 0.0, 1.0, 1.0, 1.0])
    x = y[lk.INPLANE_STATE[:5]].tolist() + [0.0]
    a, b = np.empty(6), np.empty(6)
    lk.sub_rhs(
        np.array(x),
        y,
        lk.INPLANE_STATE,
        lk.INPLANE_RATE,
        np.zeros(4),
        P,
        a,
        np.empty(11),
        np.empty(12),
        np.empty(7),
        np.empty(4),
    )
    lk.subsystem_rhs(
        np.array(x),
        np.zeros(4),
        (P, y, lk.INPLANE_STATE, lk.INPLANE_RATE),
        b,
        (np.empty(7), np.empty(11), np.empty(12)),
        np.empty(4),
    )
    assert np.array_equal(a, b) and np.all(np.isfinite(a))

"""The compiled methods' one table (flatbody_env.integrators.specs) and the numba-free scipy path."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from flatbody_env.integrators import available_methods, get_method
from flatbody_env.integrators.specs import BATCH_METHODS, ENV_METHODS, GPU_METHODS, ROTATION_METHODS, SPECS

ROOT = Path(__file__).resolve().parents[2]


def test_scipy_path_imports_no_numba():
    """Looking up and running a scipy method (and listing every method) compiles nothing and imports no numba."""
    code = (
        "import sys, numpy as np\n"
        "from flatbody_env.integrators import Tolerances, available_methods, get_method\n"
        "from flatbody_env.physics.body import default_body\n"
        "y = np.array([0.05, 0.0, 1.45, 1.77, 0.02, 0.0, 0.05, 1.4, 0.9, 1.0, 0.0])\n"
        "get_method('DOP853').integrate(default_body(), y, np.array([0.0, 0.1]), tol=Tolerances(), with_rotation=True)\n"
        "assert 'DOP853-numba' in [m.name for m in available_methods()]\n"
        "print('numba' in sys.modules)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "False"


def test_every_map_is_derived_from_the_table():
    from flatbody_env import batch
    from flatbody_env.cli.args import name_list
    from flatbody_env.cli.bench import _gpu_methods
    from flatbody_env.integrators import batch_solve, compiled_methods, rotation_kernels

    names = [s.name for s in SPECS]
    assert [m.name for m in available_methods() if m.compiled] == names
    assert all(get_method(s.name).info is s.info for s in SPECS)
    assert batch.BATCH_METHODS == batch_solve.BATCH_METHODS == BATCH_METHODS == tuple(batch_solve.KIND)
    assert tuple(rotation_kernels.ENV_STEP_WITH_ROTATION) == ROTATION_METHODS
    assert compiled_methods.ENV_METHODS == ENV_METHODS
    assert name_list("methods", _gpu_methods)(",".join(GPU_METHODS)) == list(GPU_METHODS)


def test_every_method_declares_its_check_and_spec():
    """One declared ``check`` on every registered method (the seam calls it; ``integrate`` refuses what it refuses)."""
    import numpy as np
    import pytest

    from flatbody_env.integrators import Tolerances
    from flatbody_env.physics.body import Body, default_body
    from flatbody_env.physics.potentials import CustomPotential

    body = default_body()
    custom = Body(
        inertia=body.inertia,
        potential=CustomPotential(value=lambda l, m, r: 0.5 * (l * l + m * m), gradient=lambda l, m, r: (l, m, 0.0)),
        thickness=body.thickness,
    )
    y = np.array([0.05, 0.0, 1.45, 1.77, 0.02, 0.0, 0.05, 1.4, 0.9, 1.0, 0.0])
    for info in available_methods():
        meth = get_method(info.name)
        assert meth.spec is (None if not info.compiled else next(s for s in SPECS if s.name == info.name))
        tol = Tolerances(step=None if info.adaptive else 0.05)
        assert meth.check(body, tol) == (0.0 if info.adaptive else 0.05)
        with pytest.raises(ValueError, match="^step: "):
            meth.check(body, Tolerances(step=0.05) if info.adaptive else Tolerances())
        if info.compiled:  # a custom potential runs Python code: refused by check and by integrate alike
            for call in (
                lambda meth=meth, tol=tol: meth.check(custom, tol),
                lambda meth=meth, tol=tol: meth.integrate(custom, y, [0.0, 0.1], tol=tol),
            ):
                with pytest.raises(ValueError, match="^potential: "):
                    call()


def test_the_env_steps_compiled_exactly_the_methods_the_table_marks():
    """``spec.env`` decides the compiled stepper and ``spec.fused_batch`` the fused batch (no name checked in the seam);
    RATTLE-suzuki4 steps through ``integrate``, as it always did."""
    from flatbody_env.integrators import Tolerances
    from flatbody_env.integrators.steppers import CompiledEnvStep, GenericEnvStep, make_env_step
    from flatbody_env.physics.body import default_body

    body = default_body()
    assert "RATTLE-suzuki4" not in ENV_METHODS and {s.name for s in SPECS if s.fused_batch} == {"DOP853-numba"}
    for spec in SPECS:
        meth = get_method(spec.name)
        tol = Tolerances(rtol=1e-11, atol=1e-11, step=None if spec.info.adaptive else 0.05)
        st = make_env_step(meth, body, tol, first_step=0.05 if spec.info.adaptive else 0.0)
        assert isinstance(st, CompiledEnvStep if spec.env else GenericEnvStep) and st.method == spec.name
        if spec.env:
            assert (st._fused is not None) == spec.fused_batch


def test_the_env_looks_its_integrator_up_once(monkeypatch):
    """From the env's construction through its steps the method is looked up by name once (its configuration) and
    never in the method table by name: the seam is given the object."""
    import gymnasium as gym
    import numpy as np

    from flatbody_env.integrators import base, compiled_methods, specs

    class Counting(dict):
        looked_up = 0

        def __getitem__(self, key):
            type(self).looked_up += 1
            return super().__getitem__(key)

        def get(self, key, default=None):
            type(self).looked_up += 1
            return super().get(key, default)

    class Table(Counting):
        pass

    for name in ("DOP853-numba", "RK4", "DOP853"):
        Counting.looked_up = Table.looked_up = 0
        monkeypatch.setattr(base, "_REGISTRY", Counting(base._REGISTRY))
        for module in (specs, compiled_methods):
            monkeypatch.setattr(module, "BY_NAME", Table(specs.BY_NAME))
        env = gym.make("FlatBody-v1", integrator=name).unwrapped
        env.reset(seed=0)
        for _ in range(3):
            env.step(np.zeros(env.action_space.shape, np.float32))
        monkeypatch.undo()
        assert (Counting.looked_up, Table.looked_up) == (1, 0), name
        assert env.stepping_integrator == name

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
    from flatbody_env.cli import gpu
    from flatbody_env.integrators import batch_solve, compiled_methods, rotation_kernels

    names = [s.name for s in SPECS]
    assert [m.name for m in available_methods() if m.compiled] == names
    assert all(get_method(s.name).info is s.info for s in SPECS)
    assert batch.BATCH_METHODS == batch_solve.BATCH_METHODS == BATCH_METHODS == tuple(batch_solve.KIND)
    assert tuple(rotation_kernels.ENV_STEP_WITH_ROTATION) == ROTATION_METHODS
    assert compiled_methods.ENV_METHODS == ENV_METHODS
    assert gpu._methods(",".join(GPU_METHODS)) == list(GPU_METHODS)

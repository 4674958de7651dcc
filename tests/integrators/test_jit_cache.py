"""The on-disk cache of the compiled kernels: a caller recompiles when a callee in another file changes."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

CALLER = textwrap.dedent("""
    import callee_mod
    from flatbody_env.integrators.jit import njit, retarget

    g = retarget(callee_mod.g)

    @njit
    def f(x):
        return 2.0 * g(x)
""")
RUN = "import caller_mod; print(caller_mod.f(1.0), sum(caller_mod.f.stats.cache_hits.values()))"


def _run(folder: Path) -> tuple[float, int]:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(folder / "cache"), PYTHONPATH=os.pathsep.join([str(folder), str(ROOT)]))
    proc = subprocess.run([sys.executable, "-c", RUN], capture_output=True, text=True, cwd=folder, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    value, hits = proc.stdout.split()
    return float(value), int(hits)


def test_caller_recompiles_when_a_callee_changes(tmp_path):
    callee = tmp_path / "callee_mod.py"
    callee.write_text("def g(x):\n    return x + 1.0\n")
    (tmp_path / "caller_mod.py").write_text(CALLER)
    assert _run(tmp_path) == (4.0, 0)  # compiled and cached
    assert _run(tmp_path) == (4.0, 1)  # loaded from the cache
    callee.write_text("def g(x):\n    return x + 2.0\n")  # only the callee's file changes
    stat = callee.stat()
    os.utime(callee, (stat.st_atime + 10, stat.st_mtime + 10))
    assert _run(tmp_path) == (6.0, 0)  # the caller did not load its stale machine code
    assert _run(tmp_path) == (6.0, 1)


def test_an_inlined_callee_gives_its_caller_a_cache_entry_of_its_own(tmp_path):
    """Marking a callee :func:`~flatbody_env.integrators.jit.inlined` changes its callers' machine code: their cached
    entry is not reused (the mark is part of the key); the value is the same."""
    (tmp_path / "callee_mod.py").write_text("def g(x):\n    return x + 1.0\n")
    (tmp_path / "caller_mod.py").write_text(CALLER)
    assert _run(tmp_path) == (4.0, 0)
    marked = CALLER.replace("g = retarget(callee_mod.g)", "g = retarget(inlined(callee_mod.g))")
    (tmp_path / "caller_mod.py").write_text(marked.replace("import njit, retarget", "import inlined, njit, retarget"))
    assert _run(tmp_path) == (4.0, 0)  # compiled anew, with g inlined
    assert _run(tmp_path) == (4.0, 1)


def test_the_scalar_right_hand_side_is_compiled_into_its_callers():
    """The kernels a DOP853 step calls 13 times with six arrays are marked inlined (numba's ``inline="always"``), and
    so are the J1 ≠ J2 kinetic term and the store they call (a call left in them keeps the arrays' reference counts)."""
    from flatbody_env.integrators import jit
    from flatbody_env.physics import hamiltonian

    for kernel in (jit.rhs_core, jit.rhs_kernel):
        assert kernel.targetoptions.get("inline") == "always", kernel
    assert {hamiltonian.kinetic_general.__code__, hamiltonian.store_kinetic.__code__} <= jit.INLINED
    assert jit.rhs_iso.targetoptions.get("inline") is None  # scalars in, a tuple out: LLVM inlines it by itself

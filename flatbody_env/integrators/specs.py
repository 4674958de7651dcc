"""The compiled methods in one table: everything else about them is derived from :data:`SPECS`.

Each :class:`MethodSpec` names a method, what ``flatbody methods`` lists for it (:class:`MethodInfo`),
the kernel family that runs it (``kind``: ``"dop853"``, ``"rk4"``, ``"split"``, ``"rattle"``) with its
composition coefficients (:mod:`.compositions`), and where it runs: ``env`` (the environment steps it
through its compiled stepper, :func:`.steppers.make_env_step`; the others through ``integrate``),
``fused_batch`` (the environment's batch may run the fused structure-of-arrays DOP853 of
:mod:`.batch_kernels`), ``carries_R`` (the same stepping code on (y, vec(R)), :mod:`.rotation_kernels`),
``batchable`` (``simulate_batch``, :mod:`.batch_solve`) and ``gpu`` (``flatbody bench gpu``,
:mod:`.cuda`). Registration (:mod:`.compiled_methods`), the environment's steppers, the batch and
rotation maps, ``simulate_batch``'s methods and ``bench gpu``'s list all read this table; ``flatbody
methods`` lists it.

numpy only: reading it (and registering the methods) compiles nothing and imports no numba.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flatbody_env.integrators.base import MethodInfo
from flatbody_env.integrators.compositions import KAHAN_LI6, STRANG, SUZUKI4, YOSHIDA4

RK4_KIND = 0
SPLIT_KIND = 1
DOP853_KIND = 2
KIND_CODES = {"rk4": RK4_KIND, "split": SPLIT_KIND, "dop853": DOP853_KIND}
"""The integer ``kind`` the two-polar kernels dispatch on (RATTLE has its own kernels)."""


@dataclass(frozen=True)
class MethodSpec:
    """One compiled method (module docstring)."""

    info: MethodInfo
    kind: str
    coeffs: np.ndarray = field(default_factory=lambda: STRANG)
    env: bool = False
    """The environment steps it through its compiled stepper (one compiled call per step and per batch)."""
    fused_batch: bool = False
    """The environment's batch may run the fused structure-of-arrays DOP853 (:mod:`.batch_kernels`: first step dt,
    J1 = J2; bit for bit the stepper's result)."""
    carries_R: bool = False
    batchable: bool = False
    gpu: bool = False

    @property
    def name(self) -> str:
        return self.info.name

    @property
    def code(self) -> int:
        """The kernels' integer kind (two-polar methods)."""
        return KIND_CODES[self.kind]

    @property
    def stages(self) -> int:
        """RHS (or force) evaluations of one fixed step."""
        return 4 if self.kind == "rk4" else self.coeffs.size


_TP = "two-polar"
_SPLIT = ("casimir", "p_theta", "symplectic")
_RATTLE = ("constraints", "casimir", "lab_spin", "p_theta", "symplectic")
_PASS = "passes through lambda = mu; p_theta only for J1 = J2"
_TWO_POLAR_EVERYWHERE = dict(env=True, carries_R=True, batchable=True, gpu=True)

SPECS = (
    MethodSpec(
        MethodInfo(
            name="DOP853-numba",
            adaptive=True,
            order=8,
            chart=_TP,
            compiled=True,
            preserves=(),
            description="compiled port of scipy's DOP853 (Hairer's coefficients and step control), two-polar chart",
        ),
        "dop853",
        fused_batch=True,
        **_TWO_POLAR_EVERYWHERE,
    ),
    MethodSpec(
        MethodInfo(
            name="RK4",
            adaptive=False,
            order=4,
            chart=_TP,
            compiled=True,
            preserves=(),
            description="classical fixed-step Runge-Kutta 4, compiled, two-polar chart",
        ),
        "rk4",
        **_TWO_POLAR_EVERYWHERE,
    ),
    MethodSpec(
        MethodInfo(
            name="splitting-strang",
            adaptive=False,
            order=2,
            chart=_TP,
            compiled=True,
            preserves=_SPLIT,
            description="Poisson splitting with exact flows (docs/physics.md 8), Strang, J1 = J2 only",
        ),
        "split",
        STRANG,
        **_TWO_POLAR_EVERYWHERE,
    ),
    MethodSpec(
        MethodInfo(
            name="splitting-suzuki4",
            adaptive=False,
            order=4,
            chart=_TP,
            compiled=True,
            preserves=_SPLIT,
            description="Poisson splitting, Suzuki 5-stage order-4 composition, J1 = J2 only",
        ),
        "split",
        SUZUKI4,
        **_TWO_POLAR_EVERYWHERE,
    ),
    MethodSpec(
        MethodInfo(
            name="splitting-yoshida4",
            adaptive=False,
            order=4,
            chart=_TP,
            compiled=True,
            preserves=_SPLIT,
            description="Poisson splitting, Yoshida triple-jump order-4 composition, J1 = J2 only",
        ),
        "split",
        YOSHIDA4,
        **_TWO_POLAR_EVERYWHERE,
    ),
    MethodSpec(
        MethodInfo(
            name="RATTLE",
            adaptive=False,
            order=2,
            chart="regular",
            compiled=True,
            preserves=_RATTLE,
            description=f"RATTLE on the regular phi-psi formulation (docs/physics.md 5), {_PASS}",
        ),
        "rattle",
        STRANG,
    ),
    MethodSpec(
        MethodInfo(
            name="RATTLE-suzuki4",
            adaptive=False,
            order=4,
            chart="regular",
            compiled=True,
            preserves=_RATTLE,
            description=f"Suzuki 5-stage composition of RATTLE, regular chart, {_PASS}",
        ),
        "rattle",
        SUZUKI4,
    ),
    MethodSpec(
        MethodInfo(
            name="RATTLE-kahanli6",
            adaptive=False,
            order=6,
            chart="regular",
            compiled=True,
            preserves=_RATTLE,
            description=f"Kahan-Li 9-stage order-6 composition of RATTLE, regular chart, {_PASS}",
        ),
        "rattle",
        KAHAN_LI6,
    ),
)
"""The compiled methods, in registration order."""

BY_NAME = {s.name: s for s in SPECS}
ENV_METHODS = tuple(s.name for s in SPECS if s.env)
"""Methods the environment steps through their compiled stepper."""
ROTATION_METHODS = tuple(s.name for s in SPECS if s.carries_R)
"""Methods whose compiled step carries R."""
BATCH_METHODS = tuple(s.name for s in SPECS if s.batchable)
"""Methods of ``simulate_batch`` and the CPU batch kernels."""
GPU_METHODS = tuple(s.name for s in SPECS if s.gpu)
"""Methods with a CUDA kernel (``flatbody bench gpu --methods``)."""

__all__ = [
    "BATCH_METHODS",
    "BY_NAME",
    "DOP853_KIND",
    "ENV_METHODS",
    "GPU_METHODS",
    "KIND_CODES",
    "MethodSpec",
    "RK4_KIND",
    "ROTATION_METHODS",
    "SPECS",
    "SPLIT_KIND",
]

"""The task of ``FlatBodyAnyBody-v0``: the ``FlatBody-v0`` task for a body drawn per episode.

Each reset first draws the body's constants — J (J1 = J2), J3, the V3 constant κ (eq. (39) of [1]) and
the thickness constants a, b of V_ϱ = a/ϱ + bϱ²/2 (eq. (40)) — each log-uniformly in its range
(x = lo·(hi/lo)^u, so that x and 1/x are equally likely about 1; the ranges are the fields of
:class:`ReachAnyBody`), then a target and a start exactly as ``FlatBody-v0`` does for that body:
a spectrally stable ellipse of the circulation family in the same shape ranges with settling rate
r ≥ ``min_settling_rate`` (the settling rate of *that* body, by the exact test: the shipped table
holds the default body only), and the same start noise. The body's constants are appended to the
observation (:data:`BODY_OBSERVATION_NAMES`), so that one policy can serve every body; the equilibrium
thickness ϱ* = (a/b)^{1/3} (eq. (54)) follows from them.

Measured for bodies of these ranges (12 bodies × 40 shapes): 50–70 % of the shapes give a stable
ellipse and 5–50 % of those pass the filter, so a reset tries about 5–30 shapes, with a Riccati solve
per stable shape (the reset's cost: docs/tasks.md, ``FlatBodyAnyBody-v0``).

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from flatbody_env.env.task import DEFAULT_LIMITS, Episode, ReachStationaryEllipse, target_row
from flatbody_env.physics import validation
from flatbody_env.physics.body import Body, Inertia
from flatbody_env.physics.potentials import V3, ThicknessPotential

BODY_OBSERVATION_NAMES = ("J", "J3", "kappa", "a", "b")
"""The body's constants appended to the observation (entries 16–20), in this order."""
BODY_DRAWS = len(BODY_OBSERVATION_NAMES)
"""Uniforms a body draws (one per constant, in :data:`BODY_OBSERVATION_NAMES` order)."""


def body_from_constants(constants) -> Body:
    """The body (J1 = J2 = J, V3 with κ, V_ϱ with a, b) of the constants (J, J3, κ, a, b) — e.g. the
    observation's entries 16–20."""
    J, J3, kappa, a, b = (float(x) for x in constants)
    return Body(inertia=Inertia.isotropic(J, J3), potential=V3(kappa=kappa), thickness=ThicknessPotential(a=a, b=b))


def body_constants(body: Body) -> np.ndarray:
    """(J, J3, κ, a, b) of a body of this task's family (the inverse of :func:`body_from_constants`)."""
    if not isinstance(body.potential, V3) or body.thickness is None or not body.inertia.is_isotropic:
        raise ValueError("body: expected an isotropic body with V3 and the thickness potential")
    return np.array([body.inertia.J1, body.inertia.J3, body.potential.kappa, body.thickness.a, body.thickness.b])


@dataclass(frozen=True, kw_only=True)
class ReachAnyBody(ReachStationaryEllipse):
    """Reach a stationary ellipse of a body drawn per episode (module docstring)."""

    varies_body: ClassVar[bool] = True

    inertia_range: tuple[float, float] = (0.5, 2.0)
    """Range of J (= J1 = J2) and of J3."""
    kappa_range: tuple[float, float] = (0.5, 2.0)
    """Range of the V3 constant κ."""
    thickness_range: tuple[float, float] = (0.5, 2.0)
    """Range of the thickness constants a and b."""
    observe_body: bool = True
    """Append the body's constants to the observation (``FlatBodyAnyBody-v0``); False: the policy must infer the body
    from the motion (``FlatBodyAnyBody-v1``)."""

    @property
    def compiled_targets(self) -> bool:
        """The episode sampler's kernels draw this task's targets only without the settling-rate filter (the shipped
        table holds the default body alone): the v1 id, with ``min_settling_rate=0``."""
        return self.min_settling_rate == 0

    @property
    def body_observation_names(self) -> tuple[str, ...]:
        return BODY_OBSERVATION_NAMES if self.observe_body else ()

    def __post_init__(self) -> None:
        validation.boolean("observe_body", self.observe_body)  # first: the properties below read it
        super().__post_init__()
        for name in ("inertia_range", "kappa_range", "thickness_range"):
            object.__setattr__(
                self, name, validation.interval(name, getattr(self, name), low=0.01, high=100.0, strict=False)
            )

    def ranges(self) -> np.ndarray:
        """(5, 2) ranges of (J, J3, κ, a, b)."""
        return np.array(
            [self.inertia_range, self.inertia_range, self.kappa_range, self.thickness_range, self.thickness_range],
            dtype=float,
        )

    def sample_body(self, rng: np.random.Generator) -> Body:
        """A body (module docstring) from :data:`BODY_DRAWS` uniforms u of ``rng``: lo·(hi/lo)^u each of (J, J3, κ, a, b)."""
        r = self.ranges()
        return body_from_constants(r[:, 0] * (r[:, 1] / r[:, 0]) ** rng.random(BODY_DRAWS))

    def draw(
        self,
        rng: np.random.Generator,
        body: Body | None = None,
        *,
        limits=DEFAULT_LIMITS,
        control: str = "torque+dilatation",
        simulator: Any = None,
    ) -> Episode:
        """A body, then the target and the start of ``FlatBody-v0`` for it (``body`` is ignored: the task draws its own)."""
        own = self.sample_body(rng)
        target = self.sample_target(rng, own, limits=limits, control=control)
        return Episode(
            state=self.sample_initial_state(rng, target, control), target=target_row(target), ellipse=target, body=own
        )

    def body_observation_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if not self.observe_body:
            return np.zeros(0), np.zeros(0)
        r = self.ranges()
        return r[:, 0].copy(), r[:, 1].copy()


__all__ = ["BODY_DRAWS", "BODY_OBSERVATION_NAMES", "ReachAnyBody", "body_constants", "body_from_constants"]

"""Potentials of the flat body: in-plane V_λμ (eqs. (37)–(39) of [1]) and thickness V_ϱ (eq. (40)).

The total potential is separated as in eq. (36) of [1],

.. math:: V(\\lambda, \\mu, \\varrho) = V_{\\lambda\\mu}(\\lambda, \\mu) + V_\\varrho(\\varrho),

unless the user supplies a full :class:`CustomPotential` ``V(λ, μ, ϱ)`` with its gradient.

Each built-in potential is a frozen dataclass whose fields carry the paper's symbols, and
also exists as a branch of the scalar kernel :func:`potential_kernel` (plain float
arithmetic, no numpy) so that compiled integrators can inline it. The kernel selects the
in-plane potential by an integer code (:data:`KIND_V1`, …) with two constants ``c1, c2``;
:func:`invariant_gradient_kernel` is its gradient in the invariants (tr, det) of the regular
formulation, which the potentials' ``invariant_gradient`` methods call.

Barriers (erratum E10 of [2]): V1 has none at λμ → 0, so the plate can collapse to a
segment in finite time; V2, V3 and V_ϱ have barriers.

Symmetry (erratum E9 of [2]): V is a function of Φ only if it is symmetric under λ ↔ μ.
V2 with ``c ≠ d`` is not; it is still a valid potential in the two-polar chart away from
λ = μ, and in the regular chart it is evaluated on the singular values in the order fixed
by the initial state.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009), eqs. (36)–(40).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]), §2 (E9, E10) and §5 (potentials in invariants).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

KIND_CUSTOM = 0
KIND_V1 = 1
KIND_V2 = 2
KIND_V3 = 3


def _check_positive(owner: str, **values: float) -> None:
    """Each value a finite number in :data:`~flatbody_env.physics.validation.PARAM_RANGE` (``ValueError`` naming ``owner.name``)."""
    from flatbody_env.physics.validation import PARAM_RANGE, number

    for name, value in values.items():
        number(f"{owner}.{name}", value, low=PARAM_RANGE[0], high=PARAM_RANGE[1])


def potential_kernel(kind, c1, c2, a, b, lam, mu, rho):
    """Value and gradient of the built-in potential, scalar kernel.

    .. math::
        V_1 = \\tfrac{k}{2}(\\lambda^2+\\mu^2), \\quad
        V_2 = c(\\lambda^{-2}+\\lambda^2) + d(\\mu^{-2}+\\mu^2), \\quad
        V_3 = \\kappa\\left(\\frac{1}{\\lambda\\mu} + \\frac{\\lambda^2+\\mu^2}{2}\\right), \\quad
        V_\\varrho = \\frac{a}{\\varrho} + \\frac{b}{2}\\varrho^2

    (eqs. (37), (38), (39), (40) of [1]).

    Parameters
    ----------
    kind : int
        :data:`KIND_V1` (``c1 = k``), :data:`KIND_V2` (``c1 = c``, ``c2 = d``),
        :data:`KIND_V3` (``c1 = κ``); any other value contributes no in-plane term.
    c1, c2, a, b : float
        Potential constants; ``a = b = 0`` switches V_ϱ off.
    lam, mu, rho : float
        Stretches λ, μ and thickness ϱ, all > 0.

    Returns
    -------
    V, dV_dlambda, dV_dmu, dV_drho : float
    """
    v = 0.0
    gl = 0.0
    gm = 0.0
    if kind == KIND_V1:
        v = 0.5 * c1 * (lam * lam + mu * mu)
        gl = c1 * lam
        gm = c1 * mu
    elif kind == KIND_V2:
        il2 = 1.0 / (lam * lam)
        im2 = 1.0 / (mu * mu)
        v = c1 * (il2 + lam * lam) + c2 * (im2 + mu * mu)
        gl = c1 * (2.0 * lam - 2.0 * il2 / lam)
        gm = c2 * (2.0 * mu - 2.0 * im2 / mu)
    elif kind == KIND_V3:
        ilm = 1.0 / (lam * mu)
        v = c1 * (ilm + 0.5 * (lam * lam + mu * mu))
        gl = c1 * (lam - ilm / lam)
        gm = c1 * (mu - ilm / mu)
    v += a / rho + 0.5 * b * rho * rho
    gr = -a / (rho * rho) + b * rho
    return v, gl, gm, gr


def invariant_gradient_kernel(kind, c1, tr, det):
    """(∂V/∂tr, ∂V/∂det) of the built-in in-plane potential as a function of the invariants, scalar kernel.

    With tr = λ² + μ² and det = λ²μ² (docs/physics.md §7) eqs. (37)–(39) of [1] read

    .. math::
        V_1 = \\tfrac{k}{2}\\,\\mathrm{tr}, \\quad
        V_2\\big|_{c=d} = c\\,\\mathrm{tr}\\left(1 + \\frac{1}{\\det}\\right), \\quad
        V_3 = \\kappa\\left(\\det^{-1/2} + \\frac{\\mathrm{tr}}{2}\\right).

    V2 with c ≠ d is no function of the invariants (erratum E9 of [2]): its callers refuse it.

    Parameters
    ----------
    kind : int or float
        :data:`KIND_V1` (``c1 = k``), :data:`KIND_V2` (``c1 = c = d``), :data:`KIND_V3`
        (``c1 = κ``); any other value gives (0, 0).
    c1 : float
        The potential's first constant.
    tr, det : float
        The invariants, ``det > 0``.

    Returns
    -------
    dV_dtr, dV_ddet : float
    """
    if kind == KIND_V1:
        return 0.5 * c1, 0.0
    if kind == KIND_V2:
        return c1 * (1.0 + 1.0 / det), -c1 * tr / (det * det)
    if kind == KIND_V3:
        return 0.5 * c1, -0.5 * c1 * det**-1.5
    return 0.0, 0.0


@dataclass(frozen=True, kw_only=True)
class V1:
    """Harmonic in-plane potential, eq. (37) of [1]: V = k/2 (λ² + μ²). No collapse barrier (E10)."""

    k: float
    """Stiffness k > 0."""
    name: str = field(default="V1", init=False)

    def __post_init__(self) -> None:
        _check_positive("potential", k=self.k)

    kind = KIND_V1

    @property
    def constants(self) -> tuple[float, float]:
        return (float(self.k), 0.0)

    def hessian(self, lam: float, mu: float) -> np.ndarray:
        """Second derivatives [[V_λλ, V_λμ], [V_μλ, V_μμ]]."""
        return np.array([[self.k, 0.0], [0.0, self.k]])

    def invariant_gradient(self, tr: float, det: float) -> tuple[float, float] | None:
        """(∂V/∂tr, ∂V/∂det) with tr = λ²+μ², det = λ²μ² (docs/physics.md §7): V1 = k/2·tr (:func:`invariant_gradient_kernel`)."""
        return invariant_gradient_kernel(KIND_V1, float(self.k), tr, det)

    lower_bound = 0.0


@dataclass(frozen=True, kw_only=True)
class V2:
    """Anisotropic barrier potential, eq. (38) of [1]: V = c(λ⁻² + λ²) + d(μ⁻² + μ²).

    Symmetric under λ ↔ μ only when ``c == d`` (erratum E9 of [2]).
    """

    c: float
    """Constant c > 0 of the λ term."""
    d: float
    """Constant d > 0 of the μ term."""
    name: str = field(default="V2", init=False)

    def __post_init__(self) -> None:
        _check_positive("potential", c=self.c, d=self.d)

    kind = KIND_V2

    @property
    def constants(self) -> tuple[float, float]:
        return (float(self.c), float(self.d))

    def hessian(self, lam: float, mu: float) -> np.ndarray:
        return np.array([[self.c * (2.0 + 6.0 / lam**4), 0.0], [0.0, self.d * (2.0 + 6.0 / mu**4)]])

    def invariant_gradient(self, tr: float, det: float) -> tuple[float, float] | None:
        """V2 with c = d is c·tr·(1 + 1/det) (docs/physics.md §7, :func:`invariant_gradient_kernel`); with c ≠ d it is no function of invariants."""
        if self.c != self.d:
            return None
        return invariant_gradient_kernel(KIND_V2, float(self.c), tr, det)

    @property
    def lower_bound(self) -> float:
        return 2.0 * (self.c + self.d)


@dataclass(frozen=True, kw_only=True)
class V3:
    """Area-barrier potential, eq. (39) of [1]: V = κ (1/(λμ) + (λ² + μ²)/2)."""

    kappa: float
    """Constant κ > 0."""
    name: str = field(default="V3", init=False)

    def __post_init__(self) -> None:
        _check_positive("potential", kappa=self.kappa)

    kind = KIND_V3

    @property
    def constants(self) -> tuple[float, float]:
        return (float(self.kappa), 0.0)

    def hessian(self, lam: float, mu: float) -> np.ndarray:
        k = self.kappa
        return np.array(
            [
                [k * (1.0 + 2.0 / (lam**3 * mu)), k / (lam * mu) ** 2],
                [k / (lam * mu) ** 2, k * (1.0 + 2.0 / (lam * mu**3))],
            ]
        )

    def invariant_gradient(self, tr: float, det: float) -> tuple[float, float] | None:
        """V3 = κ(det^{-1/2} + tr/2) (docs/physics.md §7, :func:`invariant_gradient_kernel`)."""
        return invariant_gradient_kernel(KIND_V3, float(self.kappa), tr, det)

    @property
    def lower_bound(self) -> float:
        # 1/(λμ) + (λ²+μ²)/2 ≥ 1/(λμ) + λμ ≥ 2
        return 2.0 * self.kappa


@dataclass(frozen=True, kw_only=True)
class ThicknessPotential:
    """Thickness potential, eq. (40) of [1]: V_ϱ = a/ϱ + b ϱ²/2 (nonlinear oscillations of ϱ).

    Its minimum is at ϱ* = (a/b)^{1/3} (eq. (54) of [1]); the small-oscillation frequency there
    is √(V_ϱ''(ϱ*)/J3) = √(3b/J3).
    """

    a: float
    """Compression barrier a > 0."""
    b: float
    """Stretching stiffness b > 0."""

    def __post_init__(self) -> None:
        _check_positive("thickness", a=self.a, b=self.b)

    @property
    def rho_star(self) -> float:
        """Equilibrium thickness ϱ* = (a/b)^{1/3} (eq. (54) of [1])."""
        return (self.a / self.b) ** (1.0 / 3.0)

    def second_derivative(self, rho: float) -> float:
        return 2.0 * self.a / rho**3 + self.b

    @property
    def lower_bound(self) -> float:
        return 1.5 * self.a ** (2.0 / 3.0) * self.b ** (1.0 / 3.0)


@dataclass(frozen=True, kw_only=True)
class CustomPotential:
    """A user potential V(λ, μ, ϱ) with its gradient (replaces the in-plane potential).

    Parameters
    ----------
    value : callable
        ``value(lam, mu, rho) -> float``.
    gradient : callable
        ``gradient(lam, mu, rho) -> (dV/dλ, dV/dμ, dV/dϱ)``.
    lower_bound : float, optional
        A lower bound of V, if known (used to bound the closest approach to λ = μ); ``-inf``
        means unknown.
    label : str
        A name for summaries and recordings.

    Notes
    -----
    A :class:`ThicknessPotential` given beside it in the :class:`~flatbody_env.physics.body.Body` is added.
    Custom potentials run in Python (no compiled kernel), so they are slower.
    """

    value: Callable[[float, float, float], float]
    gradient: Callable[[float, float, float], tuple[float, float, float]]
    lower_bound: float = -math.inf
    label: str = "custom"
    name: str = field(default="custom", init=False)

    kind = KIND_CUSTOM

    def __post_init__(self) -> None:
        if not callable(self.value) or not callable(self.gradient):
            raise ValueError("potential: a custom potential needs callables 'value' and 'gradient'")

    @property
    def constants(self) -> tuple[float, float]:
        return (0.0, 0.0)

    def invariant_gradient(self, tr: float, det: float) -> tuple[float, float] | None:
        return None

    def hessian(self, lam: float, mu: float, rho: float = 1.0, h: float = 1e-6) -> np.ndarray:
        """In-plane second derivatives by central differences of the supplied gradient."""
        gp = np.asarray(self.gradient(lam + h, mu, rho), float)
        gm = np.asarray(self.gradient(lam - h, mu, rho), float)
        hp = np.asarray(self.gradient(lam, mu + h, rho), float)
        hm = np.asarray(self.gradient(lam, mu - h, rho), float)
        row0 = (gp[:2] - gm[:2]) / (2 * h)
        row1 = (hp[:2] - hm[:2]) / (2 * h)
        hess = np.array([row0, row1])
        return 0.5 * (hess + hess.T)


InPlanePotential = V1 | V2 | V3 | CustomPotential

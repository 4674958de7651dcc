"""Parameters of the body: inertia (eq. (29) of [1]), potential (eqs. (36)–(40)), spin convention.

:class:`Body` is the single parameter object of the physics layer. It is packed into a flat
float64 vector only at the integrator boundary (:meth:`Body.kernel_params`), with the layout

=====  ========  ===============================================================
index  name      meaning
=====  ========  ===============================================================
0      J1        inertia along material axis 1 (eq. (29) of [1])
1      J2        inertia along material axis 2
2      J3        inertia of the thickness direction
3      kind      in-plane potential code (0 custom, 1 V1, 2 V2, 3 V3)
4      c1        k (V1), c (V2), κ (V3)
5      c2        d (V2), else 0
6      a         V_ϱ compression constant (0: no thickness potential)
7      b         V_ϱ stretching constant
8      conv      +1: corrected spin bracket (default), −1: the paper's printed eqs. (43)–(46)
=====  ========  ===============================================================

Spin conventions
----------------
``"corrected"`` (default) uses {s_i, s_j} = +ε_ijk s_k, i.e. ṡ = ω × s, the bracket that
follows from the paper's own definitions eq. (25) and eq. (28) (erratum E3 of [2]); with it the
laboratory spin R s is conserved. ``"paper"`` reproduces the printed eqs. (43)–(46) exactly
(ṡ = s × ω); it still conserves H and |s|² but not R s (erratum E4 of [2]).

References
----------
.. [1] ``shared/paper/000_b5acfe912a09eb12.txt``.
.. [2] ``shared/physics/NOTES.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flatbody_env.physics.potentials import KIND_CUSTOM, CustomPotential, InPlanePotential, ThicknessPotential, V1, V2, V3, _check_positive, potential_kernel

SPIN_CONVENTIONS = ("corrected", "paper")
KERNEL_PARAMS_SIZE = 9


@dataclass(frozen=True, kw_only=True)
class Inertia:
    """Inertia J = diag(J1, J2, J3) in material axes (eq. (29) of [1]).

    J1 = J2 = J is the paper's isotropic case (section 3.2 of [1]).
    """

    J1: float
    """Inertia along material axis 1 (in-plane)."""
    J2: float
    """Inertia along material axis 2 (in-plane)."""
    J3: float
    """Inertia of the thickness direction."""

    def __post_init__(self) -> None:
        _check_positive("params", J1=self.J1, J2=self.J2, J3=self.J3)

    @classmethod
    def isotropic(cls, J: float, J3: float) -> "Inertia":
        """J1 = J2 = J (section 3.2 of [1])."""
        return cls(J1=J, J2=J, J3=J3)

    @property
    def is_isotropic(self) -> bool:
        return self.J1 == self.J2

    @property
    def matrix(self) -> np.ndarray:
        return np.diag([self.J1, self.J2, self.J3]).astype(float)


@dataclass(frozen=True, kw_only=True)
class Body:
    """Everything the equations of motion need: inertia, potential, and spin convention."""

    inertia: Inertia
    """Inertia J1, J2, J3."""
    potential: InPlanePotential
    """In-plane potential V_λμ (V1, V2, V3) or a full custom V(λ, μ, ϱ)."""
    thickness: ThicknessPotential | None = None
    """Thickness potential V_ϱ (eq. (40) of [1]); None for none (a custom V may carry it)."""
    spin_convention: str = "corrected"
    """``"corrected"`` (default, erratum E3 of NOTES.md) or ``"paper"`` (printed eqs. (43)–(46))."""
    _params: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.inertia, Inertia):
            raise ValueError("params: expected an Inertia(J1=..., J2=..., J3=...)")
        if not isinstance(self.potential, (V1, V2, V3, CustomPotential)):
            raise ValueError("potential: expected V1, V2, V3 or CustomPotential")
        if self.thickness is not None and not isinstance(self.thickness, ThicknessPotential):
            raise ValueError("thickness: expected ThicknessPotential(a=..., b=...) or None")
        if self.spin_convention not in SPIN_CONVENTIONS:
            raise ValueError(
                f"spin_convention: must be one of {SPIN_CONVENTIONS}, got {self.spin_convention!r}"
            )
        c1, c2 = self.potential.constants
        a, b = (self.thickness.a, self.thickness.b) if self.thickness is not None else (0.0, 0.0)
        conv = 1.0 if self.spin_convention == "corrected" else -1.0
        params = np.array(
            [self.inertia.J1, self.inertia.J2, self.inertia.J3, float(self.potential.kind), c1, c2, a, b, conv],
            dtype=np.float64,
        )
        params.setflags(write=False)
        object.__setattr__(self, "_params", params)

    # --- the integrator boundary -------------------------------------------------------------
    def kernel_params(self) -> np.ndarray:
        """The flat parameter vector (layout in the module docstring), read-only, shape (9,)."""
        return self._params

    @property
    def compiled(self) -> bool:
        """True when every term has a scalar kernel (no Python callback)."""
        return self.potential.kind != KIND_CUSTOM

    # --- potential --------------------------------------------------------------------------------
    def potential_terms(self, lam: float, mu: float, rho: float) -> tuple[float, float, float, float]:
        """(V, ∂V/∂λ, ∂V/∂μ, ∂V/∂ϱ) of the total potential (eq. (36) of [1])."""
        p = self._params
        v, gl, gm, gr = potential_kernel(int(p[3]), p[4], p[5], p[6], p[7], lam, mu, rho)
        if self.potential.kind == KIND_CUSTOM:
            v += float(self.potential.value(lam, mu, rho))
            g = self.potential.gradient(lam, mu, rho)
            gl += float(g[0])
            gm += float(g[1])
            gr += float(g[2])
        return v, gl, gm, gr

    def potential_energy(self, lam, mu, rho):
        """V(λ, μ, ϱ), vectorised over arrays."""
        lam, mu, rho = np.broadcast_arrays(*(np.asarray(x, float) for x in (lam, mu, rho)))
        out = np.empty(lam.shape)
        for idx in np.ndindex(lam.shape):
            out[idx] = self.potential_terms(float(lam[idx]), float(mu[idx]), float(rho[idx]))[0]
        return out if out.shape else float(out)

    @property
    def potential_lower_bound(self) -> float:
        """A lower bound of V over the configuration space (−inf when unknown)."""
        lb = float(self.potential.lower_bound)
        if self.thickness is not None:
            lb += self.thickness.lower_bound
        return lb

    def describe(self) -> str:
        J = self.inertia
        pot = self.potential
        if isinstance(pot, V1):
            ptxt = f"V1(k={pot.k:g})"
        elif isinstance(pot, V2):
            ptxt = f"V2(c={pot.c:g}, d={pot.d:g})"
        elif isinstance(pot, V3):
            ptxt = f"V3(kappa={pot.kappa:g})"
        else:
            ptxt = f"custom({pot.label})"
        ttxt = f" + V_rho(a={self.thickness.a:g}, b={self.thickness.b:g})" if self.thickness else ""
        inert = f"J={J.J1:g}" if J.is_isotropic else f"J1={J.J1:g}, J2={J.J2:g}"
        conv = "" if self.spin_convention == "corrected" else ", spin_convention='paper'"
        return f"{inert}, J3={J.J3:g}, {ptxt}{ttxt}{conv}"


def default_body() -> Body:
    """J = J3 = 1, V3 with κ = 1 and V_ϱ with a = b = 1: barriers on every collapse (NOTES E10)."""
    return Body(
        inertia=Inertia.isotropic(1.0, 1.0),
        potential=V3(kappa=1.0),
        thickness=ThicknessPotential(a=1.0, b=1.0),
    )


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
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md``: the verified formulas and the errata of [1].
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flatbody_env.physics import validation
from flatbody_env.physics.potentials import (
    KIND_CUSTOM,
    CustomPotential,
    InPlanePotential,
    ThicknessPotential,
    V1,
    V2,
    V3,
    _check_positive,
    potential_kernel,
)

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
    def isotropic(cls, J: float, J3: float) -> Inertia:
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
    """``"corrected"`` (default, erratum E3 of docs/physics.md) or ``"paper"`` (printed eqs. (43)–(46))."""
    _params: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.inertia, Inertia):
            raise ValueError("params: expected an Inertia(J1=..., J2=..., J3=...)")
        if not isinstance(self.potential, (V1, V2, V3, CustomPotential)):
            raise ValueError("potential: expected V1, V2, V3 or CustomPotential")
        if self.thickness is not None and not isinstance(self.thickness, ThicknessPotential):
            raise ValueError("thickness: expected ThicknessPotential(a=..., b=...) or None")
        validation.string("spin_convention", self.spin_convention, choices=SPIN_CONVENTIONS)
        c1, c2 = self.potential.constants
        a, b = (self.thickness.a, self.thickness.b) if self.thickness is not None else (0.0, 0.0)
        conv = 1.0 if self.spin_convention == "corrected" else -1.0
        params = np.array(
            [self.inertia.J1, self.inertia.J2, self.inertia.J3, float(self.potential.kind), c1, c2, a, b, conv],
            dtype=np.float64,
        )
        params.setflags(write=False)
        object.__setattr__(self, "_params", params)
        # the potential's kernel arguments as Python numbers (numpy scalars make the plain-float kernel slower)
        object.__setattr__(self, "_potential_args", (int(params[3]), float(c1), float(c2), float(a), float(b)))

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
        kind, c1, c2, a, b = self._potential_args
        v, gl, gm, gr = potential_kernel(kind, c1, c2, a, b, lam, mu, rho)
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

    # --- data -------------------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "") -> Body:
        """A body from its JSON form ``{"params", "potential", "thickness"[, "spin_convention"]}``.

        ``params`` is ``{"J", "J3"}`` (isotropic) or ``{"J1", "J2", "J3"}``; ``potential`` is
        ``{"name": "V1", "k"}``, ``{"name": "V2", "c", "d"}`` or ``{"name": "V3", "kappa"}``
        (eqs. (37)–(39) of the paper); ``thickness`` is ``{"a", "b"}`` (eq. (40)) or null. Other
        top-level fields are the caller's business (a scene adds ``state``, ``t_end``, …).

        Raises
        ------
        ValueError
            Naming the field (prefixed by ``where``) and the allowed range.
        """
        pre = f"{where}." if where else ""
        data = validation.mapping(where or "body", data)
        validation.keys(
            where or "body", data, set(data) | {"params", "potential", "thickness"}, ("params", "potential")
        )
        inertia = _inertia_from(pre + "params", validation.mapping(pre + "params", data["params"]))
        potential = _potential_from(pre + "potential", validation.mapping(pre + "potential", data["potential"]))
        thick = data.get("thickness")
        thickness = None
        if thick is not None:
            thick = validation.mapping(pre + "thickness", thick)
            validation.keys(pre + "thickness", thick, ("a", "b"), ("a", "b"))
            thickness = ThicknessPotential(
                a=validation.number(
                    pre + "thickness.a", thick["a"], low=validation.PARAM_RANGE[0], high=validation.PARAM_RANGE[1]
                ),
                b=validation.number(
                    pre + "thickness.b", thick["b"], low=validation.PARAM_RANGE[0], high=validation.PARAM_RANGE[1]
                ),
            )
        convention = validation.string(
            pre + "spin_convention", data.get("spin_convention", "corrected"), choices=SPIN_CONVENTIONS
        )
        return cls(inertia=inertia, potential=potential, thickness=thickness, spin_convention=convention)

    def to_dict(self) -> dict[str, Any]:
        """The JSON form read by :meth:`from_dict` (a custom potential has none: ``ValueError``)."""
        J = self.inertia
        params = {"J": J.J1, "J3": J.J3} if J.is_isotropic else {"J1": J.J1, "J2": J.J2, "J3": J.J3}
        pot = self.potential
        if isinstance(pot, V1):
            potential = {"name": "V1", "k": pot.k}
        elif isinstance(pot, V2):
            potential = {"name": "V2", "c": pot.c, "d": pot.d}
        elif isinstance(pot, V3):
            potential = {"name": "V3", "kappa": pot.kappa}
        else:
            raise ValueError("potential: a custom potential (Python callables) has no JSON form")
        out: dict[str, Any] = {
            "params": params,
            "potential": potential,
            "thickness": None if self.thickness is None else {"a": self.thickness.a, "b": self.thickness.b},
        }
        if self.spin_convention != "corrected":
            out["spin_convention"] = self.spin_convention
        return out

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


_POTENTIAL_FIELDS = {"V1": ("k",), "V2": ("c", "d"), "V3": ("kappa",)}


def _inertia_from(where: str, params: Mapping[str, Any]) -> Inertia:
    if "J" in params:
        validation.keys(where, params, ("J", "J3"), ("J", "J3"))
        J = validation.number(f"{where}.J", params["J"], low=validation.PARAM_RANGE[0], high=validation.PARAM_RANGE[1])
        return Inertia(
            J1=J,
            J2=J,
            J3=validation.number(
                f"{where}.J3", params["J3"], low=validation.PARAM_RANGE[0], high=validation.PARAM_RANGE[1]
            ),
        )
    if "J1" in params or "J2" in params:
        validation.keys(where, params, ("J1", "J2", "J3"), ("J1", "J2", "J3"))
        return Inertia(
            **{
                k: validation.number(
                    f"{where}.{k}", params[k], low=validation.PARAM_RANGE[0], high=validation.PARAM_RANGE[1]
                )
                for k in ("J1", "J2", "J3")
            }
        )
    validation.keys(where, params, ("J", "J1", "J2", "J3"))
    raise ValueError(f"{where}.J: missing field (give J and J3, or J1, J2 and J3; each in [1e-06, 1e+06])")


def _potential_from(where: str, pot: Mapping[str, Any]):
    if "name" not in pot:
        raise ValueError(f"{where}.name: missing field (allowed: V1, V2, V3)")
    name = pot["name"]
    if not isinstance(name, str) or name not in _POTENTIAL_FIELDS:
        raise ValueError(f"{where}.name: unknown potential {name!r} (allowed: V1, V2, V3)")
    fields = _POTENTIAL_FIELDS[name]
    validation.keys(where, pot, ("name", *fields), fields)
    values = {
        k: validation.number(f"{where}.{k}", pot[k], low=validation.PARAM_RANGE[0], high=validation.PARAM_RANGE[1])
        for k in fields
    }
    return {"V1": V1, "V2": V2, "V3": V3}[name](**values)


def default_body() -> Body:
    """J = J3 = 1, V3 with κ = 1 and V_ϱ with a = b = 1: barriers on every collapse (erratum E10)."""
    return Body(
        inertia=Inertia.isotropic(1.0, 1.0),
        potential=V3(kappa=1.0),
        thickness=ThicknessPotential(a=1.0, b=1.0),
    )

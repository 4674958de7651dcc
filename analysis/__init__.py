"""Analysis of the flat body: stationary ellipses, stability, invariants (uses physics + integrators only)."""

# Stationary ellipses, stability, families, invariants: exported lazily (PEP 562) so that
# importing ``flatbody_env.cli.analysis`` for ``flatbody --help`` does not load scipy.optimize.
_LAZY = {
    "families": ("Family", "FamilyEvent", "FamilyPoint", "follow_family", "shape_stability_grid", "stability_grid"),
    "invariants": ("DriftRow", "InvariantReport", "invariants_along"),
    "stability": (
        "StabilityResult",
        "ZeroMode",
        "analyse_stability",
        "reduced_jacobian",
        "sample_stable_target",
        "stability_of",
        "stability_of_shape",
        "steady_rotation_stability",
    ),
    "stationary": (
        "SearchBox",
        "StationaryEllipse",
        "spins_for_shape",
        "stationary_ellipses",
        "steady_rotations",
        "v1_closed_form",
    ),
    "verification": ("verify_bounded", "verify_growth", "verify_stationary"),
}
_WHERE = {name: module for module, names in _LAZY.items() for name in names}


def __getattr__(name):
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'analysis' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(f".{module}", __name__), name)


__all__ = sorted(_WHERE)

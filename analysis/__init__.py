"""Analysis of the flat body: stationary ellipses, stability, invariants (uses physics + integrators only)."""

# Stationary ellipses, stability, families, invariants (issue 5).
from .families import Family, FamilyEvent, FamilyPoint, follow_family, shape_stability_grid, stability_grid
from .invariants import DriftRow, InvariantReport, invariants_along, load_trajectory
from .stability import (
    StabilityResult,
    ZeroMode,
    analyse_stability,
    reduced_jacobian,
    sample_stable_target,
    stability_of,
    stability_of_shape,
    steady_rotation_stability,
)
from .stationary import SearchBox, StationaryEllipse, spins_for_shape, stationary_ellipses, steady_rotations, v1_closed_form
from .verification import verify_bounded, verify_growth, verify_stationary

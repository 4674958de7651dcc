"""Analysis of the flat body: stationary ellipses, stability, invariants (uses physics + integrators only)."""

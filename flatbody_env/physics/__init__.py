"""The model: a flat affinely-rigid body with thickness (numpy/scipy only).

One module per concept — :mod:`.state` (the state layout), :mod:`.potentials`, :mod:`.body`,
:mod:`.hamiltonian`, :mod:`.equations` (equations of motion), :mod:`.kinematics`,
:mod:`.invariants` (conserved quantities), :mod:`.regular` (the chart regular at λ = μ),
:mod:`.equilibria` (stationary ellipses) and :mod:`.controllability`. ``docs/physics.md`` gives the
model, the corrected equations and the errata of the paper. Nothing here imports gymnasium, numba,
rerun, torch or stable-baselines3 (a test proves it).
"""

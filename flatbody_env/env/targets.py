"""The settling-rate table: the task's reachability test at reset without a Riccati solve.

:meth:`~flatbody_env.env.task.ReachStationaryEllipse.sample_target` keeps a sampled target shape
(λ*, λ*/μ*) only if a stationary ellipse of the circulation family exists there, is spectrally
stable and settles at a rate r ≥ ``min_settling_rate``
(:func:`flatbody_env.physics.controllability.settling_rate`: a linearisation and a Riccati solve,
milliseconds). r, existence and stability depend on the shape alone (not on the sign of
(s3, p_θ)), so for the default body, limits and controls they are tabulated once on a grid of
shapes and shipped with the package (:data:`TABLE_PATH`, format :data:`TABLE_VERSION`).

Decision (:meth:`SettlingRateTable.decide`). The shape falls in one grid cell. When its four
corners all hold a finite r, r is interpolated bilinearly; the table also holds, per cell, a
bound ``margin`` on the interpolation error (:data:`SAFETY` × the error measured at the cell's
centre against the exact r, plus a floor). The shape is accepted when r̂ − margin ≥ threshold and
rejected when r̂ + margin < threshold. Cells crossed by the default threshold 0.15 s⁻¹ carry a
finer :data:`FINE` × :data:`FINE` sub-grid (margins ~64× smaller). A cell whose corners and centre
are all without an ellipse (none exists, or it is unstable) rejects. A cell on the edge of
existence (some corners without an ellipse) holds the range of r over an :data:`EDGE_SUB`² lattice
of its shapes: it accepts a shape where a stable ellipse exists when the whole range, less a pad,
clears the threshold (r rises steeply toward the edge), and rejects when it all lies below.
Anything else is *unsure* and the caller runs the exact test: 2 in 40 000 uniform draws for the
shipped table. So the accepted targets are those of the exact test (the tests draw the same
targets with and without the table from the same seeds, and check the decisions against the exact
test at random shapes).

The table applies only to what it was computed for (:meth:`SettlingRateTable.applies`): the body
(``Body.to_dict``), the control limits, ``"torque+dilatation"``, the cheap-control weight
:data:`~flatbody_env.physics.controllability.CHEAP_CONTROL_R` and target ranges inside its grid;
otherwise the exact test runs at every draw, as before.

Regenerate (after a change to the physics, the default body or the limits)::

    flatbody targets-table            # writes flatbody_env/env/data/settling_rates_v1.npz

(:func:`build_table`; its run time: docs/env.md, "Resets without a Riccati solve"). Bump
:data:`TABLE_VERSION` when the file's layout changes.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flatbody_env.physics.body import Body, default_body
from flatbody_env.physics.controllability import CHEAP_CONTROL_R, settling_rate, target_state
from flatbody_env.physics.equilibria import stationary_from_shape
from flatbody_env.physics.potentials import KIND_CUSTOM

TABLE_VERSION = 1
"""Layout version of the table file (its name carries it)."""
TABLE_PATH = Path(__file__).resolve().parent / "data" / f"settling_rates_v{TABLE_VERSION}.npz"
"""The shipped table (default body, limits (0.5, 0.5, 0.5, 1), ``"torque+dilatation"``)."""
SAFETY = 4.0
"""Factor on the interpolation error measured at a cell's centre that makes the cell's margin."""
MARGIN_FLOOR = 1e-6
"""Smallest margin (s⁻¹) of a cell."""
GRID_LAMBDA = (1.3, 2.0, 71)
"""(first, last, count) of the λ* grid of the shipped table."""
GRID_ASPECT = (1.5, 3.5, 81)
"""(first, last, count) of the λ*/μ* grid of the shipped table."""
REFINE_THRESHOLD = 0.15
"""The task's default ``min_settling_rate``: cells it crosses are refined, so that few draws are unsure."""
FINE = 8
"""Sub-grid (FINE × FINE sub-cells) of a refined cell."""
EDGE_SUB = 6
"""Lattice (EDGE_SUB × EDGE_SUB) sampled inside each cell on the edge of existence or stability."""
EDGE_SAFETY = 0.25
"""Margin of an edge cell: EDGE_SAFETY × (its r range) + :data:`MARGIN_FLOOR`."""
ACCEPT, REJECT, UNSURE, ACCEPT_IF_STABLE = 1, 0, -1, 2


def exact_rate(body: Body, lam: float, aspect: float, limits) -> float:
    """r of the shape (λ*, λ*/μ*) (circulation family, sign +1): NaN when no stable ellipse exists there."""
    try:
        t = stationary_from_shape(body, lam, lam / aspect, branch="circulation", sign=1.0)
    except ValueError:
        return math.nan
    if not t.stable:
        return math.nan
    return settling_rate(body, target_state(t.lam, t.mu, t.rho, t.s3, t.p_theta), limits, np.ones(4, dtype=bool))


@dataclass(frozen=True)
class SettlingRateTable:
    """r on a grid of target shapes, with per-cell interpolation margins (module docstring)."""

    lambdas: np.ndarray
    """λ* grid (n_λ,), uniform."""
    aspects: np.ndarray
    """λ*/μ* grid (n_a,), uniform."""
    rate: np.ndarray
    """r (n_a, n_λ) (s⁻¹); NaN where no stable ellipse of the circulation family exists."""
    margin: np.ndarray
    """Bound on |bilinear r − exact r| per cell (n_a − 1, n_λ − 1); inf where the cell is not interpolated."""
    invalid: np.ndarray
    """(n_a − 1, n_λ − 1) bool: corners and centre all without a stable ellipse (the cell rejects)."""
    edge_lo: np.ndarray
    """(n_a − 1, n_λ − 1): on a cell at the edge of existence or stability, the least r of the
    ellipses sampled in it (corners and an :data:`EDGE_SUB`² lattice); NaN elsewhere."""
    edge_hi: np.ndarray
    """The greatest r of those samples."""
    refined: np.ndarray
    """(n_a − 1, n_λ − 1) int: index into ``fine_rate`` of a cell crossed by the default threshold
    (:data:`REFINE_THRESHOLD`), refined on a :data:`FINE` × :data:`FINE` sub-grid; −1 elsewhere."""
    fine_rate: np.ndarray
    """(n_refined, FINE + 1, FINE + 1) r on the sub-grid nodes of the refined cells."""
    fine_margin: np.ndarray
    """(n_refined, FINE, FINE) margins of the sub-cells (as ``margin``)."""
    meta: dict

    # --- use ------------------------------------------------------------------------------------
    def applies(self, body: Body, limits, control: str, target_lambda, target_aspect) -> bool:
        """Whether the table answers for this body, these limits, controls and target ranges."""
        return not self.mismatch(body, limits, control, target_lambda, target_aspect)

    def mismatch(self, body: Body, limits, control: str, target_lambda, target_aspect) -> tuple[str, ...]:
        """The settings the table was not computed for, by the env's keyword that sets each (``control``,
        ``torque_limit``/``force_limit``, ``body``, ``target_lambda``, ``target_aspect``; ``settling_table`` when the
        table is of another version); empty when it :meth:`applies`."""
        m = self.meta
        lim = np.asarray(limits, dtype=float)
        table_lim = np.asarray(m.get("limits") or [np.nan] * 4, dtype=float)
        out = []
        if m.get("version") != TABLE_VERSION or m.get("cheap_control_r") != CHEAP_CONTROL_R:
            out.append("settling_table")
        if control != "torque+dilatation":
            out.append("control")
        if lim.shape != table_lim.shape or not np.array_equal(lim[:3], table_lim[:3]):
            out.append("torque_limit")
        if lim.shape != table_lim.shape or lim[3] != table_lim[3]:
            out.append("force_limit")
        custom = getattr(body.potential, "kind", None) == KIND_CUSTOM  # Python callables: no JSON form
        if custom or json.loads(json.dumps(body.to_dict())) != m.get("body"):
            out.append("body")
        if not (self.lambdas[0] <= target_lambda[0] and target_lambda[1] <= self.lambdas[-1]):
            out.append("target_lambda")
        if not (self.aspects[0] <= target_aspect[0] and target_aspect[1] <= self.aspects[-1]):
            out.append("target_aspect")
        return tuple(out)

    def decide(self, lam: float, aspect: float, threshold: float) -> int:
        """:data:`ACCEPT`, :data:`REJECT`, :data:`ACCEPT_IF_STABLE` (an edge cell: accept if a stable
        ellipse exists at this shape) or :data:`UNSURE` (run the exact test) (module docstring;
        :func:`decide_kernel` on plain-float copies of the arrays)."""
        return decide_kernel(lam, aspect, threshold, self._grid, *self._lists)

    def kernel_arrays(self) -> tuple:
        """The arrays :func:`decide_kernel` reads, as numpy arrays (for the compiled reset):
        ``grid`` (l0, a0, dl, da, n_λ, n_a), then those of :data:`KERNEL_ARRAYS` (``rate``, ``margin``, ``invalid``
        (uint8), ``edge_lo``, ``edge_hi``, ``refined``, ``fine_rate``, ``fine_margin``)."""
        return (
            np.array(self._grid, dtype=np.float64),
            *(np.ascontiguousarray(getattr(self, name), dtype=dtype) for name, dtype in KERNEL_ARRAYS),
        )

    def __post_init__(self) -> None:
        # plain-float copies for the per-draw lookup (numpy scalar indexing costs more than the arithmetic)
        object.__setattr__(self, "_lists", tuple(getattr(self, name).tolist() for name, _ in KERNEL_ARRAYS))
        lam, asp = self.lambdas, self.aspects
        grid = [lam[0], asp[0], lam[1] - lam[0], asp[1] - asp[0], len(lam), len(asp)]
        object.__setattr__(self, "_grid", [float(g) for g in grid])

    # --- file -----------------------------------------------------------------------------------
    def save(self, path: str | Path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp.npz")
        arrays = {name: getattr(self, name) for name in ("lambdas", "aspects", *dict(KERNEL_ARRAYS))}
        np.savez_compressed(tmp, **arrays, meta=np.array(json.dumps(self.meta, sort_keys=True)))
        tmp.replace(path)

    @classmethod
    def load(cls, path: str | Path) -> SettlingRateTable:
        with np.load(path, allow_pickle=False) as f:
            meta = json.loads(str(f["meta"]))
            if meta.get("version") != TABLE_VERSION:
                raise ValueError(f"table: {path} has version {meta.get('version')!r}, expected {TABLE_VERSION}")
            return cls(**{name: f[name] for name in ("lambdas", "aspects", *dict(KERNEL_ARRAYS))}, meta=meta)


KERNEL_ARRAYS = (
    ("rate", np.float64), ("margin", np.float64), ("invalid", np.uint8), ("edge_lo", np.float64),
    ("edge_hi", np.float64), ("refined", np.int64), ("fine_rate", np.float64), ("fine_margin", np.float64),
)  # fmt: skip
"""The table's arrays after the grid that :func:`decide_kernel` reads, in its order, with the compiled reset's dtypes."""
EMPTY_KERNEL_ARRAYS = (
    np.zeros(6), np.zeros((2, 2)), np.zeros((1, 1)), np.zeros((1, 1), np.uint8), np.zeros((1, 1)), np.zeros((1, 1)),
    np.full((1, 1), -1, np.int64), np.zeros((1, 2, 2)), np.zeros((1, 1, 1)),
)  # fmt: skip
"""Arrays of :meth:`SettlingRateTable.kernel_arrays`' types for kernels that never read a table."""


def decide_kernel(
    lam, aspect, threshold, grid, rate, margin, invalid, edge_lo, edge_hi, refined, fine_rate, fine_margin
):
    """:meth:`SettlingRateTable.decide` on the table's arrays (plain floats: the same source runs on
    nested lists in Python and compiled on numpy arrays at the environment's reset).

    ``grid`` = (λ₀, a₀, Δλ, Δa, n_λ, n_a); the arrays are the table's fields of the same names
    (indexed ``[j][i]``: aspect row j, λ column i). Returns :data:`ACCEPT`, :data:`REJECT`,
    :data:`ACCEPT_IF_STABLE` or :data:`UNSURE`.
    """
    x = (lam - grid[0]) / grid[2]
    y = (aspect - grid[1]) / grid[3]
    i = min(max(int(math.floor(x)), 0), int(grid[4]) - 2)
    j = min(max(int(math.floor(y)), 0), int(grid[5]) - 2)
    if invalid[j][i]:
        return REJECT
    m = margin[j][i]
    if m == math.inf:
        lo = edge_lo[j][i]
        hi = edge_hi[j][i]
        if lo != lo:  # no stable ellipse was sampled in this edge cell
            return UNSURE
        pad = EDGE_SAFETY * (hi - lo) + MARGIN_FLOOR
        if lo - pad >= threshold:
            return ACCEPT_IF_STABLE
        if hi + pad < threshold:
            return REJECT
        return UNSURE
    fx = x - i
    fy = y - j
    q = refined[j][i]
    if q >= 0:  # a cell crossed by the default threshold: its sub-grid
        x = fx * FINE
        y = fy * FINE
        i = min(int(x), FINE - 1)
        j = min(int(y), FINE - 1)
        fx = x - i
        fy = y - j
        r = fine_rate[q]
        m = fine_margin[q][j][i]
    else:
        r = rate
    r_hat = (
        (1 - fx) * (1 - fy) * r[j][i]
        + fx * (1 - fy) * r[j][i + 1]
        + (1 - fx) * fy * r[j + 1][i]
        + fx * fy * r[j + 1][i + 1]
    )
    if r_hat - m >= threshold:
        return ACCEPT
    if r_hat + m < threshold:
        return REJECT
    return UNSURE


def _rates(args) -> list[float]:
    body_dict, limits, points = args
    body = Body.from_dict(body_dict)
    return [exact_rate(body, lam, aspect, limits) for lam, aspect in points]


def _map_rates(body: Body, limits, points: list[tuple[float, float]], workers: int, progress: bool) -> list[float]:
    from concurrent.futures import ProcessPoolExecutor

    from flatbody_env.progress import progress_bar

    chunks = [points[k : k + 64] for k in range(0, len(points), 64)]
    jobs = [(body.to_dict(), limits, c) for c in chunks]
    out: list[float] = []
    with ProcessPoolExecutor(max_workers=workers) as pool:
        for part in progress_bar(
            pool.map(_rates, jobs), total=len(jobs), desc="settling rates", unit="chunk", enabled=progress
        ):
            out.extend(part)
    return out


def build_table(
    body: Body | None = None,
    limits=(0.5, 0.5, 0.5, 1.0),
    grid_lambda=GRID_LAMBDA,
    grid_aspect=GRID_ASPECT,
    workers: int = 2,
    progress: bool = False,
) -> SettlingRateTable:
    """Compute the table: exact r at every grid node, and at the centre of every cell whose
    corners all hold an ellipse or none does (module docstring)."""
    from flatbody_env.physics import validation

    workers = validation.workers("workers", workers)
    body = body or default_body()
    limits = np.asarray(limits, dtype=float)
    lambdas = np.linspace(*grid_lambda)
    aspects = np.linspace(*grid_aspect)
    nl, na = len(lambdas), len(aspects)
    nodes = [(float(lam), float(a)) for a in aspects for lam in lambdas]
    rate = np.array(_map_rates(body, limits, nodes, workers, progress)).reshape(na, nl)
    corners = np.stack([rate[:-1, :-1], rate[:-1, 1:], rate[1:, :-1], rate[1:, 1:]])
    all_finite = np.isfinite(corners).all(axis=0)
    none_finite = ~np.isfinite(corners).any(axis=0)
    cells = np.argwhere(all_finite | none_finite)
    centres = [(0.5 * float(lambdas[i] + lambdas[i + 1]), 0.5 * float(aspects[j] + aspects[j + 1])) for j, i in cells]
    centre = np.full((na - 1, nl - 1), np.nan)
    centre[cells[:, 0], cells[:, 1]] = _map_rates(body, limits, centres, workers, progress)
    finite = all_finite & np.isfinite(centre)
    interp = corners.mean(axis=0)  # bilinear at the centre
    margin = np.where(finite, SAFETY * np.abs(interp - centre) + MARGIN_FLOOR, np.inf)
    invalid = none_finite & ~np.isfinite(centre)
    # cells on the edge of existence/stability: the range of r over the ellipses that exist there
    # (corners and a SUB x SUB lattice inside); r rises steeply toward the edge
    edge_lo = np.full((na - 1, nl - 1), np.nan)
    edge_hi = np.full((na - 1, nl - 1), np.nan)
    mixed = np.argwhere(~all_finite & ~none_finite)
    f = (np.arange(EDGE_SUB) + 0.5) / EDGE_SUB
    pts = [
        (float(lambdas[i] + fx * (lambdas[i + 1] - lambdas[i])), float(aspects[j] + fy * (aspects[j + 1] - aspects[j])))
        for j, i in mixed
        for fy in f
        for fx in f
    ]
    sub = np.array(_map_rates(body, limits, pts, workers, progress)).reshape(len(mixed), EDGE_SUB * EDGE_SUB)
    for (j, i), r_sub in zip(mixed, sub):
        r = np.concatenate([r_sub, corners[:, j, i]])
        r = r[np.isfinite(r)]
        if r.size:
            edge_lo[j, i], edge_hi[j, i] = r.min(), r.max()
    # cells crossed by the default threshold: a FINE x FINE sub-grid (nodes and sub-cell centres)
    lo = np.min(corners, axis=0) - margin  # NaN outside the interpolated cells (excluded by ``finite``)
    hi = np.max(corners, axis=0) + margin
    cross = np.argwhere(finite & (lo <= REFINE_THRESHOLD) & (hi >= REFINE_THRESHOLD))
    refined = np.full((na - 1, nl - 1), -1, dtype=np.int64)
    g = np.arange(FINE + 1) / FINE
    c = (np.arange(FINE) + 0.5) / FINE
    fine_rate = np.empty((len(cross), FINE + 1, FINE + 1))
    fine_margin = np.empty((len(cross), FINE, FINE))
    if len(cross):
        dl, da = float(lambdas[1] - lambdas[0]), float(aspects[1] - aspects[0])
        pts = [(float(lambdas[i]) + fx * dl, float(aspects[j]) + fy * da) for j, i in cross for fy in g for fx in g]
        pts += [(float(lambdas[i]) + fx * dl, float(aspects[j]) + fy * da) for j, i in cross for fy in c for fx in c]
        r = np.array(_map_rates(body, limits, pts, workers, progress))
        n_nodes = len(cross) * (FINE + 1) ** 2
        fine_rate[:] = r[:n_nodes].reshape(len(cross), FINE + 1, FINE + 1)
        sub_centre = r[n_nodes:].reshape(len(cross), FINE, FINE)
        sub_interp = 0.25 * (
            fine_rate[:, :-1, :-1] + fine_rate[:, :-1, 1:] + fine_rate[:, 1:, :-1] + fine_rate[:, 1:, 1:]
        )
        fine_margin[:] = SAFETY * np.abs(sub_interp - sub_centre) + MARGIN_FLOOR
        fine_margin[~np.isfinite(fine_margin)] = np.inf
        refined[cross[:, 0], cross[:, 1]] = np.arange(len(cross))
    meta = {
        "version": TABLE_VERSION,
        "body": json.loads(json.dumps(body.to_dict())),
        "limits": [float(x) for x in limits],
        "control": "torque+dilatation",
        "cheap_control_r": CHEAP_CONTROL_R,
        "safety": SAFETY,
        "margin_floor": MARGIN_FLOOR,
        "fine": FINE,
        "refine_threshold": REFINE_THRESHOLD,
        "edge_sub": EDGE_SUB,
        "edge_safety": EDGE_SAFETY,
        "grid_lambda": list(grid_lambda),
        "grid_aspect": list(grid_aspect),
        "regenerate": "flatbody targets-table",
    }
    return SettlingRateTable(
        lambdas=lambdas,
        aspects=aspects,
        rate=rate,
        margin=margin,
        invalid=invalid,
        edge_lo=edge_lo,
        edge_hi=edge_hi,
        refined=refined,
        fine_rate=fine_rate,
        fine_margin=fine_margin,
        meta=meta,
    )


_LOADED: dict[str, SettlingRateTable | None] = {}


def shipped_table() -> SettlingRateTable | None:
    """The table shipped with the package (loaded once), or None when the file is missing."""
    key = str(TABLE_PATH)
    if key not in _LOADED:
        _LOADED[key] = SettlingRateTable.load(TABLE_PATH) if TABLE_PATH.exists() else None
    return _LOADED[key]


__all__ = [
    "ACCEPT",
    "EMPTY_KERNEL_ARRAYS",
    "KERNEL_ARRAYS",
    "ACCEPT_IF_STABLE",
    "REJECT",
    "UNSURE",
    "SettlingRateTable",
    "TABLE_PATH",
    "TABLE_VERSION",
    "build_table",
    "exact_rate",
    "shipped_table",
]

"""Sub-commands of the analysis service: ``ellipses``, ``stability``, ``family``, ``stability-map``, ``invariants``.

The body is given by flags (``--potential V1|V2|V3`` with ``--k`` / ``--c --d`` / ``--kappa``,
``--a --b`` for V_ϱ, ``--J --J3``; unset constants take the default body's values: J = J3 = 1,
κ = k = c = d = 1, a = b = 1) or by ``--scene FILE`` (a scene JSON or a built-in scene name),
whose state also supplies s3 and p_θ unless ``--s3`` / ``--p-theta`` are given.

Bad input → exit code 2 with one line (a ``ValueError`` naming the flag and the allowed range).

Every default and bound is read from the library (:class:`analysis.stationary.SearchBox`, the family and
map defaults of :mod:`analysis.families`, the ranges of :mod:`flatbody_env.physics.validation`), never
written again here; those modules import without scipy, so ``flatbody --help`` stays fast.
"""

from __future__ import annotations

import json
from pathlib import Path

from analysis.families import DEFAULT_FAMILY_RANGE, DEFAULT_SEEDS, MAP_GRID, MAP_LAM_RANGE, MAP_MU_RANGE, PARAMETERS
from analysis.stationary import SearchBox
from flatbody_env.answers import (
    ellipses_answer,
    family_run,
    invariants_run,
    solutions,
    stability_answer,
    stability_map_answer,
)
from flatbody_env.cli.args import (
    body_constant,
    check_output_path,
    float_range,
    int_at_least,
    momentum,
    output_file,
    positive_float,
)
from flatbody_env.physics.validation import (
    FAMILY_SEEDS_RANGE,
    MAP_GRID_RANGE,
    MOMENTUM_MAX,
    PARAM_RANGE,
    SEARCH_GRID_RANGE,
)

BOX = SearchBox()
"""The library's search box: its λ, μ ranges and grid are the defaults of ``--lam-range``, ``--mu-range``, ``--grid``."""
_PARAM_TEXT = f"[{PARAM_RANGE[0]:g}, {PARAM_RANGE[1]:g}]"

_CONSTANTS = ("k", "c", "d", "kappa", "a", "b", "J", "J3")
_FOR_POTENTIAL = {"k": "V1", "c": "V2", "d": "V2", "kappa": "V3"}


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _pair(value: tuple[float, float]) -> str:
    """A range default as the flag takes it (``0.02,50``)."""
    return f"{value[0]:g},{value[1]:g}"


def add_body_arguments(p) -> None:
    """Flags that define the body and the spins (s3, p_θ)."""
    g = p.add_argument_group("body (default: J = J3 = 1, V3 kappa = 1, V_rho a = b = 1)")
    g.add_argument(
        "--scene", metavar="FILE", help="take the constants (and s3, p_theta) from a scene JSON or built-in scene"
    )
    g.add_argument("--potential", choices=("V1", "V2", "V3"), default=None, help="in-plane potential (default V3)")
    g.add_argument("--k", type=body_constant("--k"), default=None, help=f"V1 stiffness k in {_PARAM_TEXT}")
    g.add_argument("--c", type=body_constant("--c"), default=None, help=f"V2 constant c in {_PARAM_TEXT}")
    g.add_argument("--d", type=body_constant("--d"), default=None, help=f"V2 constant d in {_PARAM_TEXT}")
    g.add_argument("--kappa", type=body_constant("--kappa"), default=None, help=f"V3 constant kappa in {_PARAM_TEXT}")
    g.add_argument("--a", type=body_constant("--a"), default=None, help=f"thickness potential a in {_PARAM_TEXT}")
    g.add_argument("--b", type=body_constant("--b"), default=None, help=f"thickness potential b in {_PARAM_TEXT}")
    g.add_argument("--J", type=body_constant("--J"), default=None, help=f"in-plane inertia J in {_PARAM_TEXT}")
    g.add_argument("--J3", type=body_constant("--J3"), default=None, help=f"thickness inertia J3 in {_PARAM_TEXT}")
    p.add_argument("--s3", type=momentum("--s3"), default=None, help="spin component s3 (conserved with |s|)")
    p.add_argument(
        "--p-theta", dest="p_theta", type=momentum("--p-theta"), default=None, help="material momentum p_theta"
    )


def add_box_arguments(p) -> None:
    lo, hi = SEARCH_GRID_RANGE
    p.add_argument(
        "--lam-range",
        type=float_range("--lam-range"),
        default=BOX.lam,
        metavar="LO,HI",
        help=f"search range of lambda (default {_pair(BOX.lam)})",
    )
    p.add_argument(
        "--mu-range",
        type=float_range("--mu-range"),
        default=BOX.mu,
        metavar="LO,HI",
        help=f"search range of mu (default {_pair(BOX.mu)})",
    )
    p.add_argument(
        "--grid",
        type=int_at_least("--grid", lo, hi),
        default=BOX.n,
        metavar="N",
        help=f"grid points per axis of the root search, in [{lo}, {hi}] (default {BOX.n})",
    )


def add_map_arguments(p, *, grid_range: tuple[int, int], grid_name: str = "--grid") -> None:
    """The shape grid of a stability map (``flatbody stability-map``, ``flatbody sweep stability-map``):
    ``--lam-range``, ``--mu-range``, ``--grid`` with the defaults of :mod:`analysis.families` and ``grid_range``
    (:data:`~flatbody_env.physics.validation.MAP_GRID_RANGE` or ``SWEEP_GRID_RANGE``)."""
    lo, hi = grid_range
    p.add_argument(
        "--lam-range",
        type=float_range("--lam-range"),
        default=MAP_LAM_RANGE,
        metavar="LO,HI",
        help=f"lambda range (default {_pair(MAP_LAM_RANGE)})",
    )
    p.add_argument(
        "--mu-range",
        type=float_range("--mu-range"),
        default=MAP_MU_RANGE,
        metavar="LO,HI",
        help=f"mu range (default {_pair(MAP_MU_RANGE)}); only mu < lambda is used",
    )
    p.add_argument(
        "--grid",
        type=int_at_least(grid_name, lo, hi),
        default=MAP_GRID,
        metavar="N",
        help=f"grid points per axis, in [{lo}, {hi}] (default {MAP_GRID})",
    )


def _box(args):
    return SearchBox(lam=args.lam_range, mu=args.mu_range, n=args.grid)


def resolve_body(args, *, need_spins: bool = True):
    """(body, s3, p_theta) from the flags (or the scene); ValueError naming the flag on bad input."""
    from flatbody_env.physics.body import Body

    given = [c for c in _CONSTANTS if getattr(args, c) is not None]
    s3 = args.s3
    pt = args.p_theta
    if args.scene is not None:
        from flatbody_env.scene import load_scene

        if given or args.potential is not None:
            bad = _flag(given[0]) if given else "--potential"
            raise ValueError(f"{bad}: give the constants either by flags or by --scene, not both")
        scene = load_scene(args.scene)
        body = scene.body
        s3 = scene.state["s3"] if s3 is None else s3
        pt = scene.state["p_theta"] if pt is None else pt
    else:
        pot_name = args.potential or "V3"
        for c in given:
            if c in _FOR_POTENTIAL and _FOR_POTENTIAL[c] != pot_name:
                raise ValueError(f"{_flag(c)}: applies to {_FOR_POTENTIAL[c]} only (the potential is {pot_name})")
        val = {c: (1.0 if getattr(args, c) is None else getattr(args, c)) for c in _CONSTANTS}  # ranges: cli.args
        fields = {"V1": ("k",), "V2": ("c", "d"), "V3": ("kappa",)}[pot_name]
        body = Body.from_dict(
            {
                "params": {"J": val["J"], "J3": val["J3"]},
                "potential": {"name": pot_name, **{c: val[c] for c in fields}},
                "thickness": {"a": val["a"], "b": val["b"]},
            }
        )
    if need_spins:
        if s3 is None:
            raise ValueError("--s3: required (a finite number), or give --scene")
        if pt is None:
            raise ValueError("--p-theta: required (a finite number), or give --scene")
        s3, pt = float(s3), float(pt)
    if not body.inertia.is_isotropic:
        raise ValueError("--scene: the analysis needs an isotropic body (J1 = J2)")
    return body, s3, pt


def _solutions(args, body, s3, pt):
    return solutions(body, s3, pt, box=_box(args), branch=args.branch, spin=args.spin)


def _header(body, s3, pt) -> str:
    return f"body: {body.describe()};  s3 = {s3:g}, p_theta = {pt:g}"


def _ellipses(args) -> int:
    body, s3, pt = resolve_body(args)
    if args.json:
        print(json.dumps(ellipses_answer(body, s3, pt, box=_box(args), branch=args.branch, spin=args.spin)))
        return 0
    sols = _solutions(args, body, s3, pt)
    print(_header(body, s3, pt))
    if not sols:
        print("no stationary ellipse in the search box (branch N needs s3 * p_theta > 0 for V1; see docs/analysis.md)")
        return 0
    print(
        f"{'#':>2} {'branch':<6} {'lambda':>12} {'mu':>12} {'rho':>10} {'omega3':>11} {'theta_dot':>11} {'energy':>13} {'residual':>9}  kind"
    )
    for i, e in enumerate(sols):
        print(
            f"{i:>2} {e.branch:<6} {e.lam:12.8f} {e.mu:12.8f} {e.rho:10.6f} {e.omega3:11.6f} {e.theta_dot:11.6f} "
            f"{e.energy:13.8f} {e.residual:9.1e}  {e.kind if e.branch == 'N' else 'in-plane axis ' + e.branch[1]}"
        )
    return 0


def _stability(args) -> int:
    from analysis.stability import analyse_stability

    body, s3, pt = resolve_body(args)
    if args.json:
        print(json.dumps(stability_answer(body, s3, pt, box=_box(args), branch=args.branch, spin=args.spin)))
        return 0
    results = [analyse_stability(body, e) for e in _solutions(args, body, s3, pt)]
    print(_header(body, s3, pt))
    if not results:
        print("no stationary ellipse in the search box")
        return 0
    for i, r in enumerate(results):
        e = r.ellipse
        print(f"\n#{i} branch {e.branch}: lambda = {e.lam:.8f}, mu = {e.mu:.8f}, rho = {e.rho:.6f} ({e.kind})")
        print(
            f"   classification: {r.classification}; nonlinear: {r.nonlinear}; max Re = {r.max_real_part:.6g}"
            + (f"; out-of-plane q = {r.out_of_plane_q:.6g}" if r.out_of_plane_q is not None else "")
        )
        print("   eigenvalues: " + ", ".join(f"{z.real:+.6f}{z.imag:+.6f}i" for z in r.eigenvalues))
        print(
            "   zero modes: "
            + (", ".join(f"{m.quantity}" for m in r.zero_modes) or "none identified")
            + (f" (+{r.unexplained_zero_modes} unexplained)" if r.unexplained_zero_modes else "")
        )
        print(f"   energy-Casimir test: {r.energy_casimir}")
        for note in r.notes:
            print(f"   note: {note}")
    return 0


def _family(args) -> int:
    body, s3, pt = resolve_body(args, need_spins=False)
    fam, answer = family_run(
        body,
        args.vary,
        args.start,
        args.stop,
        s3=s3,
        p_theta=pt,
        seeds=args.seeds,
        box=_box(args),
        step=args.step,
        out=args.out,
        plot=args.plot,
        progress=True,
        names=("--from", "--to"),
    )
    start, stop, s3, pt, out, npts = (
        answer["range"][0],
        answer["range"][1],
        answer["s3"],
        answer["p_theta"],
        answer["csv"],
        answer["points"],
    )
    if args.json:
        print(json.dumps(answer))
        return 0
    fixed = {"s3": f"p_theta = {pt:g}", "p_theta": f"s3 = {s3:g}"}.get(args.vary, f"s3 = {s3:g}, p_theta = {pt:g}")
    print(f"body: {body.describe()}; {fixed}; {args.vary} in [{start:g}, {stop:g}]")
    print(f"{len(fam.branches)} branch(es), {npts} points")
    for bi, br in enumerate(fam.branches):
        if not br:
            continue
        counts = {}
        for fp in br:
            counts[fp.classification] = counts.get(fp.classification, 0) + 1
        print(
            f"  branch {bi}: {args.vary} from {br[0].param:.6g} to {br[-1].param:.6g}, {len(br)} points, "
            + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
        )
    for e in fam.events:
        print(
            f"  {e.kind} on branch {e.branch} at {args.vary} = {e.param:.6g} (lambda = {e.lam:.6g}, mu = {e.mu:.6g}) {e.detail}"
        )
    for e in fam.ends:
        if e.reason != "range":
            print(
                f"  branch {e.branch} ends at {args.vary} = {e.param:.6g} (lambda = {e.lam:.4g}, mu = {e.mu:.4g}): {e.detail}"
            )
    if fam.empty_seeds:
        print(
            f"  no stationary ellipse in the search box at {args.vary} = "
            + ", ".join(f"{v:.6g}" for v in fam.empty_seeds)
        )
    if fam.scale != "linear":
        print(
            f"  the range spans decades: followed in {'ln' if fam.scale == 'log' else 'asinh'}({args.vary}), seeds evenly spaced in it"
        )
    if out is not None:
        print(f"wrote {out}" + (f" and {args.plot}" if args.plot else ""))
    return 0


def _stability_map(args) -> int:
    body, _, _ = resolve_body(args, need_spins=False)
    out = args.out
    if out is None and args.plot is not None:
        out = str(check_output_path("--out", Path(args.plot).with_suffix(".csv"), (".csv",)))
    rows = stability_map_answer(body, args.lam_range, args.mu_range, args.grid, out=out, plot=args.plot, progress=True)[
        "rows"
    ]
    if args.json:
        print(json.dumps({"rows": rows}))
        return 0
    print(f"body: {body.describe()}; {len(rows)} stationary ellipses on a {args.grid} x {args.grid} shape grid")
    for kind in ("rigid", "circulating"):
        sel = [r for r in rows if r["kind"] == kind]
        counts: dict[str, int] = {}
        for r in sel:
            key = r["classification"] + (" (energy-Casimir stable)" if r["nonlinear"] == "stable" else "")
            counts[key] = counts.get(key, 0) + 1
        print(f"  {kind}: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    if out is not None:
        print(f"wrote {out}" + (f" and {args.plot}" if args.plot else ""))
    return 0


def _invariants(args) -> int:
    from analysis.invariants import format_drift_table
    from flatbody_env.simulation import read_trajectory

    data = read_trajectory(args.trajectory)
    body = None
    given = [c for c in _CONSTANTS if getattr(args, c) is not None]
    if args.scene is not None or given or args.potential is not None:
        body, _, _ = resolve_body(args, need_spins=False)
    report, body = invariants_run(data, body)
    if args.json:
        print(json.dumps(report.to_dict()))
        return 0
    print(format_drift_table(report))
    if body is None:
        print("\n(no body known: give --scene or the constant flags for H and the rates dG/dt, dC/dt)")
    if report.C is None:
        print("(no rotation in the file: save it with 'flatbody simulate --with-rotation' for C, dC/dt and R s)")
    return 0


def register(sub) -> None:
    p = sub.add_parser("ellipses", help="stationary ellipses for given s3, p_theta (eqs. 52-54 of the paper)")
    add_body_arguments(p)
    add_box_arguments(p)
    p.add_argument(
        "--branch",
        choices=("N", "A", "all"),
        default="N",
        help="N: s1 = s2 = 0 (paper); A: in-plane axis (needs --spin)",
    )
    p.add_argument("--spin", type=momentum("--spin"), default=None, help="spin about the in-plane axis for branch A")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_ellipses)

    p = sub.add_parser("stability", help="eigenvalues and classification of each stationary ellipse")
    add_body_arguments(p)
    add_box_arguments(p)
    p.add_argument(
        "--branch",
        choices=("N", "A", "all"),
        default="N",
        help="N: s1 = s2 = 0 (paper); A: in-plane axis (needs --spin)",
    )
    p.add_argument("--spin", type=momentum("--spin"), default=None, help="spin about the in-plane axis for branch A")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_stability)

    p = sub.add_parser("family", help="follow stationary ellipses over a parameter (continuation, folds, stability)")
    add_body_arguments(p)
    add_box_arguments(p)
    p.add_argument(
        "--vary",
        default=PARAMETERS[0],
        help=f"{PARAMETERS[0]}, {PARAMETERS[1]} or a constant ({', '.join(PARAMETERS[2:])}); default {PARAMETERS[0]}",
    )
    start, stop = DEFAULT_FAMILY_RANGE
    p.add_argument(
        "--from", dest="start", type=momentum("--from"), default=start, help=f"start of the range (default {start:g})"
    )
    p.add_argument(
        "--to", dest="stop", type=momentum("--to"), default=stop, help=f"end of the range (default {stop:g})"
    )
    lo, hi = FAMILY_SEEDS_RANGE
    p.add_argument(
        "--seeds",
        type=int_at_least("--seeds", lo, hi),
        default=DEFAULT_SEEDS,
        help=f"parameter values at which all solutions are sought, in [{lo}, {hi}] (default {DEFAULT_SEEDS})",
    )
    p.add_argument(
        "--step",
        type=positive_float("--step", MOMENTUM_MAX),
        default=None,
        help="largest continuation step (default range/60)",
    )
    p.add_argument(
        "--out", type=output_file("--out", (".csv",)), metavar="FILE.csv", help="write the family table (CSV)"
    )
    p.add_argument(
        "--plot",
        type=output_file("--plot", (".png",)),
        metavar="FILE.png",
        help="draw the family chart coloured by stability (PNG)",
    )
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(handler=_family)

    p = sub.add_parser("stability-map", help="stability of the stationary ellipses over a grid of shapes (lambda, mu)")
    add_body_arguments(p)
    add_map_arguments(p, grid_range=MAP_GRID_RANGE)
    p.add_argument("--out", type=output_file("--out", (".csv",)), metavar="FILE.csv", help="write the table (CSV)")
    p.add_argument("--plot", type=output_file("--plot", (".png",)), metavar="FILE.png", help="draw the map (PNG)")
    p.add_argument("--json", action="store_true", help="print JSON rows")
    p.set_defaults(handler=_stability_map)

    p = sub.add_parser("invariants", help="invariants and drift table along a saved trajectory")
    p.add_argument("trajectory", metavar="TRAJECTORY.json", help="from 'flatbody simulate --with-rotation --out FILE'")
    add_body_arguments(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_invariants)

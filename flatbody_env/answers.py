"""The JSON answers of the analysis questions, written once for every front end.

``flatbody simulate|scenes|methods|ellipses|stability|family|stability-map|invariants|failure-study
--json`` print these dicts, the HTTP service returns them and the sweeps store them as rows — so
every front end gives the same keys and the same numbers. Inputs are validated objects (a
:class:`~flatbody_env.physics.body.Body`, a :class:`~flatbody_env.scene.Scene`, finite numbers);
files are written atomically (:mod:`flatbody_env.output`).
"""

from __future__ import annotations

from pathlib import Path

from flatbody_env.output import atomic_write, check_output_path
from flatbody_env.physics import validation


def simulate_trajectory(
    scene,
    *,
    t_end=None,
    times=None,
    samples=None,
    method="auto",
    rtol=1e-10,
    atol=1e-10,
    step=None,
    model="auto",
    with_rotation=False,
    max_nfev=None,
    max_wall_time=None,
):
    """The trajectory ``flatbody simulate`` prints (its JSON is ``traj.to_dict()``); the service calls this too.

    ``scene`` is a :class:`~flatbody_env.scene.Scene`; ``t_end`` defaults to the scene's; ``times``
    (explicit output times, returned exactly) or ``samples`` (an even grid of that many points), not both;
    ``max_nfev`` / ``max_wall_time`` bound the work (None: the defaults of :func:`flatbody_env.simulate`).
    """
    from flatbody_env.simulation import simulate

    if times is not None and samples is not None:
        raise ValueError("times: give times (--times) or samples (--samples), not both")
    t_end = t_end if t_end is not None else scene.t_end
    if times is None and samples is not None:
        import numpy as np

        times = np.linspace(0.0, t_end, samples)
    budget = {k: v for k, v in (("max_nfev", max_nfev), ("max_wall_time", max_wall_time)) if v is not None}
    return simulate(
        scene,
        t_end=t_end,
        times=times,
        method=method,
        rtol=rtol,
        atol=atol,
        step=step,
        model=model,
        with_rotation=with_rotation,
        **budget,
    )


def scenes_answer() -> dict:
    """What ``flatbody scenes --json`` prints: ``{name: scene JSON}`` of the built-in scenes."""
    from flatbody_env.scene import builtin_scenes

    return {name: sc.to_dict() for name, sc in builtin_scenes().items()}


def methods_answer() -> list:
    """What ``flatbody methods --json`` prints: one ``MethodInfo.as_dict()`` per integrator."""
    from flatbody_env.integrators import available_methods

    return [m.as_dict() for m in available_methods()]


def solutions(body, s3: float, pt: float, *, box=None, branch: str = "N", spin: float | None = None) -> list:
    """The stationary ellipses of branch N (s3, p_θ given), A (``spin`` about an in-plane axis) or all."""
    from analysis.stationary import SearchBox, stationary_ellipses, steady_rotations

    box = box or SearchBox()
    out = []
    if branch in ("N", "all"):
        out += stationary_ellipses(body, s3, pt, box=box)
    if branch in ("A", "all"):
        if spin is None:
            if branch == "A":
                raise ValueError(
                    "--spin: required with --branch A (the spin s about the in-plane axis, finite and non-zero)"
                )
        else:
            out += steady_rotations(body, spin, box=box)
    return out


def ellipses_answer(body, s3: float, p_theta: float, *, box=None, branch: str = "N", spin: float | None = None) -> dict:
    """What ``flatbody ellipses --json`` prints: ``{"solutions": [StationaryEllipse.to_dict(), ...]}`` (the service's answer too)."""
    return {"solutions": [e.to_dict() for e in solutions(body, s3, p_theta, box=box, branch=branch, spin=spin)]}


def stability_answer(
    body, s3: float, p_theta: float, *, box=None, branch: str = "N", spin: float | None = None
) -> dict:
    """What ``flatbody stability --json`` prints: ``{"solutions": [StabilityResult.to_dict(), ...]}`` (the service's answer too)."""
    from analysis.stability import analyse_stability

    sols = solutions(body, s3, p_theta, box=box, branch=branch, spin=spin)
    return {"solutions": [analyse_stability(body, e).to_dict() for e in sols]}


def family_summary(fam, *, csv: str | None = None, plot: str | None = None) -> dict:
    """The ``family --json`` object of a :class:`analysis.families.Family` (also a ``sweep family`` row): the range,
    the branches' points and events, where and why each branch ends (``ends``), the continuation's ``scale`` and the
    seeds (``empty_seeds``: those where the search box held no stationary ellipse)."""
    return {
        "param": fam.param_name,
        "range": list(fam.param_range),
        "s3": fam.s3,
        "p_theta": fam.p_theta,
        "branches": len(fam.branches),
        "points": sum(len(b) for b in fam.branches),
        "events": [
            {"kind": e.kind, "branch": e.branch, "param": e.param, "lambda": e.lam, "mu": e.mu, "detail": e.detail}
            for e in fam.events
        ],
        "ends": [
            {"branch": e.branch, "param": e.param, "lambda": e.lam, "mu": e.mu, "reason": e.reason, "detail": e.detail}
            for e in getattr(fam, "ends", ())
        ],
        "scale": getattr(fam, "scale", "linear"),
        "seeds": list(getattr(fam, "seeds", ())),
        "empty_seeds": list(getattr(fam, "empty_seeds", ())),
        "csv": csv,
        "plot": plot,
    }


def family_run(
    body,
    vary,
    start,
    stop,
    *,
    s3=None,
    p_theta=None,
    seeds=None,
    box=None,
    step=None,
    out=None,
    plot=None,
    progress=False,
    names=("start", "stop"),
    on_stage=None,
):
    """Follow a family of stationary ellipses over ``vary`` (:func:`analysis.families.follow_family`); returns
    ``(family, family_summary)``, writing the CSV and the chart when ``out`` / ``plot`` are given. ``s3``,
    ``p_theta``, ``seeds`` None: the library's defaults (:data:`analysis.families.DEFAULT_S3`, ``DEFAULT_P_THETA``,
    ``DEFAULT_SEEDS``). ``names``: the range's fields in the caller's words (``("--from", "--to")``,
    ``("from", "to")``), which a refused range is named by (:func:`analysis.families.check_range`). ``on_stage``:
    called with ``"csv"`` and ``"plot"`` before each file is written (a job's progress)."""
    from analysis.families import (
        DEFAULT_P_THETA,
        DEFAULT_S3,
        DEFAULT_SEEDS,
        PARAMETERS,
        check_range,
        follow_family,
        write_family_csv,
    )

    validation.string("--vary", vary, choices=PARAMETERS)
    start, stop = check_range(vary, start, stop, names=names)
    s3 = DEFAULT_S3 if s3 is None else float(s3)
    pt = DEFAULT_P_THETA if p_theta is None else float(p_theta)
    seeds = DEFAULT_SEEDS if seeds is None else seeds
    fam = follow_family(body, vary, start, stop, s3=s3, p_theta=pt, seeds=seeds, box=box, step=step, progress=progress)
    if plot is not None and not any(fam.branches):  # said in the request's terms, before any file is written
        raise ValueError(
            f"family: no stationary ellipse over {vary} from {start:g} to {stop:g}"
            + "".join(f", {k} = {v:g}" for k, v in (("s3", s3), ("p_theta", pt)) if k != vary)
            + ": "
            f"the search box held none at any of the {len(fam.seeds) or seeds} seeds, so there is no family to chart "
            "(move the range or widen the search box)"
        )
    if out is None and plot is not None:
        out = str(check_output_path("--out", Path(plot).with_suffix(".csv"), (".csv",)))
    stage = on_stage or (lambda _: None)
    if out is not None:
        stage("csv")
        atomic_write(out, lambda tmp: write_family_csv(fam, tmp))
    if plot is not None:
        stage("plot")
        from analysis.plots import plot_family

        atomic_write(plot, lambda tmp: plot_family(out, tmp))
    return fam, family_summary(fam, csv=out, plot=plot)


def family_answer(body, vary: str, start: float, stop: float, **options) -> dict:
    """What ``flatbody family --json`` prints (options: s3, p_theta, seeds, box, step, out, plot, progress)."""
    return family_run(body, vary, start, stop, **options)[1]


def stability_map_answer(
    body, lam_range, mu_range, grid: int, *, out=None, plot=None, progress: bool = False, on_stage=None
) -> dict:
    """What ``flatbody stability-map --json`` prints: ``{"rows": [...]}`` (files written when asked;
    ``progress``: a bar over the grid's rows on stderr; ``on_stage``: called with ``"csv"`` and ``"plot"``
    before each file is written)."""
    import numpy as np

    from analysis.families import shape_stability_grid, write_table_csv

    (lo_l, hi_l), (lo_m, hi_m) = lam_range, mu_range
    rows = shape_stability_grid(body, np.linspace(lo_l, hi_l, grid), np.linspace(lo_m, hi_m, grid), progress=progress)
    if plot is not None and not rows:  # said in the request's terms, before any file is written
        raise ValueError(
            f"stability-map: no stationary ellipse with lambda in [{lo_l:g}, {hi_l:g}] and mu in [{lo_m:g}, {hi_m:g}] "
            f"on the {grid} x {grid} grid, so there is no map to chart (move or widen the ranges)"
        )
    if out is None and plot is not None:
        out = str(check_output_path("--out", Path(plot).with_suffix(".csv"), (".csv",)))
    stage = on_stage or (lambda _: None)
    if out is not None:
        stage("csv")
        atomic_write(out, lambda tmp: write_table_csv(rows, tmp))
    if plot is not None:
        stage("plot")
        from analysis.plots import plot_shape_map

        atomic_write(
            plot, lambda tmp: plot_shape_map(out, tmp, title=f"Stationary ellipses by shape, {body.describe()}")
        )
    return {"rows": rows}


def invariants_run(data, body):
    """``(InvariantReport, body)`` of a trajectory (dict or :class:`~flatbody_env.simulation.Trajectory`); without
    ``body`` the body of the built-in scene named in its meta is used when there is one."""
    from analysis.invariants import invariants_along
    from flatbody_env.simulation import Trajectory

    traj = data if isinstance(data, Trajectory) else Trajectory.from_dict(data)
    if body is None:
        from flatbody_env.scene import builtin_scenes

        scenes = builtin_scenes()
        if traj.scene in scenes:
            body = scenes[traj.scene].body
    return invariants_along(traj, body), body


def invariants_answer(data, body=None) -> dict:
    """What ``flatbody invariants --json`` prints for a trajectory (its dict form or a ``Trajectory``); without
    ``body``, the body of the built-in scene named in ``meta.scene`` is used when there is one."""
    return invariants_run(data, body)[0].to_dict()


def failure_rows(points) -> list[dict]:
    """The ``failure-study --json`` rows: one plain dict per :class:`analysis.failure_study.FailurePoint`."""
    import dataclasses

    return [dataclasses.asdict(p) for p in points]

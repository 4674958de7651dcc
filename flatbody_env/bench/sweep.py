"""``flatbody bench sweep``: how the sweep engine scales over workers.

Measured side by side in one run, on the stability map of the default body:

1. **serial**: every task of the sweep in this process, no Dask — the reference wall time and each
   task's own cost (the per-task costs drive the simulation below).
2. **local workers** (1, 2, …): an embedded Dask cluster of that many worker processes (1: in
   this process) — start-up time (cluster + warm-up imports) and the run's wall time; speed-up =
   serial / run, and end to end (start-up included).
3. **scheduler overhead per task**: ``noop_tasks`` empty tasks on a cluster of ``sim_workers``
   processes; wall / tasks is what the scheduler and the transport cost per task.
4. **simulated multi-node run**: the same tasks on ``sim_workers`` worker processes, each task
   *sleeping* for its measured serial cost — sleeping workers use no core, so N processes on this
   machine stand in for N machines. The measured wall time is compared with the model

       T(W) = t₀ + n·o + makespan(costs, W)

   (t₀: connecting to a running cluster, o: the overhead per task, the makespan: list scheduling
   of the measured costs in submission order on W workers), which is then extrapolated to 8, 32,
   128 workers.
5. **break-even grid size**: with c the measured cost per grid point and r λ-rows per task, the
   serial map costs c·G² and the cluster t₀ + (G/r)·o + c·G²/W; the cluster pays off above the
   positive root G* of c·G²(1 − 1/W) = t₀ + (G/r)·o (reported for the embedded 2-process cluster
   with its start-up, and for running clusters of 8/32/128 workers).

Output (:func:`report`): ``scaling.json`` (everything), ``scaling.csv`` (one figure per row) and the
chart ``scaling.png`` drawn from the saved JSON (:func:`plot`; ``--plot-only`` redraws it).
"""

from __future__ import annotations

import heapq
import math
import os
import time
from pathlib import Path
from typing import Any

from flatbody_env.bench.harness import Report, Stopwatch, Table
from flatbody_env.physics import validation
from flatbody_env.provenance import machine
from flatbody_env.sweep.tasks import Task, execute, plan

NAME = "scaling"
"""The files' stem: ``scaling.json``, ``.csv``, ``.png``."""


def _noop(x: int) -> int:
    return x


def _sleep(seconds: float) -> float:
    time.sleep(seconds)
    return seconds


def _warm() -> int:
    """Import what the map's tasks import (a sweep's first task on a fresh worker pays this)."""
    import analysis.families  # noqa: F401
    import flatbody_env.physics.body  # noqa: F401

    return os.getpid()


def makespan(costs: list[float], workers: int) -> float:
    """Wall time of ``costs`` on ``workers`` identical workers when each task, in submission
    order, goes to the first worker that is free (what Dask's scheduler-side queueing does)."""
    if not costs:
        return 0.0
    loads = [0.0] * min(workers, len(costs))
    heapq.heapify(loads)
    for c in costs:
        heapq.heappush(loads, heapq.heappop(loads) + c)
    return max(loads)


def model_time(costs: list[float], workers: int, *, t0: float, overhead: float) -> float:
    """T(W) = t₀ + n·o + makespan(costs, W) (the module docstring's model)."""
    return t0 + len(costs) * overhead + makespan(costs, workers)


def break_even_grid(cost_per_point: float, workers: int, *, t0: float, overhead: float, rows_per_task: int) -> float:
    """Smallest grid size G above which W workers beat the serial map (positive root of
    c·G²(1 − 1/W) − (o/r)·G − t₀ = 0); ``inf`` for one worker."""
    a = cost_per_point * (1.0 - 1.0 / workers)
    if a <= 0:
        return math.inf
    b = overhead / rows_per_task
    return (b + math.sqrt(b * b + 4.0 * a * t0)) / (2.0 * a)


def _spec(grid: int, chunk: int) -> dict[str, Any]:
    from analysis.families import MAP_LAM_RANGE, MAP_MU_RANGE
    from flatbody_env.scene import load_scene

    return {
        "kind": "stability-map",
        "body": load_scene("default").body.to_dict(),
        "lam_range": list(MAP_LAM_RANGE),
        "mu_range": list(MAP_MU_RANGE),
        "grid": grid,
        "chunk": chunk,
    }


def _timed_cluster_run(tasks: list[Task], workers: int) -> dict[str, float]:
    from distributed import wait

    from flatbody_env.sweep.cluster import dask_client

    startup = Stopwatch.started()
    with dask_client(workers=workers) as client:
        client.wait_for_workers(workers)
        client.run(_warm)
        startup_s = startup.seconds
        with Stopwatch() as run:
            futures = client.map(execute, tasks, pure=False)
            wait(futures)
            outcomes = client.gather(futures)
    bad = [o.key for o in outcomes if o.error is not None]
    if bad:
        raise RuntimeError(f"bench sweep: tasks failed on the cluster: {', '.join(bad[:3])}")
    return {"startup_s": startup_s, "run_s": run.seconds}


def measure(
    *,
    grid: int = 48,
    chunk: int = 2,
    workers: tuple[int, ...] = (1, 2),
    sim_workers: int = 4,
    noop_tasks: int = 400,
    extrapolate: tuple[int, ...] = (8, 32, 128),
) -> dict[str, Any]:
    """Run the benchmark (module docstring); returns a JSON-able report, with the machine it ran on."""
    from distributed import Client, LocalCluster, wait

    spec = _spec(grid, chunk)
    tasks = plan(spec, "unused")  # the map's tasks write no files
    _warm()
    with Stopwatch() as serial_run:
        outcomes = [execute(task) for task in tasks]
    serial = serial_run.seconds
    if any(o.error for o in outcomes):
        raise RuntimeError("bench sweep: a serial task failed: " + next(o.error for o in outcomes if o.error))
    costs = [o.seconds for o in outcomes]
    per_point = sum(costs) / (grid * grid)

    local = []
    for w in workers:
        r = _timed_cluster_run(tasks, w)
        local.append(
            {
                "workers": w,
                **r,
                "speedup": serial / r["run_s"],
                "speedup_end_to_end": serial / (r["startup_s"] + r["run_s"]),
            }
        )

    import logging

    from flatbody_env.sweep.cluster import QUIET_SCHEDULER, workers_leave_sigint

    cluster = None
    try:
        with workers_leave_sigint():
            cluster = LocalCluster(
                n_workers=sim_workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
                scheduler_kwargs=QUIET_SCHEDULER,
            )
        with Stopwatch() as connecting:
            client = Client(cluster.scheduler_address)  # as a user connects to a running cluster
            client.wait_for_workers(sim_workers)
        connect = connecting.seconds
        client.run(_warm)
        wait(client.map(_noop, range(sim_workers), pure=False))
        with Stopwatch() as noops:
            wait(client.map(_noop, range(noop_tasks), pure=False))
        overhead = noops.seconds / noop_tasks
        with Stopwatch() as simulated:
            wait(client.map(_sleep, costs, pure=False))
        sim_wall = simulated.seconds
        client.close()
    finally:
        if cluster is not None:
            cluster.close()
    sim_model = model_time(costs, sim_workers, t0=0.0, overhead=overhead)
    # the same map at a larger grid: G/chunk tasks of chunk·G points each, at the measured cost per point
    big_grid = 1000
    big_costs = [per_point * chunk * big_grid] * math.ceil(big_grid / chunk)
    extra = []
    for w in extrapolate:
        extra.append(
            {
                "workers": w,
                "grid": grid,
                "predicted_s": model_time(costs, w, t0=connect, overhead=overhead),
                "predicted_speedup": serial / model_time(costs, w, t0=connect, overhead=overhead),
                "grid_big": big_grid,
                "predicted_big_s": model_time(big_costs, w, t0=connect, overhead=overhead),
                "predicted_big_speedup": sum(big_costs) / model_time(big_costs, w, t0=connect, overhead=overhead),
                "break_even_grid": break_even_grid(per_point, w, t0=connect, overhead=overhead, rows_per_task=chunk),
            }
        )
    local2 = next((x for x in local if x["workers"] == 2), None)
    return {
        "grid": grid,
        "chunk": chunk,
        "tasks": len(tasks),
        "points": grid * grid,
        "serial_s": serial,
        "task_cost_mean_s": sum(costs) / len(costs),
        "task_cost_max_s": max(costs),
        "cost_per_point_s": per_point,
        "task_costs_s": costs,
        "local": local,
        "overhead_per_task_s": overhead,
        "overhead_over_task_cost": overhead / (sum(costs) / len(costs)),
        "connect_s": connect,
        "noop_tasks": noop_tasks,
        "simulated": {
            "workers": sim_workers,
            "wall_s": sim_wall,
            "model_s": sim_model,
            "ideal_s": sum(costs) / sim_workers,
            "speedup": sum(costs) / sim_wall,
        },
        "extrapolated": extra,
        "break_even_local_2": None
        if local2 is None
        else break_even_grid(per_point, 2, t0=local2["startup_s"], overhead=overhead, rows_per_task=chunk),
        "machine": machine(),
    }


def tables(rep: dict[str, Any]) -> list[Table]:
    """The report's figures for the terminal (no docs block: docs/scaling.md quotes them)."""
    load = rep["machine"]["load_avg_1min"]
    sim = rep["simulated"]
    runs = [["serial (no Dask)", "—", f"{rep['serial_s']:.2f} s", "1.00×", "—"]]
    runs += [
        [
            f"{x['workers']} local worker(s)",
            f"{x['startup_s']:.2f} s",
            f"{x['run_s']:.2f} s",
            f"{x['speedup']:.2f}×",
            f"{x['speedup_end_to_end']:.2f}×",
        ]
        for x in rep["local"]
    ]
    runs.append(
        [
            f"{sim['workers']} simulated nodes (tasks sleep their measured cost)",
            f"{rep['connect_s']:.2f} s (connect)",
            f"{sim['wall_s']:.2f} s (model {sim['model_s']:.2f}, ideal {sim['ideal_s']:.2f})",
            f"{sim['speedup']:.2f}×",
            "—",
        ]
    )
    notes = [
        f"task cost mean {rep['task_cost_mean_s'] * 1e3:.0f} ms, max {rep['task_cost_max_s'] * 1e3:.0f} ms; "
        f"{rep['cost_per_point_s'] * 1e3:.2f} ms per grid point; scheduler overhead "
        f"{rep['overhead_per_task_s'] * 1e3:.2f} ms per task ({rep['overhead_over_task_cost']:.1%} of a mean task)"
    ]
    if rep["break_even_local_2"] is not None:
        notes.append(
            f"embedded 2-process cluster (start-up included) pays off above grid {rep['break_even_local_2']:.0f}"
        )
    model = [
        [
            str(x["workers"]),
            f"{x['predicted_s']:.2f} s ({x['predicted_speedup']:.1f}×)",
            f"{x['predicted_big_s']:.1f} s ({x['predicted_big_speedup']:.1f}×)",
            f"{x['break_even_grid']:.0f}",
        ]
        for x in rep["extrapolated"]
    ]
    big = rep["extrapolated"][0]["grid_big"] if rep["extrapolated"] else 1000
    return [
        Table(
            title=f"stability map {rep['grid']} x {rep['grid']} ({rep['tasks']} tasks of {rep['chunk']} lambda rows), "
            f"{rep['machine']['cpu_count']} cores (load {'?' if load is None else f'{load:.1f}'})",
            columns=["run", "start-up", "wall time", "speed-up", "with start-up"],
            rows=runs,
            notes=notes,
            block=None,
        ),
        Table(
            title="the model, extrapolated",
            columns=["workers", f"grid {rep['grid']}", f"grid {big}", "pays off above grid"],
            rows=model,
            block=None,
        ),
    ]


def report(rep: dict[str, Any]) -> Report:
    """The files of a run (:func:`flatbody_env.bench.harness.write_report`): the JSON holds everything, the CSV one
    figure per row (section, workers, figure, value), the PNG is :func:`plot` of the saved JSON."""
    rows: list[list[Any]] = [
        ["serial", 0, "wall_s", rep["serial_s"]],
        ["serial", 0, "task_cost_mean_s", rep["task_cost_mean_s"]],
        ["serial", 0, "cost_per_point_s", rep["cost_per_point_s"]],
    ]
    for x in rep["local"]:
        rows += [["local", x["workers"], k, x[k]] for k in ("startup_s", "run_s", "speedup", "speedup_end_to_end")]
    sim = rep["simulated"]
    rows += [
        ["scheduler", sim["workers"], "overhead_per_task_s", rep["overhead_per_task_s"]],
        ["scheduler", sim["workers"], "connect_s", rep["connect_s"]],
    ]
    rows += [["simulated", sim["workers"], k, sim[k]] for k in ("wall_s", "model_s", "ideal_s", "speedup")]
    for x in rep["extrapolated"]:
        rows += [
            ["model", x["workers"], k, x[k]]
            for k in ("predicted_s", "predicted_speedup", "predicted_big_s", "predicted_big_speedup", "break_even_grid")
        ]
    if rep["break_even_local_2"] is not None:
        rows.append(["local", 2, "break_even_grid", rep["break_even_local_2"]])
    return Report(
        name=NAME,
        record=rep,
        header=["section", "workers", "figure", "value"],
        rows=rows,
        chart=plot,
        chart_from="json",
        tables=tables(rep),
    )


def plot(json_path: str | Path, png_path: str | Path) -> Path:
    """Two panels: speed-up over workers (measured, simulated, modelled) and time over grid size
    (serial vs clusters; the crossings are the break-even grid sizes)."""
    from flatbody_env.figures import chart

    rep = validation.read_json("--plot-only", json_path)
    costs = rep["task_costs_s"]
    chunk, big = rep["chunk"], rep["extrapolated"][0]["grid_big"] if rep["extrapolated"] else 1000
    big_costs = [rep["cost_per_point_s"] * chunk * big] * math.ceil(big / chunk)
    c_point, o, t0 = rep["cost_per_point_s"], rep["overhead_per_task_s"], rep["connect_s"]
    with chart(png_path, size=(11, 5.2), ncols=2) as c:
        ax1, ax2 = c.axes[0]
        ws = [1, 2, 4, 8, 16, 32, 64, 128]
        ax1.plot(
            ws,
            [rep["serial_s"] / model_time(costs, w, t0=t0, overhead=o) for w in ws],
            "-",
            color="0.5",
            label=f"model, grid {rep['grid']} ({rep['tasks']} tasks)",
        )
        ax1.plot(
            ws,
            [sum(big_costs) / model_time(big_costs, w, t0=t0, overhead=o) for w in ws],
            "--",
            color="C2",
            label=f"model, grid {big} ({len(big_costs)} tasks)",
        )
        ax1.plot(ws, ws, ":", color="k", lw=0.8, label="ideal")
        ax1.plot(
            [x["workers"] for x in rep["local"]],
            [x["speedup"] for x in rep["local"]],
            "o",
            color="C0",
            label="measured, local processes",
        )
        ax1.plot(
            [rep["simulated"]["workers"]],
            [rep["simulated"]["speedup"]],
            "s",
            color="C1",
            label="measured, simulated nodes",
        )
        ax1.set_xscale("log", base=2)
        ax1.set_yscale("log", base=2)
        ax1.set_xlabel("workers")
        ax1.set_ylabel("speed-up over serial")
        ax1.set_title("sweep stability-map: speed-up")
        ax1.legend(loc="upper left")
        ax1.grid(alpha=0.3)
        grids = [int(g) for g in (10 ** (x / 20) for x in range(20, 81))]
        ax2.plot(grids, [c_point * g * g for g in grids], "-", color="k", label="serial")
        for k, w in enumerate((2, 8, 32, 128)):
            ax2.plot(
                grids,
                [
                    t0 + math.ceil(g / chunk) * o + makespan([c_point * chunk * g] * math.ceil(g / chunk), w)
                    for g in grids
                ],
                "-",
                color=f"C{k}",
                label=f"{w} workers (running cluster)",
            )
        local2 = next((x for x in rep["local"] if x["workers"] == 2), None)
        if local2 is not None:
            ax2.plot(
                grids,
                [
                    local2["startup_s"]
                    + math.ceil(g / chunk) * o
                    + makespan([c_point * chunk * g] * math.ceil(g / chunk), 2)
                    for g in grids
                ],
                "--",
                color="C0",
                label=f"2 local processes (start-up {local2['startup_s']:.1f} s)",
            )
        ax2.set_xscale("log")
        ax2.set_yscale("log")
        ax2.set_xlabel("grid points per axis")
        ax2.set_ylabel("wall time (s, model from measured costs)")
        ax2.set_title(f"overhead {o * 1e3:.1f} ms/task, connect {t0:.2f} s, {c_point * 1e3:.2f} ms/point")
        ax2.legend(loc="upper left")
        ax2.grid(alpha=0.3, which="both")
        c.caption(
            f"Measured on {rep.get('machine', {}).get('cpu_count', '?')} core(s): the stability map, grid {rep['grid']}, "
            f"{rep['tasks']} tasks of {chunk} λ rows. Model: T(W) = t₀ + n·o + makespan(task costs, W), "
            "t₀ connecting to a running cluster, o the scheduler overhead per task,\n"
            "makespan the tasks handed out in order to W workers. Simulated nodes: worker processes whose tasks "
            "sleep for their measured cost (a sleeping worker uses no core). Right: where a cluster's line\n"
            "crosses the serial one, the cluster pays off (the break-even grid)."
        )
    return Path(png_path)


__all__ = ["NAME", "break_even_grid", "makespan", "measure", "model_time", "plot", "report", "tables"]

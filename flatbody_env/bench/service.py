"""``flatbody bench service``: latency and throughput of the HTTP service under load.

The service is started as ``flatbody serve`` in a subprocess on a free loopback port with a fresh
data dir (:func:`flatbody_env.service.launch.start_service`); a long job (a large ``stability-map``)
is queued first so that the figures are taken while a worker process is busy with it. Then, for each
endpoint (``GET /health``, ``POST /ellipses`` with the default body, a short ``POST /simulate``) and
each number of concurrent clients, a real HTTP client (httpx, one connection per client) sends at
most ``requests`` requests for at most ``seconds`` seconds. Reported: p50 and p99 latency,
requests/s and the number of errors (any answer other than 200 counts). Output
(:func:`report`): ``service_benchmark.json`` and ``.csv``, and the chart ``.png`` drawn from the
saved JSON (:func:`plot`; ``flatbody bench service --plot-only`` redraws it).
"""

from __future__ import annotations

import asyncio
import os
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flatbody_env.bench.harness import Report, Stopwatch, Table
from flatbody_env.physics import validation

ENDPOINTS: dict[str, tuple[str, str, dict[str, Any] | None]] = {
    "GET /health": ("GET", "/health", None),
    "POST /ellipses": (
        "POST",
        "/ellipses",
        {
            "body": {
                "params": {"J": 1.0, "J3": 1.0},
                "potential": {"name": "V3", "kappa": 1.0},
                "thickness": {"a": 1.0, "b": 1.0},
            },
            "s3": 2.0,
            "p_theta": 0.5,
        },
    ),
    "POST /simulate": ("POST", "/simulate", {"scene": "default", "t_end": 1.0, "samples": 11}),
}
"""What is measured: name → (HTTP method, path, JSON body)."""

LONG_JOB = {"kind": "stability-map", "params": {"grid": 200}}
"""The job that keeps one worker busy during the measurement."""

NAME = "service_benchmark"
"""The files' stem: ``service_benchmark.json``, ``.csv``, ``.png``."""


@dataclass(frozen=True, kw_only=True)
class LoadRow:
    """One endpoint at one number of concurrent clients."""

    endpoint: str
    clients: int
    requests: int
    errors: int
    seconds: float
    p50_ms: float
    p99_ms: float
    requests_per_s: float


@dataclass(frozen=True, kw_only=True)
class ServiceBenchmark:
    """All rows and the state of the long job during the run."""

    rows: list[LoadRow]
    workers: int
    cpus: int
    long_job: dict[str, Any]

    @property
    def errors(self) -> int:
        """Answers other than 200, over all rows."""
        return sum(r.errors for r in self.rows)

    def tables(self) -> list[Table]:
        """The rows (the terminal's text), under a line naming the service and the long job's status."""
        return [
            Table(
                title=f"service with {self.workers} worker process(es) on {self.cpus} CPU(s); long job "
                f"{self.long_job['kind']} status at the end: {self.long_job['status_at_end']}",
                columns=["endpoint", "clients", "requests", "errors", "p50 ms", "p99 ms", "req/s"],
                rows=[
                    [
                        r.endpoint,
                        str(r.clients),
                        str(r.requests),
                        str(r.errors),
                        f"{r.p50_ms:.2f}",
                        f"{r.p99_ms:.2f}",
                        f"{r.requests_per_s:.1f}",
                    ]
                    for r in self.rows
                ],
                block=None,
            )
        ]


async def _load(url: str, name: str, clients: int, requests: int, seconds: float) -> LoadRow:
    import httpx

    method, path, body = ENDPOINTS[name]
    latencies: list[float] = []
    errors = 0
    issued = 0
    run = Stopwatch.started()

    async def client() -> None:
        nonlocal issued, errors
        async with httpx.AsyncClient(base_url=url, timeout=120.0) as http:
            while issued < requests and run.seconds < seconds:
                issued += 1
                with Stopwatch() as one:
                    try:
                        r = await http.request(method, path, json=body)
                        ok = r.status_code == 200
                    except httpx.HTTPError:
                        ok = False
                latencies.append(one.seconds)
                errors += 0 if ok else 1

    await asyncio.gather(*(client() for _ in range(clients)))
    elapsed = run.seconds
    lat = np.array(latencies) * 1e3
    return LoadRow(
        endpoint=name,
        clients=clients,
        requests=len(latencies),
        errors=errors,
        seconds=elapsed,
        p50_ms=float(np.percentile(lat, 50)),
        p99_ms=float(np.percentile(lat, 99)),
        requests_per_s=len(latencies) / elapsed,
    )


def measure(
    *, clients: tuple[int, ...] = (1, 8, 32), requests: int = 200, seconds: float = 20.0, workers: int = 2
) -> ServiceBenchmark:
    """Start the service, queue the long job and load each endpoint at each client count (module docstring)."""
    import httpx

    from flatbody_env.service.launch import start_service, stop_service

    validation.number("seconds", seconds, positive=True, high=600.0)
    rows: list[LoadRow] = []
    with tempfile.TemporaryDirectory(prefix="flatbody-bench-service-") as data_dir:
        proc, url = start_service(data_dir, workers=workers)
        try:
            for method, path, body in ENDPOINTS.values():  # warm every worker process once
                for _ in range(workers):
                    httpx.request(method, url + path, json=body, timeout=120.0)
            job_id = httpx.post(url + "/jobs", json=LONG_JOB, timeout=30.0).json()["id"]
            time.sleep(0.5)  # the worker picks the job up
            status_at_start = httpx.get(f"{url}/jobs/{job_id}", timeout=30.0).json()["status"]
            for name in ENDPOINTS:
                for c in clients:
                    rows.append(asyncio.run(_load(url, name, c, requests, seconds)))
            status_at_end = httpx.get(f"{url}/jobs/{job_id}", timeout=30.0).json()["status"]
            httpx.delete(f"{url}/jobs/{job_id}", timeout=30.0)
        finally:
            stop_service(proc)
    return ServiceBenchmark(
        rows=rows,
        workers=workers,
        cpus=os.cpu_count() or 1,
        long_job={
            "kind": LONG_JOB["kind"],
            "params": LONG_JOB["params"],
            "status_at_start": status_at_start,
            "status_at_end": status_at_end,
        },
    )


def report(result: ServiceBenchmark) -> Report:
    """The files of a run (:func:`flatbody_env.bench.harness.write_report`): the JSON holds everything, the CSV one
    row per endpoint and client count, the PNG is :func:`plot` of the saved JSON."""
    fields = list(LoadRow.__dataclass_fields__)
    return Report(
        name=NAME,
        record={
            "workers": result.workers,
            "cpus": result.cpus,
            "long_job": result.long_job,
            "rows": [asdict(r) for r in result.rows],
        },
        header=fields,
        rows=[[asdict(r)[f] for f in fields] for r in result.rows],
        chart=plot,
        chart_from="json",
        tables=result.tables(),
    )


def load(json_path: str | Path) -> ServiceBenchmark:
    """A saved ``service_benchmark.json`` read back."""
    data = validation.read_json("--plot-only", json_path)
    return ServiceBenchmark(
        rows=[LoadRow(**r) for r in data["rows"]],
        workers=int(data["workers"]),
        cpus=int(data["cpus"]),
        long_job=dict(data["long_job"]),
    )


def plot(json_path: str | Path, png_path: str | Path) -> Path:
    """The chart of a saved ``service_benchmark.json``: latency (p50, p99) and requests/s over the number
    of concurrent clients, one colour per endpoint; a caption says what was measured."""
    from flatbody_env.figures import chart

    result = load(json_path)
    with chart(png_path, size=(11, 5.4), ncols=2) as c:
        ax1, ax2 = c.axes[0]
        names = list(dict.fromkeys([*ENDPOINTS, *(r.endpoint for r in result.rows)]))
        for k, name in enumerate(names):
            sel = sorted((r for r in result.rows if r.endpoint == name), key=lambda r: r.clients)
            if not sel:
                continue
            x = [r.clients for r in sel]
            color = f"C{k}"
            ax1.plot(x, [r.p50_ms for r in sel], "o-", color=color, label=f"{name}, p50")
            ax1.plot(x, [r.p99_ms for r in sel], "s--", color=color, label=f"{name}, p99")
            ax2.plot(x, [r.requests_per_s for r in sel], "o-", color=color, label=name)
        clients = sorted({r.clients for r in result.rows})
        for ax in (ax1, ax2):
            ax.set_xscale("log", base=2)
            ax.set_xticks(clients, [str(c) for c in clients])
            ax.minorticks_off()
            ax.set_xlabel("concurrent clients (one connection each)")
            ax.grid(True, alpha=0.3)
        ax1.set_yscale("log")
        ax1.set_ylabel("latency per request (ms, log scale)")
        ax1.set_title("latency: p50 (solid, circles), p99 (dashed, squares)")
        ax2.set_ylim(0, 1.15 * max([r.requests_per_s for r in result.rows], default=1.0))
        ax2.set_ylabel("requests / s (answered)")
        ax2.set_title("throughput")
        handles, labels = ax1.get_legend_handles_labels()
        c.legend(handles, labels, where="below", ncol=max(1, len(names)))
        c.title(
            f"flatbody serve: {result.workers} worker process(es) on {result.cpus} CPU(s), "
            f"while a {result.long_job['kind']} job runs"
        )
        requests = max((r.requests for r in result.rows), default=0)
        c.caption(
            f"p50 / p99: the median and the 99th percentile of the time from sending a request to reading "
            f"its answer, at most {requests} requests per point; requests/s: answered requests over the "
            f"time taken.\nThe load generator runs on the same machine as the service; "
            f"{result.errors} error(s) (any answer other than 200). Colours: the endpoints, as in the legend.",
        )
    return Path(png_path)


__all__ = ["ENDPOINTS", "LONG_JOB", "NAME", "LoadRow", "ServiceBenchmark", "load", "measure", "plot", "report"]

"""The real service in a subprocess: ``flatbody serve`` on a free loopback port, for the load benchmark
(``flatbody bench service``), the tests and the documented-commands check.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path


def _free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on (the OS's pick)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_service(
    data_dir: str | Path,
    *,
    workers: int,
    port: int | None = None,
    timeout: float = 60.0,
    env: dict[str, str] | None = None,
    preexec_fn=None,
    log_path: str | Path | None = None,
) -> tuple[subprocess.Popen, str]:
    """Start ``flatbody serve`` on a loopback port in a subprocess; ``(process, base URL)`` once /health answers.

    Parameters
    ----------
    data_dir : str or Path
        The service's ``--data-dir``.
    workers : int
        The service's ``--workers``.
    port : int, optional
        The port (default: a free one).
    timeout : float
        Seconds to wait for ``/health``; then the process is killed and ``RuntimeError`` raised.
    env : dict, optional
        Variables added to the service's environment (e.g. ``FLATBODY_LIMIT_MAX_QUEUED_JOBS``).
    preexec_fn : callable, optional
        Run in the child before it starts (e.g. a ``resource.setrlimit``).
    log_path : str or Path, optional
        The service's stdout and stderr go to that file (kept, e.g. to look for tracebacks) instead of a pipe.
    """
    import httpx

    port = port or _free_port()
    cmd = [
        sys.executable,
        "-m",
        "flatbody_env.cli",
        "serve",
        "--host",
        "127.0.0.1",
        "--port",
        str(port),
        "--workers",
        str(workers),
        "--data-dir",
        str(data_dir),
        "--log-level",
        "warning",
    ]
    if log_path is None:
        proc = subprocess.Popen(
            cmd,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, **(env or {})},
            preexec_fn=preexec_fn,
        )
    else:
        with open(log_path, "w", encoding="utf-8") as log:  # the child keeps its own copy of the descriptor
            proc = subprocess.Popen(
                cmd,
                stdout=log,
                stderr=subprocess.STDOUT,
                text=True,
                env={**os.environ, **(env or {})},
                preexec_fn=preexec_fn,
            )
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            said = proc.stderr.read() if proc.stderr else Path(log_path).read_text()
            raise RuntimeError(f"flatbody serve exited with code {proc.returncode}: {said[-2000:]}")
        try:
            if httpx.get(url + "/health", timeout=1.0).status_code == 200:
                return proc, url
        except httpx.HTTPError:
            pass
        time.sleep(0.1)
    proc.kill()
    raise RuntimeError(f"flatbody serve did not answer /health within {timeout:g} s")


def stop_service(proc: subprocess.Popen, *, timeout: float = 30.0) -> None:
    """Stop a service that :func:`start_service` started: SIGTERM (uvicorn's graceful shutdown, which also ends the
    job workers), then SIGKILL if it has not exited within ``timeout`` seconds. A process that already ended is left."""
    if proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


__all__ = ["start_service", "stop_service"]

"""Fixtures of the sweep tests: a real Dask cluster and a real PostgreSQL server on loopback."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def worktree_env() -> dict[str, str]:
    """The environment of subprocesses: this source tree first on the path, one thread each."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.update(OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    return env


def _stop(procs) -> None:
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


@pytest.fixture(scope="session")
def dask_cluster(tmp_path_factory):
    """``tcp://127.0.0.1:PORT``: a scheduler and 2 single-thread worker processes started with the
    ``dask scheduler`` / ``dask worker`` commands, as on a real cluster."""
    pytest.importorskip("distributed")
    dask = shutil.which("dask")
    if dask is None:
        pytest.skip("no 'dask' command on PATH (pip install 'dask[distributed]')")
    log = tmp_path_factory.mktemp("dask")
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = worktree_env()
    procs = [
        subprocess.Popen(
            [dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
            cwd=ROOT,
            env=env,
            stdout=(log / "scheduler.log").open("w"),
            stderr=subprocess.STDOUT,
        )
    ]
    try:
        time.sleep(1.0)
        for i in range(2):
            procs.append(
                subprocess.Popen(
                    [
                        dask,
                        "worker",
                        address,
                        "--nthreads",
                        "1",
                        "--nworkers",
                        "1",
                        "--no-dashboard",
                        "--host",
                        "127.0.0.1",
                        "--name",
                        f"w{i}",
                    ],
                    cwd=ROOT,
                    env=env,
                    stdout=(log / f"worker{i}.log").open("w"),
                    stderr=subprocess.STDOUT,
                )
            )
        from distributed import Client

        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=120)
        yield address
    finally:
        _stop(procs[1:])
        _stop(procs[:1])


PG_BIN = sorted(Path("/usr/lib/postgresql").glob("*/bin/initdb"))


@pytest.fixture(scope="session")
def postgres_url():
    """``postgresql://postgres@127.0.0.1:PORT/postgres``: a throw-away server (initdb + pg_ctl of
    Debian's postgresql package) on loopback, run as the ``postgres`` user when the tests run as
    root; skipped with the reason when PostgreSQL or the driver is absent."""
    pytest.importorskip("psycopg", reason="psycopg 3 (pip install 'psycopg[binary]') drives the PostgreSQL storage")
    if not PG_BIN:
        pytest.skip("PostgreSQL is not installed (apt-get install -y postgresql: /usr/lib/postgresql/*/bin/initdb)")
    bindir = PG_BIN[-1].parent
    base = Path(tempfile.mkdtemp(prefix="flatbody-pg-"))
    port = free_port()
    as_root = os.geteuid() == 0
    if as_root:
        try:
            import pwd

            pw = pwd.getpwnam("postgres")
        except KeyError:
            shutil.rmtree(base, ignore_errors=True)
            pytest.skip("running as root and there is no 'postgres' user to run the server")
        os.chown(base, pw.pw_uid, pw.pw_gid)

    def run(*cmd):
        line = " ".join(cmd)
        full = ["su", "postgres", "-s", "/bin/sh", "-c", line] if as_root else ["/bin/sh", "-c", line]
        return subprocess.run(full, capture_output=True, text=True, timeout=120)

    data = base / "data"
    r = run(str(bindir / "initdb"), "-D", str(data), "-A", "trust", "-U", "postgres", "--no-sync", "-E", "UTF8")
    if r.returncode != 0:
        shutil.rmtree(base, ignore_errors=True)
        pytest.skip(f"initdb failed: {r.stderr.strip()[:200]}")
    opts = f"'-p {port} -k {base} -c listen_addresses=127.0.0.1 -c fsync=off'"
    r = run(str(bindir / "pg_ctl"), "-D", str(data), "-o", opts, "-l", str(base / "server.log"), "-w", "start")
    if r.returncode != 0:
        shutil.rmtree(base, ignore_errors=True)
        pytest.skip(f"pg_ctl start failed: {r.stderr.strip()[:200]}")
    try:
        yield f"postgresql://postgres@127.0.0.1:{port}/postgres"
    finally:
        run(str(bindir / "pg_ctl"), "-D", str(data), "-m", "immediate", "-w", "stop")
        shutil.rmtree(base, ignore_errors=True)


@pytest.fixture(scope="session")
def cli():
    """``cli(*argv)``: ``python -m flatbody_env.cli ARGV`` from this source tree (a fresh process)."""

    def run(*argv: str, timeout: float = 600) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "flatbody_env.cli", *argv],
            cwd=ROOT,
            env=worktree_env(),
            capture_output=True,
            text=True,
            timeout=timeout,
        )

    return run


@pytest.fixture(scope="session")
def spawn():
    """``spawn(*argv)``: start ``python -m flatbody_env.cli ARGV`` without waiting (a Popen)."""

    def start(*argv: str) -> subprocess.Popen:
        return subprocess.Popen(
            [sys.executable, "-m", "flatbody_env.cli", *argv],
            cwd=ROOT,
            env=worktree_env(),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )

    return start

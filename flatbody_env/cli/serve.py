"""``flatbody serve``: the analysis service over HTTP (``bench service``, its load figures: :mod:`flatbody_env.cli.bench`).

The app lives in :mod:`flatbody_env.service`; uvicorn, FastAPI and httpx are imported in the handlers.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from flatbody_env.cli.args import int_at_least
from flatbody_env.physics import validation

LOOPBACK = ("127.0.0.1", "localhost", "::1")


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"port: expected an integer, got {text!r}") from None
    if not 0 <= value <= 65535:
        raise validation.refusal("port", "be an integer in [0, 65535]", value, error=argparse.ArgumentTypeError)
    return value


def default_workers() -> int:
    """Worker processes by default: the CPU count, at most 4."""
    return max(1, min(4, os.cpu_count() or 1))


def _serve(args) -> int:
    import sqlite3

    import uvicorn

    from flatbody_env.service.app import create_app

    data = Path(args.data_dir)
    if data.exists() and not data.is_dir():
        raise ValueError(f"data_dir: {args.data_dir!r} exists and is not a directory")
    # a directory, corrupt or foreign file in place of the job database: one line, exit 2, file untouched
    validation.sqlite_file("data_dir", data / "jobs.sqlite3", ("jobs",))
    _check_bind(args.host, args.port)
    try:
        app = create_app(args.data_dir, workers=args.workers)
    except sqlite3.Error as exc:
        raise ValueError(
            f"data_dir: cannot use the job database in {args.data_dir!r} ({' '.join(str(exc).split())})"
        ) from None
    where = f"http://{'[' + args.host + ']' if ':' in args.host else args.host}:{args.port}/"
    if args.host not in LOOPBACK:
        print(
            f"flatbody serve: listening on {args.host}:{args.port}, reachable from other machines as you asked; "
            "there is no authentication built in (put it behind a reverse proxy to share it)",
            file=sys.stderr,
        )
    print(
        f"flatbody serve: {where} (page), {where}docs (API); data in {args.data_dir}; {args.workers} worker process(es)",
        file=sys.stderr,
    )
    try:
        interrupted = _serve_until_stopped(
            lambda: uvicorn.run(
                app,
                host=args.host,
                port=args.port,
                log_level=args.log_level,
                # the client's address is the connection's unless the user names the proxies in front of the service:
                # a header any local client can set must not choose whose job quota a request counts against
                proxy_headers=args.trusted_proxies is not None,
                forwarded_allow_ips=args.trusted_proxies or "",
            )
        )
    except SystemExit as exc:  # uvicorn exits 1 or 3 when it cannot start (e.g. the port was taken meanwhile)
        if exc.code in (0, None):
            return 0
        raise ValueError(
            f"port: the server could not start on {args.host}:{args.port} (uvicorn's exit status {exc.code}; see the log line above)"
        ) from None
    if interrupted:
        raise KeyboardInterrupt  # stopped by Ctrl-C: 'flatbody: interrupted', exit code 130
    return 0


def _check_bind(host: str, port: int) -> None:
    """Refuse (``ValueError`` naming ``port`` / ``host``: exit 2, one line) an address the server cannot listen on."""
    import socket

    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (OSError, UnicodeError) as exc:
        raise ValueError(f"host: cannot resolve {host[:60]!r} ({getattr(exc, 'strerror', None) or exc})") from None
    family, kind, proto, _, address = infos[0]
    try:
        with socket.socket(family, kind, proto) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind(address)
    except OSError as exc:
        raise ValueError(
            f"port: cannot listen on {host}:{port} ({exc.strerror or exc}); choose another --port or stop what holds it"
        ) from None


def _serve_until_stopped(run) -> bool:
    """Call ``run()`` (uvicorn, which stops cleanly on SIGINT and swallows it); True when a Ctrl-C stopped it.

    uvicorn restores the SIGINT handler it found and raises the signal again once the server is
    down: the handler installed here notes it (and raises KeyboardInterrupt as Python's does).
    """
    import signal
    import threading

    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        run()
        return False
    seen: list[int] = []

    def on_sigint(signum, frame):
        seen.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, on_sigint)
    try:
        run()
    except KeyboardInterrupt:
        seen.append(signal.SIGINT)
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    return bool(seen)


def _proxies(text: str) -> str:
    """``--trusted-proxies``: comma-separated IP addresses (argparse type; one line naming the flag otherwise)."""
    import ipaddress

    parts = [p.strip() for p in text.split(",") if p.strip()]
    if not parts or len(parts) > 64:
        raise validation.refusal(
            "trusted_proxies", "be 1 to 64 comma-separated IP addresses", text[:60], error=argparse.ArgumentTypeError
        )
    for part in parts:
        try:
            ipaddress.ip_address(part)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{part[:40]!r} is not an IP address") from None
    return ",".join(parts)


def register(sub) -> None:
    p = sub.add_parser("serve", help="the analysis service: HTTP API (/docs) and a web page on loopback")
    p.add_argument("--host", default="127.0.0.1", help="interface to listen on (default 127.0.0.1, loopback only)")
    p.add_argument("--port", type=_port, default=8000, help="TCP port (default 8000)")
    p.add_argument(
        "--workers",
        type=int_at_least("workers", 1, validation.MAX_WORKERS),
        default=default_workers(),
        help="worker processes for requests, and jobs run at once (default: CPUs, at most 4)",
    )
    p.add_argument(
        "--data-dir", default="flatbody-data", metavar="DIR", help="job database and files (default ./flatbody-data)"
    )
    p.add_argument(
        "--trusted-proxies",
        metavar="IPS",
        type=_proxies,
        help="comma-separated addresses of reverse proxies whose X-Forwarded-For names the client (default: none; the "
        "connection's address counts, so no header can dodge the per-client job quota)",
    )
    p.add_argument(
        "--log-level",
        default="info",
        choices=("critical", "error", "warning", "info", "debug"),
        help="uvicorn log level",
    )
    p.set_defaults(handler=_serve)

"""Where a result came from: the source's git hash and the machine it ran on.

Written beside every trained model (``config.yml``, ``run.json``) and every benchmark's JSON, so that a
figure can be traced to the code and the hardware that made it.
"""

from __future__ import annotations

import os
import platform
import shlex
import subprocess
import sys
from pathlib import Path
from typing import Any


def cpu_name() -> str:
    """The CPU's model name and core count, e.g. ``"AMD EPYC (2 cores)"``."""
    name = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    name = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{name} ({os.cpu_count()} cores)"


def git_hash(where: Path | None = None) -> str:
    """``git rev-parse HEAD`` of the source tree (``"unknown"`` outside a repository)."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=where or Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() if out.returncode == 0 and out.stdout.strip() else "unknown"


def machine() -> dict[str, Any]:
    """Where a benchmark ran: CPU, cores, load, Python, numpy and numba versions, the source's git hash."""
    import numba
    import numpy

    try:
        load = round(os.getloadavg()[0], 2)
    except OSError:
        load = None
    return {
        "cpu": cpu_name(),
        "cpu_count": os.cpu_count(),
        "load_avg_1min": load,
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "numba": numba.__version__,
        "git": git_hash(),
    }


def invocation(command: list[str] | None = None) -> dict[str, Any]:
    """The command that made a result: ``command`` (the argument list, default ``[python, *sys.argv]``) and
    ``command_line`` (the arguments after the interpreter, shell-quoted: what to type again)."""
    argv = list(command) if command is not None else [sys.executable, *sys.argv]
    shown = argv[1:] if command is None else argv
    return {"command": argv, "command_line": shlex.join(str(a) for a in shown)}


def versions(*packages: str) -> dict[str, str]:
    """The installed version of each of ``packages`` (distribution names; ``"absent"`` when not installed), and
    Python's; read from the package metadata, nothing imported."""
    from importlib.metadata import PackageNotFoundError, version

    found = {"python": platform.python_version()}
    for name in packages:
        try:
            found[name] = version(name)
        except PackageNotFoundError:
            found[name] = "absent"
    return found


__all__ = ["cpu_name", "git_hash", "invocation", "machine", "versions"]

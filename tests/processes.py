"""Child processes of the tests: Ctrl-C as a terminal sends it, and never a process left behind."""

from __future__ import annotations

import os
import signal
import subprocess


def sigint_default() -> None:
    """``preexec_fn`` of a child that a test interrupts: SIGINT back to its default, as a terminal's job has it (a
    suite started from a background job inherits SIGINT ignored, and Python then installs no KeyboardInterrupt)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def interrupt(proc: subprocess.Popen, timeout: float = 60) -> tuple[str, str]:
    """Send SIGINT to ``proc``'s process group (``start_new_session=True``), as Ctrl-C in a terminal
    reaches every process of the job, and return its remaining (stdout, stderr); a process that does
    not end within ``timeout`` seconds is killed and the test fails on the timeout."""
    try:
        os.killpg(proc.pid, signal.SIGINT)
        return proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()

"""Screenshots of a recording in the real rerun viewer, on a machine without a display.

The native viewer (the ``rerun`` executable of the SDK's version) runs inside an Xvfb virtual
display with Mesa's software Vulkan driver (lavapipe); :class:`rerun.experimental.ViewerClient`
opens the file, pauses at each requested ``sim_time`` and saves the window (and, on request, each
visible view) as PNG. Everything binds to 127.0.0.1; the viewer and Xvfb started here are stopped
by process id when done.

Needs the Debian/Ubuntu packages ``xvfb`` and ``mesa-vulkan-drivers``; :func:`viewer_unavailable`
says what is missing. ``flatbody record-shots`` is the command-line face of :func:`screenshots`.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from flatbody_env.output import atomic_path

LAVAPIPE_ICDS = (
    "/usr/share/vulkan/icd.d/lvp_icd.x86_64.json",
    "/usr/share/vulkan/icd.d/lvp_icd.aarch64.json",
    "/usr/share/vulkan/icd.d/lvp_icd.json",
)
"""Where Debian/Ubuntu's ``mesa-vulkan-drivers`` puts the software Vulkan driver's manifest."""


@dataclass(frozen=True, kw_only=True)
class Shot:
    """One saved screenshot: the window (``view`` None) or one view, at ``sim_time`` = ``t``."""

    path: Path
    t: float
    view: str | None
    view_class: str | None
    reports: tuple[str, ...] = ()
    """What the view said it failed to visualize (empty when healthy; window shots: all views')."""


def _lavapipe() -> str | None:
    return next((p for p in LAVAPIPE_ICDS if Path(p).exists()), None)


def _rerun_exe() -> str | None:
    """The ``rerun`` viewer of this interpreter's environment (its scripts folder, as a virtual
    environment used without activation has it), else the one on ``PATH``."""
    beside = Path(sys.executable).parent / "rerun"
    if beside.is_file() and os.access(beside, os.X_OK):
        return str(beside)
    return shutil.which("rerun")


def viewer_unavailable() -> str | None:
    """None when screenshots can be taken here, else the reason (what to install)."""
    missing = []
    if _rerun_exe() is None:
        missing.append("the 'rerun' viewer executable (pip install rerun-sdk==0.41.*)")
    if shutil.which("Xvfb") is None:
        missing.append("Xvfb (apt-get install xvfb)")
    if _lavapipe() is None:
        missing.append("software Vulkan (apt-get install mesa-vulkan-drivers)")
    return ("needs " + ", ".join(missing)) if missing else None


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start_xvfb(width: int, height: int) -> tuple[subprocess.Popen, str]:
    """Xvfb on a display it picks itself (``-displayfd``); returns (process, ":N")."""
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write_fd), "-screen", "0", f"{width}x{height}x24", "-nolisten", "tcp"],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write_fd)
    with os.fdopen(read_fd) as f:
        number = f.readline().strip()
    if not number.isdigit():
        proc.kill()
        proc.wait(10)
        raise RuntimeError("viewer: Xvfb did not start (no display number)")
    return proc, f":{number}"


def _stop(proc: subprocess.Popen | None) -> None:
    if proc is not None and proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


def _slug(name: str) -> str:
    out = "".join(c if (c.isascii() and c.isalnum()) else "_" for c in name)
    while "__" in out:
        out = out.replace("__", "_")
    return out.strip("_")[:32] or "view"


def _compact_png(path: Path, colors: int) -> None:
    """Rewrite a PNG with a palette of ``colors`` (small files for docs; 0 keeps it as it is)."""
    if colors <= 0:
        return
    from PIL import Image

    with Image.open(path) as img:
        small = img.convert("RGB").quantize(colors=colors, method=Image.Quantize.FASTOCTREE)
    with atomic_path(path) as tmp:
        small.save(tmp, format="PNG", optimize=True)


def screenshots(
    rrd: str | Path,
    times: list[float],
    out_dir: str | Path,
    *,
    size: tuple[int, int] = (1600, 1000),
    views: bool | tuple[str, ...] = False,
    prefix: str | None = None,
    settle_s: float = 2.5,
    open_s: float = 4.0,
    colors: int = 0,
) -> list[Shot]:
    """Open ``rrd`` in the real viewer and save screenshots at the given ``sim_time`` values.

    Parameters
    ----------
    rrd : str or Path
        A finished recording.
    times : list of float
        Model times (≥ 0) paused at in turn (``sim_time`` is logged in the recording's time unit,
        :func:`flatbody_env.recording.layout.time_unit`).
    out_dir : str or Path
        Folder of the PNGs ``PREFIX_tTT.TT.png`` (window) and ``PREFIX_tTT.TT_VIEW.png`` (views).
    size : (int, int)
        Window size in logical points, (width, height), each in [320, 4096].
    views : bool or tuple of str
        Also save each view that is on screen (views in hidden tabs are skipped): all of them
        (True) or those whose class (``"Tensor"``, ``"3D"``, …) or name is in the tuple.
    prefix : str, optional
        File-name prefix (default: the recording's file stem).
    settle_s, open_s : float
        Seconds to let the software renderer settle after each time change / after opening.
    colors : int
        Reduce each PNG to a palette of this many colours (0: keep full colour).

    Returns
    -------
    list of Shot

    Raises
    ------
    ValueError
        Bad arguments, or the viewer cannot run here (the message says what to install).
    RuntimeError
        The viewer started but did not answer.
    """
    rrd = Path(rrd)
    if not rrd.is_file():
        raise ValueError(f"file: no file {str(rrd)!r}")
    times = [float(t) for t in times]
    if not times or any(not (t >= 0.0) for t in times):
        raise ValueError(f"times: expected one or more sim_time values ≥ 0, got {times!r}")
    width, height = (int(v) for v in size)
    from flatbody_env.physics import validation

    validation.requirement(
        "size",
        f"{width}x{height}",
        320 <= width <= 4096 and 320 <= height <= 4096,
        "have width and height in [320, 4096]",
    )
    reason = viewer_unavailable()
    if reason:
        raise ValueError(f"viewer: cannot render here — {reason}")
    from rerun.experimental import ViewerClient

    from flatbody_env.recording.reader import read_recording, time_scale

    scale = time_scale(read_recording(rrd).static)  # the timeline's seconds per model time unit

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = prefix or rrd.stem
    xvfb = viewer = None
    shots: list[Shot] = []
    try:
        xvfb, display = _start_xvfb(width, height)
        port = _free_port()
        env = dict(os.environ, DISPLAY=display, WGPU_BACKEND="vulkan", VK_ICD_FILENAMES=str(_lavapipe()), CI="1")
        env.pop("WAYLAND_DISPLAY", None)
        viewer = subprocess.Popen(
            [
                str(_rerun_exe()),
                "--bind",
                "127.0.0.1",
                "--port",
                str(port),
                "--window-size",
                f"{width}x{height}",
                "--hide-welcome-screen",
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        client = None
        deadline = time.monotonic() + 90.0
        while time.monotonic() < deadline:
            if viewer.poll() is not None:
                raise RuntimeError(f"viewer: the rerun viewer exited with code {viewer.returncode} before answering")
            try:
                client = ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy")
                client.get_state()
                break
            except Exception:  # not listening yet
                client = None
                time.sleep(0.5)
        if client is None:
            raise RuntimeError("viewer: the rerun viewer did not answer within 90 s")
        client.open(str(rrd.resolve()))
        deadline = time.monotonic() + 60.0
        while client.get_state().loading and time.monotonic() < deadline:
            time.sleep(0.25)
        time.sleep(open_s)
        for t in times:
            client.set_time("sim_time", duration=t * scale, play_state="paused")
            time.sleep(settle_s)
            state = client.get_state()
            path = out_dir / f"{stem}_t{t:05.2f}.png"
            client.save_screenshot(str(path))
            _compact_png(path, colors)
            every = tuple(f"{v.name}: {r.summary}" for v in state.views for r in (v.reports or []))
            shots.append(Shot(path=path, t=t, view=None, view_class=None, reports=every))
            if views:
                for v in state.views:
                    if not v.visible or (views is not True and v.view_class not in views and v.name not in views):
                        continue
                    vpath = out_dir / f"{stem}_t{t:05.2f}_{_slug(v.name)}.png"
                    try:
                        client.save_screenshot(str(vpath), view_id=v.view_id)
                    except Exception:  # a view in a hidden tab has no pixels
                        continue
                    if not vpath.exists():
                        continue
                    _compact_png(vpath, colors)
                    shots.append(
                        Shot(
                            path=vpath,
                            t=t,
                            view=v.name,
                            view_class=v.view_class,
                            reports=tuple(r.summary for r in (v.reports or [])),
                        )
                    )
    finally:
        _stop(viewer)
        _stop(xvfb)
    return shots

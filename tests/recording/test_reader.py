"""Reading back: a finished file verifies with rerun's own checker; an open or cut one does not."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import rerun.chunk as rrc

from flatbody_env.recording.reader import read_recording, verify_recording
from flatbody_env.recording.writer import Recorder
import recording_oracles as oracles

strict_rerun = oracles.strict_rerun
scene = oracles.scene
traj = oracles.traj
recorded = oracles.recorded  # fixtures


def test_file_is_complete_when_the_call_returns(recorded, tmp_path, scene, traj):
    path, _ = recorded
    assert len(rrc.RrdReader(path).store().stream().to_chunks()) > 10  # store() needs the footer
    assert "verified" in verify_recording(path)
    # the rerun CLI itself
    exe = shutil.which("rerun")
    cmd = [exe] if exe else [sys.executable, "-m", "rerun"]
    proc = subprocess.run(
        cmd + ["rrd", "verify", str(path)], capture_output=True, text=True, env=dict(os.environ, CI="1"), timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    # an open recording is streamed to a temporary file next to its target, without a footer yet; the
    # target appears when it is closed; a cut file fails verification
    live = tmp_path / "live.rrd"
    rec = Recorder(live, scene.body, block=4)
    for k in range(10):
        rec.append(traj.t[k], traj.y[:, k], traj.rotation[k], energy=traj.energy[k])
    rec.rec.flush()
    assert not live.exists()
    (partial,) = tmp_path.glob(".live.rrd.*.tmp.rrd")
    deadline = time.monotonic() + 30  # the copy thread writes it: a hang guard, not a timing
    while partial.stat().st_size == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    with pytest.warns(Warning, match="no footer"), pytest.raises(Exception):  # noqa: B017 - rerun's reader raises its own (unexported) error type
        rrc.RrdReader(partial).store()
    rec.close()
    assert not partial.exists()
    assert len(rrc.RrdReader(live).store().stream().to_chunks()) > 0
    assert read_recording(live)["/world/body"].step.size == 10
    cut = tmp_path / "cut.rrd"
    raw = Path(path).read_bytes()
    cut.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ValueError, match="rerun rrd verify"):
        verify_recording(cut)

"""The recording commands: ``record``, ``record-env``, ``record-info``, ``record-shots --frames``, ``bench recording``."""

from __future__ import annotations


import gymnasium as gym
import numpy as np
import pytest

from flatbody_env.cli.main import main
from flatbody_env.recording.reader import read_recording
from recording_oracles import FakeFlatBodyEnv, SCALARS
import recording_oracles as oracles

strict_rerun = oracles.strict_rerun
scene = oracles.scene  # fixtures


def test_record_command(tmp_path, capsys):
    out = tmp_path / "run.rrd"
    assert main(["record", "--scene", "default", "--t-end", "1", "--samples", "51", "--out", str(out), "--verify"]) == 0
    assert "rerun rrd verify: ok" in capsys.readouterr().out
    data = read_recording(out)
    assert data["/series/lambda"].step.size == 51
    assert data["/series/energy"].sim_time[-1] == pytest.approx(1.0)
    assert main(["record-info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "/world/body" in text and "51" in text and "verified" in text
    # G and C, rebuilt from their logged entries (/series/G, /series/C), at the first and the last step
    lam, mu, rho = (data[f"/series/{n}"].components[SCALARS][0, 0] for n in ("lambda", "mu", "rho"))
    for sym, eig in (("G", [lam**2, mu**2, rho**2]), ("C", [lam**-2, mu**-2, rho**-2])):
        assert (
            f"{sym} (/series/{sym}) at step 0 (sim_time 0):" in text
            and f"{sym} (/series/{sym}) at step 50 (sim_time 1):" in text
        )
        rows = text.split(f"{sym} (/series/{sym}) at step 0 (sim_time 0):\n", 1)[1].splitlines()[:3]
        M = np.array([[float(x) for x in r.strip().strip("[]").split()] for r in rows])
        assert np.allclose(M, M.T) and np.allclose(np.linalg.eigvalsh(M), sorted(eig), atol=1e-5)
        entries = data[f"/series/{sym}"].components[SCALARS][0]
        assert np.allclose(M[[0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]], entries, atol=1e-6)


def test_record_command_bad_input(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["record", "--scene", "default", "--out", str(tmp_path / "run.txt")])
    assert exc.value.code == 2
    assert main(["record", "--scene", "no-such-scene", "--out", str(tmp_path / "a.rrd")]) == 2
    assert main(["record-info", str(tmp_path / "missing.rrd")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "out:" in err


def test_record_env_command(tmp_path, capsys):
    gym.register(id="FakeFlatBodyForRecording-v0", entry_point=FakeFlatBodyEnv, kwargs={"n_steps": 12})
    try:
        out = tmp_path / "env.rrd"
        assert (
            main(
                [
                    "record-env",
                    "--env-id",
                    "FakeFlatBodyForRecording-v0",
                    "--episodes",
                    "2",
                    "--policy",
                    "random",
                    "--out",
                    str(out),
                    "--verify",
                ]
            )
            == 0
        )
        printed = capsys.readouterr().out
        assert str(out) in printed and str(tmp_path / "env-1.rrd") in printed
        data = read_recording(tmp_path / "env-1.rrd")
        assert data["/series/action/tau1"].step.size == 12
        assert np.all(np.abs(data["/series/action/tau1"].components[SCALARS]) <= 1.0)
        assert main(["record-env", "--env-id", "NoSuchEnv-v0", "--out", str(out)]) == 2
        assert "env-id" in capsys.readouterr().err
    finally:
        gym.registry.pop("FakeFlatBodyForRecording-v0", None)


def test_record_env_command_on_flatbody_v0(tmp_path, capsys):
    out = tmp_path / "fb.rrd"
    assert (
        main(
            ["record-env", "--episodes", "1", "--max-steps", "20", "--policy", "random", "--out", str(out), "--verify"]
        )
        == 0
    )
    data = read_recording(out)
    assert data["/series/lambda"].step.size == 21
    assert data["/series/reward/total"].step.size == 20


@pytest.mark.slow  # the command itself runs in the smoke test (tests/cli/test_smoke.py)
def test_bench_recording_with_a_tiny_budget(tmp_path, capsys):
    """``flatbody bench recording`` runs to the end (it once died after its timing runs) and writes its files."""
    import json

    out = tmp_path / "bench"
    page = tmp_path / "page.md"
    page.write_text("# page\n\n<!-- bench:recording -->\nold table\n<!-- /bench:recording -->\n\nafter\n")
    assert (
        main(
            [
                "bench",
                "recording",
                "--steps",
                "40",
                "--sizes",
                "20",
                "--repeats",
                "2",
                "--block",
                "8",
                "--frames",
                "30",
                "--episode-repeats",
                "1",
                "--out-dir",
                str(out),
                "--docs",
                str(page),
            ]
        )
        == 0
    )
    result = json.loads((out / "recording.json").read_text())
    ep = result["episode"]
    assert ep["compiled_method"] == "DOP853-numba" and ep["scene_auto_method"] == "DOP853-numba"
    assert ep["speedup"] == pytest.approx(ep["former_s"] / ep["compiled_s"]) and ep["stepping_former_s"] > 0
    text = page.read_text()
    assert "old table" not in text and text.endswith("<!-- /bench:recording -->\n\nafter\n")
    assert f"{result['frame']['median_ms']:.2f} ms" in text and "DOP853-numba carrying R" in text
    assert [r["steps"] for r in result["sizes"]] == [20, 40]
    assert all(r["min_s"] <= r["median_s"] <= r["max_s"] and r["file_bytes"] > 0 for r in result["sizes"])
    assert result["live"]["steps"] == 40 and result["cpus"] >= 1
    assert result["frame"]["frames"] == 30 and 0 < result["frame"]["median_ms"] <= result["frame"]["p90_ms"]
    assert (out / "recording.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "wrote" in capsys.readouterr().out
    # a page without the markers: one line naming the field, exit 2
    (tmp_path / "plain.md").write_text("no markers\n")
    assert (
        main(
            [
                "bench",
                "recording",
                "--steps",
                "20",
                "--sizes",
                "20",
                "--repeats",
                "1",
                "--block",
                "8",
                "--frames",
                "4",
                "--episode-repeats",
                "1",
                "--out-dir",
                str(out),
                "--docs",
                str(tmp_path / "plain.md"),
            ]
        )
        == 2
    )
    assert "docs:" in capsys.readouterr().err


def test_record_shots_frames_writes_the_documented_picture_of_the_rgb_array_frames(tmp_path, capsys):
    """``record-shots --frames 0,120`` (docs/recording.md's picture): two 256 px frames of FlatBody-v1, seed 7,
    8 white pixels apart: the env's frame of each state with the episode's status (task, step, distance)."""
    from PIL import Image

    from flatbody_env.env.rendering import frame_status, render_frame

    assert main(["record-shots", "--frames", "0,3", "--seed", "7", "--out", str(tmp_path / "img")]) == 0
    path = tmp_path / "img" / "frame-rgb_array.png"
    assert f"wrote {path}" in capsys.readouterr().out
    with Image.open(path) as img:
        assert img.format == "PNG" and img.size == (2 * 256 + 8, 256)
        strip = np.asarray(img.convert("RGB"))
    env = gym.make("FlatBody-v1", render_mode="rgb_array")
    _, info = env.reset(seed=7)
    env.action_space.seed(7)
    u = env.unwrapped

    def frame(info):
        return render_frame(u.physics_state, u.rotation, u.target, u.time, status=frame_status(env, info))

    first = frame(info)
    bare = render_frame(u.physics_state, u.rotation, u.target, u.time)  # the status apart: only the top left differs
    assert np.array_equal(first[60:], bare[60:]) and not np.array_equal(first[:60, :150], bare[:60, :150])
    assert np.array_equal(env.render(), first)  # the env's own rgb_array frame carries the status too
    for _ in range(3):
        _, _, _, _, info = env.step(env.action_space.sample())
    np.testing.assert_array_equal(strip[:, :256], first)
    np.testing.assert_array_equal(strip[:, 264:], frame(info))
    assert (strip[:, 256:264] == 255).all() and not np.array_equal(strip[:, :256], strip[:, 264:])
    # a recording and --frames together, or neither: one line, exit 2
    assert main(["record-shots", str(tmp_path / "x.rrd"), "--frames", "0,1", "--out", str(tmp_path)]) == 2
    assert main(["record-shots", "--out", str(tmp_path)]) == 2
    with pytest.raises(SystemExit) as exc:
        main(["record-shots", "--frames", "5,3"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("file:") == 2 and "frames:" in err


def test_record_shots_bad_input_is_one_line(tmp_path, capsys):
    assert main(["record-shots", str(tmp_path / "missing.rrd"), "--out", str(tmp_path)]) == 2
    with pytest.raises(SystemExit) as exc:
        main(["record-shots", str(tmp_path / "x.rrd"), "--times", "0,-1"])
    assert exc.value.code == 2
    with pytest.raises(SystemExit) as exc:
        main(["record-shots", str(tmp_path / "x.rrd"), "--size", "10x10"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "file:" in err and "times:" in err and "size:" in err

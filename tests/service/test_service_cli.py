"""``flatbody serve`` and ``flatbody bench service`` from the command line."""

from __future__ import annotations

import json

import pytest

from flatbody_env.cli.main import main as cli


@pytest.fixture
def fake_uvicorn(monkeypatch):
    import uvicorn

    calls = []
    monkeypatch.setattr(uvicorn, "run", lambda app, **kw: calls.append(kw))
    return calls


def test_serve_binds_loopback_by_default(fake_uvicorn, capsys, tmp_path):
    assert cli(["serve", "--data-dir", str(tmp_path / "d")]) == 0
    assert fake_uvicorn == [
        {"host": "127.0.0.1", "port": 8000, "log_level": "info", "proxy_headers": False, "forwarded_allow_ips": ""}
    ]  # no proxy trusted unless --trusted-proxies names it
    assert "reachable from other machines" not in capsys.readouterr().err


def test_serve_elsewhere_is_said_in_the_log(fake_uvicorn, capsys, tmp_path):
    assert cli(["serve", "--host", "0.0.0.0", "--port", "8123", "--data-dir", str(tmp_path / "d")]) == 0
    assert fake_uvicorn[0]["host"] == "0.0.0.0"
    err = capsys.readouterr().err
    assert "0.0.0.0:8123" in err and "reachable from other machines" in err and "no authentication" in err


@pytest.mark.parametrize(
    "argv, words",
    [
        (["serve", "--port", "70000"], "port: must be an integer in [0, 65535]"),
        (["serve", "--workers", "0"], "flatbody serve: error: --workers: must be an integer in [1, 256], got 0"),
        (["bench", "service", "--clients", "0,8"], "--clients: must be an integer in [1, 256]"),
    ],
)
def test_bad_options_exit_2_with_one_line(fake_uvicorn, capsys, argv, words):
    with pytest.raises(SystemExit) as exc:
        cli(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1


def test_one_service_per_data_dir(fake_uvicorn, capsys, tmp_path):
    from flatbody_env.service.app import create_app

    app = create_app(tmp_path, workers=1)  # holds the data dir
    assert cli(["serve", "--data-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "data-dir" in err and "in use" in err and len(err.strip().splitlines()) == 1
    app.state.service.store.unlock()
    assert cli(["serve", "--data-dir", str(tmp_path)]) == 0


@pytest.mark.slow  # the command itself runs in the smoke test (tests/cli/test_smoke.py)
def test_bench_service_writes_its_figures(tmp_path, capsys):
    assert (
        cli(
            [
                "bench",
                "service",
                "--clients",
                "1,2",
                "--requests",
                "4",
                "--seconds",
                "5",
                "--workers",
                "1",
                "--out-dir",
                str(tmp_path),
            ]
        )
        == 0
    )
    data = json.loads((tmp_path / "service_benchmark.json").read_text())
    rows = data["rows"]
    assert [(r["endpoint"], r["clients"]) for r in rows] == [
        (e, c) for e in ("GET /health", "POST /ellipses", "POST /simulate") for c in (1, 2)
    ]
    assert all(r["errors"] == 0 and 1 <= r["requests"] <= 4 and r["p50_ms"] <= r["p99_ms"] for r in rows)
    assert data["long_job"]["status_at_start"] in ("queued", "running")
    assert (tmp_path / "service_benchmark.csv").read_text().count("\n") == len(rows) + 1
    assert (tmp_path / "service_benchmark.png").read_bytes()[:4] == b"\x89PNG"

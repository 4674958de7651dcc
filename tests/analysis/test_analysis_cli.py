"""The analysis commands: JSON shapes, tables, files, and exit code 2 on bad input."""

from __future__ import annotations

import json

import pytest

from flatbody_env.cli.main import main
from flatbody_env.physics.state import STATE_NAMES

BODY = ["--potential", "V3", "--kappa", "1", "--a", "1", "--b", "1", "--J", "1", "--J3", "1"]


def run(capsys, *argv):
    rc = main(list(argv))
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_ellipses_json_shape(capsys):
    rc, out, _ = run(capsys, "ellipses", *BODY, "--s3", "2", "--p-theta", "0.5", "--json")
    assert rc == 0
    data = json.loads(out)
    assert list(data) == ["solutions"] and len(data["solutions"]) == 1
    sol = data["solutions"][0]
    assert set(sol) == {"state", "omega3", "theta_dot", "energy", "residual"}
    assert list(sol["state"]) == list(STATE_NAMES)
    assert sol["residual"] <= 1e-10
    assert sol["state"]["s3"] == 2.0 and sol["state"]["p_theta"] == 0.5


def test_stability_json_shape(capsys):
    rc, out, _ = run(capsys, "stability", *BODY, "--s3", "2", "--p-theta", "0.5", "--json")
    assert rc == 0
    sol = json.loads(out)["solutions"][0]
    assert set(sol) == {"state", "eigenvalues", "max_real_part", "classification"}
    assert len(sol["eigenvalues"]) == 10 and all(len(e) == 2 for e in sol["eigenvalues"])
    assert sol["classification"] in ("elliptic", "hyperbolic", "degenerate")
    assert sol["max_real_part"] == max(e[0] for e in sol["eigenvalues"])


def test_v1_and_v2_flags_and_tables(capsys):
    rc, out, _ = run(capsys, "ellipses", "--potential", "V1", "--k", "1", "--s3", "2.5", "--p-theta", "1.5")
    assert rc == 0 and "1.50000000" in out and "0.50000000" in out
    rc, out, _ = run(capsys, "stability", "--potential", "V1", "--k", "1", "--s3", "2.5", "--p-theta", "1.5")
    assert rc == 0 and "hyperbolic" in out and "casimir, p_theta" in out
    rc, out, _ = run(
        capsys, "ellipses", "--potential", "V2", "--c", "1", "--d", "2", "--s3", "2", "--p-theta", "0.5", "--json"
    )
    assert rc == 0 and len(json.loads(out)["solutions"]) == 2


def test_scene_and_branch_a(capsys):
    rc, out, _ = run(capsys, "ellipses", "--scene", "default", "--branch", "all", "--spin", "1", "--json")
    assert rc == 0
    sols = json.loads(out)["solutions"]
    assert any(s["state"]["s2"] != 0.0 for s in sols) and any(s["state"]["p_theta"] == 1.77 for s in sols)


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["ellipses", "--kappa", "-1", "--s3", "2", "--p-theta", "0.5"], "--kappa"),
        (["ellipses", "--k", "1", "--s3", "2", "--p-theta", "0.5"], "--k"),
        (["ellipses", "--s3", "2"], "--p-theta"),
        (["stability", "--s3", "inf", "--p-theta", "1"], "--s3"),
        (["ellipses", "--s3", "2", "--p-theta", "1", "--lam-range", "3,1"], "--lam-range"),
        (["ellipses", "--s3", "x", "--p-theta", "1"], "--s3"),
        (["ellipses", "--scene", "anisotropic", "--s3", "1", "--p-theta", "1"], "isotropic"),
        (["ellipses", "--scene", "default", "--kappa", "2"], "--kappa"),
        (["ellipses", "--branch", "A", "--s3", "1", "--p-theta", "1"], "--spin"),
        (["family", "--vary", "q"], "--vary"),
        (["family", "--vary", "k"], "param"),
        (["family", "--from", "2", "--to", "1"], "--to"),
        (["invariants", "/nonexistent/traj.json"], "trajectory"),
    ],
)
def test_bad_input_exit_code_2_one_line(capsys, argv, flag):
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse errors
        rc = exc.code
    err = capsys.readouterr().err
    assert rc == 2
    lines = [l for l in err.splitlines() if l.strip()]
    assert len(lines) == 1 and flag in lines[0], err


def test_family_writes_csv_and_png(capsys, tmp_path):
    csv_path, png = tmp_path / "family.csv", tmp_path / "family.png"
    rc, out, _ = run(
        capsys,
        "family",
        *BODY,
        "--vary",
        "s3",
        "--from",
        "0.6",
        "--to",
        "2.5",
        "--p-theta",
        "0.5",
        "--out",
        str(csv_path),
        "--plot",
        str(png),
    )
    assert rc == 0 and "stability-change" in out
    header = csv_path.read_text().splitlines()[0].split(",")
    assert header[:4] == ["branch", "event", "param_name", "param"] and "classification" in header
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_invariants_command_on_saved_trajectory(capsys, tmp_path):
    traj = tmp_path / "traj.json"
    rc = main(["simulate", "--scene", "default", "--t-end", "2", "--with-rotation", "--out", str(traj)])
    capsys.readouterr()
    assert rc == 0
    rc, out, _ = run(capsys, "invariants", str(traj))
    assert rc == 0 and "lab_spin" in out and "dG/dt" in out
    rc, out, _ = run(capsys, "invariants", str(traj), "--json")
    data = json.loads(out)
    names = [r["name"] for r in data["drift"]]
    assert names[:4] == ["energy", "casimir", "p_theta", "lab_spin"]
    assert all(r["max_abs_drift"] < 1e-6 for r in data["drift"] if r["conserved"])

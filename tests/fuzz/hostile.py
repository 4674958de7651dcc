"""Hostile inputs for the ``flatbody`` command and its Python API, and a runner that classifies outcomes.

Used by ``tests/fuzz/test_fuzz.py`` (hypothesis) and by the probe (``python tests/fuzz/hostile.py
[N]``), which runs every case in-process under a per-case time limit and prints the tally:
clean exits 0/1/2, tracebacks (an exception escaping ``main``), internal errors (an unexpected exception
``main`` printed as ``flatbody: internal error (...)``), hangs (past the limit), NaN in
a successful JSON output, and error messages longer than a few lines.
"""

from __future__ import annotations

import contextlib
import io
import json

import signal
import sys
from pathlib import Path

DEEP = "[" * 100_000 + "]" * 100_000
BAD_NUMBERS = [
    10**400,
    -(10**400),
    1e308,
    -1e308,
    1e-308,
    0,
    -1,
    0.0,
    True,
    None,
    "1",
    "V1",
    ["V1"],
    {"x": 1},
    [],
    1e7,
    1e-7,
]
BAD_TEXT = [
    "1e400",
    "9" * 400,
    "-1",
    "0",
    "nan",
    "inf",
    "-inf",
    "1e308",
    "1e-308",
    "x",
    "",
    "1,2",
    "[1]",
    "0x10",
    "1e-400",
]
SCENE_FIELDS = [
    ("params", "J"),
    ("params", "J3"),
    ("potential", "name"),
    ("potential", "kappa"),
    ("thickness", "a"),
    ("thickness", "b"),
    ("state", "lambda"),
    ("state", "mu"),
    ("state", "rho"),
    ("state", "s3"),
    ("state", "p_theta"),
    ("state", "p_rho"),
    ("t_end",),
    ("name",),
    ("params",),
    ("potential",),
    ("state",),
]
TRAJ_FIELDS = [
    ("t",),
    ("state",),
    ("meta",),
    ("rotation",),
    ("energy",),
    ("state", "lambda"),
    ("state", "theta"),
    ("initial_state",),
]


def base_scene() -> dict:
    from flatbody_env.scene import load_scene

    return load_scene("default").to_dict()


def _set(data: dict, path: tuple, value) -> dict:
    out = json.loads(json.dumps(data))
    node = out
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return out


def scene_texts() -> list[str]:
    """Scene files as JSON text: one field replaced by a hostile value each, plus broken files."""
    base = base_scene()
    texts = [json.dumps(_set(base, path, value)) for path in SCENE_FIELDS for value in BAD_NUMBERS]
    texts += [
        "",
        "{",
        "null",
        "[]",
        DEEP,
        '{"params": ' + DEEP + "}",
        json.dumps({"potential": {"name": ["V1"]}}),
        json.dumps(_set(base, ("potential", "name"), {"V1": 1})),
    ]
    return texts


def trajectory_texts() -> list[str]:
    from flatbody_env.simulation import simulate

    good = simulate("default", t_end=0.2, times=[0.0, 0.1, 0.2], with_rotation=True).to_dict()
    texts = [
        json.dumps(_set(good, path, value))
        for path in TRAJ_FIELDS
        for value in [3.0, None, [], "x", {"a": 1}, [[[[0.0]]]], 10**400, True]
    ]
    texts += [
        "",
        "{",
        DEEP,
        json.dumps({"t": 3.0}),
        json.dumps({"state": None, "t": [0]}),
        json.dumps({"meta": [], "t": [0], "state": {}}),
    ]
    return texts


def cases(folder: Path) -> list[list[str]]:
    """Argument vectors (each a hostile input to one of simulate, record, ellipses, stability, family,
    invariants, record-info); files are written under ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    out: list[list[str]] = []
    for i, text in enumerate(scene_texts()):
        path = folder / f"scene{i}.json"
        path.write_text(text)
        cmd = ("simulate", "record", "ellipses", "stability", "family")[i % 5]
        if cmd == "simulate":
            out.append(["simulate", str(path), "--t-end", "0.5", "--samples", "5"])
        elif cmd == "record":
            out.append(["record", str(path), "--t-end", "0.2", "--samples", "5", "--out", str(folder / f"r{i}.rrd")])
        elif cmd == "family":
            out.append(["family", "--scene", str(path), "--from", "1.5", "--to", "2", "--seeds", "2", "--grid", "12"])
        else:
            out.append([cmd, "--scene", str(path), "--grid", "12"])
    for i, text in enumerate(trajectory_texts()):
        path = folder / f"traj{i}.json"
        path.write_text(text)
        out.append(["invariants", str(path), "--json"])
    for flag in ("--t-end", "--times", "--samples", "--rtol", "--step", "--max-nfev"):
        for text in BAD_TEXT:
            extra = ["--method", "RK4"] if flag == "--step" else []
            out.append(["simulate", "--scene", "default", flag, text, *extra])
    for flag in ("--J", "--kappa", "--s3", "--p-theta", "--grid", "--lam-range"):
        for text in BAD_TEXT:
            out.append(
                ["ellipses", flag, text, "--s3", "2", "--p-theta", "0.5"]
                if flag not in ("--s3", "--p-theta")
                else [
                    "stability",
                    flag,
                    text,
                    "--grid",
                    "12",
                    *(["--p-theta", "0.5"] if flag == "--s3" else ["--s3", "2"]),
                ]
            )
    for text in BAD_TEXT[:8]:
        out.append(["family", "--from", text, "--to", "2", "--seeds", "2", "--grid", "12"])
    (folder / "adir").mkdir(exist_ok=True)
    (folder / "plain.txt").write_text("not a recording")
    (folder / "fake.rrd").write_bytes(b"\x00garbage" * 10)
    paths = ["/nonexistent/dir/x", str(folder / "adir"), "/proc/version", "/dev/null", "", str(folder / "adir") + "/"]
    for p in paths:
        out.append(
            [
                "simulate",
                "--scene",
                "default",
                "--t-end",
                "0.2",
                "--out",
                p + (".json" if p and not p.endswith("/") and "adir" not in p else ""),
            ]
        )
        out.append(["record", "--scene", "default", "--t-end", "0.2", "--samples", "5", "--out", p + ".rrd"])
        out.append(
            [
                "family",
                "--from",
                "1.5",
                "--to",
                "2",
                "--seeds",
                "2",
                "--grid",
                "12",
                "--out",
                p + ".csv",
                "--plot",
                p + ".png",
            ]
        )
    for p in [
        str(folder / "plain.txt"),
        str(folder / "fake.rrd"),
        str(folder / "adir"),
        "/nonexistent.rrd",
        "/dev/null",
        str(folder / "scene0.json"),
    ]:
        out.append(["record-info", p, "--no-verify"])
    # extreme but in-range magnitudes: must stop at the budget, not hang
    for J, s3 in ((1e-6, 1e6), (1e6, 1e-6), (1e-6, 1.0)):
        path = folder / f"extreme{J}.json"
        path.write_text(json.dumps(_set(_set(base_scene(), ("params", "J"), J), ("state", "s3"), s3)))
        out.append(["simulate", str(path), "--t-end", "1000", "--max-seconds", "5"])
        out.append(["simulate", str(path), "--t-end", "1000", "--method", "DOP853-numba"])
    return out


class _Timeout(Exception):
    pass


def run_case(argv: list[str], limit: float = 30.0) -> dict:
    """Run ``flatbody ARGV`` in-process; classify the outcome."""
    from flatbody_env.cli.main import main

    out, err = io.StringIO(), io.StringIO()

    def alarm(signum, frame):
        raise _Timeout

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, limit)
    outcome = "exit"
    code = None
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 2
    except _Timeout:
        outcome = "hang"
    except BaseException as exc:  # an exception escaping main is a traceback for the user
        outcome = "traceback"
        err.write(f"Traceback: {type(exc).__name__}: {exc}"[:500])
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    text_err = err.getvalue()
    nan = False
    if outcome == "exit" and code == 0 and out.getvalue().lstrip().startswith(("{", "[")):
        try:
            json.loads(out.getvalue(), parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
        except ValueError:
            nan = True
    if "Traceback" in text_err and outcome == "exit":
        outcome = "traceback"
    elif (
        "internal error" in text_err and outcome == "exit"
    ):  # an exception main caught and printed as one line: still a bug
        outcome = "internal-error"
    return {
        "argv": argv,
        "outcome": outcome,
        "code": code,
        "nan": nan,
        "err_lines": len(text_err.strip().splitlines()),
        "err": text_err[-300:],
    }


def probe(folder: Path, limit: float = 30.0) -> dict:
    rows = [run_case(argv, limit) for argv in cases(folder)]
    tally = {
        "cases": len(rows),
        "exit_0": sum(r["outcome"] == "exit" and r["code"] == 0 for r in rows),
        "exit_1": sum(r["outcome"] == "exit" and r["code"] == 1 for r in rows),
        "exit_2": sum(r["outcome"] == "exit" and r["code"] == 2 for r in rows),
        "other_exit": sum(r["outcome"] == "exit" and r["code"] not in (0, 1, 2) for r in rows),
        "tracebacks": sum(r["outcome"] == "traceback" for r in rows),
        "internal_errors": sum(r["outcome"] == "internal-error" for r in rows),
        "hangs": sum(r["outcome"] == "hang" for r in rows),
        "nan_outputs": sum(r["nan"] for r in rows),
        "long_errors": sum(r["err_lines"] > 3 for r in rows),
        "commands": sorted({r["argv"][0] for r in rows}),
    }
    return {
        "tally": tally,
        "bad": [
            r for r in rows if r["outcome"] != "exit" or r["nan"] or r["err_lines"] > 3 or r["code"] not in (0, 1, 2)
        ],
    }


if __name__ == "__main__":  # python tests/fuzz/hostile.py [FOLDER]
    import tempfile

    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="flatbody-probe-"))
    result = probe(folder)
    print(json.dumps(result["tally"], indent=2))
    for r in result["bad"][:40]:
        print(r["outcome"], r["code"], " ".join(r["argv"])[:160], "|", r["err"].strip()[-200:].replace("\n", " / "))

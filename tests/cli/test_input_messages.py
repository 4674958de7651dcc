"""The wording of the CLI's input errors: exit code 2 and one line ``flatbody COMMAND: error: --flag: ...`` that
names the flag once (never ``--J: --J:``), states the allowed range once (never ``must lie in (allowed range
[...])``) and uses the flags' own names (``--from``, ``--to``, ``--ranges``; never the library's ``start``/``stop``)."""

from __future__ import annotations

import contextlib
import io
import re

import pytest

from flatbody_env.cli.main import build_parser, flag_message, main

GARBLED = re.compile(r"lie in \(allowed range")
DOUBLED = re.compile(r"(--[\w-]+): \1\b")


def _run(argv, capsys) -> tuple[int, str]:
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse's own errors
        rc = exc.code
    return rc, capsys.readouterr().err.strip()


@pytest.mark.parametrize(
    "argv, line",
    [
        (["ellipses", "--J", "-1"], "flatbody ellipses: error: --J: must lie in [1e-06, 1e+06], got -1.0"),
        (["stability", "--J3", "1e7"], "flatbody stability: error: --J3: must lie in [1e-06, 1e+06], got 10000000.0"),
        (["ellipses", "--s3", "2e6"], "flatbody ellipses: error: --s3: must lie in [-1e+06, 1e+06], got 2000000.0"),
        (["simulate", "--rtol", "0"], "flatbody simulate: error: --rtol: must lie in [1e-16, 1], got 0.0"),
        (["simulate", "--t-end", "1e7"], "flatbody simulate: error: --t-end: must lie in (0, 1e+06], got 10000000.0"),
        (
            ["simulate", "--t-end", "-1"],
            "flatbody simulate: error: --t-end: must be > 0 (allowed range (0, 1e+06]), got -1.0",
        ),
        (
            ["family", "--from", "4", "--to", "0.05"],
            "flatbody family: error: --to: must be greater than --from (4), got 0.05",
        ),
        (
            ["family", "--vary", "J", "--from", "1e-7", "--to", "1"],
            "flatbody family: error: --from: must lie in [1e-06, 1e+06], got 1e-07",
        ),
        (
            ["family", "--vary", "kappa", "--from", "0.5", "--to", "2e6"],
            "flatbody family: error: --to: must lie in [-1e+06, 1e+06], got 2000000.0",
        ),
    ],
)
def test_one_line_naming_the_flag_once_with_one_range(argv, line, capsys):
    rc, err = _run(argv, capsys)
    assert (rc, err) == (2, line)


def test_every_typed_flag_names_itself_once_and_its_range_cleanly():
    """Every flag with a type, of every command, given values out of any range: the error names the flag once,
    states the range without doubling it, and says nothing of internal names or tracebacks."""
    parser = build_parser()
    flags = []

    def walk(p, prefix):
        for action in p._actions:
            if isinstance(action.choices, dict) and not action.option_strings:
                for name, sub in action.choices.items():
                    walk(sub, [*prefix, name])
            elif action.option_strings and action.nargs != 0 and action.type is not None:
                flags.append((prefix, action.option_strings[-1]))

    walk(parser, [])
    assert len(flags) > 100  # the walk found the commands' flags
    bad = []
    for prefix, flag in flags:
        for text in ("-5", "0", "1e7", "nan", "x", "3,1"):
            err = io.StringIO()
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                try:
                    parser.parse_args([*prefix, f"{flag}={text}"])
                    continue
                except SystemExit as exc:
                    assert exc.code == 2
            line = err.getvalue().strip()
            if "the following arguments are required" in line:  # the value was accepted
                continue
            if (
                "\n" in line
                or GARBLED.search(line)
                or DOUBLED.search(line)
                or re.search(r"\b(start|stop)\b", line)
                or f"error: {flag}: " not in line
            ):
                bad.append(line)
    assert not bad, bad[:5]


def test_flag_message_drops_the_field_a_shared_check_put_in_front():
    assert (
        flag_message("argument --J: --J: must lie in [1e-06, 1e+06], got 0.0")
        == "--J: must lie in [1e-06, 1e+06], got 0.0"
    )
    assert flag_message("argument --t-end: t_end: must be > 0") == "--t-end: must be > 0"
    assert flag_message("argument -n/--n-envs: n_envs: must be an integer") == "--n-envs: must be an integer"


def test_sweep_family_ranges_are_refused_up_front_naming_the_flag(tmp_path, capsys):
    out = tmp_path / "sweep"
    argv = ["sweep", "family", "--vary", "s3", "J", "--ranges", "0,2", "--out", str(out), "--workers", "0"]
    rc, err = _run([*argv, "--no-progress"], capsys)
    assert rc == 2
    assert err == ("flatbody sweep: error: --ranges: must lie in [1e-06, 1e+06], got 0.0 (the range 0,2 with --vary J)")
    assert not out.exists()  # refused before any task ran (it failed as a task naming its start before)


def test_an_unusable_output_folder_is_bad_input(capsys):
    rc, err = _run(["bench", "env", "--out-dir", "d" * 400], capsys)
    assert rc == 2 and err.startswith("flatbody bench env: error: --out-dir: ") and "\n" not in err

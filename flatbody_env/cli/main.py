"""The ``flatbody`` command.

Sub-commands live in the modules of :data:`COMMAND_MODULES` (the app layer: the only place that
imports :mod:`analysis` and :mod:`agents`).

Exit codes: 0 success; 1 an integration or run failed, or an output file could not be written
(one line says when and why); 2 bad input (one line names the field and the allowed range).
"""

from __future__ import annotations

import argparse
import re
import sys

from flatbody_env.cli import (
    agents,
    analysis,
    bench,
    integrators,
    record,
    serve,
    simulate,
    sweep,
)

COMMAND_MODULES = (simulate, record, bench, analysis, integrators, agents, sweep, serve)
"""The declared command registry: modules that contribute sub-commands, in help order. Each has
``register(subparsers)`` (:mod:`.bench` every ``flatbody bench`` target); they keep heavy imports inside their
handlers so that ``flatbody --help`` stays fast."""


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit code 2); negative numbers in any spelling (``-2``, ``-.5``,
    ``-2e0``, ``-1E-3``) are values, not flags."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.stderr.write(f"{self.prog}: error: {flag_message(message)}\n")
        raise SystemExit(2)


_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")
_ARGUMENT = re.compile(r"^argument ([^:]+): (.*)$", re.S)
_FIELD = re.compile(r"^[\w.\[\]-]+: ")


def flag_message(message: str) -> str:
    """argparse's ``argument --t-end: t_end: must be ...`` as ``--t-end: must be ...``: the flag the user typed
    once, then what is wrong (the field name a shared check put in front is dropped)."""
    m = _ARGUMENT.match(message)
    if m is None:
        return message
    flag, rest = m.group(1).split("/")[-1], m.group(2)
    if _FIELD.match(rest):
        rest = rest.split(": ", 1)[1]
    return f"{flag}: {rest}"


def build_parser() -> Parser:
    parser = Parser(
        prog="flatbody",
        description="A flat affinely-rigid body with thickness: simulate, analyse, record, train.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for module in COMMAND_MODULES:
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one ``flatbody`` command; returns its exit code.

    Every command is dispatched here, so this is where an error becomes one line on stderr and an
    exit code (module docstring), every line starting ``flatbody COMMAND:`` as argparse's own do (``flatbody
    family: error: --to: must be greater than --from (4), got 0.05``), and where Ctrl-C ends any command:
    ``flatbody COMMAND: interrupted`` (with
    what was kept, when the command says so) and exit code 130, no traceback. Commands keep their
    partial results themselves (a sweep's stored rows, training's checkpoint).
    """
    import os

    # rerun's Rust log lines (e.g. a file sink's failed write) would add lines to the one-line errors below
    os.environ.setdefault("RUST_LOG", "off")
    prog = "flatbody"  # every line below starts as argparse's own: "flatbody COMMAND: ..."
    try:
        from flatbody_env.integrators import IntegrationError

        parser = build_parser()
        args = parser.parse_args(argv)
        prog = " ".join(["flatbody", *(str(v) for v in (args.command, getattr(args, "target", None)) if v)])
        if getattr(args, "handler", None) is None:
            parser.print_help()
            return 2
        return int(args.handler(args) or 0)
    except KeyboardInterrupt as exc:
        detail = _one_line(exc)
        sys.stderr.write(f"{prog}: interrupted{f' ({detail})' if detail else ''}\n")
        return 130
    except IntegrationError as exc:
        sys.stderr.write(f"{prog}: {_one_line(exc)}\n")
        return 1
    except ValueError as exc:
        sys.stderr.write(f"{prog}: error: {_one_line(exc)}\n")
        return 2
    except BrokenPipeError:
        return 0
    except OSError as exc:  # I/O failures (disk full, permissions changed mid-run, output.OutputError)
        where = f" {exc.filename!r}" if getattr(exc, "filename", None) else ""
        sys.stderr.write(f"{prog}: I/O error{where}: {_one_line(exc.strerror or exc)}\n")
        return 1
    except MemoryError:
        sys.stderr.write(f"{prog}: out of memory (use smaller sizes; docs/reliability.md lists the bounds)\n")
        return 1
    except Exception as exc:
        import sqlite3

        if os.environ.get("FLATBODY_DEBUG"):
            raise
        if isinstance(exc, sqlite3.Error) or _writer_failure(exc):
            # a database or a recording's file writer failed (disk full, I/O error): what was stored is kept
            what = "the database" if isinstance(exc, sqlite3.Error) else "the recording (disk full or file too large?)"
            sys.stderr.write(f"{prog}: I/O error writing {what}: {_one_line(exc)}\n")
            return 1
        sys.stderr.write(
            f"{prog}: internal error ({type(exc).__name__}: {_one_line(exc)}); "
            "set FLATBODY_DEBUG=1 for the traceback and please report it\n"
        )
        return 1


def _writer_failure(exc: BaseException) -> bool:
    """rerun's file sink reports a failed write (disk full, file too large) as a RuntimeError."""
    text = str(exc)
    return isinstance(exc, RuntimeError) and any(
        k in text for k in ("File-writer", "Failed to write", "sink", "os error")
    )


def _one_line(exc) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 400 else text[:397] + "..."


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())

"""The ``flatbody`` command (the app layer): a declared registry of command modules."""

from __future__ import annotations


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``flatbody`` console script (see :mod:`flatbody_env.cli.main`)."""
    from flatbody_env.cli.main import main as _main

    return _main(argv)


__all__ = ["main"]

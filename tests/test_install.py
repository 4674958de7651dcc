"""The install is reproducible: README's two commands are CI's, and constraints.txt locks what they install.

A fresh resolver picks the newest releases of everything; ``constraints.txt`` holds the set the test
suite last passed on (written by ``bash .ci/lock`` only after that set passed). These tests keep the
three places that describe the install — README's quick start, ``.ci/run`` and the lock — telling one story.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]


def _quick_start_commands() -> list[str]:
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Quick start") :]
    block = re.search(r"```bash\n(.*?)```", section, re.S)
    assert block, "README's quick start has a bash block"
    return [line.strip() for line in block.group(1).splitlines() if line.strip()]


def _pins() -> dict[str, Version]:
    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        name, sep, version = line.partition("==")
        assert sep, f"constraints.txt: {line!r} is not an exact pin (name==version)"
        pins[canonicalize_name(name)] = Version(version)
    return pins


def _requirements() -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return [Requirement(r) for r in project["dependencies"] + project["optional-dependencies"]["test"]]


def test_readme_quick_start_is_two_commands_and_ci_runs_exactly_them():
    commands = _quick_start_commands()
    assert len(commands) == 2, commands
    install, tests = commands
    assert (
        install.startswith("python3 -m venv .venv && ")
        and "-c constraints.txt" in install
        and install.endswith("flatbody demo")
    )
    assert "pytest" in tests
    ci = [
        line.strip()
        for line in (ROOT / ".ci" / "run").read_text().splitlines()
        if line.strip() and not line.lstrip().startswith("#")
    ]
    for command in commands:
        assert command in ci, f".ci/run does not run README's command {command!r}"
    assert ci.index(commands[0]) < ci.index(commands[1])
    # a fresh environment every run: .ci/run removes any .venv before README's first command makes one
    assert "rm -rf .venv" in ci and ci.index("rm -rf .venv") < ci.index(commands[0])


@pytest.mark.parametrize("requirement", _requirements(), ids=str)
def test_every_dependency_is_pinned_within_its_declared_range(requirement):
    pins = _pins()
    name = canonicalize_name(requirement.name)
    assert name in pins, f"{requirement.name} is a dependency but constraints.txt does not pin it (bash .ci/lock)"
    assert requirement.specifier.contains(pins[name], prereleases=True), (
        f"constraints.txt pins {requirement.name}=={pins[name]}, outside pyproject's {requirement}"
    )
    for extra in requirement.extras:  # dask[distributed] -> distributed, psycopg[binary] -> psycopg-binary
        assert any(extra in n for n in pins), f"{requirement}: what its extra {extra!r} brings is not pinned"


def test_the_lock_says_how_it_is_made():
    head = (ROOT / "constraints.txt").read_text().splitlines()[:3]
    assert any("bash .ci/lock" in line for line in head)
    assert (ROOT / ".ci" / "lock").exists()


def test_ci_has_every_real_component_it_installs():
    """In CI (``CI`` set, as the CI runner sets it) the components ``.ci/run`` installs are really there, so
    the tests that need them run instead of skipping: the rerun viewer (Xvfb, software Vulkan, the
    environment's ``rerun``), the browser and its driver, and a PostgreSQL server."""
    import os
    import shutil

    if not os.environ.get("CI"):
        pytest.skip(
            "only CI promises these components (.ci/run installs them); elsewhere their tests skip with a reason"
        )
    from flatbody_env.recording.viewer import viewer_unavailable

    assert viewer_unavailable() is None, viewer_unavailable()
    assert shutil.which("chromium") and shutil.which("chromedriver")
    assert sorted(Path("/usr/lib/postgresql").glob("*/bin/initdb")), "no PostgreSQL server (initdb)"
    assert shutil.which("dask"), "the dask command of this environment"

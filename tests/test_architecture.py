"""The house's layering, proved: light imports stay light, layers run one way, gym registration works."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("gymnasium", "numba", "rerun", "torch", "stable_baselines3")


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)


@pytest.mark.parametrize("module", ["flatbody_env.physics", "analysis", "flatbody_env"])
def test_light_imports_stay_light(module):
    """Importing the physics wing, the analysis package or the scripting API loads none of the heavy stacks."""
    code = (
        f"import sys, {module}\n"
        "import flatbody_env.physics.state, flatbody_env.physics.equilibria, flatbody_env.physics.regular\n"
        f"print(','.join(m for m in {HEAVY!r} if m in sys.modules))"
    )
    proc = _run(code)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "", f"{module} imported {proc.stdout.strip()}"


def test_import_contracts_hold():
    """import-linter's contracts of pyproject.toml (layers one way; no import circles at any depth; the env's kernels and
    the agents' loader one way; physics/analysis free of heavy stacks)."""
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from importlinter.cli import lint_imports_command; sys.argv=['lint-imports']; lint_imports_command()",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert "0 broken" in proc.stdout


@pytest.mark.parametrize(
    "code",
    [
        # RL Zoo's --gym-packages imports the package after gymnasium
        "import gymnasium as gym, flatbody_env\nenv = gym.make('FlatBody-v0')",
        # the module: prefix makes gymnasium import the package itself
        "import gymnasium as gym\nenv = gym.make('flatbody_env:FlatBody-v0')",
        # the package first, gymnasium later: registered when gymnasium finishes importing
        "import flatbody_env\nimport gymnasium as gym\nenv = gym.make('FlatBody-v0')",
    ],
    ids=["gym-then-package", "module-prefix", "package-then-gym"],
)
def test_flatbody_v0_registers(code):
    proc = _run(code + "\nobs, info = env.reset(seed=0)\nprint(obs.shape, type(env.unwrapped).__name__)")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["(16,)", "FlatBodyEnv"]


def test_package_never_cites_the_source_folder():
    """Neither the package nor its docs point at paths a user who installs it never has."""
    offenders = []
    for folder in ("flatbody_env", "analysis", "agents", "docs"):
        for path in (ROOT / folder).rglob("*"):
            if path.suffix in (".py", ".md", ".json", ".yml", ".html", ".js") and path.is_file():
                text = path.read_text(encoding="utf-8", errors="replace")
                if "shared/" in text or "NOTES.md" in text:
                    offenders.append(str(path.relative_to(ROOT)))
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    if "shared/" in readme:
        offenders.append("README.md")
    assert not offenders, offenders

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


# -- the one reading door, the one trust check ----------------------------------------------------------------------
_PICKLE_LOADS = (
    r"pickle\.loads?\(",
    r"torch\.load\(",
    r"cloudpickle",
    r"\b(PPO|SAC|cls)\.load\(",
    r"VecNormalize\.load",
)
_FILE_READS = (
    r"np\.load\(",
    r"yaml\.(safe_)?load\(",
    r"json\.load\(",
    r"(?<!validation)\.read_text\(",
    r"(?<!validation)\.read_bytes\(",
    r"csv\.(Dict)?[Rr]eader\((?!io\.StringIO\(validation)",
    r"\bopen\([^)]*\)",
)
_READ_EXCEPTIONS = {
    # the package's own data and system files, never a user's file (package resources, not paths)
    "flatbody_env/scene.py": r"entry\.read_text",
    "flatbody_env/service/models.py": r"entry\.read_text",
    "flatbody_env/service/app.py": r"\.read_text\(",
    "flatbody_env/provenance.py": r"/proc/cpuinfo",
    # the env layer is another wing's (its shipped settling-rate table)
    "flatbody_env/env/targets.py": r"np\.load\(",
    # the service's own log file and lock, a screenshot it just took, rerun's own pipe
    "flatbody_env/service/launch.py": r"log_path|proc\.stderr",
    "flatbody_env/service/store.py": r"service\.lock",
    "flatbody_env/recording/viewer.py": r"Image\.open|Popen|fdopen|client\.open",
    "flatbody_env/recording/sink.py": r"open\(tmp, \"wb\"\)|os\.open\(fifo",
    # bench compare: the log file its own worker process writes into (in a scratch folder it made)
    "flatbody_env/bench/compare.py": r"log_path",
    # the package's own kernel sources, hashed into the key of the CUDA kernels' on-disk cache
    "flatbody_env/integrators/cuda.py": r"path\.read_bytes\(\)",
}


def _source_lines(pattern: str):
    import re

    rx = re.compile(pattern)
    for package in ("agents", "analysis", "flatbody_env"):
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                code = line.split("#", 1)[0]
                if rx.search(code) and not code.strip().startswith(('"', "'")):
                    yield rel, n, line.strip()


def test_every_pickle_is_loaded_behind_the_one_trust_check():
    """Nothing is unpickled outside agents/numpy_policy.py, where every load reads its bytes through read_pickled
    (the trust check, then the reading door)."""
    found = [hit for p in _PICKLE_LOADS for hit in _source_lines(p) if hit[0] != "agents/numpy_policy.py"]
    assert found == [], found


def test_every_file_is_read_through_the_one_door():
    """No module reads a file itself: validation.read_bytes and the readers built on it are the one door (the few
    exceptions read the package's own data or files the program itself just made)."""
    import re

    found = []
    for p in _FILE_READS:
        for rel, n, line in _source_lines(p):
            if rel == "flatbody_env/physics/validation.py":
                continue
            allowed = _READ_EXCEPTIONS.get(rel)
            if allowed and re.search(allowed, line):
                continue
            if re.search(r"open\((tmp|held|name|target|self\.data_dir)|atomic_open|os\.open\(target|Popen|pidfd", line):
                continue  # writers (the writing door, a temporary of ours), processes
            found.append((rel, n, line))
    assert found == [], found

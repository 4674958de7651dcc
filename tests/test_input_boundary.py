"""The input boundary, held: every check of what enters the package goes through
``flatbody_env/physics/validation.py``, the one place that composes a refusal's "X: must be …" / "X: must lie in …"
text. A ``raise`` anywhere else whose expression spells such a rule itself (a string constant, or the constant part of
an f-string) fails here with its ``file:line``; comments and docstrings do not count."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("flatbody_env", "analysis", "agents")
VALIDATION = ROOT / "flatbody_env" / "physics" / "validation.py"
RULE = re.compile(r"\bmust (be|lie)\b")


def _composed_rules(tree: ast.AST) -> list[int]:
    """Lines of the ``raise`` statements whose raised expression (or ``from`` cause) holds a string constant matching
    :data:`RULE` (f-strings' constant parts are ``Constant`` nodes inside their ``JoinedStr``)."""
    lines = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Raise):
            continue
        parts = [p for p in (node.exc, node.cause) if p is not None]
        if any(
            isinstance(sub, ast.Constant) and isinstance(sub.value, str) and RULE.search(sub.value)
            for part in parts
            for sub in ast.walk(part)
        ):
            lines.append(node.lineno)
    return lines


def _sources() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py") if p.resolve() != VALIDATION.resolve())


def test_the_rule_finder_sees_constants_and_fstrings_but_not_comments():
    code = (
        "# x: must be an integer\n"
        "def f(x):\n"
        '    """x: must be an integer."""\n'
        "    if x:\n"
        "        raise ValueError(f'{x}: must lie in [0, 1], got {x!r}')\n"
        "    if not x:\n"
        "        raise TypeError('x: must be ' + 'an integer')\n"
        "    raise v.refusal('x', 'be an integer')\n"
    )
    assert _composed_rules(ast.parse(code)) == [5, 7]


def test_no_check_composes_its_own_rule_outside_validation():
    assert len(_sources()) > 100
    offenders = []
    for path in _sources():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        offenders += [f"{path.relative_to(ROOT)}:{line}" for line in sorted(_composed_rules(tree))]
    assert not offenders, (
        f"{len(offenders)} raise statement(s) compose their own 'must be'/'must lie' message; check through "
        "flatbody_env.physics.validation (number, integer, count, string(choices=...), boolean, interval, "
        "requirement, refusal) instead:\n" + "\n".join(offenders)
    )

"""``flatbody methods`` lists the methods in one order, whatever a process imported first (the service's
answer and the command's must agree)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _names(first_import: str) -> list[str]:
    code = f"{first_import}\nfrom flatbody_env.answers import methods_answer\nimport json\nprint(json.dumps([m['name'] for m in methods_answer()]))"
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    return json.loads(
        subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    )


def test_method_list_does_not_depend_on_import_order():
    plain = _names("")
    compiled_first = _names("import flatbody_env.integrators.compiled_methods")
    assert plain == compiled_first
    assert plain.index("DOP853") < plain.index("DOP853-numba") and len(plain) == len(set(plain))

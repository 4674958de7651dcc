"""``flatbody bench compare REV``: the core figures of this working tree against a git revision, in one run.

So that a regression is seen before it lands: the revision is checked out beside this checkout (``git worktree
add --detach`` into a temporary folder, removed afterwards), and two worker processes are started, each with its
tree first on ``PYTHONPATH`` (:mod:`.compare_worker`, the same script for both). Each figure is set up in both
workers (one untimed block: compiling, caches), then timed **in alternation**, REV and this tree in turn within
every round and in the other order every other round (:func:`~flatbody_env.bench.harness.alternate_samples`,
``mirror``; asv's ``continuous`` compares two revisions the same way, but builds environments and runs its own
suites: here the two trees share this venv, and the figures are the project's own). A figure is the best of
``rounds`` blocks; the ratio this tree / REV is the result (> 1: slower now).

The figures (:data:`FIGURES`), on the newest single-env id both trees register (``FlatBody-v1``, else
``FlatBody-v0``), or on the id given (``--env``, e.g. ``FlatBodyAnyBody-v1``'s batch of bodies drawn per episode):

* ``env-step`` — ``gym.make(ID)``'s ``step`` (with its wrappers), 1000 zero-action steps a block, resets included;
* ``vector-step`` — ``FlatBodyVectorEnv`` with ID's task, N = 1024, 20 random-action steps a block (autoresets
  included), per env-step;
* ``simulate`` — ``simulate("planar-v3", t_end=100, method="DOP853-numba", model="two-polar")``: the planar scene on
  the compiled kernel, the full model;
* ``recording`` — ``flatbody record-env --env-id ID --max-steps 100`` to a finished ``.rrd``;
* ``ppo`` — one PPO iteration of stable-baselines3 on ID (8 envs × 512 steps = 4096 env steps, 4 epochs, one torch
  thread): the rollout and the update;
* ``planner`` — ID's planner (``agents.planner.settings_for``) planning 8 reference episodes (seeds 10000 …) together,
  5 control steps a block, per episode and control step (the first step, set up untimed, is the one that refines its
  plan ``initial_iterations`` times; a horizon to the episode's end shrinks as the blocks go on, alike in both trees).

Output (:func:`report`): ``compare.json``, ``compare.csv`` and ``compare.png`` (:func:`plot`), the table on the
terminal. A ``REV`` that is not a commit of this checkout is refused with one line naming ``rev`` (exit 2).
"""

from __future__ import annotations

import json
import os
import select
import shutil
import statistics
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flatbody_env.bench.harness import Report, Table, alternate_samples
from flatbody_env.physics import validation

NAME = "compare"
"""The files' stem: ``compare.json``, ``.csv``, ``.png``."""


@dataclass(frozen=True, kw_only=True)
class Figure:
    """One core figure: what a block times and how a block's time becomes the figure."""

    what: str
    unit: str
    scale: float
    """The figure = seconds per counted unit × scale (µs: 1e6, ms: 1e3, s: 1)."""


FIGURES = {
    "env-step": Figure(what="single env step, gym.make({env})", unit="µs per step", scale=1e6),
    "vector-step": Figure(what="FlatBodyVectorEnv step, N = 1024, {env}'s task", unit="µs per env-step", scale=1e6),
    "simulate": Figure(what="compiled simulate, planar-v3 to t = 100 (DOP853-numba)", unit="ms per call", scale=1e3),
    "recording": Figure(what="record-env, {env}, 100 steps to a finished .rrd", unit="s per recording", scale=1.0),
    "ppo": Figure(what="SB3 PPO iteration on {env}, 8 x 512 env steps", unit="s per iteration", scale=1.0),
    "planner": Figure(what="{env}'s planner, 8 episodes x 5 control steps", unit="ms per episode-step", scale=1e3),
}
"""The core figures, in the order they are timed (module docstring)."""

SETUP_S = 1200.0
"""The longest a worker may take to start and set a figure up (an old tree compiles its kernels first)."""
BLOCK_S = 600.0
"""The longest one timed block may take."""


def _git(root: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, check=False)


def this_tree() -> Path:
    """The checkout this package runs from; a ``ValueError`` naming ``rev`` when it is not a git checkout."""
    import flatbody_env

    root = Path(flatbody_env.__file__).resolve().parents[1]
    top = _git(root, "rev-parse", "--show-toplevel") if shutil.which("git") else None
    if top is None or top.returncode != 0 or Path(top.stdout.strip()).resolve() != root:
        raise ValueError(f"rev: bench compare needs a git checkout of flatbody; {str(root)!r} is not one")
    return root


def resolve(rev: str, root: Path) -> str:
    """The full commit id of ``rev`` in the checkout ``root``; a ``ValueError`` naming ``rev`` when it is none."""
    text = validation.string("rev", rev)
    if not text.strip() or text.startswith("-") or any(c in text for c in "\0\n\r"):
        raise ValueError(f"rev: expected a commit, branch or tag of this checkout, got {text[:60]!r}")
    found = _git(root, "rev-parse", "--verify", "--quiet", "--end-of-options", f"{text}^{{commit}}")
    if found.returncode != 0:
        raise ValueError(f"rev: {text[:60]!r} is not a commit of this checkout ({root})")
    return found.stdout.strip()


class _Refused(RuntimeError):
    """A worker answered a request with an error (it is still running)."""


class _Worker:
    """One tree's worker process (:mod:`.compare_worker`) and its request/answer pipe."""

    def __init__(self, label: str, tree: Path, scratch: Path) -> None:
        self.label = label
        self.log_path = scratch / f"{label}-worker.log"
        env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1", "RUST_LOG": "off"}
        env.pop("PYTHONSTARTUP", None)
        self._log = open(self.log_path, "w", encoding="utf-8")  # noqa: SIM115 (closed in close())
        run_dir = scratch / f"{label}-cwd"
        run_dir.mkdir()
        self.proc = subprocess.Popen(
            [sys.executable, "-P", str(Path(__file__).with_name("compare_worker.py"))],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._log,
            text=True,
            cwd=run_dir,
            env=env,
        )

    def ask(self, request: dict[str, Any], timeout: float) -> dict[str, Any]:
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        line = self.proc.stdout.readline() if ready else ""
        if not line:
            why = "did not answer in time" if not ready else "stopped"
            raise RuntimeError(f"bench compare: the {self.label} tree's worker {why} ({request}); {self._tail()}")
        answer = json.loads(line)
        if "error" in answer:
            raise _Refused(f"the {self.label} tree: {answer['error']}")
        return answer

    def _tail(self) -> str:
        self._log.flush()
        lines = self.log_path.read_text(encoding="utf-8", errors="replace").strip().splitlines()
        return "its last words: " + (" | ".join(lines[-3:]) if lines else "none")

    def close(self) -> None:
        try:
            if self.proc.poll() is None:
                self.proc.stdin.write(json.dumps({"do": "quit"}) + "\n")
                self.proc.stdin.flush()
                self.proc.wait(timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait()
        finally:
            self._log.close()


def run(
    rev: str, *, figures=None, rounds: int = 5, progress: bool = False, env_id: str | None = None
) -> dict[str, Any]:
    """Time :data:`FIGURES` (or ``figures`` among them) of this working tree against ``rev`` (module docstring);
    returns the JSON record. ``env_id``: the task of the env figures (default: the newest single-env id both trees
    register); ``ValueError`` naming ``env`` when this tree or ``rev`` does not register it."""
    from flatbody_env.progress import progress_bar
    from flatbody_env.provenance import machine

    names = list(figures or FIGURES)
    unknown = [n for n in names if n not in FIGURES]
    if unknown or not names:
        raise ValueError(f"figures: expected names from {', '.join(FIGURES)}, got {', '.join(unknown) or 'none'}")
    rounds = validation.integer("rounds", rounds, low=1, high=100)
    if env_id is not None:
        from flatbody_env.env.registration import task_spec

        env_id = task_spec(env_id).env_id
    root = this_tree()
    commit = resolve(rev, root)
    head = _git(root, "rev-parse", "HEAD").stdout.strip()
    changed = len([ln for ln in _git(root, "status", "--porcelain").stdout.splitlines() if ln.strip()])
    before = machine()
    scratch = Path(tempfile.mkdtemp(prefix="flatbody-compare-"))
    checkout = scratch / "tree"
    workers: list[_Worker] = []
    bar = progress_bar(total=2 * len(names) + rounds, desc="bench compare", unit="step", enabled=progress)
    try:
        added = _git(root, "worktree", "add", "--detach", "--quiet", str(checkout), commit)
        if added.returncode != 0:
            raise RuntimeError(f"bench compare: git worktree add failed: {added.stderr.strip()[:300]}")
        old, new = _Worker("REV", checkout, scratch), _Worker("working", root, scratch)
        workers += [old, new]
        hello = {w.label: w.ask({"do": "hello", "env": env_id}, SETUP_S) for w in workers}
        if Path(hello["working"]["package"]).resolve() != (root / "flatbody_env").resolve():
            raise RuntimeError(f"bench compare: the working tree's worker imported {hello['working']['package']}")
        if Path(hello["REV"]["package"]).resolve() != (checkout / "flatbody_env").resolve():
            raise RuntimeError(f"bench compare: the REV worker imported {hello['REV']['package']}, not the checkout")
        asked = env_id
        env_id = next((e for e in hello["working"]["envs"] if e in hello["REV"]["envs"]), None)
        if asked is not None and env_id is None:
            raise validation.refusal("env", f"be an id {rev} registers too", asked)
        if env_id is None:
            raise RuntimeError("bench compare: the two trees register no FlatBody id in common")
        failed: dict[str, str] = {}
        for name in names:
            for w in (old, new):
                bar.set_postfix_str(f"setting up {name} ({w.label})")
                try:
                    w.ask({"do": "setup", "figure": name, "env": env_id}, SETUP_S)
                except _Refused as exc:  # the figure cannot run on that tree: reported, the others go on
                    failed[name] = str(exc)[:300]
                bar.update(1)
        timed = [n for n in names if n not in failed]
        counts: dict[str, int] = {}

        def case(w: _Worker, name: str):
            def once() -> float:
                answer = w.ask({"do": "time", "figure": name}, BLOCK_S)
                counts[name] = int(answer["count"])
                return float(answer["seconds"])

            return once

        cases = {f"{name}|{w.label}": case(w, name) for name in timed for w in (old, new)}
        bar.set_postfix_str("timing in alternation")
        times = alternate_samples(cases, rounds, warm=False, mirror=True, progress=lambda k: bar.update(1))
    finally:
        bar.close()
        for w in workers:
            w.close()
        _git(root, "worktree", "remove", "--force", str(checkout))
        _git(root, "worktree", "prune")
        shutil.rmtree(scratch, ignore_errors=True)
    after = machine()
    rows = []
    for name in names:
        fig = FIGURES[name]
        if name in failed:
            rows.append(
                {
                    "figure": name,
                    "what": fig.what.format(env=env_id),
                    "unit": fig.unit,
                    "old": None,
                    "new": None,
                    "ratio": None,
                    "failed": failed[name],
                }
            )
            continue
        per = fig.scale / counts[name]
        old_s, new_s = times[f"{name}|REV"], times[f"{name}|working"]
        rows.append(
            {
                "figure": name,
                "what": fig.what.format(env=env_id),
                "unit": fig.unit,
                "old": min(old_s) * per,
                "new": min(new_s) * per,
                "ratio": min(new_s) / min(old_s),
                "old_blocks": [t * per for t in old_s],
                "new_blocks": [t * per for t in new_s],
            }
        )
    return {
        "benchmark": "compare",
        "rev": rev,
        "rev_commit": commit,
        "working_tree": {"head": head, "changed_files": changed},
        "env_id": env_id,
        "rounds": rounds,
        "figures": rows,
        "load_avg_1min": {"before": before.get("load_avg_1min"), "after": after.get("load_avg_1min")},
    }


def tables(result: dict[str, Any]) -> list[Table]:
    """The comparison: old / new / ratio per figure (the terminal's text)."""
    rev = f"{result['rev']} ({result['rev_commit'][:7]})"
    wt = result["working_tree"]
    dirty = f" + {wt['changed_files']} changed" if wt["changed_files"] else ""
    here = f"working tree ({wt['head'][:7]}{dirty})"
    load = result.get("load_avg_1min") or {}
    fmt = lambda v: f"{v:.4g}"  # noqa: E731
    return [
        Table(
            title=f"bench compare: this {here} against {rev}, best of {result['rounds']} alternated rounds",
            columns=["figure", "what", "unit", rev, "working tree", "new / old", "medians"],
            rows=[
                [
                    r["figure"],
                    r["what"],
                    r["unit"],
                    fmt(r["old"]),
                    fmt(r["new"]),
                    f"{r['ratio']:.2f}×",
                    f"{statistics.median(r['new_blocks']) / statistics.median(r['old_blocks']):.2f}×",
                ]
                if r.get("ratio") is not None
                else [r["figure"], r["what"], r["unit"], "n/a", "n/a", f"not timed: {r.get('failed', '')}", ""]
                for r in result["figures"]
            ],
            notes=[
                "new / old > 1: slower now. Each figure: the best of its blocks, REV and this tree timed in turn in "
                "every round (the other order every other round), one process each, one thread each; medians: the "
                "ratio of the median blocks (far from new / old: the machine's load moved during the run).",
                f"load average (1 min) before / after: {load.get('before')} / {load.get('after')}",
            ],
            block=None,
        )
    ]


def report(result: dict[str, Any]) -> Report:
    """``compare.json`` (``result``), ``compare.csv`` (one row per figure), ``compare.png`` (:func:`plot`) and the
    table."""
    header = ["figure", "what", "unit", "old", "new", "ratio_new_over_old"]
    return Report(
        name=NAME,
        record=result,
        header=header,
        rows=[[r["figure"], r["what"], r["unit"], r["old"], r["new"], r["ratio"]] for r in result["figures"]],
        chart=plot,
        tables=tables(result),
    )


def plot(json_path: str | Path, png_path: str | Path) -> Path:
    """The ratio this tree / REV of each figure (log scale, 1 = unchanged), every block of both trees as dots."""
    from flatbody_env.figures import PALETTE, chart

    result = validation.read_json("--plot-only", json_path)
    rows = [r for r in result["figures"] if r.get("ratio") is not None]
    if not rows:
        raise ValueError(f"--plot-only: {json_path} holds no timed figure")
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

    rev = result["rev"]
    with chart(png_path, size=(9.6, 1.6 + 0.95 * len(rows) + 1.2)) as c:
        ax = c.ax
        ys = list(range(len(rows)))[::-1]
        for y, r in zip(ys, rows, strict=True):
            colour = PALETTE["bad"] if r["ratio"] > 1.05 else PALETTE["good"] if r["ratio"] < 0.95 else "0.35"
            ax.plot([b / r["old"] for b in r["old_blocks"]], [y + 0.2] * len(r["old_blocks"]), "|", color="0.6", ms=9)
            ax.plot([b / r["old"] for b in r["new_blocks"]], [y - 0.2] * len(r["new_blocks"]), "|", color=colour, ms=9)
            ax.plot([1.0, r["ratio"]], [y, y], "-", color=colour, lw=2)
            ax.plot([r["ratio"]], [y], "o", color=colour, ms=8)
            ax.annotate(
                f"{r['old']:.3g} → {r['new']:.3g} {r['unit']}  ({r['ratio']:.2f}×)",
                (r["ratio"], y),
                xytext=(8, 2),
                textcoords="offset points",
                ha="left",
                va="bottom",
                fontsize=8,
            )
        ax.axvline(1.0, color=PALETTE["reference"], lw=0.8, ls=":")
        ax.set_yticks(ys, [f"{r['figure']}\n{r['what']}" for r in rows], fontsize=7.5)
        spread = [b / r["old"] for r in rows for b in r["old_blocks"] + r["new_blocks"]]
        lo, hi = min([0.7, *spread]), max([1.5, *spread])
        ax.set_xscale("log")
        ax.set_xlim(lo / 1.15, hi * 2.2)
        ax.xaxis.set_major_locator(FixedLocator([v for v in (0.25, 0.5, 0.67, 0.8, 1, 1.25, 1.5, 2, 3, 4, 8)]))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.xaxis.set_minor_locator(NullLocator())
        ax.set_ylim(-0.7, len(rows) - 0.3)
        ax.set_xlabel(f"time of this tree / time of {rev} (log scale; < 1 faster, > 1 slower)")
        ax.grid(True, axis="x", alpha=0.3)
        wt = result["working_tree"]
        ax.set_title(
            f"flatbody bench compare: working tree ({wt['head'][:7]}) against {rev} ({result['rev_commit'][:7]})"
        )
        load = result.get("load_avg_1min") or {}
        c.caption(
            f"Dot: this tree's best block over {rev}'s best block ({result['rounds']} rounds; in each round both "
            f"trees, each in its own process, timed in turn). Ticks: every block over {rev}'s best, {rev}'s above "
            "the line (grey), this tree's below: where they overlap, the difference is within the machine's noise. "
            f"Labels: {rev}'s figure → this tree's. Red: > 5 % slower, green: > 5 % faster. "
            f"Load average (1 min) before / after the run: {load.get('before')} / {load.get('after')}."
        )
    return Path(png_path)


__all__ = ["FIGURES", "NAME", "Figure", "plot", "report", "resolve", "run", "tables", "this_tree"]

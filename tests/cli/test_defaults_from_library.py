"""Every default and bound of a shared option is the library's named one: the command's argparse
defaults and ranges, the service's request models and the library functions all read the same names
(:mod:`flatbody_env.physics.validation` for bounds; :class:`analysis.stationary.SearchBox`, the family
and map defaults of :mod:`analysis.families`, :data:`agents.evaluate.EVAL_SEED`,
:data:`flatbody_env.simulation.DEFAULT_SAMPLES` for defaults)."""

from __future__ import annotations

import argparse
import inspect
import subprocess
import sys
from pathlib import Path

import pytest

from agents import evaluate
from analysis import families
from analysis.stationary import SearchBox
from flatbody_env import simulation
from flatbody_env.cli.main import build_parser
from flatbody_env.physics import validation

BOX = SearchBox()


def _command(*names: str) -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = build_parser()
    for name in names:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[name]
    return parser


def _option(parser: argparse.ArgumentParser, flag: str) -> argparse.Action:
    return next(a for a in parser._actions if flag in a.option_strings)


def _accepts(action: argparse.Action, value) -> bool:
    try:
        action.type(str(value))
    except argparse.ArgumentTypeError:
        return False
    return True


def _integer_range(action: argparse.Action, lo: int, hi: int) -> None:
    """The option's type accepts exactly [lo, hi]."""
    assert _accepts(action, lo) and _accepts(action, hi)
    assert not _accepts(action, lo - 1) and not _accepts(action, hi + 1)


@pytest.mark.parametrize("command", [("ellipses",), ("stability",), ("family",), ("sweep", "family")])
def test_search_box_options_are_the_library_search_box(command):
    p = _command(*command)
    assert _option(p, "--lam-range").default == BOX.lam
    assert _option(p, "--mu-range").default == BOX.mu
    grid = _option(p, "--grid")
    assert grid.default == BOX.n
    _integer_range(grid, *validation.SEARCH_GRID_RANGE)
    assert f"default {BOX.n}" in grid.help


def test_family_options_are_the_library_family_defaults():
    p = _command("family")
    assert (_option(p, "--from").default, _option(p, "--to").default) == families.DEFAULT_FAMILY_RANGE
    seeds = _option(p, "--seeds")
    assert seeds.default == families.DEFAULT_SEEDS
    _integer_range(seeds, *validation.FAMILY_SEEDS_RANGE)
    assert _option(p, "--vary").default == families.PARAMETERS[0]
    sweep = _command("sweep", "family")
    assert _option(sweep, "--ranges").default == [families.DEFAULT_FAMILY_RANGE]
    assert _option(sweep, "--seeds").default == families.DEFAULT_SEEDS
    _integer_range(_option(sweep, "--seeds"), *validation.FAMILY_SEEDS_RANGE)
    # the library's and the answers' own defaults are the same names
    signature = inspect.signature(families.follow_family).parameters
    assert (signature["s3"].default, signature["p_theta"].default, signature["seeds"].default) == (
        families.DEFAULT_S3,
        families.DEFAULT_P_THETA,
        families.DEFAULT_SEEDS,
    )


@pytest.mark.parametrize(
    "command, grid_range",
    [(("stability-map",), validation.MAP_GRID_RANGE), (("sweep", "stability-map"), validation.SWEEP_GRID_RANGE)],
)
def test_stability_map_options_are_the_library_map_defaults(command, grid_range):
    p = _command(*command)
    assert _option(p, "--lam-range").default == families.MAP_LAM_RANGE
    assert _option(p, "--mu-range").default == families.MAP_MU_RANGE
    grid = _option(p, "--grid")
    assert grid.default == families.MAP_GRID
    _integer_range(grid, *grid_range)


def test_evaluation_seed_is_named_once():
    from flatbody_env.sweep import tasks

    assert _option(_command("evaluate"), "--seed").default == evaluate.EVAL_SEED
    assert _option(_command("sweep", "seeds"), "--eval-seed").default == evaluate.EVAL_SEED
    assert tasks.EVAL_SEED == evaluate.EVAL_SEED
    for function in (evaluate.evaluate_all, evaluate.evaluate_task):
        assert inspect.signature(function).parameters["seed"].default == evaluate.EVAL_SEED


@pytest.mark.parametrize("command", [("simulate",), ("record",)])
def test_sample_counts_start_at_the_named_minimum(command):
    samples = _option(_command(*command), "--samples")
    _integer_range(samples, validation.MIN_SAMPLES, validation.MAX_SAMPLES)


def test_simulate_help_states_the_library_sample_default():
    assert f"default {simulation.DEFAULT_SAMPLES}," in _option(_command("simulate"), "--samples").help


def test_service_models_read_the_same_names():
    from flatbody_env.service import models

    family = models.FamilyJobParams()
    assert (family.start, family.stop, family.seeds) == (*families.DEFAULT_FAMILY_RANGE, families.DEFAULT_SEEDS)
    assert (family.lam_range, family.mu_range, family.grid) == (BOX.lam, BOX.mu, BOX.n)
    stability_map = models.StabilityMapJobParams()
    assert (stability_map.lam_range, stability_map.mu_range, stability_map.grid) == (
        families.MAP_LAM_RANGE,
        families.MAP_MU_RANGE,
        families.MAP_GRID,
    )
    assert models.EvaluateJobParams().seed == evaluate.EVAL_SEED
    assert models.RecordJobParams().samples == models.RECORD_JOB_SAMPLES


def test_the_default_energy_tolerance_is_one_rule():
    rtol, atol = 1e-10, 1e-12
    assert simulation.energy_tol_scale(rtol, atol) == max(
        simulation.ADAPTIVE_ENERGY_TOL_FLOOR, simulation.ADAPTIVE_ENERGY_TOL_FACTOR * rtol
    )
    assert simulation.energy_tol_scale(rtol, atol, adaptive=False) == simulation.FIXED_STEP_ENERGY_TOL
    assert simulation.default_energy_tol(-3.0, rtol, atol) == 3.0 * simulation.energy_tol_scale(rtol, atol)
    assert simulation.default_energy_tol(0.5, rtol, atol) == simulation.energy_tol_scale(rtol, atol)


def test_reading_the_defaults_does_not_load_scipy():
    """The command reads SearchBox and the family defaults when it builds its parser: ``flatbody --help`` stays fast."""
    code = (
        "import sys\nfrom flatbody_env.cli.main import build_parser\nbuild_parser()\n"
        "print(','.join(m for m in ('scipy.optimize', 'scipy.linalg') if m in sys.modules))"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=Path(__file__).resolve().parents[2],
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == ""

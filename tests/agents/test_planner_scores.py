"""The planner reference (agents/planner.py) and the suite's normalised scores and IQM (agents/scores.py)."""

from __future__ import annotations

import numpy as np
import pytest

from agents.evaluate import env_kwargs_for


def test_the_planners_model_is_the_env_itself():
    """A plan rolled out by the planner's batch from the observed state lands where the env lands (float32
    observations: to 1e-6), so the planner restates no formula and is causal (it reads the observation only)."""
    from agents.planner import Planner, PlannerSettings
    from flatbody_env.env import transition as tr
    from flatbody_env.env.task import state_from_observation
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    kw = env_kwargs_for("FlatBody-v1")
    env = FlatBodyVectorEnv(1, **kw)
    obs, _ = env.reset(seed=10001)
    planner = Planner(kw, 1, PlannerSettings(samples=4, horizon=20))
    y, t = state_from_observation(obs.astype(np.float64))
    tg = np.zeros((6, 1))
    tg[:4], tg[4] = t, y[3]
    planner.core.set_bodies(np.repeat(y, 4, axis=1), np.repeat(tg, 4, axis=1))
    actions = np.random.default_rng(0).uniform(-1, 1, (20, 4))
    for a in actions:
        planner.core.step(np.repeat(a[None], 4, axis=0))
        _, _, _, _, info = env.step(a[None])
        assert planner.core.S[tr.R_DISTANCE, 0] == pytest.approx(info["distance"][0], abs=1e-6)


def test_a_planners_batch_observes_the_bodies_it_is_given_as_a_reset_would():
    """Where the task observes the body (``observe_body``), the planner's batch put at an episode's body observes
    that body's constants at once, as a reset writes them: the law it perturbs reads them from there."""
    from agents.planner import Planner, PlannerSettings
    from flatbody_env.env import transition as tr
    from flatbody_env.env.task import state_from_observation
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    kw = env_kwargs_for("FlatBodyAnyBody-v1", {"observe_body": True})
    env = FlatBodyVectorEnv(2, **kw)
    obs, _ = env.reset(seed=10000)
    planner = Planner(kw, 2, PlannerSettings(samples=2, horizon=2))
    y, t = state_from_observation(obs[:, :16].astype(np.float64))
    tg = np.zeros((6, 2))
    tg[:4], tg[4] = t, y[3]
    planner.core.set_bodies(*(np.repeat(a, 2, axis=1) for a in (y, tg, env.body_params)))  # 2 samples per episode
    seen = planner.core.OBS[:, 16:21]
    assert np.array_equal(seen, np.repeat(obs[:, 16:21], 2, axis=0))  # float32 both, from the same doubles
    assert np.array_equal(seen[::2], env.body_params[list(tr.P_CONSTANTS)].T.astype(np.float32))


def test_the_planner_acts_and_counts_its_compute():
    from agents.evaluate import run_episodes, summarize

    compute: dict = {}  # a small plan (the default: 48 samples over 60 steps) is counted the same way, 5x faster
    small = {"samples": 8, "horizon": 10}
    records = run_episodes(
        "planner", episodes=1, seed=10000, env_id="FlatBodyHoldUnstable-v1", compute=compute, planner=small
    )
    assert len(records) == 1 and compute["body_steps_per_step"] == 8 * 10
    assert compute["settings"]["samples"] == 8 and compute["settings"]["horizon"] == 10
    assert compute["episode_steps"] >= 1 and compute["seconds"] > 0
    assert compute["label"] == "planner (MPPI around the passivity law, true model)"
    assert summarize(records)["success_rate"] in (0.0, 1.0)


def test_a_planner_to_the_end_learns_the_steps_left_from_the_env_and_reports_what_it_rolled_out():
    """Through ``evaluate``: the env's clock gives the planner its steps left, the horizon shrinks over the episode's
    last steps, and the compute reported is the body-steps rolled out (the first step's extra refinements included)."""
    from agents.evaluate import run_episodes

    compute: dict = {}
    small = {"samples": 4, "horizon": 10, "knots": 4, "initial_iterations": 2}
    records = run_episodes(
        "planner", episodes=1, seed=10000, env_id="FlatBodyAnyBody-v1", compute=compute, planner=small
    )
    steps = compute["episode_steps"]
    assert records[0]["length"] == steps == 400  # the whole episode (none ends early here)
    rolled = 4 * 10 * 2 + sum(4 * min(10, 400 - k) for k in range(1, steps))
    assert compute["body_steps_per_step"] == round(rolled / steps)
    assert compute["settings"]["to_end"] and "to the episode's end" in compute["label"]


def test_the_planner_row_names_the_law_its_plans_perturb():
    """Every prior by the name its baseline row has (the reference table names the planner from its settings)."""
    from agents.planner import PRIOR_LAWS, PlannerSettings, label

    names = {prior: label(PlannerSettings(prior=prior)) for prior in PRIOR_LAWS}
    assert names["pumping"] == "planner (MPPI around the LQR with pumping, true model)"
    assert names["lqr"] == "planner (MPPI around the LQR, true model)"
    assert names["none"] == "planner (MPPI over open-loop plans, true model)"
    assert len(set(names.values())) == len(PRIOR_LAWS)


def test_without_warm_start_the_planners_action_is_a_function_of_the_observation():
    """``warm_start=False``: the plan found at one step does not carry to the next, so with the same noise the action
    in a state is the same whatever came before; with the warm start (the default) the earlier plan changes it."""
    from agents.planner import Planner, PlannerSettings, label
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    kw = env_kwargs_for("FlatBody-v1")
    env = FlatBodyVectorEnv(2, **kw)
    obs, _ = env.reset(seed=[10000, 10001])
    before, _, _, _, _ = env.step(np.full((2, env.single_action_space.shape[0]), 0.5, dtype=np.float32))
    for warm in (False, True):
        settings = PlannerSettings(samples=8, horizon=10, prior="none", warm_start=warm)
        fresh, primed = Planner(kw, 2, settings, seed=3), Planner(kw, 2, settings, seed=3)
        primed.act(before)  # a step before: its plan warm-starts the next only with warm_start
        primed.rng = np.random.default_rng(3)  # the same noise for the step compared
        a, b = fresh.act(obs), primed.act(obs)
        assert np.array_equal(a, b) != warm, warm
    assert label(settings) == "planner (MPPI over open-loop plans, true model)"
    assert label(PlannerSettings(warm_start=False)) == "planner (MPPI over open-loop plans, no warm start, true model)"


def test_a_horizon_to_the_episodes_end_scores_each_plan_on_its_own_remaining_steps():
    """``to_end``: an episode with h steps left is rolled out h steps and its terminal weight falls on the h-th state —
    the same returns, candidate for candidate, as a fixed horizon of h (the first h steps of the same candidates), for
    two episodes with different steps left planned together; and only as many body-steps are rolled out."""
    from agents.planner import Planner, PlannerSettings
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    kw = env_kwargs_for("FlatBodyTorque-v1")
    env = FlatBodyVectorEnv(2, **kw)
    obs, _ = env.reset(seed=[10000, 10001])
    from flatbody_env.env.task import state_from_observation

    y, t = state_from_observation(obs.astype(np.float64))
    common = {"samples": 4, "prior": "pumping", "terminal": 50.0}
    cand = np.random.default_rng(1).uniform(-0.5, 0.5, (2, 4, 12, env.single_action_space.shape[0]))
    to_end = Planner(kw, 2, PlannerSettings(horizon=12, to_end=True, **common))
    to_end._obs = obs
    got = to_end._rollout(y, t, None, cand, np.array([7, 3]))
    assert to_end.body_steps == 2 * 4 * 7  # the batch runs to the longer of the two ends
    for b, h in ((0, 7), (1, 3)):
        fixed = Planner(kw, 2, PlannerSettings(horizon=h, **common))
        fixed._obs = obs
        want = fixed._rollout(y, t, None, np.ascontiguousarray(cand[:, :, :h]), np.array([h, h]))
        np.testing.assert_array_equal(got[b], want[b])
    assert not np.array_equal(got[1], to_end._rollout(y, t, None, cand, np.array([7, 7]))[1])


def test_a_plan_to_the_end_refines_first_and_needs_the_steps_left():
    """``initial_iterations`` refinements at the first step after a reset, ``iterations`` later; the horizon shrinks
    with the steps left; ``to_end`` without ``steps_left`` is one ValueError naming it."""
    from agents.planner import Planner, PlannerSettings, label
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    kw = env_kwargs_for("FlatBodyTorque-v1")
    env = FlatBodyVectorEnv(1, **kw)
    obs, _ = env.reset(seed=10000)
    settings = PlannerSettings(samples=4, horizon=10, to_end=True, initial_iterations=3, prior="pumping")
    planner = Planner(kw, 1, settings)
    counts = []
    for left in (10, 9, 4, 0):  # 0: just truncated, before the autoreset (one step rolled out)
        before = planner.body_steps
        planner.act(obs, None, np.array([left]))
        counts.append(planner.body_steps - before)
    assert counts == [3 * 4 * 10, 4 * 9, 4 * 4, 4 * 1]
    planner.reset()
    before = planner.body_steps
    planner.act(obs, None, np.array([10]))
    assert planner.body_steps - before == 3 * 4 * 10
    for bad in (None, np.array([-1]), np.array([1.5]), np.array([3, 3])):
        with pytest.raises(ValueError, match="^steps_left"):
            planner.act(obs, None, bad)
    assert label(settings) == "planner (MPPI around the LQR with pumping, to the episode's end, true model)"


@pytest.mark.slow
def test_the_planner_holds_more_unstable_starts_than_the_passivity_law_it_perturbs():
    from agents.evaluate import run_episodes

    planner = run_episodes("planner", episodes=20, seed=10000, env_id="FlatBodyHoldUnstable-v1")
    law = run_episodes("passivity", episodes=20, seed=10000, env_id="FlatBodyHoldUnstable-v1")
    assert sum(r["success"] for r in planner) > sum(r["success"] for r in law)


def test_planner_settings_are_checked():
    from agents.planner import PlannerSettings

    for kw, field in (
        ({"samples": 1}, "samples"),
        ({"noise": -1.0}, "noise"),
        ({"prior": "pid"}, "prior"),
        ({"noise_floor": float("nan")}, "noise_floor"),
        ({"noise_distance": 0.0}, "noise_distance"),
        ({"warm_start": "no"}, "warm_start"),
        ({"to_end": 1}, "to_end"),
        ({"initial_iterations": -1}, "initial_iterations"),
        ({"initial_iterations": 65}, "initial_iterations"),
    ):
        with pytest.raises(ValueError, match=f"^{field}"):
            PlannerSettings(**kw)


def test_planner_overrides_are_typed_and_checked_before_anything_runs():
    from agents.planner import parse_overrides, settings_for

    got = parse_overrides(["samples=256", "horizon=160", "noise=0.6", "prior=none"])
    assert got == {"samples": 256, "horizon": 160, "noise": 0.6, "prior": "none"}
    assert parse_overrides(["warm_start=false"]) == {"warm_start": False}
    assert parse_overrides(["warm_start=True"]) == {"warm_start": True}
    s = settings_for("FlatBodyTorque-v1", got)
    assert (s.samples, s.horizon, s.noise, s.prior, s.knots) == (256, 160, 0.6, "none", 8)  # knots: the task's own
    assert settings_for("FlatBody-v1", {"samples": 8}).prior == "lqr"  # the task's own law stays unless overridden
    slow = settings_for("FlatBodySlowHard-v1", {"samples": 8})  # the slow-target planner: the pumping law, 6 s ahead
    assert (slow.samples, slow.prior, slow.horizon, slow.knots, slow.terminal) == (8, "pumping", 120, 8, 200.0)
    assert slow.body_steps == 2 * settings_for("FlatBody-v1", {"samples": 8}).body_steps
    for bad, match in (
        (["x=1"], "^--planner: must be KEY=VALUE with KEY one of samples, horizon"),
        (["samples"], "^--planner: must be KEY=VALUE"),
        (["samples=many"], "^--planner.samples: must be an integer, got 'many'"),
        (["horizon=1.5"], "^--planner.horizon: must be an integer"),
        (["samples=1"], r"^--planner.samples: must be an integer \(allowed range \[2, 4096\]\)"),
        (["noise=inf"], "^--planner.noise: must"),
        (["prior=pid"], "^--planner.prior: must be one of none, lqr, passivity"),
        (["warm_start=1"], "^--planner.warm_start: must be true or false, got 1"),
        (["warm_start=maybe"], "^--planner.warm_start: must be true or false"),
    ):
        with pytest.raises(ValueError, match=match):
            parse_overrides(bad, "--planner")


def test_a_task_report_runs_only_the_named_baselines_and_the_planner_as_overridden():
    from agents.evaluate import evaluate_task

    report = evaluate_task(
        "FlatBodyTorque-v1",
        episodes=2,
        seed=10000,
        with_agents=False,
        only=("planner",),
        planner={"samples": 6, "horizon": 5, "knots": 3},
    )
    assert list(report["policies"]) == ["planner"]
    compute = report["policies"]["planner"]["summary"]["compute"]
    assert compute["body_steps_per_step"] == 6 * 5
    assert compute["settings"]["samples"] == 6 and compute["settings"]["prior"] == "pumping"  # the task's own law
    with pytest.raises(
        ValueError, match="^baselines: must be one of zero, random, heuristic, passivity, pumping, planner, got"
    ):
        evaluate_task("FlatBody-v1", episodes=1, only=("witness",), with_agents=False)


def test_evaluate_refuses_planner_flags_in_one_line(capsys):
    from flatbody_env.cli.main import main

    for argv, text in (
        (["evaluate", "--planner", "samples=8"], "--planner: must go with --env"),
        (["evaluate", "--env", "FlatBody-v1", "--planner", "samples=1"], "--planner.samples: must be an integer"),
        (["evaluate", "--env", "FlatBody-v1", "--baselines", "witness"], "--baselines: must be one of"),
        (["evaluate", "--env", "FlatBody-v1", "--baselines", "lqr"], "--baselines: expected names from"),
    ):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse's own refusals (a --baselines name no task has)
            code = exc.code
        assert code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and text in err[0], err


def test_a_variant_of_a_task_runs_every_policy_on_it_and_says_so():
    """``--env-kwargs``: the baselines, the targets and the planner's model run on the changed task; the report records
    what changed."""
    from agents.evaluate import evaluate_task

    small = {"samples": 4, "horizon": 3, "knots": 2}
    kw = dict(episodes=2, seed=10000, with_agents=False, only=("zero", "planner"), planner=small)
    plain = evaluate_task("FlatBody-v1", **kw)
    longer = evaluate_task("FlatBody-v1", env_kwargs={"dt": 0.1}, **kw)  # 400 steps of 0.1: twice the time
    assert "variant" not in plain and longer["variant"] == {"dt": 0.1} and longer["env_kwargs"]["dt"] == 0.1
    assert longer["env_kwargs"]["task"] == plain["env_kwargs"]["task"]  # the registered keywords, one changed
    for name in ("zero", "planner"):
        a, b = (r["policies"][name]["episodes"]["final_distance"] for r in (plain, longer))
        assert a != b, name  # the same starts, stepped otherwise
    observed = evaluate_task("FlatBodyAnyBody-v1", env_kwargs={"observe_body": True}, **kw)
    assert observed["policies"]["planner"]["summary"]["episodes"] == 2


def test_evaluate_refuses_a_bad_variant_in_one_line(capsys, tmp_path):
    from flatbody_env.cli.main import main

    run = ["evaluate", "--env", "FlatBody-v1", "--episodes", "1", "--baselines", "zero", "--env-kwargs"]
    for argv, text in (
        (["evaluate", "--env-kwargs", "dt=0.1"], "--env-kwargs: must go with --env"),
        ([*run, "bogus=1"], "--env-kwargs.bogus: not a keyword of FlatBodyEnv"),
        ([*run, "dt=-1"], "--env-kwargs.dt: must lie in"),
        ([*run, "dt"], "--env-kwargs: must be KEY=VALUE"),
        ([*run, "dt=[1"], "--env-kwargs.dt:"),
        ([*run, "dt=0.1", "--out-dir", str(tmp_path / "ref")], "--env-kwargs: must not go with --out-dir"),
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and text in err[0], err
    assert not (tmp_path / "ref").exists()


# --------------------------------------------------------------------------------------------- scores
def _report(env_id, **success):
    return {"env_id": env_id, "policies": {k: {"summary": {"success_rate": v}} for k, v in success.items()}}


def test_anchors_follow_the_documented_rule():
    from agents.scores import anchors

    torque = anchors(
        _report("FlatBodyTorque-v1", zero=0.0, random=0.0, passivity=0.01, heuristic=0.03, planner=0.0, witness=1.0)
    )
    assert (torque.lo, torque.lo_from, torque.hi) == (0.03, "heuristic", 1.0) and "witness" in torque.hi_from
    hold = anchors(_report("FlatBodyHoldUnstable-v1", zero=0.0, random=0.0, passivity=0.8, heuristic=0.7, planner=0.9))
    assert (hold.lo, hold.hi, hold.hi_from) == (0.8, 0.9, "planner")
    assert hold.normalise(0.85) == pytest.approx(0.5) and hold.normalise(0.8) == pytest.approx(0.0)
    slow = anchors(_report("FlatBodySlowHard-v1", zero=0.0, random=0.0, passivity=0.15, heuristic=0.64, planner=0.6))
    assert (slow.lo, slow.hi) == (0.64, 1.0) and "ideal" in slow.hi_from
    easy = anchors(_report("FlatBody-v1", zero=0.0, random=0.0, passivity=0.28, heuristic=1.0, planner=0.5))
    assert (easy.lo, easy.lo_from, easy.hi) == (0.0, "zero", 1.0)  # a classic law solves it: anchored on zero


def test_iqm_is_the_mean_of_the_middle_half_with_a_stratified_bootstrap_interval():
    from agents.scores import iqm

    rng = np.random.default_rng(3)
    scores = rng.uniform(0, 1, (8, 5))
    q = iqm(scores, reps=500)
    flat = np.sort(scores.ravel())
    assert q["iqm"] == pytest.approx(flat[10:30].mean())  # 40 scores: drop 10 at each end
    assert q["lo"] < q["iqm"] < q["hi"] and (q["runs"], q["tasks"]) == (8, 5)
    same = iqm(np.full((4, 3), 0.7), reps=200)
    assert same["iqm"] == pytest.approx(0.7) and same["lo"] == pytest.approx(0.7) and same["hi"] == pytest.approx(0.7)
    one = iqm(scores[:1])
    assert one["lo"] == one["iqm"] == one["hi"]
    # stratified: each task keeps its own runs — a task that is constant across runs adds no spread
    wide = np.column_stack([rng.uniform(0, 1, 8), np.full(8, 0.5)])
    assert iqm(wide, reps=500)["hi"] - iqm(wide, reps=500)["lo"] > 0
    with pytest.raises(ValueError, match="^scores"):
        iqm(np.array([[np.nan]]))


def test_the_planner_and_the_policies_compute_with_the_c_librarys_functions():
    """The planner's weights and objective and the exported policy's ELU call flatbody_env.integrators.libm, not
    NumPy's ufuncs (which differ in the last bit on AVX-512 machines)."""
    import inspect
    import math

    from agents import numpy_policy, planner

    src = inspect.getsource(planner)
    assert "libm.exp(" in src and "libm.log(" in src and "np.exp(" not in src and "np.log(" not in src
    elu = numpy_policy._ACTIVATION_FUNCTIONS["elu"]
    v = np.linspace(-3.0, 3.0, 101)
    assert elu(v).tobytes() == np.array([x if x > 0 else math.expm1(x) for x in v]).tobytes()

"""Plan, then imitate (agents/imitation.py) and fine-tuning (``train(trained_agent=...)``): the plans are
what the environment does under them, the clone fits them, the fine-tuned run starts from the given weights."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

import flatbody_env  # noqa: F401  (registers the tasks)
from agents.evaluate import MODELS_DIR, Agent
from agents.imitation import EFFORT_COST, REACH_COST, Plans, PlanSettings, clone, plan
from flatbody_env.cli.main import main as flatbody

SLOW = MODELS_DIR / "ppo-FlatBodySlow-v0"
SMALL = PlanSettings(samples=8, iterations=4, elite=2, chunk=2, knots=4)


@pytest.mark.parametrize(
    "field, value",
    [
        ("knots", 0),
        ("samples", 1),
        ("elite", 9),
        ("init_std", -1.0),
        ("reach", float("nan")),
        ("iterations", 0),
        ("chunk", 0),
        ("seed", -1),
    ],
)
def test_plan_settings_refuse_bad_values_naming_the_field(field, value):
    kwargs = {"samples": 8, field: value}
    with pytest.raises(ValueError, match=field):
        PlanSettings(**kwargs)


@pytest.mark.parametrize("on_policy", [False, True])
def test_plans_are_what_the_single_environment_does_under_them(on_policy):
    """The batch search's recorded final distance of each best plan equals an independent replay: one
    gym.make env of the task, the agent's own residual form (LQR + gated residual; with ``on_policy`` the
    plan corrects the agent's policy) stepped by hand."""
    import gymnasium as gym

    plans = plan(SLOW, [3, 4], SMALL, on_policy=on_policy, progress=False)
    assert plans.knots.shape == (2, 4, 4) and plans.env_id == "FlatBodySlow-v0" and plans.on_policy == on_policy
    agent = Agent(SLOW)
    env = gym.make("FlatBodySlow-v0")
    for seed, knots, recorded in zip(plans.seeds, plans.knots, plans.final_distance):
        obs, info = env.reset(seed=int(seed))
        for t in range(400):
            u = knots[t * 4 // 400][None, :]
            if on_policy:
                u = np.clip(agent.policy_actions(obs[None, :]) + u, -1, 1)
            obs, _, term, trunc, info = env.step(agent.residual_action(obs[None, :], u)[0])
            if term or trunc:
                break
        assert t == 399 and trunc
        assert info["distance"] == pytest.approx(recorded, rel=1e-9, abs=1e-12)


def test_plan_never_costs_more_than_the_lqr_alone():
    """The LQR alone (the zero residual) is in the first draw and the best plan is kept, so the best plan's
    cost is at most the LQR's; on a target the LQR misses, the search moves the final distance."""
    from agents.imitation import _residual_agent, rollout
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    agent = _residual_agent(SLOW)
    seeds = np.array([0, 2])
    venv = FlatBodyVectorEnv(num_envs=2, autoreset_mode="SameStep", **agent.env_kwargs)
    lqr_d, _, _ = rollout(venv, agent.residual_action, seeds, np.zeros((2, 4, 4)))
    plans = plan(SLOW, seeds, PlanSettings(samples=16, iterations=6, elite=4, chunk=2, knots=4), progress=False)
    d_best, effort_best, _ = rollout(venv, agent.residual_action, plans.seeds, plans.knots)
    cost = REACH_COST * np.maximum(d_best - 0.02, 0) + EFFORT_COST * effort_best
    assert np.all(cost <= REACH_COST * np.maximum(lqr_d - 0.02, 0) + 1e-12)
    missed = lqr_d > 0.05
    assert missed.any(), lqr_d  # seed 0 or 2: a target the LQR misses (the test needs one)
    assert np.all(d_best[missed] < lqr_d[missed])


def test_plans_round_trip_without_pickles_and_refuse_other_files(tmp_path):
    p = Plans(
        env_id="FlatBodySlow-v0",
        model="m",
        seeds=np.array([1, 2]),
        final_distance=np.array([0.01, 0.2]),
        knots=np.zeros((2, 3, 4)),
    )
    p.save(tmp_path / "p.npz")
    q = Plans.load(tmp_path / "p.npz")
    assert q.env_id == p.env_id and np.array_equal(q.seeds, p.seeds) and np.array_equal(q.knots, p.knots)
    assert (p + q).seeds.tolist() == [1, 2, 1, 2]
    np.save(tmp_path / "obj.npy", np.array([object()], dtype=object))
    (tmp_path / "bad.npz").write_bytes((tmp_path / "obj.npy").read_bytes())
    with pytest.raises(ValueError, match="plans"):
        Plans.load(tmp_path / "bad.npz")
    with pytest.raises(ValueError, match="plans"):
        p + Plans(env_id="FlatBody-v0", model="m", seeds=p.seeds, final_distance=p.final_distance, knots=p.knots)


def test_clone_fits_the_plans_and_writes_a_run_that_loads(tmp_path):
    plans = plan(SLOW, [0, 1], SMALL, progress=False)
    plans = Plans(
        env_id=plans.env_id, model=plans.model, seeds=plans.seeds, final_distance=np.zeros(2), knots=plans.knots
    )  # clone both
    res = clone(plans, SLOW, tmp_path / "bc", epochs=3, progress=False)
    assert res["plans"] == 2 and res["pairs"] == 800
    assert res["mse_end"] < res["mse_start"]
    agent = Agent(tmp_path / "bc", backend="sb3")
    assert agent.env_id == "FlatBodySlow-v0" and agent.residual_action.mode == "additive"
    with pytest.raises(ValueError, match="out|holds"):
        clone(plans, SLOW, tmp_path / "bc", epochs=1, progress=False)  # an existing run is not overwritten
    plans.save(tmp_path / "p.npz")  # the command: the one run folder, the plans and the start run as its prior
    argv = ["imitate", "clone", "--plans", str(tmp_path / "p.npz"), "--model", str(SLOW), "--epochs", "2"]
    assert flatbody([*argv, "--out", str(tmp_path / "bc-cli"), "--no-progress"]) == 0
    assert {"config.yml", "run.json", "progress.csv", "model.zip", "vecnormalize.pkl", "policy.npz"} <= {
        p.name for p in (tmp_path / "bc-cli").iterdir()
    }
    prior = yaml.safe_load((tmp_path / "bc-cli" / "config.yml").read_text())["prior"]
    assert prior["trained_agent"] == str(SLOW) and prior["imitation"]["plans"] == [str(tmp_path / "p.npz")]
    assert len((tmp_path / "bc-cli" / "progress.csv").read_text().splitlines()) == 3  # header, two epochs
    with pytest.raises(ValueError, match="plans"):
        clone(
            Plans(
                env_id="FlatBody-v0",
                model="m",
                seeds=plans.seeds,
                final_distance=plans.final_distance,
                knots=plans.knots,
            ),
            SLOW,
            tmp_path / "x",
            progress=False,
        )


def test_command_refuses_bad_input_with_one_line(tmp_path, capsys):
    assert (
        flatbody(
            [
                "imitate",
                "plan",
                "--model",
                str(MODELS_DIR / "ppo-FlatBodyHoldUnstable-v0"),
                "--seeds",
                "0:2",
                "--out",
                str(tmp_path / "p.npz"),
            ]
        )
        == 2
    )
    assert "additive" in capsys.readouterr().err  # a gain-mode residual agent cannot execute an additive plan
    with pytest.raises(SystemExit):
        flatbody(["imitate", "plan", "--model", str(SLOW), "--seeds", "5:2", "--out", str(tmp_path / "p.npz")])
    argv = ["imitate", "plan", "--model", str(SLOW), "--seeds", "0:2", "--out", str(tmp_path / "p.npz")]
    with pytest.raises(SystemExit):  # the shared argument types: one line naming samples
        flatbody([*argv, "--samples", "1"])
    assert "samples" in capsys.readouterr().err
    assert flatbody([*argv, "--elite", "100"]) == 2  # more elite plans than samples: the settings' own check
    assert "elite" in capsys.readouterr().err


def test_fine_tuning_starts_from_the_given_run(tmp_path):
    """train(trained_agent=RUN): the network is RUN's (not the YAML's), config.yml names RUN, and a run
    without model.zip is refused naming the argument."""
    import yaml

    from agents.evaluate import Agent as A
    from agents.train import train

    tiny = ["n_envs=2", "n_steps=16", "batch_size=32", "n_epochs=1", "policy_kwargs.net_arch=[8]"]
    train("ppo", tmp_path / "a", n_timesteps=32, overrides=tiny, progress=False, checkpoint_freq=0, notes=False)
    train(
        "ppo",
        tmp_path / "b",
        n_timesteps=32,
        overrides=tiny[:4],
        progress=False,
        checkpoint_freq=0,
        notes=False,
        trained_agent=tmp_path / "a",
    )
    cfg = yaml.safe_load((tmp_path / "b" / "config.yml").read_text())
    assert cfg["prior"]["trained_agent"] == str(tmp_path / "a")
    net = A(tmp_path / "b", backend="sb3").model.policy.mlp_extractor.policy_net
    assert [m.out_features for m in net if hasattr(m, "out_features")] == [8]  # the loaded run's, not the YAML's 64x64
    with pytest.raises(ValueError, match="trained_agent"):
        train(
            "ppo",
            tmp_path / "c",
            n_timesteps=32,
            overrides=tiny,
            progress=False,
            checkpoint_freq=0,
            notes=False,
            trained_agent=tmp_path / "nothing",
        )


def test_fine_tuning_keeps_the_trained_agents_policy_form(tmp_path):
    """A fine-tuning run takes the trained agent's network, statistics and residual form (its weights act as they were
    trained): its config.yml says so without an override; an override that changes one of them, another algorithm
    and rsl-ppo are refused naming the field, before anything is written."""
    import yaml

    from agents.config import POLICY_FORM
    from agents.train import train

    tiny = ["n_envs=2", "n_steps=16", "batch_size=32", "n_epochs=1"]
    form = ["policy_kwargs.net_arch=[8]", "residual=heuristic", "residual_mode=additive", "residual_scale=0.3"]
    kw = dict(n_timesteps=32, progress=False, checkpoint_freq=0, notes=False)
    train("ppo", tmp_path / "a", overrides=tiny + form, **kw)
    train("ppo", tmp_path / "b", overrides=[*tiny, "learning_rate=1e-4"], trained_agent=tmp_path / "a", **kw)
    a, b = (yaml.safe_load((tmp_path / n / "config.yml").read_text())["hyperparams"] for n in "ab")
    assert b["residual"] == "heuristic" and b["residual_scale"] == 0.3 and b["policy_kwargs"]["net_arch"] == [8]
    assert all(a.get(k) == b.get(k) for k in POLICY_FORM) and b["learning_rate"] == 1e-4  # the run's own settings stay
    refusals = {
        "hyperparams.residual": dict(algo="ppo", overrides=[*tiny, "residual=passivity"]),
        "hyperparams.policy_kwargs": dict(algo="ppo", overrides=[*tiny, "policy_kwargs.net_arch=[16]"]),
        "is a ppo run": dict(algo="sac", overrides=["learning_starts=0"]),
    }
    for field, given in refusals.items():
        with pytest.raises(ValueError, match=field):
            train(given["algo"], tmp_path / "c", overrides=given["overrides"], trained_agent=tmp_path / "a", **kw)
        assert not (tmp_path / "c" / "config.yml").exists()
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "model.zip").write_bytes((tmp_path / "a" / "model.zip").read_bytes())
    for text in ("::: [", "format: 2\nalgo: 12\n"):  # a config.yml that is not a run's: one line naming the argument
        (bad / "config.yml").write_text(text)
        with pytest.raises(ValueError, match="^trained_agent: .*config.yml"):
            train("ppo", tmp_path / "c", overrides=tiny, trained_agent=bad, **kw)
        assert not (tmp_path / "c" / "config.yml").exists()
    with pytest.raises(ValueError, match="trained_agent: rsl-ppo does not fine-tune"):
        train("rsl-ppo", tmp_path / "d", n_timesteps=10**6, trained_agent=tmp_path / "a", progress=False, notes=False)


def test_clone_writes_through_the_one_door_full_disk_and_planted_links_are_one_line(tmp_path, monkeypatch, capsys):
    """clone's files go through the writing door: a full disk is one line naming the file (exit 1, no traceback, no
    temporary left, the folder not trusted), a link planted at one of its names is refused, never written through."""
    import errno
    import os

    from agents import numpy_policy as npp
    from flatbody_env import output

    monkeypatch.setenv("FLATBODY_CONFIG_HOME", str(tmp_path / "config"))
    plans = Plans(env_id="FlatBodySlow-v0", model=str(SLOW), seeds=np.array([0]), final_distance=np.zeros(1),
                  knots=np.zeros((1, 4, 4)))  # fmt: skip
    plans.save(tmp_path / "p.npz")
    argv = ["imitate", "clone", "--plans", str(tmp_path / "p.npz"), "--model", str(SLOW), "--epochs", "1", "--out"]

    def full(*args):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with monkeypatch.context() as m:
        m.setattr(output.os, "write", full)
        assert flatbody([*argv, str(tmp_path / "bc"), "--no-progress"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"flatbody imitate: I/O error: cannot write {str(tmp_path / 'bc' / 'config.yml')!r}: No space left on device"
    ]
    assert list((tmp_path / "bc").iterdir()) == [] and not npp.trusted(tmp_path / "bc")

    victim = tmp_path / "victim.pkl"
    victim.write_bytes(b"unchanged")
    (tmp_path / "bc2").mkdir()
    os.symlink(victim, tmp_path / "bc2" / "vecnormalize.pkl")
    assert flatbody([*argv, str(tmp_path / "bc2"), "--no-progress"]) == 1
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "vecnormalize.pkl" in line and "symbolic link" in line
    assert victim.read_bytes() == b"unchanged"


def test_fine_tuning_sets_the_exploration_and_warms_the_critic_up_with_the_actor_held(tmp_path):
    """``fine_tune_log_std`` sets every entry of the loaded policy's log std (its other weights unchanged);
    ``critic_warmup`` trains the value function alone over its first steps — the actor's weights leave the warm-up as
    they entered it, the critic's move — and the whole policy after it; the exploration setting without a trained
    agent is refused naming the field, before anything is written."""
    import torch

    from agents.train import actor_parameters, train

    tiny = ["n_envs=2", "n_steps=16", "batch_size=32", "n_epochs=2", "policy_kwargs.net_arch=[8]"]
    kw = dict(progress=False, checkpoint_freq=0, notes=False)
    train("ppo", tmp_path / "a", n_timesteps=32, overrides=tiny, **kw)

    def policy(name):
        return Agent(tmp_path / name, backend="sb3").model.policy

    def actor(p):
        return [q.detach().clone() for q in actor_parameters(p)]

    def critic(p):
        return [q.detach().clone() for q in [*p.mlp_extractor.value_net.parameters(), *p.value_net.parameters()]]

    a = policy("a")
    held = [*tiny[:4], "learning_rate=0.01", "fine_tune_log_std=-3.5", "critic_warmup=64"]
    train("ppo", tmp_path / "b", n_timesteps=64, overrides=held, trained_agent=tmp_path / "a", **kw)
    b = policy("b")
    assert torch.all(b.log_std == -3.5) and not torch.all(a.log_std == -3.5)
    assert all(torch.equal(x, y) for x, y in zip(actor(a)[:-1], actor(b)[:-1]))  # the actor held through the warm-up
    assert not all(torch.equal(x, y) for x, y in zip(critic(a), critic(b)))  # the critic learned
    assert all(q.requires_grad for q in actor_parameters(b))
    train("ppo", tmp_path / "c", n_timesteps=96, overrides=held, trained_agent=tmp_path / "a", **kw)
    c = policy("c")  # past the warm-up: the actor trains
    assert not all(torch.equal(x, y) for x, y in zip(actor(b)[:-1], actor(c)[:-1]))
    with pytest.raises(ValueError, match="^hyperparams.fine_tune_log_std: must come with a trained agent"):
        train("ppo", tmp_path / "d", n_timesteps=32, overrides=[*tiny, "fine_tune_log_std=-3"], **kw)
    assert not (tmp_path / "d" / "config.yml").exists()
    with pytest.raises(ValueError, match="^hyperparams.critic_warmup: unknown field"):
        train("sac", tmp_path / "e", n_timesteps=32, overrides=["critic_warmup=10"], **kw)

"""The batched reset (:class:`flatbody_env.env.sampling.EpisodeSampler`) draws what the task's Python
methods draw from the same generators, bit for bit, and leaves the generators where they would."""

import numpy as np
import pytest

from flatbody_env.env import compiled, sampling
from flatbody_env.env.env import FlatBodyEnv
from flatbody_env.env.sampling import EpisodeSampler
from flatbody_env.env.task import target_vector
from flatbody_env.physics.equilibria import stationary_from_shape


def _python_episode(env: FlatBodyEnv, seed: int):
    rng = np.random.default_rng(seed)
    target = env.task.sample_target(rng, env.body, limits=env.limits, control=env.control)
    y = env.task.sample_initial_state(rng, target, env.control)
    return y, target, rng.random()


@pytest.mark.parametrize("kernels", [compiled, sampling], ids=["compiled", "python"])
@pytest.mark.parametrize("control", ["torque+dilatation", "torque", "dilatation"])
def test_sampler_draws_the_python_episodes_bit_for_bit(kernels, control):
    env = FlatBodyEnv(control=control)
    sampler = EpisodeSampler(env.task, env.body, env.limits, control, kernels)
    assert sampler.applies
    n = 300 if kernels is compiled else 40
    rngs = [np.random.default_rng(s) for s in range(n)]
    Y = np.full((11, n + 3), np.nan)
    cols = np.arange(n) + 3  # columns other than 0..n-1: the sampler writes where it is told
    TG = sampler.sample(rngs, Y, cols)
    for s in range(n):
        y, target, next_draw = _python_episode(env, s)
        np.testing.assert_array_equal(Y[:, cols[s]], y)
        np.testing.assert_array_equal(TG[s, :4], target_vector(target))
        assert TG[s, 4] == target.p_theta
        assert rngs[s].random() == next_draw  # the generator was left where the Python methods leave it
    assert np.isnan(Y[:, :3]).all()


def test_sampler_runs_the_exact_test_where_the_table_cannot_decide():
    """Mode 0 (every shape unsure) asks Python for the Riccati test of each stable candidate and runs
    the kernel again: the same episodes as the task without the table."""
    env = FlatBodyEnv()
    exact = FlatBodyEnv(settling_table=False)
    sampler = EpisodeSampler(env.task, env.body, env.limits, env.control, compiled)
    sampler.cfg[5] = 0.0
    rngs = [np.random.default_rng(s) for s in range(6)]
    Y = np.empty((11, 6))
    TG = sampler.sample(rngs, Y, np.arange(6))
    for s in range(6):
        y, target, next_draw = _python_episode(exact, s)
        np.testing.assert_array_equal(Y[:, s], y)
        np.testing.assert_array_equal(TG[s, :4], target_vector(target))
        assert rngs[s].random() == next_draw


def test_sampler_draws_more_after_a_long_run_of_rejections():
    """A high threshold that most shapes fail: some bodies need more than the block drawn ahead."""
    env = FlatBodyEnv(min_settling_rate=0.24)
    sampler = EpisodeSampler(env.task, env.body, env.limits, env.control, compiled)
    assert sampler.applies
    n = 40
    rngs = [np.random.default_rng(s) for s in range(n)]
    Y = np.empty((11, n))
    TG = sampler.sample(rngs, Y, np.arange(n))
    assert sampler.refills > 0, "the range should need more than one block for some seeds"
    for s in range(n):
        y, target, next_draw = _python_episode(env, s)
        np.testing.assert_array_equal(Y[:, s], y)
        np.testing.assert_array_equal(TG[s, :4], target_vector(target))
        assert rngs[s].random() == next_draw


def test_sampler_gives_up_like_the_task():
    env = FlatBodyEnv(min_settling_rate=5.0)  # no shape of the table's ranges settles that fast
    assert env.sampler.applies
    with pytest.raises(ValueError, match="target_lambda/target_aspect"):
        env.sampler.sample([np.random.default_rng(0)], np.empty((11, 1)), [0])
    with pytest.raises(ValueError, match="target_lambda/target_aspect"):
        env.reset(seed=0)
    outside = FlatBodyEnv(
        target_lambda=(1.25, 1.3), target_aspect=(1.3, 1.4), min_settling_rate=5.0
    )  # outside the table: Python path
    assert not outside.sampler.applies
    with pytest.raises(ValueError, match="target_lambda/target_aspect"):
        outside.reset(seed=0)


def test_single_env_reset_uses_the_sampler_and_builds_the_same_target():
    env = FlatBodyEnv()
    assert env.sampler.applies
    obs, info = env.reset(seed=5)
    y, target, _ = _python_episode(env, 5)
    np.testing.assert_array_equal(env.physics_state, y)
    t = stationary_from_shape(
        env.body, target.lam, target.mu, branch="circulation", sign=1.0 if target.s3 + target.p_theta > 0 else -1.0
    )
    assert env.target == {
        "lambda": t.lam,
        "mu": t.mu,
        "rho": t.rho,
        "s3": t.s3,
        "p_theta": t.p_theta,
        "omega3": t.omega3,
        "theta_dot": t.theta_dot,
        "energy": t.energy,
    }
    np.testing.assert_array_equal(env.target_vector, target_vector(target))


def test_a_sampled_start_outside_the_domain_names_the_noise():
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    env = FlatBodyEnv(initial_noise=3.0)  # offsets of e^±3 in the stretches leave [0.2, 4]
    with pytest.raises(ValueError, match="initial_noise: the initial state starts outside the domain"):
        for seed in range(50):
            env.reset(seed=seed)
    with pytest.raises(ValueError, match="initial_noise: the initial state starts outside the domain"):
        FlatBodyVectorEnv(num_envs=50, initial_noise=3.0).reset(seed=0)


@pytest.mark.parametrize("kernels", [compiled, sampling], ids=["compiled", "python"])
def test_sampler_pickles_with_the_kernels_it_was_handed(kernels):
    """The sampler is handed its kernels (sampling.py imports no module above it): pickled, it comes back with
    the same module, by name, and draws the same episodes."""
    import pickle

    env = FlatBodyEnv()
    sampler = EpisodeSampler(env.task, env.body, env.limits, env.control, kernels)
    clone = pickle.loads(pickle.dumps(sampler))
    assert clone.kernels is kernels
    Y1, Y2 = np.empty((11, 3)), np.empty((11, 3))
    a = sampler.sample([np.random.default_rng(s) for s in range(3)], Y1, [0, 1, 2])
    b = clone.sample([np.random.default_rng(s) for s in range(3)], Y2, [0, 1, 2])
    np.testing.assert_array_equal(Y1, Y2)
    np.testing.assert_array_equal(a, b)

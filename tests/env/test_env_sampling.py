"""The compiled draws' candidate kernel (:func:`flatbody_env.env.sampling.candidate_kernel`, what the v1 resets run)
makes the choices of the task's Python draws (``sample_target``, the v0 resets) on the same uniforms, bit for bit;
the v0 resets draw the task's Python episodes."""

import numpy as np
import pytest

from flatbody_env.env import sampling
from flatbody_env.env.env import FlatBodyEnv
from flatbody_env.env.sampling import MAX_ATTEMPTS, draw_config
from flatbody_env.env.targets import ACCEPT, EMPTY_KERNEL_ARRAYS, REJECT, UNSURE, shipped_table
from flatbody_env.env.task import target_vector
from flatbody_env.integrators.jit import retarget
from flatbody_env.physics.equilibria import stationary_from_shape

COMPILED = retarget(sampling.candidate_kernel)


def _python_episode(env: FlatBodyEnv, seed: int):
    rng = np.random.default_rng(seed)
    target = env.task.sample_target(rng, env.body, limits=env.limits, control=env.control)
    y = env.task.sample_initial_state(rng, target, env.control)
    return y, target, rng.random()


def _kernel_target(env: FlatBodyEnv, cfg: np.ndarray, seed: int, kernel):
    """``sample_target``'s loop on the candidate kernel: its three uniforms per candidate from the seed's generator;
    a shape the table cannot judge goes to the exact test (the Python draws' rule). Returns the candidate record
    (10,), the answers seen and the generator's next draw."""
    rng = np.random.default_rng(seed)
    table = shipped_table().kernel_arrays() if cfg[5] == 1.0 else EMPTY_KERNEL_ARRAYS
    P = np.ascontiguousarray(env.body.kernel_params(), dtype=np.float64)
    pot, code, cand = np.empty((7, 4)), np.zeros(1, np.int64), np.empty(10)
    seen = set()
    for _ in range(MAX_ATTEMPTS):
        u = rng.random(3)
        answer = kernel(u[0], u[1], u[2], cfg, P, pot, code, *table, cand)
        seen.add(int(answer))
        if answer == REJECT:
            continue
        if answer == UNSURE:
            target = stationary_from_shape(env.body, cand[0], cand[1], branch=env.task.target_branch, sign=cand[9])
            if not env.task.reachable(target, env.body, env.limits, env.control):
                continue
        return cand, seen, rng.random()
    raise AssertionError("no target")


@pytest.mark.parametrize("kernel", [COMPILED, sampling.candidate_kernel], ids=["compiled", "python"])
@pytest.mark.parametrize(
    "setting", ["torque+dilatation", "torque", "dilatation", "exact test", "hold"]
)  # the table, no filter (two controls), every stable shape to the exact test, the rotation branch's saddles
def test_the_candidate_kernel_chooses_the_python_draws_targets_bit_for_bit(kernel, setting):
    if setting == "hold":
        env = FlatBodyEnv(task="hold-unstable")
    else:
        env = FlatBodyEnv(control="torque+dilatation" if setting == "exact test" else setting)
    cfg = draw_config(env.task, env.body, env.limits, env.control)
    assert cfg is not None
    if setting == "exact test":
        cfg[5] = 0.0
    n = 300 if kernel is COMPILED and setting != "exact test" else 30
    answers = set()
    for s in range(n):
        rng = np.random.default_rng(s)
        target = env.task.sample_target(rng, env.body, limits=env.limits, control=env.control)
        cand, seen, next_draw = _kernel_target(env, cfg, s, kernel)
        answers |= seen
        np.testing.assert_array_equal(cand[:5], [target.lam, target.mu, target.rho, target.s3, target.p_theta])
        assert rng.random() == next_draw  # as many candidates drawn
    assert REJECT in answers and (UNSURE in answers) == (setting == "exact test")
    assert ACCEPT in answers or setting == "exact test"


def test_the_draws_give_up_with_the_task_s_message():
    env = FlatBodyEnv(min_settling_rate=5.0)  # no shape of the table's ranges settles that fast
    with pytest.raises(ValueError, match="target_lambda/target_aspect"):
        env.reset(seed=0)
    outside = FlatBodyEnv(
        target_lambda=(1.25, 1.3), target_aspect=(1.3, 1.4), min_settling_rate=5.0
    )  # outside the table: every shape to the exact test
    assert draw_config(outside.task, outside.body, outside.limits, outside.control) is None
    with pytest.raises(ValueError, match="target_lambda/target_aspect"):
        outside.reset(seed=0)


def test_single_env_reset_draws_the_python_episode_and_builds_its_target():
    env = FlatBodyEnv()
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

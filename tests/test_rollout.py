import numpy as np
import pytest
import torch

from paramimic.config import EnvConfig, HorizonGrowthConfig
from paramimic.envs import ParamEnv
from paramimic.rl.networks import ActorCritic
from paramimic.rl.rollout import RolloutWorker

TASK = {"left_leg_length": (0.8, 1.2), "right_leg_length": (0.8, 1.2)}


def _worker(seed=3, source=None):
    probe = ParamEnv("walker", TASK, config={"max_episode_seconds": 0.5})
    obs_dim, act_dim = probe.observation_space.shape[0], probe.action_space.shape[0]
    w = RolloutWorker(
        lambda: ParamEnv("walker", TASK, config={"max_episode_seconds": 0.5}),
        num_envs=3,
        obs_dim=obs_dim,
        act_dim=act_dim,
        seed=seed,
        task_source=source,
    )
    torch.manual_seed(seed)
    policy = ActorCritic(obs_dim, act_dim, (32, 32), init_log_std=-0.5)
    w.set_weights(policy.state_dict(), version=7)
    return w, policy, obs_dim, act_dim


def test_fragment_shapes_tasks_and_episodes():
    asked = []

    def source(n):
        asked.append(n)
        return np.tile([[0.9, 1.1]], (n, 1))

    w, policy, obs_dim, act_dim = _worker(source=source)
    f = w.collect(40)  # 0.5 s episodes are 15 steps: every env finishes twice
    assert f.obs.shape == (40, 3, obs_dim) and f.actions.shape == (40, 3, act_dim)
    for arr in (f.logp, f.values, f.next_values, f.rewards, f.dphi, f.terminated, f.truncated):
        assert arr.shape == (40, 3)
    assert f.policy_version == 7
    assert np.all(f.tasks == [0.9, 1.1])  # every episode took its task from the source
    assert asked[0] == 3 and sum(asked) == len(f.tasks)
    assert np.all(f.obs[:, :, :2] == np.float32([0.9, 1.1]))  # task indices line up with obs
    assert len(f.episodes) == int(f.terminated.sum() + f.truncated.sum())
    assert len({e.episode_id for e in f.episodes}) == len(f.episodes)
    for e in f.episodes:
        assert e.length <= 15 and e.ret > 0 and set(e.reward_terms) >= {"pose", "task"}
        assert e.ended_early == (e.fell or e.diverged)  # no stall or heading rule here
    assert sum(e.ended_early for e in f.episodes) == int(f.terminated.sum())
    assert 0 < sum(e.ended_early for e in f.episodes) < len(f.episodes)  # both kinds here
    # values and log-probs are the policy's own for the recorded observations and actions
    with torch.no_grad():
        mean, value = policy(torch.from_numpy(f.obs[5]))
        logp = policy.log_prob(mean, torch.from_numpy(f.actions[5]))
    np.testing.assert_allclose(f.values[5], value.numpy(), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(f.logp[5], logp.numpy(), rtol=1e-5, atol=1e-5)
    # next_values: V(s_{t+1}) inside an episode
    cont = ~(f.terminated[:-1] | f.truncated[:-1])
    np.testing.assert_array_equal(f.next_values[:-1][cont], f.values[1:][cont])


def test_same_seed_same_fragment():
    a = _worker(seed=11)[0].collect(20)
    b = _worker(seed=11)[0].collect(20)
    np.testing.assert_array_equal(a.obs, b.obs)
    np.testing.assert_array_equal(a.actions, b.actions)
    np.testing.assert_array_equal(a.tasks, b.tasks)


def test_horizon_growth_sets_the_training_time_limit_by_policy_version():
    """env.horizon_growth: the limit goes linearly from start_seconds to the env's own over
    `samples` env steps, one policy version counting ppo.num_steps of them; evaluation is
    without it."""
    growth = HorizonGrowthConfig(start_seconds=0.2, samples=1000)
    assert growth.seconds(0, 1.0) == 0.2
    assert growth.seconds(500, 1.0) == pytest.approx(0.6)
    assert growth.seconds(5000, 1.0) == 1.0
    cfg = {"max_episode_seconds": 1.0}
    probe = ParamEnv("walker", TASK, config=cfg)
    assert probe.horizon_seconds == pytest.approx(1.0)
    w = RolloutWorker(
        lambda: ParamEnv("walker", TASK, config=cfg),
        num_envs=2,
        obs_dim=probe.observation_space.shape[0],
        act_dim=probe.action_space.shape[0],
        seed=0,
        horizon=(growth, 100),  # a version stands for 100 env steps
    )
    policy = ActorCritic(probe.observation_space.shape[0], probe.action_space.shape[0], (16,), -2.0)
    lengths = {}
    for version in (0, 5, 10):  # 0.2 s, 0.6 s, 1.0 s: 6, 18 and 30 control steps at 30 Hz
        w.set_weights(policy.state_dict(), version)
        f = w.collect(100)
        lengths[version] = {e.length for e in f.episodes[1:] if not e.ended_early}
    assert lengths[0] == {6} and lengths[5] == {18} and lengths[10] == {30}
    assert EnvConfig(horizon_growth={"samples": 10}).for_evaluation().horizon_growth is None

import numpy as np
import pytest

from paramimic.curriculum.marginal_value import MarginalValue
from paramimic.rl.networks import RunningMeanStd
from paramimic.task_space import TaskSpace

SPACE = TaskSpace.from_ranges({"left": (0.7, 1.3), "right": (0.7, 1.3), "v": (1.0, 1.0)})


def test_marginal_value_regresses_values_on_task_parameters():
    rng = np.random.default_rng(0)
    a = SPACE.sample(rng, 4000)
    # a known V̄: asymmetric legs are harder, plus state noise that V̄ marginalizes out
    v = 12.0 - 20.0 * np.abs(a[:, 0] - a[:, 1]) + rng.normal(0, 1.0, len(a))
    mv = MarginalValue(SPACE, hidden=(64, 64), lr=3e-3, mu_lr=1e-3, batch_size=128, seed=0)
    mv.fit(a, v, steps=3000)
    test = np.array([[1.0, 1.0, 1.0], [0.7, 1.3, 1.0], [1.3, 0.7, 1.0]])
    np.testing.assert_allclose(mv.predict(test), [12.0, 0.0, 0.0], atol=1.0)
    # μ ← μ − α_μ (μ − mean v): starts at the first batch's mean and stays at the average
    assert mv.mu == pytest.approx(v.mean(), abs=0.3)
    clone = MarginalValue(SPACE, seed=5)
    clone.from_state(mv.to_state())
    np.testing.assert_array_equal(clone.predict(test), mv.predict(test))
    assert clone.mu == mv.mu


def test_running_mean_std_matches_batch_statistics():
    rng = np.random.default_rng(1)
    x = rng.normal(3.0, 2.0, (1000, 4))
    rms = RunningMeanStd(4)
    for chunk in np.array_split(x, 7):
        rms.update(chunk)
    np.testing.assert_allclose(rms.mean, x.mean(axis=0))
    np.testing.assert_allclose(rms.var, x.var(axis=0))
    assert rms.count == 1000


def test_numpy_policy_is_the_same_function_as_the_torch_one():
    import torch

    from paramimic.rl.networks import ActorCritic
    from paramimic.rl.numpy_mlp import NumpyPolicy

    torch.manual_seed(0)
    policy = ActorCritic(11, 3, (32, 32), init_log_std=-0.7, obs_clip=3.0)
    stats = RunningMeanStd(11)
    stats.update(np.random.default_rng(0).normal(2.0, 3.0, (100, 11)))
    policy.set_normalizer(stats)
    fast = NumpyPolicy(policy.numpy_weights())  # what a rollout actor gets, without torch
    assert fast.obs_clip == 3.0
    rng = np.random.default_rng(1)
    obs = rng.normal(0, 5, (7, 11)).astype(np.float32)
    noise = rng.standard_normal((7, 3))
    for n in (noise, None):
        for a, b in zip(policy.act(obs, n), fast.act(obs, n), strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(policy.value(obs), fast.value(obs), rtol=1e-5, atol=1e-5)

import numpy as np
import pytest
import torch

from paramimic.rl.ppo import ppo_loss


def test_clipped_loss_by_hand():
    # ratios e^{Δlogp}: [2.0, 0.5, 1.0]; advantages [1, 1, -1]; ε = 0.2
    # sample 0: min(2·1, 1.2·1) = 1.2 ; sample 1: min(0.5, 0.8) = 0.5 ; sample 2: min(-1, -1) = -1
    # policy loss = -(1.2 + 0.5 - 1)/3 = -0.7/3
    # value loss = ½ mean((V − R)²) with V − R = [1, -2, 0] → ½·5/3
    # total = -0.7/3 + 0.5·(5/6) − 0.01·1.5
    old = torch.zeros(3)
    new = torch.log(torch.tensor([2.0, 0.5, 1.0]))
    adv = torch.tensor([1.0, 1.0, -1.0])
    values = torch.tensor([1.0, 0.0, 3.0])
    returns = torch.tensor([0.0, 2.0, 3.0])
    loss, stats = ppo_loss(new, old, adv, values, returns, torch.tensor(1.5), 0.2, 0.5, 0.01)
    assert stats["policy_loss"] == pytest.approx(-0.7 / 3)
    assert stats["value_loss"] == pytest.approx(5 / 6)
    assert float(loss) == pytest.approx(-0.7 / 3 + 0.5 * 5 / 6 - 0.015, rel=1e-6)
    assert stats["clip_fraction"] == pytest.approx(2 / 3)


def _loss_with_advantage_one(new_logp):
    """The clipped surrogate of one sample: old log-prob 0, advantage 1, clip 0.2, no value or
    entropy terms."""
    z = torch.zeros(1)
    return ppo_loss(new_logp, z, torch.ones(1), z, z, torch.tensor(0.0), 0.2, 0.0, 0.0)


def test_gradient_vanishes_outside_the_clip_region():
    new = torch.tensor([np.log(2.0)], requires_grad=True)
    loss, _ = _loss_with_advantage_one(new)
    loss.backward()
    assert float(new.grad) == 0.0  # ratio 2 > 1.2 with A > 0: clipped, no push further
    new2 = torch.tensor([0.0], requires_grad=True)
    loss2, _ = _loss_with_advantage_one(new2)
    loss2.backward()
    assert float(new2.grad) == pytest.approx(-1.0)  # d(−ρA)/dlogp at ρ = 1


def _batch(rng: np.random.Generator, n: int = 256, obs_dim: int = 4, act_dim: int = 2):
    from paramimic.rl.ppo import Batch

    return Batch(
        obs=rng.standard_normal((n, obs_dim)),
        actions=rng.standard_normal((n, act_dim)),
        logp=np.full(n, -2.0),
        values=np.zeros(n),
        advantages=rng.standard_normal(n),
        returns=rng.standard_normal(n),
        tasks=np.zeros((n, 1)),
    )


def _learner(**ppo):
    from paramimic.config import PPOConfig
    from paramimic.rl.ppo import PPOLearner

    base = {"num_steps": 256, "minibatch_size": 64, "num_epochs": 2, "hidden_sizes": (16,)}
    cfg = PPOConfig(**(base | ppo))
    return PPOLearner(4, 2, cfg, seed=0)


def test_a_frozen_std_stays_where_it_was_set_and_the_rest_learns():
    learner = _learner(learn_std=False, init_log_std=float(np.log(0.2)))
    before = [p.detach().clone() for p in learner.policy.pi.parameters()]
    metrics = learner.update(_batch(np.random.default_rng(0)))
    assert metrics["std"] == pytest.approx(0.2)
    assert any(
        not torch.equal(a, b) for a, b in zip(before, learner.policy.pi.parameters(), strict=True)
    )
    learned = _learner()  # the default learns it
    assert learned.update(_batch(np.random.default_rng(0)))["std"] != pytest.approx(np.exp(-1.0))


def test_the_adaptive_step_size_shrinks_on_large_kl_and_survives_a_checkpoint():
    from paramimic.rl.ppo import LR_MIN

    learner = _learner(desired_kl=1e-6, policy_lr=1e-3)  # every minibatch moves "too far"
    metrics = learner.update(_batch(np.random.default_rng(1)))
    # 8 minibatch steps, each / 1.5 once its KL exceeds 2e-6 (the first one sees KL 0 → x 1.5)
    assert LR_MIN <= metrics["policy_lr"] < 1e-3 / 1.5**4
    restored = _learner(desired_kl=1e-6, policy_lr=1e-3)
    restored.load_state_dict(learner.state_dict())
    assert restored.policy_opt.param_groups[0]["lr"] == metrics["policy_lr"]
    fixed = _learner(policy_lr=1e-3)
    assert fixed.update(_batch(np.random.default_rng(1)))["policy_lr"] == 1e-3


def test_an_input_that_hardly_varied_is_not_blown_up_with_the_std_floored():
    # input 0 varied by 0.7 mm in training (the biped's torso on its ball joint), input 1 by 0.3
    rng = np.random.default_rng(0)
    obs = np.column_stack([0.25 + 7e-4 * rng.standard_normal(4096), rng.standard_normal(4096)])
    shifted = np.array([[0.255, 0.0]], np.float32)  # the torso 5 mm higher: a body 2 % taller
    normalized = {}
    for floor in (0.0, 0.02):
        learner = _learner(obs_std_floor=floor)
        learner.normalizer.update(np.column_stack([obs, np.zeros((4096, 2))]))
        learner.policy.set_normalizer(learner.normalizer)
        x = np.column_stack([shifted, np.zeros((1, 2), np.float32)])
        normalized[floor] = learner.policy.normalize(torch.from_numpy(x))[0].numpy()
        # the actors' numpy policy divides by the same std
        assert learner.weights()["obs_std"][0] == pytest.approx(max(7e-4, floor), rel=0.05)
    assert normalized[0.0][0] > 6.0  # 5 mm is ~7 sigma of the experience
    assert normalized[0.02][0] == pytest.approx(0.25, abs=0.03)  # 5 mm / 2 cm
    assert normalized[0.0][1] == pytest.approx(normalized[0.02][1])  # a varied input unchanged


def test_a_bfloat16_update_multiplies_in_bfloat16_and_moves_the_policy_as_float32_does():
    from paramimic.rl.ppo import native_bf16, update_dtype

    assert update_dtype("float32") == torch.float32
    assert update_dtype("bfloat16") == torch.bfloat16
    assert update_dtype("auto") == (torch.bfloat16 if native_bf16() else torch.float32)
    moved = {}
    for precision in ("float32", "bfloat16"):
        learner = _learner(update_precision=precision, hidden_sizes=(64, 64))
        x = torch.randn(8, 4)
        with learner._precision():
            mean, value = learner.policy(x)
        assert mean.dtype == value.dtype == getattr(torch, precision)
        before = torch.cat([p.detach().flatten().clone() for p in learner.policy.pi.parameters()])
        metrics = learner.update(_batch(np.random.default_rng(2)))
        after = torch.cat([p.detach().flatten() for p in learner.policy.pi.parameters()])
        assert metrics["skipped_steps"] == 0 and metrics["update_steps"] == 8
        assert next(learner.policy.parameters()).dtype == torch.float32  # weights stay float32
        moved[precision] = after - before
    cos = torch.nn.functional.cosine_similarity(moved["float32"], moved["bfloat16"], dim=0)
    assert cos > 0.95
    norms = moved["bfloat16"].norm() / moved["float32"].norm()
    assert norms == pytest.approx(1.0, abs=0.1)

import numpy as np
import pytest

from paramimic.rl.gae import compute_gae


def _loop_gae(r, s, v, nv, term, trunc, dphi, gamma, lam):
    """Plain Python loop over [L21] Eq. 9, one environment at a time."""
    T, B = r.shape
    adv = np.zeros((T, B))
    for b in range(B):
        a = 0.0
        for t in reversed(range(T)):
            g = gamma ** dphi[t, b]
            integral = (1 - g) / (1 - gamma)
            boot = 0.0 if term[t, b] else nv[t, b]
            delta = integral * r[t, b] + s[t, b] + g * boot - v[t, b]
            if term[t, b] or trunc[t, b]:
                a = 0.0
            a = delta + g * lam ** dphi[t, b] * a
            adv[t, b] = a
    return adv


def _random(seed, T=37, B=5):
    rng = np.random.default_rng(seed)
    r, s = rng.random((T, B)), rng.random((T, B)) * (rng.random((T, B)) < 0.1)
    v, nv = rng.random((T, B)), rng.random((T, B))
    term = rng.random((T, B)) < 0.05
    trunc = (rng.random((T, B)) < 0.05) & ~term
    dphi = np.exp(rng.normal(0, 0.3, (T, B)))
    return r, s, v, nv, term, trunc, dphi


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_matches_python_loop(seed):
    args = _random(seed)
    adv, ret = compute_gae(*args, gamma=0.95, gae_lambda=0.9)
    expected = _loop_gae(*args, 0.95, 0.9)
    np.testing.assert_allclose(adv, expected, rtol=1e-12)
    np.testing.assert_allclose(ret, expected + args[2], rtol=1e-12)


def test_unit_steps_equal_standard_gae():
    r, s, v, nv, term, trunc, _ = _random(3)
    s = np.zeros_like(s)
    adv, _ = compute_gae(r, s, v, nv, term, trunc, np.ones_like(r), 0.95, 0.95)
    # textbook GAE: δ = r + γ V' (1 - term) − V;  A = δ + γλ (1 - done) A'
    expected = np.zeros_like(r)
    a = np.zeros(r.shape[1])
    for t in reversed(range(len(r))):
        delta = r[t] + 0.95 * nv[t] * (1 - term[t]) - v[t]
        a = delta + 0.95 * 0.95 * (1 - (term[t] | trunc[t])) * a
        expected[t] = a
    np.testing.assert_allclose(adv, expected, rtol=1e-12)


def test_hand_worked_example():
    # Two steps of one env, γ = 0.5, λ = 1.
    # step 0: Δφ = 1, r = 1, V = 0.  step 1: Δφ = 2, r = 1, spike 2, V = 1, V(next) = 4.
    # step 1: γ^2 = 0.25, ∫ = (1 − 0.25)/(1 − 0.5) = 1.5
    #         δ1 = 1.5·1 + 2 + 0.25·4 − 1 = 3.5 ; A1 = 3.5
    # step 0: δ0 = 1·1 + 0.5·V1 − 0 = 1 + 0.5 = 1.5 ; A0 = 1.5 + 0.5·1·3.5 = 3.25
    r = np.array([[1.0], [1.0]])
    s = np.array([[0.0], [2.0]])
    v = np.array([[0.0], [1.0]])
    nv = np.array([[1.0], [4.0]])
    no = np.zeros((2, 1), bool)
    dphi = np.array([[1.0], [2.0]])
    adv, ret = compute_gae(r, s, v, nv, no, no, dphi, gamma=0.5, gae_lambda=1.0)
    np.testing.assert_allclose(adv[:, 0], [3.25, 3.5])
    np.testing.assert_allclose(ret[:, 0], [3.25, 4.5])


def test_splitting_a_step_keeps_the_discounted_reward():
    # [L21] Fig. 4: one step of Δφ = 2 collects as much as two unit steps of the same rate.
    gamma = 0.8
    one, _ = compute_gae(
        np.array([[1.0]]),
        np.zeros((1, 1)),
        np.zeros((1, 1)),
        np.zeros((1, 1)),
        np.ones((1, 1), bool),
        np.zeros((1, 1), bool),
        np.array([[2.0]]),
        gamma,
        1.0,
    )
    two, _ = compute_gae(
        np.ones((2, 1)),
        np.zeros((2, 1)),
        np.zeros((2, 1)),
        np.zeros((2, 1)),
        np.array([[False], [True]]),
        np.zeros((2, 1), bool),
        np.ones((2, 1)),
        gamma,
        1.0,
    )
    assert one[0, 0] == pytest.approx(two[0, 0])  # 1 + 0.8 = 1.8


def test_truncation_bootstraps_but_termination_does_not():
    r = np.zeros((1, 2))
    v = np.zeros((1, 2))
    nv = np.full((1, 2), 10.0)
    term = np.array([[True, False]])
    trunc = np.array([[False, True]])
    adv, _ = compute_gae(r, r, v, nv, term, trunc, np.ones((1, 2)), 0.9, 0.9)
    np.testing.assert_allclose(adv[0], [0.0, 9.0])

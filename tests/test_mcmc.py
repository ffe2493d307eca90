import numpy as np
import pytest
from scipy import stats

from paramimic.curriculum.mcmc import (
    AdaptiveSampler,
    concentration,
    metropolis_hastings,
    surrogate_log_density,
)
from paramimic.task_space import TaskSpace

SPACE = TaskSpace.from_ranges({"leg": (0.5, 1.5), "v": (1.0, 1.0)})


def v_bar(a):
    return 2.0 + 2.0 * np.asarray(a)[:, 0]  # known marginal value: longer legs are easier


def test_acceptance_ratio_by_hand():
    # V̄ = 3, 4 with μ = 4, k = 10: log P̄ = −10·(−1/4) = 2.5 and 0 → ᾱ(3→4) = e^{-2.5}
    lp = surrogate_log_density(np.array([3.0, 4.0]), mu=4.0, k=10.0)
    np.testing.assert_allclose(lp, [2.5, 0.0])


@pytest.mark.parametrize("k", [0.0, 2.0, 10.0])
def test_samples_follow_the_target_density(k):
    mu = 4.0
    rng = np.random.default_rng(7)
    samples = metropolis_hastings(
        lambda a: surrogate_log_density(v_bar(a), mu, k),
        SPACE,
        rng,
        n_samples=40_000,
        n_chains=200,
        burn_in=50,
    )
    assert samples.shape == (40_000, 2)
    assert np.all(samples[:, 1] == 1.0)  # a zero-width range stays fixed
    edges = np.linspace(0.5, 1.5, 11)
    observed, _ = np.histogram(samples[:, 0], bins=edges)
    # expected mass per bin of p(x) ∝ exp(−k(2 + 2x − μ)/μ), integrated exactly
    if k == 0:
        mass = np.diff(edges)
    else:
        c = 2.0 * k / mu
        mass = np.diff(-np.exp(-c * edges) / c)
    expected = mass / mass.sum() * len(samples)
    # MCMC samples are correlated; thin by 10 chain steps for the chi-square test
    chi2 = float(np.sum((observed - expected) ** 2 / expected)) / 10.0
    assert stats.chi2.sf(chi2, df=len(expected) - 1) > 0.01
    if k == 10.0:
        assert observed[0] > 5 * observed[-1]  # the poor (short legs) get far more samples


def test_k_zero_is_uniform_sampling_and_state_round_trips():
    sampler = AdaptiveSampler(SPACE, k=0.0, n_mcmc=5000, seed=1)
    sampler.refill(v_bar, mu=4.0)
    assert not sampler.adaptive
    hist, _ = np.histogram(sampler.buffer[:, 0], bins=5, range=(0.5, 1.5))
    assert stats.chisquare(hist).pvalue > 0.01
    adaptive = AdaptiveSampler(SPACE, k=10.0, n_mcmc=1000, seed=2)
    adaptive.refill(v_bar, mu=4.0)
    assert adaptive.adaptive
    clone = AdaptiveSampler(SPACE, k=1.0, seed=99)
    clone.from_state(adaptive.to_state())
    np.testing.assert_array_equal(clone.next_tasks(8), adaptive.next_tasks(8))
    assert clone.k == 10.0


def test_nonpositive_mu_falls_back_to_uniform():
    sampler = AdaptiveSampler(SPACE, k=10.0, n_mcmc=100, seed=0)
    sampler.refill(v_bar, mu=-1.0)
    assert not sampler.adaptive


def test_concentration_by_hand():
    """Half the box at V̄ = 0.5 μ, half at 1.5 μ: weights e^{k/2} and e^{-k/2}, so the effective
    share is (a + b)² / (2 (a² + b²)) and the lowest half holds a / (a + b) of the mass."""
    mu = 4.0
    v = np.array([0.5 * mu] * 500 + [1.5 * mu] * 500)
    for k in (0.0, 2.0, 10.0):
        a, b = np.exp(k / 2), np.exp(-k / 2)
        got = concentration(v, mu, k, low=0.5)
        assert got["effective_share"] == pytest.approx((a + b) ** 2 / (2 * (a * a + b * b)))
        assert got["low_mass"] == pytest.approx(a / (a + b))
    assert concentration(v, mu, 0.0)["effective_share"] == pytest.approx(1.0)
    assert concentration(v, mu, 0.0, low=0.5)["low_mass"] == pytest.approx(0.5)
    assert concentration(v, mu, 40.0)["effective_share"] < 0.51  # all on the low half

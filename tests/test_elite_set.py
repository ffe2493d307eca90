"""The elite set of [L21] §5.2 (Eq. 13): hand-worked cases, and its k-d tree against brute force."""

import numpy as np
import pytest

from paramimic.curriculum.elite_set import EliteRule, EliteSet


def test_enter_replace_and_dismiss_by_hand():
    e = EliteSet(2, rule=EliteRule(radius=0.1, threshold=0.1, improvement=0.02))
    assert not e.offer([0.0, 0.0], 0.1, "failed").accepted  # F must exceed the threshold 0.1
    first = e.offer([0.0, 0.0], 0.5, "a")
    assert first.accepted and first.replaced == [] and first.improved  # a new region counts
    # (0.06, 0.09): d² = 0.0036 + 0.0081 = 0.0117 >= r² = 0.01: not a neighbour, enters beside
    assert e.offer([0.06, 0.09], 0.3, "b").accepted and len(e) == 2
    # (0.05, 0.0) is within r of a (d² 0.0025) and of b (0.0001 + 0.0081 = 0.0082):
    # 0.45 beats b (0.3) but not a (0.5): dismissed
    assert not e.offer([0.05, 0.0], 0.45, "c").accepted
    # 0.51 beats both; by 0.01 over a (< 0.02 margin), so it does not count as an improvement
    d = e.offer([0.05, 0.0], 0.51, "d")
    assert d.accepted and sorted(d.replaced) == ["a", "b"] and not d.improved
    assert [e.keys[s] for s in e.live()] == ["d"]
    # beats d by 0.09 > 0.02: counts
    assert e.offer([0.04, 0.01], 0.6, "f").improved


def test_weights_are_the_diagonal_metric_a():
    # A = diag(1, 100): a step of 0.02 along y is a distance² of 0.04 > r² = 0.01
    e = EliteSet(2, weights=[1.0, 100.0], rule=EliteRule(radius=0.1))
    e.offer([0.0, 0.0], 0.9, "a")
    assert e.offer([0.0, 0.02], 0.5, "b").accepted  # not a neighbour in this metric
    assert not e.offer([0.05, 0.0], 0.5, "c").accepted  # a neighbour of a along x


@pytest.mark.parametrize("rebuild_every", [4, 64])
def test_tree_queries_equal_brute_force_under_inserts_and_deletes(rebuild_every):
    rng = np.random.default_rng(0)
    w = np.array([1.0, 4.0, 0.5])
    e = EliteSet(
        3, weights=w, rebuild_every=rebuild_every, rule=EliteRule(radius=0.15, threshold=0.0)
    )
    for i in range(600):
        e.offer(rng.random(3), float(rng.random()), f"e{i}")
        if i % 50 == 49:
            live = e.live()
            params = e.params[live]
            for q in rng.random((10, 3)):
                d2 = ((params - q) ** 2 * w).sum(axis=1)
                brute = set(live[d2 < 0.15**2].tolist())
                assert set(e.neighbours(q).tolist()) == brute
                k = 5
                nearest = e.nearest(q, k)
                assert np.allclose(np.sort(d2)[:k], ((e.params[nearest] - q) ** 2 * w).sum(1))
            lo, hi = np.array([0.2, 0.2, 0.2]), np.array([0.6, 0.7, 0.8])
            box = live[np.all((params >= lo) & (params <= hi), axis=1)]
            assert set(e.within_box(lo, hi).tolist()) == set(box.tolist())
    # every live elite is the best within r of itself: no two live ones are neighbours
    live = e.live()
    for s in live:
        assert e.neighbours(e.params[s]).tolist() == [s]
    assert e.tree is not None and len(e) == len(live)


def test_state_round_trip():
    rng = np.random.default_rng(1)
    e = EliteSet(2, rebuild_every=8)
    for i in range(100):
        e.offer(rng.random(2), float(rng.random()), f"e{i}")
    f = EliteSet(2, rebuild_every=8)
    f.from_state(e.to_state())
    assert f.to_state() == e.to_state()
    q = np.array([0.5, 0.5])
    assert [f.keys[s] for s in f.nearest(q, 3)] == [e.keys[s] for s in e.nearest(q, 3)]

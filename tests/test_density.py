"""KDE density (Eq. 15), region labels and the phase switch of [L21] §6 on known inputs."""

import numpy as np
import pytest

from paramimic.curriculum.density import (
    SURROUNDING,
    UNVISITED,
    VISITED,
    Density,
    PhaseSwitch,
    explored_ratio,
    regions,
)
from paramimic.task_space import TaskSpace

# gravity 0..2 and height 0..1, target velocity fixed: normalized x = g/2, y = h
SPACE = TaskSpace.from_ranges({"g": (0.0, 2.0), "h": (0.0, 1.0), "v": (1.0, 1.0)})


def test_density_by_hand():
    kde = Density(SPACE, np.array([[1.0, 0.5, 1.0], [1.2, 0.5, 1.0]]), bandwidth=0.1)
    # at the first point: e⁰ + exp(−(0.1/0.1)²) = 1 + e⁻¹ (the second is 0.1 away, normalized)
    assert kde([[1.0, 0.5, 1.0]])[0] == pytest.approx(1 + np.exp(-1))
    # halfway: two points 0.05 away: 2 exp(−0.25)
    assert kde([[1.1, 0.5, 1.0]])[0] == pytest.approx(2 * np.exp(-0.25))
    assert kde([[0.0, 0.0, 1.0]])[0] == 0.0  # nothing within 3h
    assert Density(SPACE, np.empty((0, 3)))([[1.0, 0.5, 1.0]])[0] == 0.0


def test_regions_and_explored_ratio():
    assert regions(np.array([1.5, 0.8, 0.5, 0.2, 0.1])).tolist() == [
        VISITED, VISITED, SURROUNDING, SURROUNDING, UNVISITED,
    ]  # fmt: skip
    # elites on a dense grid over the left half of the box: about half of A is visited
    g, h = np.meshgrid(np.linspace(0, 1.0, 21), np.linspace(0, 1, 21))
    pts = np.stack([g.ravel(), h.ravel(), np.ones(g.size)], axis=1)
    kde = Density(SPACE, pts, bandwidth=0.05)
    probe = SPACE.sample(np.random.default_rng(0), 4000)
    assert explored_ratio(kde, probe) == pytest.approx(0.5, abs=0.05)


def test_phase_switch_on_scripted_rates():
    p = PhaseSwitch(smoothing=0.0)  # no smoothing: each sample decides
    assert p.observe(SURROUNDING, 5.0) == "exploration"  # no rate in A_h yet
    assert p.observe(VISITED, 2.0) == "exploration"  # 5 > 2: keep exploring
    assert p.observe(SURROUNDING, 1.0) == "refinement"  # 1 < 2: refine
    assert p.observe(VISITED, 0.5) == "exploration"  # A_s (1) above A_h (0.5) again
    assert p.switches == 2
    with pytest.raises(ValueError, match="not.*unvisited|unvisited"):
        p.observe(UNVISITED, 1.0)
    q = PhaseSwitch(smoothing=0.5)
    q.observe(VISITED, 2.0)
    q.observe(SURROUNDING, 4.0)
    assert q.observe(SURROUNDING, 0.0) == "exploration"  # EMA 2.0 is not below 2.0
    assert q.observe(SURROUNDING, 0.0) == "refinement"  # EMA 1.0 < 2.0


def test_sample_band_draws_only_from_the_band():
    from paramimic.curriculum.density import sample_band

    kde = Density(SPACE, np.array([[1.0, 0.5, 1.0]]), bandwidth=0.1)
    rng = np.random.default_rng(0)
    ring = sample_band(SPACE, kde, rng, 20, 0.2, 0.8)  # A_s: a ring around the one elite
    assert len(ring) == 20
    rho = kde(ring)
    assert np.all((rho >= 0.2) & (rho < 0.8))
    assert len(sample_band(SPACE, kde, rng, 5, 2.0)) == 0  # nowhere that dense


def test_the_curricula_of_l21_section_7_3_switch_by_their_own_rules():
    # alternating: a fixed number of policy updates per phase, whatever the rates say
    alt = PhaseSwitch(rule="alternating", smoothing=0.0)
    alt.observe(SURROUNDING, 0.0, 5)
    alt.observe(VISITED, 9.0, 5)  # ours would refine here; alternating keeps its clock
    assert [alt.tick(i, phase_updates=20) for i in (19, 20, 39, 40)] == [
        "exploration", "refinement", "refinement", "exploration"
    ]  # fmt: skip
    assert alt.switches == 2 and alt.started == 40
    # exploration-only: explore until ER = 1, then refine for good
    exp = PhaseSwitch(rule="exploration_only", smoothing=0.0)
    assert exp.tick(500, explored_ratio=0.99) == "exploration"
    assert exp.tick(501, explored_ratio=1.0) == "refinement"
    exp.observe(SURROUNDING, 5.0, 502)
    exp.observe(VISITED, 0.0, 502)  # A_s far more fruitful: ours would explore again
    assert exp.tick(10_000, explored_ratio=0.5) == "refinement" and exp.switches == 1
    # mastering: exploration ends as ours does, refinement on mastery, either on its timeout
    mas = PhaseSwitch(rule="mastering", smoothing=0.0)
    mas.observe(SURROUNDING, 2.0, 0)
    assert mas.observe(VISITED, 3.0, 7) == "refinement" and mas.started == 7
    mas.observe(SURROUNDING, 9.0, 8)  # ours would explore again; mastering waits for mastery
    assert mas.tick(8, mastered=False, timeout=100) == "refinement"
    assert mas.tick(9, mastered=True, timeout=100) == "exploration" and mas.started == 9
    assert mas.tick(108, timeout=100) == "exploration"
    assert mas.tick(109, timeout=100) == "refinement"  # the timeout: 100 updates exploring
    # ours ignores the clock
    ours = PhaseSwitch()
    assert ours.tick(10_000, explored_ratio=1.0, mastered=True) == "exploration"

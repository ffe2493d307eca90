"""The pure [WL19] curriculum the sampler owns: state round trip in parts, the V̄ grid, k."""

import numpy as np
import pytest

from paramimic.config import ExperimentConfig
from paramimic.curriculum.adaptive import AdaptiveCurriculum, marginal_function


def _curriculum(task: dict) -> AdaptiveCurriculum:
    cfg = ExperimentConfig.model_validate(
        {"character": "hopper", "task": task, "curriculum": {"n_mcmc": 40, "k": 5.0}}
    )
    return AdaptiveCurriculum.from_config(cfg)


def _layers(d: int) -> list:
    rng = np.random.default_rng(1)
    return [(rng.normal(size=(d, 6)), rng.normal(size=6)), (rng.normal(size=(6, 1)), [3.0])]


TWO = {"leg_length": [0.8, 1.2], "torso_length": [0.9, 1.1], "target_velocity": [1, 1]}


def test_state_round_trips_part_by_part():
    a = _curriculum(TWO)
    a.update_marginal(_layers(3), mu=3.0, iteration=4, refill=True)
    a.next_tasks(5)
    a.ingest([{"length": 10, "fell": True, "diverged": False, "return": 2.5}])
    b = _curriculum(TWO)
    b.from_state(a.to_state())
    assert b.to_state() == a.to_state()
    np.testing.assert_array_equal(a.next_tasks(7), b.next_tasks(7))
    assert set(a.to_state(("core",))) == {"core"}
    assert b.summary()["episodes"] == 1 and b.summary()["fall_percent"] == 100.0
    assert b.summary()["tasks_served"] == 12 and b.mode == "adaptive"


def test_the_grid_is_v_bar_over_the_display_dims():
    c = _curriculum(TWO)
    assert c.marginal_grid() is None  # no V̄ yet
    c.update_marginal(_layers(3), mu=3.0, iteration=1, refill=False)
    g = c.marginal_grid(5)
    assert g["dims"] == ["leg_length", "torso_length"]
    assert g["xs"] == pytest.approx(np.linspace(0.8, 1.2, 5))
    v_bar = marginal_function(c.layers, c.space)
    # values[i][j] is V̄ at (xs[j], ys[i]) with the other dims at the centre (1.0 here)
    assert g["values"][3][1] == pytest.approx(v_bar(np.array([[0.9, 1.05, 1.0]]))[0], rel=1e-6)


def test_one_free_dimension_gives_a_line():
    c = _curriculum({"leg_length": [0.8, 1.2], "target_velocity": [1, 1]})
    c.update_marginal(_layers(2), mu=3.0, iteration=1, refill=False)
    g = c.marginal_grid(4)
    assert g["dims"] == ["leg_length"] and g["ys"] == [] and len(g["values"]) == 1
    assert len(g["values"][0]) == 4


def test_k_zero_is_uniform_and_negative_k_is_refused():
    c = _curriculum(TWO)
    c.set_k(0)
    assert c.mode == "uniform"
    with pytest.raises(ValueError, match="k must be >= 0"):
        c.set_k(-1)

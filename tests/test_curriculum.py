"""The pure [WL19] curriculum the sampler owns: state round trip in parts, the V̄ grid, k."""

import numpy as np
import pytest

from paramimic.config import ExperimentConfig
from paramimic.curriculum.adaptive import AdaptiveCurriculum, marginal_function
from paramimic.messages import EpisodeReport


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
    a.ingest([_episode(fell=True, ret=2.5)])
    b = _curriculum(TWO)
    b.from_state(a.to_state())
    assert b.to_state() == a.to_state()
    np.testing.assert_array_equal(a.next_tasks(7), b.next_tasks(7))
    assert set(a.to_state(("core",))) == {"core"}
    assert b.summary().episodes == 1 and b.summary().fall_percent == 100.0
    assert b.summary().tasks_served == 12 and b.mode == "adaptive"


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


def test_a_k_ramp_rises_from_0_to_k_until_k_is_set_by_hand_and_survives_a_restart():
    """[WL19] §6's remedy: k grows linearly from 0 over `k_ramp_iterations` policy updates."""
    cfg = ExperimentConfig.model_validate(
        {"character": "hopper", "task": TWO,
         "curriculum": {"n_mcmc": 40, "k": 10.0, "k_ramp_iterations": 20}}
    )  # fmt: skip
    c = AdaptiveCurriculum.from_config(cfg)
    assert c.sampler.k == 0.0 and c.mode == "uniform"
    c.update_marginal(_layers(3), mu=3.0, iteration=5, refill=False)
    assert c.sampler.k == pytest.approx(2.5)
    c.update_marginal(_layers(3), mu=3.0, iteration=40, refill=False)
    assert c.sampler.k == pytest.approx(10.0)
    c.update_marginal(_layers(3), mu=3.0, iteration=10, refill=False)
    b = AdaptiveCurriculum.from_config(cfg)
    b.from_state(c.to_state())
    assert b.sampler.k == pytest.approx(5.0) and b.k_ramp
    b.set_k(3.0)  # by hand (the API): the ramp ends
    b.update_marginal(_layers(3), mu=3.0, iteration=30, refill=False)
    assert b.sampler.k == 3.0
    assert _curriculum(TWO).sampler.k == 5.0  # no ramp: k from the start


def _widening(**widen) -> AdaptiveCurriculum:
    cfg = ExperimentConfig.model_validate(
        {
            "character": "hopper",
            "task": TWO,
            "curriculum": {"n_mcmc": 40, "k": 5.0, "widen": {"window": 10, **widen}},
        }
    )
    return AdaptiveCurriculum.from_config(cfg)


def _episode(i: int = 0, fell: bool = False, ended_early: bool = False, ret: float = 1.0):
    return EpisodeReport(f"e{i}", np.ones(3), ret, 10, fell, False, {}, ended_early or fell)


def _episodes(n: int, falls: int, early_ends: int | None = None) -> list[EpisodeReport]:
    """n episodes, the first `falls` fell, the first `early_ends` (default: the falls) ended
    early (a fall or another early end: stalled, off course)."""
    early = falls if early_ends is None else early_ends
    return [_episode(i, i < falls, i < early) for i in range(n)]


def test_a_widening_range_starts_at_the_centre_and_grows_when_mastered():
    c = _widening(start=0.2, step=0.3, promote_below=0.5)
    c.update_marginal(_layers(3), mu=3.0, iteration=0, refill=True)
    tasks = c.next_tasks(200)
    # legs 0.8-1.2 → 0.96-1.04 at width 0.2, torso 0.9-1.1 → 0.98-1.02; the velocity is fixed
    assert tasks[:, 0].min() >= 0.96 - 1e-12 and tasks[:, 0].max() <= 1.04 + 1e-12
    assert tasks[:, 0].max() - tasks[:, 0].min() > 0.05  # and it is used
    assert tasks[:, 1].min() >= 0.98 - 1e-12 and tasks[:, 1].max() <= 1.02 + 1e-12
    c.ingest(_episodes(10, falls=6))  # 60 % fell: not yet
    assert c.width == pytest.approx(0.2)
    c.ingest(_episodes(10, falls=4))  # 40 %: grow
    assert c.width == pytest.approx(0.5)
    c.ingest(_episodes(9, falls=0))  # a window is 10 episodes
    assert c.width == pytest.approx(0.5)
    c.ingest(_episodes(1, falls=0) + _episodes(20, falls=0))
    assert c.width == 1.0 and c.summary().range_width == 1.0  # capped at the whole range


def test_a_range_grows_on_episodes_that_last_not_on_those_that_end_early_standing():
    c = _widening(start=0.2, step=0.3, promote_below=0.5)  # promote_on: early_ends
    c.ingest(_episodes(10, falls=1, early_ends=8))  # 1 fell, 7 more stalled or turned away
    assert c.width == pytest.approx(0.2)
    c.ingest(_episodes(10, falls=1, early_ends=4))
    assert c.width == pytest.approx(0.5)
    d = _widening(start=0.2, step=0.3, promote_below=0.5, promote_on="falls")
    d.ingest(_episodes(10, falls=1, early_ends=8))  # the walker study's rule: falls only
    assert d.width == pytest.approx(0.5)


def test_v_bar_sampling_runs_inside_the_current_range_and_the_width_survives_a_restart():
    c = _widening(start=0.5)
    seen = []

    def v_bar(a):  # what MCMC evaluates: the points the agent will train on
        seen.append(np.asarray(a).copy())
        return np.ones(len(a))

    c.sampler.refill(lambda a: v_bar(c.pull(a)), 1.0)
    pts = np.concatenate(seen)
    assert pts[:, 0].min() >= 0.9 - 1e-12 and pts[:, 0].max() <= 1.1 + 1e-12
    c.ingest(_episodes(3, falls=1))
    d = _widening(start=0.5)
    d.from_state(c.to_state())
    assert (d.width, d.window) == (0.5, [3, 1])


def test_an_edge_judged_range_grows_on_its_edge_test_not_on_training_episodes():
    c = _widening(start=0.4, step=0.3, promote_below=0.25, promote_on="edge")
    edge = c.edge_tasks(50, seed=1)
    half = 0.5 * c.space.width
    offset = np.abs(edge - c.space.center)[:, :2] / half[:2]  # legs 0.8-1.2, torso 0.9-1.1
    np.testing.assert_allclose(offset.max(axis=1), 0.4)  # one bound reached in each row
    assert offset.min() < 0.3  # the other dims anywhere inside the range
    np.testing.assert_array_equal(edge[:, 2], 1.0)  # the fixed velocity stays put
    np.testing.assert_array_equal(edge, c.edge_tasks(50, seed=1))  # the seed decides
    c.ingest(_episodes(30, falls=0))  # training episodes do not judge this range
    assert c.width == pytest.approx(0.4)
    assert c.judge_edge(16, falls=4) == pytest.approx(0.4)  # 25 % fell: not below 25 %
    assert c.judge_edge(16, falls=3) == pytest.approx(0.7)
    assert c.judge_edge(16, falls=0) == 1.0 and c.edge_tasks(4, seed=0) is None  # whole
    d = _widening(start=0.4, promote_on="edge")
    d.from_state(c.to_state())
    assert d.width == 1.0


def test_without_widen_the_range_is_whole():
    c = _curriculum(TWO)
    assert c.width == 1.0
    tasks = c.next_tasks(500)
    assert tasks[:, 0].min() < 0.85 and tasks[:, 0].max() > 1.15


def test_a_range_off_centre_grows_from_the_base_body_not_the_box_centre():
    task = {"leg_length": [0.7, 1.5], "torso_length": [1.1, 1.3], "target_velocity": [0.5, 1.5]}

    def widening(origin: str) -> AdaptiveCurriculum:
        cfg = ExperimentConfig.model_validate({
            "character": "hopper", "task": task,
            "curriculum": {"n_mcmc": 40, "widen": {"start": 0.1, "origin": origin}},
        })  # fmt: skip
        return AdaptiveCurriculum.from_config(cfg)

    base = widening("base")
    # legs at the base body's 1.0; the torso's 1.0 is outside its range: its nearest end; the
    # goal at its centre
    np.testing.assert_allclose(base.origin, [1.0, 1.1, 1.0])
    tasks = base.next_tasks(400)
    assert np.all(np.abs(tasks - base.origin) <= [0.05 + 1e-9, 0.02 + 1e-9, 0.05 + 1e-9])
    assert tasks[:, 0].min() < 0.99 and tasks[:, 0].max() > 1.02  # both sides of the base legs
    edge = base.edge_tasks(200, seed=2)
    lo = base.origin + 0.1 * (base.space.low - base.origin)
    hi = base.origin + 0.1 * (base.space.high - base.origin)
    assert np.all((edge >= lo - 1e-9) & (edge <= hi + 1e-9))
    at_bound = np.isclose(edge, lo) | np.isclose(edge, hi)
    assert at_bound.any(axis=1).all()  # each on the range's edge in one dimension
    centre = widening("center")  # the box's centre: legs around 1.1
    np.testing.assert_allclose(centre.origin, centre.space.center)
    assert np.abs(centre.next_tasks(400)[:, 0] - 1.1).max() <= 0.04 + 1e-9

"""The [L21] curriculum (SkillCurriculum) and bootstrap on scripted episodes: elites and traces,
motions dealt per stage, batches, exploration rates and phase switches, state round trips."""

import json

import numpy as np
import pytest

from paramimic.config import CurriculumConfig, SkillCurriculumConfig
from paramimic.curriculum.bootstrap import Bootstrap
from paramimic.curriculum.density import SURROUNDING, VISITED
from paramimic.curriculum.parameterization_net import ParameterizationNet
from paramimic.curriculum.skill import SkillCurriculum
from paramimic.messages import DealTags, EpisodeReport, SkillOutcome
from paramimic.task_space import TaskSpace

SPACE = TaskSpace.from_ranges({"gravity": (0.0, 1.0), "jump_height": (0.0, 1.0)})
SHAPE = (4, 3)


def make(**skill) -> SkillCurriculum:
    cfg = CurriculumConfig(skill=SkillCurriculumConfig(**skill), chains=8, burn_in=10)
    return SkillCurriculum(SPACE, cfg, seed=0, reference=np.array([0.5, 0.5]), trace_shape=SHAPE)


def episode(i, achieved, fitness, batch=None, trace_value=None, constraint_error=None):
    trace = None if trace_value is None else np.full(SHAPE, trace_value)
    done = trace is not None
    return EpisodeReport(
        f"e{i}",
        np.asarray(achieved, float),
        1.0,
        10,
        fell=False,
        diverged=False,
        reward_terms={},
        ended_early=False,
        skill=SkillOutcome(
            np.asarray(achieved, float), fitness, trace, done, constraint_error=constraint_error
        ),
        tags=DealTags(batch=batch),
    )


def test_elites_keep_their_traces_and_replace_worse_neighbours():
    c = make()
    c.ingest([episode(0, (0.5, 0.5), 0.6, trace_value=1.0)])
    c.ingest([episode(1, (0.52, 0.5), 0.5, trace_value=2.0)])  # worse neighbour: dismissed
    c.ingest([episode(2, (0.9, 0.9), 0.05, trace_value=3.0)])  # below the threshold 0.1
    c.ingest([episode(3, (0.9, 0.9), 0.4, trace_value=None)])  # no trace (did not finish)
    assert set(c.traces) == {"e0"}
    c.ingest([episode(4, (0.51, 0.5), 0.7, trace_value=4.0)])  # better: replaces e0
    assert set(c.traces) == {"e4"}
    assert c.pending_parts() == ("elites",)  # the sampler persists the elite set
    added, removed = c.drain("traces")
    assert set(added) == {"e4"} and removed == {"e0"}
    assert added["e4"] == np.full(SHAPE, 4.0).tolist()  # JSON-able for Redis
    assert c.drain("traces") == ({}, set()) and c.pending_parts() == ()
    assert c.entries("traces") == {"e4": np.full(SHAPE, 4.0).tolist()}
    assert set(c.views(["elites"], 5)) == {"density"}
    params, traces = c.elite_data()
    assert params.tolist() == [[0.51, 0.5]] and traces.shape == (1, *SHAPE)
    assert c.stats["episodes"] == 5


def test_a_constraint_tolerance_keeps_performances_that_break_a_constraint_out():
    # [L21] §5.2 as written: the constraint only lowers F, so a performance 3 σ_task off enters
    paper = make()
    paper.ingest([episode(0, (0.5, 0.5), 0.9, trace_value=1.0, constraint_error=3.0)])
    assert set(paper.traces) == {"e0"}
    ours = make(constraint_tolerance=1.0)
    ours.ingest([episode(0, (0.5, 0.5), 0.9, trace_value=1.0, constraint_error=3.0)])
    assert ours.traces == {}
    ours.ingest([episode(1, (0.5, 0.5), 0.8, trace_value=2.0, constraint_error=0.7)])
    ours.ingest([episode(2, (0.9, 0.9), 0.8, trace_value=3.0)])  # a family without constraints
    assert set(ours.traces) == {"e1", "e2"}
    # the outcome's constraint miss crosses the actor-learner boundary
    sent = episode(3, (0.5, 0.5), 0.9, trace_value=1.0, constraint_error=2.5).skill
    assert SkillOutcome.from_dict(sent.to_dict()).constraint_error == 2.5


def test_motions_follow_the_bootstrap_stage():
    c = make(batch_size=4, episodes_per_param=1)
    deal = c.next_deal(3)
    assert deal.region == "reference" and deal.motions is None
    assert deal.tasks.tolist() == [[0.5, 0.5]] * 3  # π0 trains at a0 on m0
    c.ingest([episode(0, (0.5, 0.5), 0.9, trace_value=1.0)])
    c.ingest([episode(1, (0.8, 0.5), 0.9, trace_value=3.0)])
    c.update_motion(None, 0, None, "proxy")
    deal = c.next_deal(4)
    # kNN proxy (Eq. 14) between the two elites: a convex mix of 1.0 and 3.0
    assert deal.motions.shape == (4, *SHAPE)
    assert np.all((deal.motions >= 1.0) & (deal.motions <= 3.0))
    net = ParameterizationNet(SPACE, SHAPE, hidden=(8,), seed=0)
    net.fit(*c.elite_data(), steps=5)
    with pytest.raises(ValueError, match="stage must be"):
        c.update_motion(net.layers(), net.version, net.mse, "final")
    c.update_motion(net.layers(), net.version, net.mse, "mixed")
    tasks = SPACE.sample(np.random.default_rng(0), 200)
    motions = c.motions_for(tasks)
    from_net = np.all(np.isclose(motions, net.predict(tasks), atol=1e-5), axis=(1, 2))
    assert 0.3 < from_net.mean() < 0.7  # a random choice between P_θ and the proxy
    assert c.summary().motion_version == 1 and c.summary().stage == "mixed"


def test_a_performed_task_gets_p_theta_without_chance():
    """Evaluation and play perform a task with m_a = P_θ(a) once the mixed stage uses P_θ,
    with the kNN proxy before, and with m0 in the base stage."""
    c = make(batch_size=4, episodes_per_param=1)
    tasks = SPACE.sample(np.random.default_rng(0), 20)
    c.ingest([episode(0, (0.5, 0.5), 0.9, trace_value=1.0)])
    c.ingest([episode(1, (0.8, 0.5), 0.9, trace_value=3.0)])
    assert c.performed_motions(tasks) is None  # base: m0
    c.update_motion(None, 0, None, "proxy")
    proxy = c.performed_motions(tasks)
    assert proxy.shape == (20, *SHAPE) and np.all((proxy >= 1.0) & (proxy <= 3.0))
    net = ParameterizationNet(SPACE, SHAPE, hidden=(8,), seed=0)
    net.fit(*c.elite_data(), steps=5)
    c.update_motion(net.layers(), net.version, net.mse, "mixed")
    np.testing.assert_allclose(c.performed_motions(tasks), net.predict(tasks), atol=1e-5)
    np.testing.assert_allclose(c.performed_motions(tasks[:1]), net.predict(tasks[:1]), atol=1e-5)


def test_without_motion_parameterization_every_task_imitates_m0():
    """[L21] §7.2's A1: past the base stage the tasks spread over A while m_a stays m0; the
    elites (and so ER) are kept as with the parameterization."""
    c = make(batch_size=4, episodes_per_param=1, motion_parameterization=False)
    c.ingest([episode(0, (0.5, 0.5), 0.9, trace_value=1.0)])
    c.ingest([episode(1, (0.8, 0.5), 0.9, trace_value=3.0)])
    c.update_motion(None, 0, None, "proxy")
    deal = c.next_deal(4)
    assert deal.motions is None and deal.region != "reference"
    assert c.motions_for(SPACE.sample(np.random.default_rng(0), 5)) is None
    assert len(c.elites) == 2 and c.elite_data()[1].shape == (2, *SHAPE)


def test_batches_measure_exploration_rates_and_switch_phases():
    c = make(batch_size=5, episodes_per_param=2, probe_every=2)
    # a populated centre: A_h around (0.5, 0.5), A_s on a ring around it
    for i, g in enumerate(np.linspace(0.4, 0.6, 6)):
        c.ingest([episode(100 + i, (g, 0.5), 0.5, trace_value=0.0)])
    c.update_motion(None, 0, None, "proxy")
    deal = c.next_deal(10)  # batch 1: exploration draws from A_s
    assert deal.region == SURROUNDING
    rho = c.density(deal.tasks)
    assert np.all((rho >= 0.2) & (rho < 0.8))
    # its 10 episodes find new elites far apart: the exploration rate in A_s is 1
    eps = [episode(i, (0.105 * i, 0.95), 0.9, deal.batch, 1.0) for i in range(10)]
    c.ingest(eps)
    assert c.phase.rate_surrounding == pytest.approx(1.0)
    # late episodes of the closed batch (dealt ahead) change neither rates nor the history
    c.ingest([episode(200 + i, (0.5, 0.5), 0.1, 1, 1.0) for i in range(3)])
    assert c.phase.rate_surrounding == 1.0 and len(c.history) == 1
    deal = c.next_deal(10)  # batch 2: the occasional probe of A_h
    assert deal.region == VISITED
    assert np.all(c.density(deal.tasks) >= 0.8)
    # nothing improves there: rate 0 in A_h; A_s (1.0) > A_h (0.0): exploration goes on
    c.ingest([episode(20 + i, (0.5, 0.5), 0.1, deal.batch, 1.0) for i in range(10)])
    assert c.phase.rate_visited == 0.0 and c.phase.phase == "exploration"
    deal = c.next_deal(10)  # batch 3: A_s again, now without improvements
    c.ingest([episode(40 + i, (0.5, 0.5), 0.1, deal.batch, 1.0) for i in range(10)])
    deal = c.next_deal(10)  # batch 4: the probe of A_h finds improvements (EMA 0.5 each)
    assert deal.region == VISITED
    eps = [episode(60 + i, (0.105 * i, 0.05), 0.95, deal.batch, 1.0) for i in range(10)]
    c.ingest(eps)
    assert c.phase.rate_visited == c.phase.rate_surrounding == 0.5
    assert c.phase.phase == "exploration"
    deal = c.next_deal(10)  # batch 5: A_s without improvements: 0.25 < 0.5, refinement
    assert deal.region == SURROUNDING
    c.ingest([episode(80 + i, (0.5, 0.5), 0.1, deal.batch, 1.0) for i in range(10)])
    assert c.phase.phase == "refinement" and c.phase.switches == 1
    deal = c.next_deal(10)  # batch 6: in refinement the occasional probe is of A_s
    assert deal.region == SURROUNDING
    c.ingest([episode(90 + i, (0.5, 0.5), 0.1, deal.batch, 1.0) for i in range(10)])
    assert c.next_deal(1).region == VISITED  # batch 7: refinement draws from A_h
    s = c.summary()
    assert s.phase == "refinement" and s.explored_ratio > 0
    assert [h["episodes"] for h in s.history] == [16, 29, 39, 49, 59, 69]


def test_uniform_sampling_is_the_baseline():
    c = make(sampling="uniform", batch_size=50, episodes_per_param=1)
    assert c.next_deal(50).region == "reference"  # π0 first, as in the curriculum
    c.ingest([episode(i, (0.5, 0.5), 0.5, 1, 1.0) for i in range(50)])
    c.update_motion(None, 0, None, "proxy")
    tasks = c.next_deal(50).tasks
    assert c.summary().phase == "uniform"
    assert tasks.min(axis=0) == pytest.approx([0, 0], abs=0.1)
    assert tasks.max(axis=0) == pytest.approx([1, 1], abs=0.1)


def test_state_round_trip_continues_exactly():
    c = make(batch_size=3, episodes_per_param=1)
    for i in range(8):
        c.ingest([episode(i, (0.1 * i, 0.5), 0.5 + 0.01 * i, trace_value=float(i))])
    c.update_motion(None, 0, None, "proxy")
    c.next_deal(2)
    state = json.loads(json.dumps(c.to_state()))
    twin = make(batch_size=3, episodes_per_param=1)
    twin.from_state(state)
    assert json.dumps(twin.to_state(), sort_keys=True) == json.dumps(state, sort_keys=True)
    assert np.array_equal(twin.next_deal(5).tasks, c.next_deal(5).tasks)
    assert np.allclose(twin.next_deal(2).motions, c.next_deal(2).motions)


def test_bootstrap_stages():
    cfg = SkillCurriculumConfig(
        base_min_iterations=4, base_max_iterations=50, plateau_window=3, p_loss_threshold=0.01
    )
    b = Bootstrap(cfg)
    for it, ret in enumerate([1, 2, 3, 4, 5, 6, 7]):  # still improving
        assert b.observe(it, ret, None) == "base"
    for it, ret in enumerate([7.0, 7.05, 7.0, 7.02, 7.01, 7.0], start=7):
        stage = b.observe(it, ret, None)
    assert stage == "proxy" and b.switched_at["proxy"] == 11
    assert b.observe(13, 1.0, 0.5) == "proxy"  # P_θ's loss is still above the threshold
    assert b.observe(14, 1.0, 0.005) == "mixed"
    capped = Bootstrap(SkillCurriculumConfig(base_min_iterations=1, base_max_iterations=3))
    assert [capped.observe(i, float(i), None) for i in range(3)] == ["base", "base", "proxy"]
    twin = Bootstrap(cfg)
    twin.from_state(json.loads(json.dumps(b.to_state())))
    assert twin.to_state() == b.to_state()


def test_the_phase_clock_starts_after_pi0_and_survives_a_state_round_trip():
    """[L21] §7.3's alternating curriculum: `phase_updates` policy updates per phase, counted
    from the end of the base stage (π0's updates are not a phase)."""
    c = make(sampling="alternating", phase_updates=3)
    layers = [[np.zeros((2, 1)), np.ones(1)]]
    for it in range(10):  # π0: the clock does not run
        c.update_marginal(layers, 1.0, it, refill=False)
    assert c.summary().phase == "base" and c.phase.started == 9
    c.update_motion(None, 0, None, "proxy")
    phases = []
    for it in range(10, 16):
        c.update_marginal(layers, 1.0, it, refill=False)
        phases.append(c.phase.phase)
    assert phases == ["exploration"] * 2 + ["refinement"] * 3 + ["exploration"]
    assert c.stats["phase_switches"] == 2
    d = make(sampling="alternating", phase_updates=3)
    d.from_state(json.loads(json.dumps(c.to_state())))
    assert (d.phase.phase, d.phase.started, d.phase.rule) == ("exploration", 15, "alternating")


def test_mastering_refines_while_the_visited_skills_mean_marginal_value_still_rises():
    """[L21] §7.3's mastering: refinement ends once the mean V̄ over the visited skills (the
    live elites) rose by less than `mastery_threshold` of itself over `mastery_window` policy
    updates; the record starts anew with each phase and survives a state round trip."""
    c = make(sampling="mastering", mastery_threshold=0.01, mastery_window=3, phase_timeout=100)
    c.update_motion(None, 0, None, "proxy")
    c.ingest([episode(0, (0.8, 0.5), 0.9, trace_value=1.0)])  # one visited skill at g = 0.8

    def v_bar(at_elite):  # V̄(a) = w x_gravity + 1 on the scaled box (x = 2g − 1 = 0.6 there)
        return [[np.array([[(at_elite - 1.0) / 0.6], [0.0]]), np.ones(1)]]

    c.update_marginal(v_bar(1.0), 1.0, 0, refill=False)
    c.phase.switch(0)  # refinement, as the exploration rates would switch it
    assert c.phase.phase == "refinement" and c.phase.progress == []
    rising = [1.0, 1.1, 1.2, 1.3, 1.4]  # 10 % an update: still mastering the region
    for it, v in enumerate(rising, start=1):
        c.update_marginal(v_bar(v), 1.0, it, refill=False)
        assert c.phase.phase == "refinement"
    assert c.phase.progress == pytest.approx(rising)
    d = make(sampling="mastering", mastery_threshold=0.01, mastery_window=3)
    d.from_state(json.loads(json.dumps(c.to_state())))
    assert d.phase.progress == pytest.approx(rising) and d.phase.phase == "refinement"
    for it, v in enumerate([1.405, 1.41], start=6):  # 1.3 -> 1.405: 8 % over 3 updates
        c.update_marginal(v_bar(v), 1.0, it, refill=False)
    assert c.phase.phase == "refinement"
    c.update_marginal(v_bar(1.412), 1.0, 8, refill=False)  # 1.4 -> 1.412: 0.9 % over 3
    assert c.phase.phase == "exploration" and c.phase.progress == [] and c.phase.started == 8
    assert not c.mastered()

"""The typed messages: shapes checked at construction, a dict round trip for the text
boundaries (Redis, the API), and what the rollouts really report."""

import json

import numpy as np
import pytest

from paramimic.messages import CurriculumSummary, DealTags, EpisodeReport, SkillOutcome, TaskDeal


def test_a_deal_checks_its_shapes_and_takes_rows_with_its_tags():
    deal = TaskDeal(np.arange(6.0).reshape(3, 2), np.zeros((3, 4, 5)), 7, "visited", 2)
    part = deal.take(np.array([2, 0, 2]))
    assert part.tasks.tolist() == [[4, 5], [0, 1], [4, 5]] and part.motions.shape == (3, 4, 5)
    assert part.tags() == DealTags(7, "visited", 2)
    assert len(part) == 3
    with pytest.raises(ValueError, match=r"tasks are \[n, d\]"):
        TaskDeal(np.zeros(3))
    with pytest.raises(ValueError, match="n = 3 tasks"):
        TaskDeal(np.zeros((3, 2)), np.zeros((2, 4, 5)))
    again = TaskDeal.from_dict(json.loads(json.dumps(deal.to_dict())))
    assert np.array_equal(again.tasks, deal.tasks) and again.tags() == deal.tags()


def test_an_episode_report_round_trips_through_json():
    report = EpisodeReport(
        "a-w0-s1-e3", np.array([1.0, 0.5]), 12.5, 40, False, False, {"pose": 3.0}, True,
        deviated=True,
        skill=SkillOutcome(np.array([1.0, 0.4]), 0.7, np.ones((2, 3)), True, held=False),
        tags=DealTags(4, "surrounding", 1),
    )  # fmt: skip
    back = EpisodeReport.from_dict(json.loads(json.dumps(report.to_dict())))
    assert back.episode_id == report.episode_id and back.tags == report.tags
    assert (back.ret, back.length, back.deviated, back.ended_early) == (12.5, 40, True, True)
    assert np.array_equal(back.skill.trace, report.skill.trace) and back.skill.held is False
    plain = EpisodeReport("b", np.zeros(1), 0.0, 1, True, False, {}, True)
    assert EpisodeReport.from_dict(plain.to_dict()).skill is None


def test_the_rollouts_report_typed_episodes_with_the_deals_tags():
    from paramimic.config import EnvConfig
    from paramimic.envs.skill_env import SkillEnv
    from paramimic.rl.rollout import RolloutWorker

    def env():
        return SkillEnv("walker", {"gravity": (0.5, 1.5)}, EnvConfig(clip="planar_jump"))

    probe = env()
    deal = TaskDeal(np.full((8, 1), 1.2), None, batch=3, region="reference", motion_version=0)
    w = RolloutWorker(env, 2, probe.observation_space.shape[0], probe.action_space.shape[0], 0)
    f = w.collect(60, deal, use_policy=False)
    assert f.episodes and all(isinstance(e, EpisodeReport) for e in f.episodes)
    for e in f.episodes:
        assert e.tags == DealTags(3, "reference", 0) and e.task.tolist() == [1.2]
        assert isinstance(e.skill, SkillOutcome)


def test_the_apis_curriculum_model_serves_every_field_of_the_summary():
    from dataclasses import fields

    from services.api.models import Curriculum

    summary = {f.name for f in fields(CurriculumSummary)}
    missing = summary - set(Curriculum.model_fields)
    assert not missing, f"the API's Curriculum model lacks {sorted(missing)}"
    extra = set(Curriculum.model_fields) - summary
    assert extra == {"run_id", "paused", "updated_at"}  # what the API adds

"""Fitness, [L21] Eq. 10, on hand-worked traces."""

import numpy as np
import pytest

from paramimic.motion.fitness import EpisodeTrace, fitness


def _trace(T=4, J=2, E=2) -> EpisodeTrace:
    return EpisodeTrace(
        pose_error=np.zeros((T, J)),
        velocity=np.zeros((T, J, 1)),
        velocity_ref=np.zeros((T, J, 1)),
        ee_height=np.zeros((T, E)),
        ee_height_ref=np.zeros((T, E)),
        contact_ref=np.ones((T, E), bool),
        ee_slide=np.zeros((T, E)),
    )


def test_a_perfect_episode_has_fitness_one_plus_the_constraint_term():
    assert fitness(_trace()) == pytest.approx(1.0)
    assert fitness(_trace(), r_constraint=0.5) == pytest.approx(1.05)  # w_constraint 0.1


def test_each_factor_by_hand():
    t = _trace()
    t.pose_error[:] = 0.5  # 2 joints x 0.25 per sample -> mean 0.5 / 2.67²
    assert fitness(t) == pytest.approx(np.exp(-0.5 / 2.67**2))
    t = _trace()
    t.velocity[:, 0, 0] = 2.0  # ‖Δv‖² = 4, denominator max(0.5, 0) = 0.5 -> 8 per sample
    assert fitness(t) == pytest.approx(np.exp(-8.0 / 75.5**2))
    t = _trace()
    t.ee_height[:, 0] = 0.1  # a planted foot 0.1 up: 0.01 per sample
    t.contact_ref[:, 1] = False
    t.ee_height[:, 1] = 5.0  # a foot in the air in m0 is not judged by height
    assert fitness(t) == pytest.approx(np.exp(-0.01 / 1.3**2))
    t = _trace()
    t.ee_slide[:, 0] = 0.2  # sliding while planted at φ and φ-1: 3 of 4 samples, /T = 4
    assert fitness(t) == pytest.approx(np.exp(-(3 * 0.04) / 4 / 0.7**2))

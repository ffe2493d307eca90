"""F(B̄, b) by editing one spec per character gives the very model a fresh build gives."""

import numpy as np
import pytest

from paramimic.characters import REGISTRY, get_character
from paramimic.characters.dimensions import Reshaper

FIELDS = (
    "body_pos", "body_quat", "body_ipos", "body_iquat", "body_mass", "body_inertia",
    "geom_size", "geom_pos", "geom_quat", "geom_rbound", "site_pos", "qpos0",
    "dof_invweight0", "body_subtreemass", "actuator_length0",
)  # fmt: skip


@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_reshaped_bodies_equal_fresh_builds(name):
    character = get_character(name)
    reshape = Reshaper(character)
    rng = np.random.default_rng(0)
    for _ in range(5):
        shape = {p.name: float(rng.uniform(p.low, p.high)) for p in character.shape_params}
        a, b = reshape(shape), character.compile(shape)
        for field in FIELDS:
            np.testing.assert_array_equal(getattr(a.model, field), getattr(b.model, field), field)
        assert (a.hip_height, a.mass, a.segment_lengths) == (
            b.hip_height,
            b.mass,
            b.segment_lengths,
        )
        np.testing.assert_array_equal(a.leg_lengths, b.leg_lengths)
        assert a.shape == b.shape
    # and back to the base body
    np.testing.assert_array_equal(reshape().model.body_pos, character.compile().model.body_pos)

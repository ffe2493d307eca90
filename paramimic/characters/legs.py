"""A character's legs as hinge chains hip - knee - ankle in the sagittal plane (`PlanarLeg`),
what `paramimic.motion.retarget` retargets."""

from __future__ import annotations

from paramimic.motion.retarget import PlanarLeg


def leg_chains(
    definition, lengths: dict[str, float], base: dict[str, float]
) -> tuple[PlanarLeg, ...]:
    """The legs of a character as `PlanarLeg`s with the body's segment `lengths` (joint to
    joint) and the base body's `base`: a planar character's (thigh, shin) segments, the foot
    being the segment whose parent is the shin; a 3D character's (thigh, shin, foot) parts,
    their hinges in the sagittal plane (`definition.sagittal_hinge(part)`). Raises ValueError
    for a character without legs."""
    joints = [j.name for j in definition.joints]
    chains = []  # (thigh, shin, (hip, knee, ankle) hinges)
    if definition.planar:
        segments = {s.name: s for s in definition.segments}
        for thigh, shin in definition.legs:
            foot = next(s for s in definition.segments if s.parent == shin)
            chains.append((thigh, shin, (segments[thigh].joint, segments[shin].joint, foot.joint)))
    elif definition.legs:  # a 3D character names its parts' sagittal hinges
        pitch = definition.sagittal_hinge
        for thigh, shin, foot in definition.legs:
            chains.append((thigh, shin, (pitch(thigh), pitch(shin), pitch(foot))))
    if not chains:
        raise ValueError(f"{definition.name!r} has no legs to retarget")
    return tuple(
        PlanarLeg(
            *(joints.index(j.name) for j in hinges),
            thigh=lengths[thigh],
            shin=lengths[shin],
            base_thigh=base[thigh],
            base_shin=base[shin],
            knee_sign=1.0 if hinges[1].range[0] >= 0.0 else -1.0,
        )
        for thigh, shin, hinges in chains
    )

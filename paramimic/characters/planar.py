"""The planar characters: `walker` (torso, two thighs, shins, feet) and `hopper` (one leg).

Root: slide x, slide z and pitch, as in gymnasium's planar MuJoCo environments. Gains and
torque limits were tuned once on the base bodies and stay fixed for every shape ([WL19] §3.1).
"""

from __future__ import annotations

from functools import partial

from paramimic.characters.body import UP, CharacterDef, Joint, Segment, ShapeParam, joint_names
from paramimic.characters.registry import Registration
from paramimic.motion.procedural import alternating, gait, planar_jump_clip

_GLOBAL = ShapeParam("global_scale", 0.5, 1.5, "height: every length and width")
_SPLIT = ShapeParam(
    "thigh_shin_split", 0.8, 1.2, "thigh length x s, shin takes the rest of the leg"
)
_TORSO = ShapeParam("torso_length", 0.7, 1.3, "torso length")
_THICK = ShapeParam("limb_thickness", 0.7, 1.3, "radius of thighs and shins, width of feet")


def _leg(side: str, hip: tuple[float, float] = (-0.8, 1.8)) -> tuple[Segment, ...]:
    sfx = f"_{side}" if side else ""
    return (
        Segment(
            f"thigh{sfx}",
            "torso",
            0.45,
            0.05,
            Joint(f"hip{sfx}", hip, 150.0, 100.0),
            attach="start",
        ),
        Segment(
            f"shin{sfx}", f"thigh{sfx}", 0.45, 0.04, Joint(f"knee{sfx}", (-2.4, 0.0), 150.0, 100.0)
        ),
        Segment(
            f"foot{sfx}",
            f"shin{sfx}",
            0.22,
            0.05,
            Joint(f"ankle{sfx}", (-0.8, 0.8), 60.0, 40.0),
            kind="foot",
        ),
    )


def _leg_scales(shape: dict[str, float], sfx: str, leg: float) -> dict[str, tuple[float, float]]:
    g, s, w = shape["global_scale"], shape["thigh_shin_split"], shape["limb_thickness"]
    thigh, shin = 0.45, 0.45
    shin_scale = (thigh + shin - thigh * s) / shin  # the leg keeps its length under the split
    return {
        f"thigh{sfx}": (g * leg * s, g * w),
        f"shin{sfx}": (g * leg * shin_scale, g * w),
        f"foot{sfx}": (g, g * w),
    }


def _walker_scales(shape: dict[str, float]) -> dict[str, tuple[float, float]]:
    g = shape["global_scale"]
    return {
        "torso": (g * shape["torso_length"], g),
        **_leg_scales(shape, "_r", shape["right_leg_length"]),
        **_leg_scales(shape, "_l", shape["left_leg_length"]),
    }


def _hopper_scales(shape: dict[str, float]) -> dict[str, tuple[float, float]]:
    g = shape["global_scale"]
    return {"torso": (g * shape["torso_length"], g), **_leg_scales(shape, "", shape["leg_length"])}


WALKER = CharacterDef(
    name="walker",
    segments=(Segment("torso", None, 0.5, 0.06, direction=UP), *_leg("r"), *_leg("l")),
    shape_params=(
        _GLOBAL,
        ShapeParam("left_leg_length", 0.5, 1.5, "left thigh and shin length"),
        ShapeParam("right_leg_length", 0.5, 1.5, "right thigh and shin length"),
        _SPLIT,
        _TORSO,
        _THICK,
    ),
    scales=_walker_scales,
    legs=(("thigh_r", "shin_r"), ("thigh_l", "shin_l")),
    end_effectors=("foot_r", "foot_l"),  # not the root (torso): in its own frame, constant
    feet=("foot_r", "foot_l"),
)

HOPPER = CharacterDef(
    name="hopper",
    segments=(Segment("torso", None, 0.4, 0.05, direction=UP), *_leg("")),
    shape_params=(
        _GLOBAL,
        ShapeParam("leg_length", 0.5, 1.5, "thigh and shin length"),
        _SPLIT,
        _TORSO,
        _THICK,
    ),
    scales=_hopper_scales,
    legs=(("thigh", "shin"),),
    end_effectors=("foot",),
    feet=("foot",),
)


# Walking at about 1 m/s: two steps of ~0.5 m per 1 s cycle. The right leg swings forward around
# φ = 0, the left half a cycle later. Hip flexion is positive forward, knees flex negative and
# bend most in mid-swing, ankles roll heel to toe.
_WALKER_LEG = {  # one leg: offset, a1, a2, phase
    "hip_{side}": (0.20, 0.32, 0.00, 0.00),
    "knee_{side}": (-0.45, -0.35, 0.05, 0.25),
    "ankle_{side}": (0.00, 0.15, 0.00, -0.10),
}
WALKER_GAIT = gait(joint_names(WALKER), 1.0, alternating(_WALKER_LEG))

# Hopping: crouch and extend twice a second, the leg swinging slightly forward in flight.
HOPPER_GAIT = gait(
    joint_names(HOPPER),
    0.5,
    {
        "hip": (0.35, 0.20, 0.00, 0.00),
        "knee": (-0.55, -0.35, 0.00, 0.25),
        "ankle": (0.15, 0.20, 0.00, 0.25),
    },
)


def _jump(character: CharacterDef) -> partial:
    """[L21] Jump at laptop scale on the character's base legs (`planar_jump_clip`)."""
    segments = {s.name: s for s in character.segments}
    thigh, shin = (segments[n].length for n in character.legs[0])
    foot = segments[character.feet[0]].thickness
    return partial(planar_jump_clip, joint_names(character), thigh, shin, foot)


_LEGS = (0.7, 1.3)


def _at_speed(**shape: tuple[float, float]) -> dict:
    """make_env kwargs: a task space of these shape ranges at the target speed 1 m/s."""
    return {"task": {**shape, "target_velocity": (1.0, 1.0)}}


def _registration(character: CharacterDef, gait, envs: dict, physics_hz: int) -> Registration:
    clips = {"planar_jump": _jump(character)}
    return Registration(character, gait=gait, clips=clips, envs=envs, physics_hz=physics_hz)


WALKER_REGISTRATION = _registration(
    WALKER,
    WALKER_GAIT,
    {
        "Walker": _at_speed(),
        # the reference retargeted per body (env.retarget), as configs/walker_legs.yaml ships
        "WalkerLegs": _at_speed(left_leg_length=_LEGS, right_leg_length=_LEGS)
        | {"config": {"retarget": True}},
    },
    # 600 Hz ([WL19] Table 2): the gait runs well at 300 Hz (benchmarks/physics_rate.py, and
    # configs/walker_legs.yaml uses it), but the planar jump clip's landings are not measured
    physics_hz=600,
)
HOPPER_REGISTRATION = _registration(
    HOPPER,
    HOPPER_GAIT,
    {"Hopper": _at_speed(), "HopperShape": _at_speed(leg_length=_LEGS, torso_length=(0.8, 1.2))},
    physics_hz=600,  # not measured yet: [WL19] Table 2's rate
)

"""3D box characters of [WL19] §5.3 built with MjSpec: B = F(B̄, b) with b = (b_g, b_l^1..N).

A base character is a tree of boxes (or ellipsoids for swimmers) under a free root joint. In the
base pose every body frame is aligned with the world (x forward, y left, z up). A part's joint
sits at `anchor` in its parent, a fraction of the parent's extents measured from the parent's
box center, and its box center sits at `offset`, a fraction of its own extents from the joint.
Scaling a part by the global variation b_g ∈ R³ and its local variation b_l^i ∈ R³ (element-wise
extents x, y, z) therefore moves every joint with the boxes it connects. One density for every
shape: mass follows volume. Swimmers move in MuJoCo's fluid model (ellipsoid lift and drag,
water density) without gravity: a body of water's density is neutrally buoyant.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import mujoco
import numpy as np

from paramimic.characters.body import (
    DENSITY,
    PLANAR_AXIS,
    Body,
    Joint,
    ShapeParam,
    add_hinge,
    add_sensors,
    add_servos,
    index_character,
    joint_names,
    world_spec,
)
from paramimic.characters.dimensions import Dims, shape_with_defaults
from paramimic.characters.registry import Registration
from paramimic.motion.procedural import SinusoidalMotion, alternating, gait

Vec3 = tuple[float, float, float]
WATER_DENSITY = 997.0  # kg/m³ ([WL19] §5.3)
WATER_VISCOSITY = 0.0009  # Pa·s
GLOBAL_RANGE = (0.5, 1.5)  # b_g ([WL19] §5.3)
LOCAL_RANGE = (0.7, 1.2)  # b_l^i
AXES = "xyz"
SWIM_DEPTH = 2.0  # m, root height of a swimmer at rest (there is no floor)


@dataclass(frozen=True)
class Part:
    """One rigid body with its joint(s) to the parent (hinges, in order from parent to child)."""

    name: str
    parent: str | None
    size: Vec3  # full extents x, y, z of the base body (m)
    anchor: Vec3 = (0.0, 0.0, 0.0)  # joint in the parent, fraction of the parent's extents
    offset: Vec3 = (0.0, 0.0, 0.0)  # box center from the joint, fraction of own extents
    joints: tuple[Joint, ...] = ()
    foot: bool = False  # a box whose 4 lower corners are ground contact points ([WL19] Eq. 1)


@dataclass(frozen=True)
class BodyPlan:
    """A base character B̄ of boxes and its shape parameterization (b_g, b_l^1..N)."""

    name: str
    parts: tuple[Part, ...]
    end_effectors: tuple[str, ...]
    legs: tuple[tuple[str, ...], ...] = ()  # parts from hip to sole of each leg
    swims: bool = False
    geom: Literal["box", "ellipsoid"] = "box"
    extra_fall_bodies: tuple[str, ...] = ()

    @property
    def root(self) -> str:
        return self.parts[0].name

    @property
    def feet(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parts if p.foot)

    @property
    def fall_bodies(self) -> tuple[str, ...]:
        return (self.root, *self.extra_fall_bodies)

    @property
    def planar(self) -> bool:
        return False  # a free root

    @cached_property
    def joints(self) -> tuple[Joint, ...]:
        return tuple(j for p in self.parts for j in p.joints)

    @cached_property
    def shape_params(self) -> tuple[ShapeParam, ...]:
        out = [
            ShapeParam(f"global_{a}", *GLOBAL_RANGE, f"b_g: every extent along {a}") for a in AXES
        ]
        for p in self.parts:
            out += [
                ShapeParam(f"{p.name}_{a}", *LOCAL_RANGE, f"b_l: {p.name} along {a}") for a in AXES
            ]
        return tuple(out)

    def sagittal_hinge(self, part: str) -> Joint:
        """The hinge of a leg part about the pitch axis (what the retargeting bends)."""
        joints = next(p for p in self.parts if p.name == part).joints
        return next(j for j in joints if j.axis == PLANAR_AXIS)

    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.shape_params)

    def default_shape(self) -> dict[str, float]:
        return dict.fromkeys(self.param_names(), 1.0)

    # --- F(B̄, b) ------------------------------------------------------------------------------

    def extents(self, shape: dict[str, float]) -> dict[str, np.ndarray]:
        """Scaled box extents of every part: size ⊙ b_g ⊙ b_l^i."""
        g = np.array([shape[f"global_{a}"] for a in AXES])
        return {
            p.name: np.array(p.size) * g * np.array([shape[f"{p.name}_{a}"] for a in AXES])
            for p in self.parts
        }

    def layout(self, shape: dict[str, float]) -> tuple[dict, dict, dict]:
        """(extents, joint position in the parent frame, joint position relative to the root
        joint in the base pose) of every part; all frames are world-aligned in the base pose."""
        ext = self.extents(shape)
        local, world = {}, {}
        by_name = {p.name: p for p in self.parts}
        for p in self.parts:
            if p.parent is None:
                local[p.name] = np.zeros(3)
                world[p.name] = np.zeros(3)
                continue
            parent = by_name[p.parent]
            local[p.name] = (np.array(parent.offset) + np.array(p.anchor)) * ext[parent.name]
            world[p.name] = world[p.parent] + local[p.name]
        return ext, local, world

    def rest_height(self, shape: dict[str, float]) -> tuple[float, np.ndarray]:
        """Root height with the soles on the ground (or the swimming depth), and leg lengths:
        the vertical distance from each leg's first joint to its sole in the base pose."""
        ext, _, world = self.layout(shape)
        by_name = {p.name: p for p in self.parts}

        def sole(name: str) -> float:
            p = by_name[name]
            return world[name][2] + (p.offset[2] - 0.5) * ext[name][2]

        legs = np.array([world[leg[0]][2] - sole(leg[-1]) for leg in self.legs])
        if self.swims:
            return SWIM_DEPTH, legs
        return -min(sole(f) for f in self.feet), legs

    def dimensions(self, shape: dict[str, float]) -> Dims:
        """What the shape sets: every part's box (size ⊙ b_g ⊙ b_l^i) and where its joint sits
        in the parent, the feet's contact corners, and the root height on the ground."""
        ext, local, _ = self.layout(shape)
        height, legs = self.rest_height(shape)
        bodies, geoms, sites = {}, {}, {}
        for p in self.parts:
            bodies[p.name] = [0.0, 0.0, height] if p.parent is None else local[p.name].tolist()
            center, half = np.array(p.offset) * ext[p.name], ext[p.name] / 2
            geoms[p.name] = {"pos": center.tolist(), "size": half.tolist()}
            sites[f"{p.name}_end"] = center.tolist()
            if p.foot:
                for i, (sx, sy) in enumerate([(-1, -1), (-1, 1), (1, -1), (1, 1)]):
                    corner = center + half * np.array([sx, sy, -1.0])  # [WL19] Eq. 1 points
                    sites[f"{p.name}_c{i}"] = corner.tolist()
        lengths = {p.name: float(ext[p.name][2]) for p in self.parts}
        return Dims(bodies, geoms, sites, legs, height, lengths)

    def compile(self, shape: dict[str, float] | None = None) -> Body:
        shape = shape_with_defaults(self, shape)
        dims = self.dimensions(shape)
        model = self.spec(shape, dims).compile()
        return index_character(self, shape, model, dims.legs, dims.hip_height, dims.lengths)

    def spec(
        self, shape: dict[str, float] | None = None, dims: Dims | None = None
    ) -> mujoco.MjSpec:
        dims = dims or self.dimensions(shape_with_defaults(self, shape))
        spec = world_spec(self.name, floor=not self.swims, light_height=dims.hip_height + 4)
        if self.swims:
            spec.option.gravity = [0.0, 0.0, 0.0]
            spec.option.density = WATER_DENSITY
            spec.option.viscosity = WATER_VISCOSITY
        kind = (
            mujoco.mjtGeom.mjGEOM_ELLIPSOID
            if self.geom == "ellipsoid"
            else mujoco.mjtGeom.mjGEOM_BOX
        )
        common = dict(
            type=kind,
            density=WATER_DENSITY if self.swims else DENSITY,
            contype=1,
            conaffinity=0,
            rgba=[0.45, 0.6, 0.85, 1],
        )
        bodies: dict[str, mujoco.MjsBody] = {}
        for p in self.parts:
            parent = spec.worldbody if p.parent is None else bodies[p.parent]
            body = parent.add_body(name=p.name, pos=dims.bodies[p.name])
            if p.parent is None:
                body.add_freejoint(name="root")
            bodies[p.name] = body
            for j in p.joints:
                add_hinge(body, j)
            g = body.add_geom(name=p.name, **dims.geoms[p.name], **common)
            if self.swims:
                g.fluid_ellipsoid = 1.0  # lift and drag of the ellipsoid model
            body.add_site(name=f"{p.name}_end", pos=dims.sites[f"{p.name}_end"])
            if p.foot:
                for i in range(4):
                    body.add_site(name=f"{p.name}_c{i}", pos=dims.sites[f"{p.name}_c{i}"])
        add_servos(spec, self.joints)
        add_sensors(spec, [j.name for j in self.joints], self.end_effectors, self.root)
        return spec


# --- the characters --------------------------------------------------------------------------

PITCH = (0.0, -1.0, 0.0)  # positive = flexion forward (as the planar characters)
ROLL = (1.0, 0.0, 0.0)
YAW = (0.0, 0.0, 1.0)


def ball(name: str, kp: float, torque: float, lim: float = 1.0) -> tuple[Joint, ...]:
    """A 3-DOF joint as roll, pitch, yaw hinges (stable PD servos need scalar joints)."""
    return (
        Joint(f"{name}_roll", (-lim, lim), kp, torque, axis=ROLL),
        Joint(f"{name}_pitch", (-lim, lim), kp, torque, axis=PITCH),
        Joint(f"{name}_yaw", (-lim, lim), kp, torque, axis=YAW),
    )


def leg(
    side: str, parent: str, anchor: Vec3, thigh: Vec3, shin: Vec3, foot: Vec3, kp: float
) -> tuple[Part, ...]:
    """Hip (3 DOF), knee (1 DOF), ankle (2 DOF, pitch and roll), box foot ([WL19] §5.3)."""
    torque = 0.6 * kp
    return (
        Part(
            f"thigh_{side}",
            parent,
            thigh,
            anchor,
            (0.0, 0.0, -0.5),
            ball(f"hip_{side}", kp, torque, 1.2),
        ),
        Part(
            f"shin_{side}",
            f"thigh_{side}",
            shin,
            (0.0, 0.0, -0.5),
            (0.0, 0.0, -0.5),
            (Joint(f"knee_{side}", (-2.4, 0.0), kp, torque),),
        ),
        Part(
            f"foot_{side}",
            f"shin_{side}",
            foot,
            (0.0, 0.0, -0.5),
            (0.25, 0.0, -0.5),  # the ankle above the rear quarter of the foot
            (
                Joint(f"ankle_{side}_pitch", (-0.8, 0.8), 0.4 * kp, 0.4 * torque),
                Joint(f"ankle_{side}_roll", (-0.5, 0.5), 0.4 * kp, 0.4 * torque, axis=ROLL),
            ),
            foot=True,
        ),
    )


def _biped_lower() -> BodyPlan:
    kp = 1500.0
    hip = Part("hip", None, (0.2, 0.3, 0.15))
    torso = Part(
        "torso",
        "hip",
        (0.22, 0.3, 0.35),
        (0.0, 0.0, 0.5),
        (0.0, 0.0, 0.5),
        ball("torso", kp, 0.6 * kp),
    )
    legs = [
        leg(s, "hip", (0.0, y, -0.5), (0.1, 0.1, 0.42), (0.08, 0.08, 0.42), (0.22, 0.1, 0.05), kp)
        for s, y in (("r", -0.3), ("l", 0.3))
    ]
    return BodyPlan(
        name="biped_lower",
        parts=(hip, torso, *legs[0], *legs[1]),
        end_effectors=("foot_r", "foot_l", "torso"),
        legs=(("thigh_r", "shin_r", "foot_r"), ("thigh_l", "shin_l", "foot_l")),
        extra_fall_bodies=("torso",),
    )


def _quadruped() -> BodyPlan:
    kp = 1200.0
    trunk = Part("trunk", None, (0.8, 0.3, 0.2))
    head = Part(
        "head", "trunk", (0.2, 0.15, 0.15), (0.5, 0.0, 0.3), (0.5, 0.0, 0.2), ball("neck", 100, 60)
    )
    legs = [
        leg(s, "trunk", (x, y, -0.5), (0.08, 0.08, 0.3), (0.06, 0.06, 0.3), (0.14, 0.08, 0.04), kp)
        for s, x, y in (
            ("fr", 0.4, -0.35),
            ("fl", 0.4, 0.35),
            ("hr", -0.4, -0.35),
            ("hl", -0.4, 0.35),
        )
    ]
    return BodyPlan(
        name="quadruped",
        parts=(trunk, head, *(p for lg in legs for p in lg)),
        end_effectors=("foot_fr", "foot_fl", "foot_hr", "foot_hl", "head"),
        legs=tuple((f"thigh_{s}", f"shin_{s}", f"foot_{s}") for s in ("fr", "fl", "hr", "hl")),
        extra_fall_bodies=("head",),
    )


def _swimjoint_names(name: str, kp: float, first: Vec3, second: Vec3) -> tuple[Joint, ...]:
    return (
        Joint(f"{name}_a", (-0.8, 0.8), kp, 0.6 * kp, axis=first),
        Joint(f"{name}_b", (-0.5, 0.5), kp, 0.6 * kp, axis=second),
    )


def _fish() -> BodyPlan:
    """Six bodies in a row, head first; each joint bends sideways (yaw) and up-down (pitch)."""
    sizes = [(0.22, 0.12, 0.18), (0.22, 0.13, 0.2), (0.2, 0.11, 0.18), (0.18, 0.08, 0.14)]
    sizes += [(0.15, 0.05, 0.1), (0.12, 0.02, 0.22)]  # the last is the caudal fin
    parts = [Part("body0", None, sizes[0])]
    for i in range(1, 6):
        parts.append(
            Part(
                f"body{i}",
                f"body{i - 1}",
                sizes[i],
                (-0.5, 0.0, 0.0),
                (-0.5, 0.0, 0.0),
                _swimjoint_names(f"spine{i}", 40.0 - 5.0 * i, YAW, PITCH),
            )
        )
    return BodyPlan(
        name="fish",
        parts=tuple(parts),
        end_effectors=("body5",),  # the tail; not the root (body0)
        swims=True,
        geom="ellipsoid",
    )


def _manta() -> BodyPlan:
    """A trunk, two wings of three bodies each and a one-body tail; wings flap (roll) and
    twist (pitch)."""
    parts = [Part("trunk", None, (0.5, 0.3, 0.1))]
    for side, y in (("r", -1.0), ("l", 1.0)):
        parent = "trunk"
        for i, (sx, sy) in enumerate([(0.42, 0.25), (0.32, 0.25), (0.2, 0.22)]):
            name = f"wing{i}_{side}"
            parts.append(
                Part(
                    name,
                    parent,
                    (sx, sy, 0.05 - 0.01 * i),
                    (0.0, 0.5 * y, 0.0),
                    (0.0, 0.5 * y, 0.0),
                    _swimjoint_names(f"{name}", 30.0 - 8.0 * i, ROLL, PITCH),
                )
            )
            parent = name
    parts.append(
        Part(
            "tail",
            "trunk",
            (0.4, 0.03, 0.03),
            (-0.5, 0, 0),
            (-0.5, 0, 0),
            _swimjoint_names("tail", 5.0, YAW, PITCH),
        )
    )
    return BodyPlan(
        name="manta",
        parts=tuple(parts),
        end_effectors=("wing2_r", "wing2_l", "tail"),
        swims=True,
        geom="ellipsoid",
    )


BIPED_LOWER = _biped_lower()
QUADRUPED = _quadruped()
FISH = _fish()
MANTA = _manta()


# --- their reference gaits ([WL19] §5.3: sinusoidal keyframes) ------------------------------

# The lower-body biped walks like the planar walker: hip pitch, knee and ankle pitch per leg,
# with a little hip roll shifting the weight over the stance leg. The offsets (the mean pose)
# stand with slightly bent knees and flat feet (hip + knee + ankle = 0).
_BIPED_LEG = {  # one leg: offset, a1, a2, phase
    "hip_{side}_pitch": (0.10, 0.32, 0.00, 0.00),
    "knee_{side}": (-0.20, -0.30, 0.05, 0.25),
    "ankle_{side}_pitch": (0.10, 0.15, 0.00, -0.10),
    "hip_{side}_roll": (0.00, 0.04, 0.00, 0.25),
}
BIPED_LOWER_GAIT = gait(joint_names(BIPED_LOWER), 1.0, alternating(_BIPED_LEG))


def _trot() -> SinusoidalMotion:
    """A trot: diagonal legs (front-right with hind-left) swing together, half a cycle apart."""
    rows = {}
    for side, phase in (("fr", 0.0), ("hl", 0.0), ("fl", 0.5), ("hr", 0.5)):
        rows[f"hip_{side}_pitch"] = (0.10, 0.30, 0.00, phase)
        rows[f"knee_{side}"] = (-0.20, -0.30, 0.00, phase + 0.25)
        rows[f"ankle_{side}_pitch"] = (0.10, 0.10, 0.00, phase - 0.10)
    return gait(joint_names(QUADRUPED), 0.6, rows)


QUADRUPED_GAIT = _trot()

# Carangiform swimming: a wave travels head to tail along the spine (yaw), its amplitude
# growing toward the tail ([WL19] §5.3: sinusoidal keyframes).
FISH_GAIT = gait(
    joint_names(FISH),
    1.0,
    {f"spine{i}_a": (0.0, 0.08 + 0.06 * i, 0.0, -0.15 * i) for i in range(1, 6)},
)

# Manta: the wings flap (roll, mirrored left and right) with a lag toward the tips and twist
# (pitch) a quarter cycle ahead, which turns the flap into thrust.
MANTA_GAIT = gait(
    joint_names(MANTA),
    1.5,
    {
        f"wing{i}_{side}_{dof}": (0.0, sign * amp, 0.0, lag - 0.1 * i)
        for i in range(3)
        for side, sign in (("l", 1.0), ("r", -1.0))
        for dof, amp, lag in (("a", 0.35, 0.0), ("b", 0.15 * sign, 0.25))
    },
)


BIPED_LOWER_REGISTRATION = Registration(BIPED_LOWER, gait=BIPED_LOWER_GAIT)
QUADRUPED_REGISTRATION = Registration(QUADRUPED, gait=QUADRUPED_GAIT)
SWIMMER_WEIGHTS = (3.0, 2.0, 4.0, 1.0, 0.5, 0.5)  # [WL19] Table 3, fish and manta ray
FISH_REGISTRATION = Registration(FISH, gait=FISH_GAIT, reward_weights=SWIMMER_WEIGHTS)
MANTA_REGISTRATION = Registration(MANTA, gait=MANTA_GAIT, reward_weights=SWIMMER_WEIGHTS)

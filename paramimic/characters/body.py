"""Parametric planar characters built with MjSpec: B = F(B̄, b) ([WL19] §3.1, §5.3).

A base character is a tree of segments. Each segment's body frame sits at its joint; its geom
extends from there along `direction` for `length`. Children attach at the parent's start or end,
so joint anchors follow the parent's (scaled) length. Geoms share one density, so mass follows
volume. Actuators are MuJoCo position servos with damping `kv`, integrated implicitly
(`implicitfast`): the stable PD controller of [WL19] Eq. 3, with gains tuned once on the base body.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from paramimic.characters.dimensions import Dims, shape_with_defaults

DENSITY = 1000.0  # kg/m^3, constant for every shape so that mass follows volume
TIMESTEP = 1.0 / 600.0  # [WL19] Table 2: 600 Hz simulation
PLANAR_AXIS = (0.0, -1.0, 0.0)  # positive angle = flexion forward in the sagittal (x-z) plane
DOWN = (0.0, 0.0, -1.0)
UP = (0.0, 0.0, 1.0)


@dataclass(frozen=True)
class Joint:
    """A hinge with a position servo. `kp` in N·m/rad, `torque` the |τ| limit in N·m."""

    name: str
    range: tuple[float, float]
    kp: float
    torque: float
    kv_ratio: float = 0.1  # kv = kv_ratio * kp
    axis: tuple[float, float, float] = PLANAR_AXIS  # hinge axis in the body frame


@dataclass(frozen=True)
class Segment:
    """One rigid segment. Capsules extend along `direction`; a foot is a box under its joint."""

    name: str
    parent: str | None
    length: float
    width: float  # capsule radius, or half-width of a foot box
    joint: Joint | None = None
    kind: Literal["capsule", "foot"] = "capsule"
    direction: tuple[float, float, float] = DOWN
    attach: Literal["start", "end"] = "end"
    thickness: float = 0.05  # foot box height (m)


@dataclass(frozen=True)
class ShapeParam:
    """A named body parameter b_i: a scale with a default of 1 and the range it is meant for."""

    name: str
    low: float
    high: float
    doc: str
    # part of `shape_space: full` (the documented family); False for a refinement that multiplies
    # another parameter (the humanoid's per-leg lengths), named in `task` to vary it
    in_full: bool = True


@dataclass(frozen=True)
class CharacterDef:
    """A base character B̄ and the map from a shape vector b to per-segment scales."""

    name: str
    segments: tuple[Segment, ...]
    shape_params: tuple[ShapeParam, ...]
    scales: Callable[
        [dict[str, float]], dict[str, tuple[float, float]]
    ]  # (shape) -> {segment: (length scale, width scale)}
    legs: tuple[tuple[str, ...], ...]  # segments whose lengths add up to each leg
    end_effectors: tuple[str, ...]
    feet: tuple[str, ...]

    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.shape_params)

    def default_shape(self) -> dict[str, float]:
        return {p.name: 1.0 for p in self.shape_params}

    @property
    def joints(self) -> tuple[Joint, ...]:
        return tuple(s.joint for s in self.segments if s.joint is not None)

    @property
    def root(self) -> str:
        return self.segments[0].name

    @property
    def fall_bodies(self) -> tuple[str, ...]:
        """Bodies whose contact with the ground is a fall."""
        return (self.root,)

    @property
    def planar(self) -> bool:
        return True  # slide x, slide z and pitch

    @property
    def swims(self) -> bool:
        return False

    def pose_qpos(self, character: Body, pose) -> np.ndarray:
        """qpos [n, nq] of clip poses (a `ClipPose` with world root heights): root x, z
        relative to the body's build height, pitch about PLANAR_AXIS; joints by name."""
        model = character.model
        qpos = np.zeros((len(pose.root_position), model.nq))
        qpos[:, 0] = pose.root_position[:, 0]
        qpos[:, 1] = pose.root_position[:, 2] - character.hip_height
        rotvec = Rotation.from_quat(pose.root_quat).as_rotvec()
        qpos[:, 2] = rotvec @ np.array(PLANAR_AXIS)
        for r, name in enumerate(pose.revolute_names):
            qpos[:, model.jnt_qposadr[model.joint(name).id]] = pose.revolute[:, r]
        return qpos

    def dimensions(self, shape: dict[str, float]) -> Dims:
        return planar_dimensions(self, shape)

    def spec(self, shape: dict[str, float] | None = None) -> mujoco.MjSpec:
        return build_spec(self, shape)

    def compile(self, shape: dict[str, float] | None = None) -> Body:
        shape = shape_with_defaults(self, shape)
        dims = self.dimensions(shape)
        model = build_spec(self, shape, dims).compile()
        return index_character(self, shape, model, dims.legs, dims.hip_height, dims.lengths)


@dataclass
class Body:
    """A compiled character: the model plus the indices the environment needs."""

    definition: CharacterDef
    shape: dict[str, float]
    model: mujoco.MjModel
    qpos_idx: np.ndarray  # qpos addresses of actuated joints
    qvel_idx: np.ndarray
    ctrl_low: np.ndarray
    ctrl_high: np.ndarray
    torque_limit: np.ndarray
    ee_site_ids: np.ndarray
    ee_sensor: slice  # sensordata of end-effector positions in the root frame, [n_ee * 3]
    tau_sensor: slice  # sensordata of actuator torques [nj]; q, dq, ee, tau are one block
    up_sensor: slice  # sensordata of the root's z axis in the world
    com_sensor: slice  # sensordata of the whole-body COM in the world
    contact_site_ids: np.ndarray
    root_body_id: int
    leg_lengths: np.ndarray
    mass: float
    hip_height: float  # root (hip) height when standing straight on the ground
    segment_lengths: dict[str, float] = field(default_factory=dict)


def joint_names(definition) -> tuple[str, ...]:
    """The actuated joints of a character, in actuator order (what a gait drives)."""
    return tuple(j.name for j in definition.joints)


def _scaled_segments(
    definition: CharacterDef, shape: dict[str, float]
) -> dict[str, tuple[float, float]]:
    scales = definition.scales(shape)
    return {
        s.name: (s.length * scales[s.name][0], s.width * scales[s.name][1])
        for s in definition.segments
    }


def planar_dimensions(definition: CharacterDef, shape: dict[str, float]) -> Dims:
    """What the shape sets in a planar character: each segment's length and width scaled
    (children attach at the parent's scaled start or end), the feet's boxes and contact points,
    and the hip height at which the straight legs stand on the ground."""
    dims = _scaled_segments(definition, shape)
    legs = [sum(dims[s][0] for s in leg) for leg in definition.legs]
    foot_drop = max(_foot_thickness(definition, shape, f) for f in definition.feet)
    hip_height = max(legs) + foot_drop
    by_name = {s.name: s for s in definition.segments}
    bodies, geoms, sites = {}, {}, {}
    for seg in definition.segments:
        length, width = dims[seg.name]
        if seg.parent is None:
            bodies[seg.name] = [0.0, 0.0, hip_height]
        elif seg.attach == "start":
            bodies[seg.name] = [0.0, 0.0, 0.0]
        else:
            parent = by_name[seg.parent]
            bodies[seg.name] = (np.array(parent.direction) * dims[parent.name][0]).tolist()
        if seg.kind == "capsule":
            end = (np.array(seg.direction) * length).tolist()
            geoms[seg.name] = {"fromto": [0, 0, 0, *end], "size": [width, 0, 0]}
            sites[f"{seg.name}_end"] = end
            continue
        # Foot: a box from 25 % of its length behind the ankle to 75 % in front, below it.
        thickness = seg.thickness * (width / seg.width)
        x0, x1 = -0.25 * length, 0.75 * length
        geoms[seg.name] = {
            "size": [length / 2, width, thickness / 2],
            "pos": [(x0 + x1) / 2, 0, -thickness / 2],
        }
        sites[f"{seg.name}_end"] = [x1, 0, -thickness / 2]
        for i, (x, y) in enumerate([(x0, -width), (x0, width), (x1, -width), (x1, width)]):
            sites[f"{seg.name}_c{i}"] = [x, y, -thickness]  # [WL19] Eq. 1 points
    lengths = {k: v[0] for k, v in dims.items()}
    return Dims(bodies, geoms, sites, np.array(legs), hip_height, lengths)


def build_spec(
    definition: CharacterDef, shape: dict[str, float] | None = None, dims: Dims | None = None
) -> mujoco.MjSpec:
    """F(B̄, b): a fresh MjSpec of the character with shape `b` standing on a ground plane."""
    shape = shape_with_defaults(definition, shape)
    dims = dims or planar_dimensions(definition, shape)
    spec = world_spec(definition.name)
    # Body geoms touch the floor but not each other (contype 1, conaffinity 0), as in gym envs.
    common = dict(density=DENSITY, contype=1, conaffinity=0, rgba=[0.45, 0.6, 0.85, 1])
    bodies: dict[str, mujoco.MjsBody] = {}
    for seg in definition.segments:
        parent = spec.worldbody if seg.parent is None else bodies[seg.parent]
        body = parent.add_body(name=seg.name, pos=dims.bodies[seg.name])
        if seg.parent is None:
            body.add_joint(name="rootx", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
            body.add_joint(name="rootz", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1])
            body.add_joint(name="rooty", type=mujoco.mjtJoint.mjJNT_HINGE, axis=list(PLANAR_AXIS))
        bodies[seg.name] = body
        if seg.joint is not None:
            add_hinge(body, seg.joint)
        kind = mujoco.mjtGeom.mjGEOM_CAPSULE if seg.kind == "capsule" else mujoco.mjtGeom.mjGEOM_BOX
        body.add_geom(name=seg.name, type=kind, **dims.geoms[seg.name], **common)
        for site, pos in dims.sites.items():
            if site.rpartition("_")[0] == seg.name:
                body.add_site(name=site, pos=pos)
    add_servos(spec, definition.joints)
    add_sensors(
        spec, [j.name for j in definition.joints], definition.end_effectors, definition.root
    )
    return spec


def world_spec(name: str, floor: bool = True, light_height: float = 4.0) -> mujoco.MjSpec:
    """An empty world every character is built into: the simulation options of [WL19] Table 2
    (600 Hz, the implicit integrator that makes the PD servos stable), a floor and a light."""
    spec = mujoco.MjSpec()
    spec.modelname = name
    spec.compiler.degree = False
    spec.option.timestep = TIMESTEP
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    if floor:
        # a checker of 0.5 m squares (a 16-pixel texture: visual only, cheap to compile), so
        # that motion and speed show in pictures
        spec.add_texture(name="checker", type=mujoco.mjtTexture.mjTEXTURE_2D,
                         builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, rgb1=[0.85, 0.85, 0.85],
                         rgb2=[0.6, 0.6, 0.62], width=16, height=16)  # fmt: skip
        checker = spec.add_material(name="checker", texrepeat=[1, 1], texuniform=True)
        checker.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "checker"
        spec.worldbody.add_geom(
            name="floor",
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[0, 0, 1],
            friction=[1.0, 0.005, 1e-4],
            material="checker",
        )
    spec.worldbody.add_light(pos=[0, 0, light_height], dir=[0, 0, -1])
    return spec


ARMATURE = 0.01  # kg m², every hinge, every body size (see `add_hinge`)


def add_hinge(body: mujoco.MjsBody, joint: Joint) -> None:
    """A limited hinge about `joint.axis` (body frame) with a constant armature.

    The armature does not follow the limb's inertia on purpose: it is what keeps the stiff PD
    servos (whose gains do not scale with the body) stable on light limbs. Scaled as the limb's
    own inertia (∝ L³w²), biped_lower and the quadruped at their half-size corners diverged
    under random actions at 600 Hz and could not hold their reference pose
    (tests/test_assorted_characters.py). At half size the armature is a
    larger share of a limb's inertia than on the base body: small bodies swing their limbs
    more sluggishly than volume alone would say."""
    body.add_joint(
        name=joint.name,
        type=mujoco.mjtJoint.mjJNT_HINGE,
        axis=list(joint.axis),
        range=list(joint.range),
        limited=mujoco.mjtLimited.mjLIMITED_TRUE,
        armature=ARMATURE,
    )


def add_servos(spec: mujoco.MjSpec, joints) -> None:
    """A position servo with damping per joint, named as the joint, clamped to the joint range
    and torque limit. Under `implicitfast` its damping k_d is integrated implicitly, as [WL19]
    Eq. 3 treats it; its stiffness acts on the current position (`stable_pd` adds the rest)."""
    for j in joints:
        act = spec.add_actuator(name=j.name, target=j.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=j.kp, kv=j.kv_ratio * j.kp)
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = list(j.range)
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-j.torque, j.torque]  # torque limits, [L21] §7.4


def add_sensors(
    spec: mujoco.MjSpec, joints: list[str], end_effectors: tuple[str, ...], root: str
) -> None:
    """One contiguous sensordata block the environment reads per step, in this order:
    joint angles [nj], joint velocities [nj], end-effectors in the root's inertial frame
    (FRAMEPOS with a body reference) [3 n_ee],
    actuator torques [nj], root z axis [3], whole-body COM [3]. Actuators are named as joints."""
    obj = mujoco.mjtObj
    kinds = mujoco.mjtSensor
    for j in joints:
        spec.add_sensor(
            name=f"q_{j}", type=kinds.mjSENS_JOINTPOS, objtype=obj.mjOBJ_JOINT, objname=j
        )
    for j in joints:
        spec.add_sensor(
            name=f"dq_{j}", type=kinds.mjSENS_JOINTVEL, objtype=obj.mjOBJ_JOINT, objname=j
        )
    for e in end_effectors:
        spec.add_sensor(
            name=f"ee_{e}",
            type=kinds.mjSENS_FRAMEPOS,
            objtype=obj.mjOBJ_SITE,
            objname=f"{e}_end",
            reftype=obj.mjOBJ_BODY,
            refname=root,
        )
    for j in joints:
        spec.add_sensor(
            name=f"tau_{j}",
            type=kinds.mjSENS_ACTUATORFRC,
            objtype=obj.mjOBJ_ACTUATOR,
            objname=j,
        )
    # the body frame (XBODY), not its inertial frame, whose axes follow the principal moments
    spec.add_sensor(name="up", type=kinds.mjSENS_FRAMEZAXIS, objtype=obj.mjOBJ_XBODY, objname=root)
    spec.add_sensor(name="com", type=kinds.mjSENS_SUBTREECOM, objtype=obj.mjOBJ_BODY, objname=root)


def _foot_thickness(definition: CharacterDef, shape: dict[str, float], foot: str) -> float:
    seg = next(s for s in definition.segments if s.name == foot)
    return seg.thickness * definition.scales(shape)[foot][1]


def index_character(
    definition,
    shape: dict[str, float],
    model: mujoco.MjModel,
    legs: np.ndarray,
    hip_height: float,
    lengths: dict[str, float],
) -> Body:
    """The indices of a compiled model built with `add_sensors` and sites `{ee}_end`,
    `{foot}_c0..3`. `definition` has `joints`, `end_effectors`, `feet` and `root`."""
    joints = definition.joints
    jids = [model.joint(j.name).id for j in joints]
    feet_sites = [f"{f}_c{i}" for f in definition.feet for i in range(4)]
    root = model.body(definition.root).id
    return Body(
        definition=definition,
        shape=shape,
        model=model,
        qpos_idx=np.array([model.jnt_qposadr[j] for j in jids]),
        qvel_idx=np.array([model.jnt_dofadr[j] for j in jids]),
        ctrl_low=np.array([j.range[0] for j in joints]),
        ctrl_high=np.array([j.range[1] for j in joints]),
        torque_limit=np.array([j.torque for j in joints]),
        ee_site_ids=np.array([model.site(f"{e}_end").id for e in definition.end_effectors]),
        contact_site_ids=np.array([model.site(s).id for s in feet_sites]),
        ee_sensor=slice(
            model.sensor(f"ee_{definition.end_effectors[0]}").adr[0],
            model.sensor(f"ee_{definition.end_effectors[-1]}").adr[0] + 3,
        ),
        tau_sensor=slice(
            model.sensor(f"tau_{joints[0].name}").adr[0],
            model.sensor(f"tau_{joints[-1].name}").adr[0] + 1,
        ),
        up_sensor=_sensor_slice(model, "up"),
        com_sensor=_sensor_slice(model, "com"),
        root_body_id=root,
        leg_lengths=legs,
        mass=float(model.body_subtreemass[root]),
        hip_height=hip_height,
        segment_lengths=lengths,
    )


def _sensor_slice(model: mujoco.MjModel, name: str) -> slice:
    s = model.sensor(name)
    return slice(int(s.adr[0]), int(s.adr[0] + s.dim[0]))


def stable_pd(model: mujoco.MjModel, timestep: float) -> mujoco.MjModel:
    """A copy of `model` whose servos are the stable PD controller of [WL19] Eq. 3 (Tan et al.
    2011; [L21] §7 uses its linear-time form): τ = −k_p(q + h q̇ − q̄) − k_d(q̇ + h q̈).

    The stiffness acting on the predicted position q + h q̇ is a damping of k_p h added to k_d;
    MuJoCo's `implicitfast` integrates every velocity-dependent actuator force implicitly, so
    the k_d (q̇ + h q̈) half is its own. The one difference from Eq. 3: MuJoCo treats the added
    k_p h q̇ implicitly too (M + h(k_d + h k_p) where Eq. 3 has M + h k_d), a little more damped."""
    model = copy.copy(model)
    model.actuator_biasprm[:, 2] -= model.actuator_gainprm[:, 0] * timestep
    return model

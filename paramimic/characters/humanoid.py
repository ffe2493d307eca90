"""The 3D humanoid of DeepMimic, built with MjSpec from its character description.

Bodies, joint offsets, shapes, masses and torque limits come from `character_humanoid3d.txt`
(shipped in `paramimic/data/deepmimic/`, MIT). Body frames keep the file's Y-up convention; the
free root joint carries the Z-up world pose. Each spherical joint becomes three hinges about the
local x, y, z axes in that order, so that every joint has a stable PD position servo (MuJoCo's
position actuators need a scalar joint); a clip's joint quaternion maps onto them as intrinsic
x-y-z Euler angles. Revolute joints (knees, elbows) are hinges about local z.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cached_property, partial
from importlib import resources

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from paramimic.characters.body import (
    ARMATURE,
    Body,
    Joint,
    ShapeParam,
    add_sensors,
    add_servos,
    index_character,
    world_spec,
)
from paramimic.characters.dimensions import Dims, shape_with_defaults
from paramimic.characters.registry import Registration
from paramimic.motion.clip import Clip, ClipPose, load_deepmimic

DATA = resources.files("paramimic") / "data" / "deepmimic"
# PD gains of DeepMimic's humanoid3d controller (kp in N·m/rad; kd = kp / 10)
KP = {"chest": 1000.0, "neck": 100.0, "hip": 500.0, "knee": 500.0, "ankle": 400.0}
KP |= {"shoulder": 400.0, "elbow": 300.0}
AXES = "xyz"
EULER = "XYZ"
# [WL19] §5.1, Fig. 2: legs up to 2x longer or shorter, arms 1.5x longer or 2x shorter (a),
# height 0.75-1.5x, every body 0.5-1.5x thicker (c): the family of `shape_space: full`. Each leg
# on its own (b, the paper's ±10 % inside a wider range) and the upper and the lower body's
# thickness on their own (d) multiply those (left leg: leg_length x left_leg_length); a config
# names them in `task` to vary them.
SHAPE_PARAMS = (
    ShapeParam("leg_length", 0.5, 2.0, "thigh and shin length"),
    ShapeParam("arm_length", 0.5, 1.5, "upper and lower arm length"),
    ShapeParam("height", 0.75, 1.5, "every length and width"),
    ShapeParam("thickness", 0.5, 1.5, "every width (capsule and sphere radii, box width)"),
    ShapeParam("left_leg_length", 0.5, 1.5, "the left thigh and shin, x leg_length", False),
    ShapeParam("right_leg_length", 0.5, 1.5, "the right thigh and shin, x leg_length", False),
    ShapeParam("upper_thickness", 0.5, 1.5, "widths above the pelvis, x thickness", False),
    ShapeParam("lower_thickness", 0.5, 1.5, "widths of the pelvis and legs, x thickness", False),
)
LEG, ARM = ("hip", "knee"), ("shoulder", "elbow")
SIDES = ("right", "left")  # the skeleton's order
BASE_LEG = (
    0.421546 + 0.40987
)  # thigh + shin of the file  # intrinsic: the x hinge first, then y in the rotated frame, then z


@dataclass(frozen=True)
class HumanoidDef:
    """The DeepMimic humanoid3d; the same interface as the planar `CharacterDef`."""

    name: str = "humanoid"
    end_effectors: tuple[str, ...] = ("right_ankle", "left_ankle", "right_wrist", "left_wrist")
    feet: tuple[str, ...] = ("right_ankle", "left_ankle")
    root: str = "root"
    fall_bodies: tuple[str, ...] = ("root", "chest", "neck")  # DeepMimic's EnableFallContact
    shape_params: tuple[ShapeParam, ...] = SHAPE_PARAMS
    planar: bool = False  # a free root
    swims: bool = False
    # the leg chains the sagittal retargeting bends (`paramimic/motion/retarget.py`): each hip's
    # and ankle's last Euler hinge (z, after x and y) and the knee lie in the thigh's sagittal
    # plane, the thigh and shin hanging along it (the file's offsets are along -y only)
    legs: tuple[tuple[str, ...], ...] = tuple(
        (f"{side}_hip", f"{side}_knee", f"{side}_ankle") for side in ("right", "left")
    )

    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.shape_params)

    def default_shape(self) -> dict[str, float]:
        return dict.fromkeys(self.param_names(), 1.0)

    @staticmethod
    def limb_scale(name: str, shape: dict[str, float]) -> float:
        """Length scale along a body's own limb axis: height x leg (x that side's) or arm
        length."""
        limb = 1.0
        if name.endswith(LEG):
            limb = shape["leg_length"] * shape[f"{name.split('_')[0]}_leg_length"]
        elif name.endswith(ARM):
            limb = shape["arm_length"]
        return shape["height"] * limb

    @staticmethod
    def width_scale(name: str, shape: dict[str, float]) -> float:
        """Width scale of a body: height x thickness x its half's (the pelvis and the legs are
        the lower body)."""
        lower = name == "root" or name.endswith(LEG + ("ankle",))
        half = shape["lower_thickness" if lower else "upper_thickness"]
        return shape["height"] * shape["thickness"] * half

    @cached_property
    def description(self) -> dict:
        return json.loads((DATA / "character_humanoid3d.txt").read_text())

    @cached_property
    def skeleton(self) -> list[dict]:
        return self.description["Skeleton"]["Joints"]

    @cached_property
    def joints(self) -> tuple[Joint, ...]:
        """Actuated hinges in the order of the file's joints."""
        out = []
        for j in self.skeleton:
            kp = next((v for k, v in KP.items() if j["Name"].endswith(k)), None)
            if j["Type"] == "spherical":
                for axis in AXES:
                    lim = np.pi / 2 if axis == "y" else np.pi  # Euler y stays in ±π/2
                    out.append(Joint(f"{j['Name']}_{axis}", (-lim, lim), kp, j["TorqueLim"]))
            elif j["Type"] == "revolute":
                out.append(
                    Joint(j["Name"], (j["LimLow0"], j["LimHigh0"]), kp, float(j["TorqueLim"]))
                )
        return tuple(out)

    def sagittal_hinge(self, part: str) -> Joint:
        """A leg part's hinge in the sagittal plane: the knee's own, a ball joint's z hinge."""
        names = (part, f"{part}_z")
        return next(j for j in self.joints if j.name in names)

    @cached_property
    def spherical(self) -> tuple[str, ...]:
        return tuple(j["Name"] for j in self.skeleton if j["Type"] == "spherical")

    @cached_property
    def revolute(self) -> tuple[str, ...]:
        return tuple(j["Name"] for j in self.skeleton if j["Type"] == "revolute")

    def dimensions(self, shape: dict[str, float]) -> Dims:
        """What the shape sets: joint offsets along a limb scale with that limb's length (the
        file's bodies hang along their local y), shapes scale in length and thickness, and
        masses follow the shapes' volumes; the hip height of the straight legs."""
        shapes = {b["Name"]: b for b in self.description["BodyDefs"]}
        bodies, geoms, sites = {}, {}, {}
        for j in self.skeleton:
            along = 1.0
            if j["Parent"] >= 0:
                along = self.limb_scale(self.skeleton[j["Parent"]]["Name"], shape)
            attach = np.array([j["AttachX"], j["AttachY"], j["AttachZ"]])
            bodies[j["Name"]] = (attach * along).tolist()
            length = self.limb_scale(j["Name"], shape)
            width = self.width_scale(j["Name"], shape)
            b = _scaled_shape(shapes[j["Name"]], length, width, shape["height"])
            geoms[j["Name"]], corners = _shape_dims(b)
            sites |= corners
            if j["Name"] in self.end_effectors:
                sites[f"{j['Name']}_end"] = [b["AttachX"], b["AttachY"], 0.0]
        # (right, left), the skeleton's order; the root path scales with the mean hip height
        legs = np.array([BASE_LEG * self.limb_scale(f"{side}_hip", shape) for side in SIDES])
        hip_height = float(legs.mean() + 0.05 * shape["height"])
        # joint to joint along each leg (the retargeting's thigh and shin)
        lengths = {}
        for j in self.skeleton:
            if j["Name"].endswith(("knee", "ankle")):
                lengths[self.skeleton[j["Parent"]]["Name"]] = float(
                    np.linalg.norm(bodies[j["Name"]])
                )
        return Dims(bodies, geoms, sites, legs, hip_height, lengths)

    def compile(self, shape: dict[str, float] | None = None) -> Body:
        shape = shape_with_defaults(self, shape)
        dims = self.dimensions(shape)
        model = self.spec(shape, dims).compile()
        return index_character(self, shape, model, dims.legs, dims.hip_height, dims.lengths)

    def spec(self, shape: dict | None = None, dims: Dims | None = None) -> mujoco.MjSpec:
        """The humanoid with shape b (see `dimensions`)."""
        dims = dims or self.dimensions(shape_with_defaults(self, shape))
        spec = world_spec(self.name)
        shapes = {b["Name"]: b for b in self.description["BodyDefs"]}
        # Body geoms touch the floor but not each other, as in DeepMimic's collision groups.
        common = dict(contype=1, conaffinity=0, rgba=[0.47, 0.55, 0.69, 1])
        bodies: dict[int, mujoco.MjsBody] = {}
        for j in self.skeleton:
            name = j["Name"]
            parent = spec.worldbody if j["Parent"] < 0 else bodies[j["Parent"]]
            body = parent.add_body(name=name, pos=dims.bodies[name])
            bodies[j["ID"]] = body
            if j["Parent"] < 0:
                body.add_freejoint(name="root")
            elif j["Type"] == "spherical":
                for axis in AXES:
                    body.add_joint(
                        name=f"{name}_{axis}",
                        type=mujoco.mjtJoint.mjJNT_HINGE,
                        axis=[float(axis == a) for a in AXES],
                        armature=ARMATURE,
                    )
            elif j["Type"] == "revolute":
                body.add_joint(
                    name=name,
                    type=mujoco.mjtJoint.mjJNT_HINGE,
                    axis=[0, 0, 1],
                    range=[j["LimLow0"], j["LimHigh0"]],
                    limited=mujoco.mjtLimited.mjLIMITED_TRUE,
                    armature=ARMATURE,
                )
            kind = _GEOM_TYPES[shapes[name]["Shape"]]
            body.add_geom(name=name, type=kind, **dims.geoms[name], **common)
            for site in (*(f"{name}_c{i}" for i in range(4)), f"{name}_end"):
                if site in dims.sites:
                    body.add_site(name=site, pos=dims.sites[site])
        add_servos(spec, self.joints)
        add_sensors(spec, [j.name for j in self.joints], self.end_effectors, self.root)
        return spec

    def pose_qpos(self, character: Body, pose: ClipPose) -> np.ndarray:
        """qpos [n, nq] of clip poses: free root (position, w-first quaternion) and the hinge
        angles of each joint, found by name."""
        model = character.model
        n = len(pose.root_position)
        qpos = np.zeros((n, model.nq))
        # the clip's root path scaled by the body's hip height (a simple retargeting)
        qpos[:, 0:3] = pose.root_position * (character.hip_height / (BASE_LEG + 0.05))
        qpos[:, 3:7] = Rotation.from_quat(pose.root_quat).as_quat(scalar_first=True)
        for s, name in enumerate(self.spherical):
            angles = Rotation.from_quat(pose.spherical[:, s]).as_euler(EULER)
            for i, axis in enumerate(AXES):
                qpos[:, model.jnt_qposadr[model.joint(f"{name}_{axis}").id]] = angles[:, i]
        for r, name in enumerate(self.revolute):
            qpos[:, model.jnt_qposadr[model.joint(name).id]] = pose.revolute[:, r]
        return qpos


def _volume(b: dict) -> float:
    if b["Shape"] == "sphere":
        return np.pi / 6 * b["Param0"] ** 3
    if b["Shape"] == "capsule":
        r = b["Param0"] / 2
        return np.pi * r**2 * b["Param1"] + 4 / 3 * np.pi * r**3
    return b["Param0"] * b["Param1"] * b["Param2"]


def _scaled_shape(b: dict, length: float, width: float, height: float) -> dict:
    """A body shape of the file scaled: capsules along y by `length`, radii by `width`;
    spheres by `width`; boxes (feet) by `height`, their height and width by `width`. The
    shape's center moves with the length; mass x volume ratio (one density per body)."""
    out = dict(b)
    if b["Shape"] == "capsule":
        out |= {"Param0": b["Param0"] * width, "Param1": b["Param1"] * length}
        out |= {"Param2": b["Param2"] * width}
        center = np.array([b["AttachX"], b["AttachY"] * length, b["AttachZ"]])
    elif b["Shape"] == "sphere":
        out |= {k: b[k] * width for k in ("Param0", "Param1", "Param2")}
        center = np.array([b["AttachX"], b["AttachY"], b["AttachZ"]]) * length
    else:
        out |= {"Param0": b["Param0"] * height, "Param1": b["Param1"] * width}
        out |= {"Param2": b["Param2"] * width}
        center = np.array([b["AttachX"] * height, b["AttachY"] * width, b["AttachZ"]])
    out["AttachX"], out["AttachY"], out["AttachZ"] = center.tolist()
    out["Mass"] = float(b["Mass"]) * _volume(out) / _volume(b)
    return out


_GEOM_TYPES = {
    "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
    "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
    "box": mujoco.mjtGeom.mjGEOM_BOX,
}


def _shape_dims(b: dict) -> tuple[dict, dict[str, list[float]]]:
    """A DeepMimic body shape as geom attributes with its mass: sphere (Param0 = diameter),
    capsule along local y (Param0 = diameter, Param1 = cylinder length) or box (Param0..2 =
    full sizes, its sole's corners as contact sites)."""
    center = np.array([b["AttachX"], b["AttachY"], b["AttachZ"]])
    mass = float(b["Mass"])
    if b["Shape"] == "sphere":
        return {"pos": center.tolist(), "size": [b["Param0"] / 2, 0, 0], "mass": mass}, {}
    if b["Shape"] == "capsule":
        half = np.array([0.0, b["Param1"] / 2, 0.0])
        fromto = [*(center - half), *(center + half)]
        return {"fromto": fromto, "size": [b["Param0"] / 2, 0, 0], "mass": mass}, {}
    if b["Shape"] == "box":
        half = np.array([b["Param0"], b["Param1"], b["Param2"]]) / 2
        corners = {
            f"{b['Name']}_c{i}": (center + half * np.array([sx, -1.0, sz])).tolist()
            for i, (sx, sz) in enumerate([(-1, -1), (-1, 1), (1, -1), (1, 1)])
        }  # the sole: lowest face in y
        return {"pos": center.tolist(), "size": half.tolist(), "mass": mass}, corners
    raise ValueError(f"unknown DeepMimic shape {b['Shape']!r} of body {b['Name']!r}")


HUMANOID = HumanoidDef()


# shipped clips: name -> its file (humanoid3d_<file>.txt in DeepMimic's format); DeepMimic's in
# data/deepmimic, one imported from the shared CMU BVH file by `paramimic clip import` in data/cmu
CLIPS = {name: DATA / f"humanoid3d_{name}.txt"
         for name in ("walk", "run", "jump", "backflip", "cartwheel")}  # fmt: skip
CLIPS["dance"] = DATA / "humanoid3d_dance_b.txt"  # in place, looping: [WL19] Fig. 2c
CLIPS["cmu_walk"] = DATA.parent / "cmu" / "humanoid3d_cmu_walk.txt"  # a user's mocap, imported


def humanoid_clip(name: str) -> Clip:
    """A shipped humanoid3d clip by name: DeepMimic's walk, run, jump, backflip, cartwheel and
    dance, and cmu_walk (the shared CMU BVH walk as `paramimic clip import --loop` imports it)."""
    if name not in CLIPS:
        raise KeyError(f"no humanoid clip {name!r}; shipped: {', '.join(CLIPS)}")
    return load_deepmimic(CLIPS[name], name=f"humanoid_{name}")


HUMANOID_REGISTRATION = Registration(
    HUMANOID,
    clips={f"humanoid_{name}": partial(humanoid_clip, name) for name in CLIPS},
    clip_file=load_deepmimic,  # a user's humanoid3d clip in DeepMimic's format
    reward_weights=(4.0, 1.0, 2.0, 1.0, 2.0, 1.0),  # [WL19] Table 3, biped (full)
    # the looping clips as [WL19] reference gaits (ParamEnv), as configs/humanoid_walk.yaml
    # sets them: paramimic/HumanoidWalkGait-v0 and paramimic/HumanoidRunGait-v0
    envs={
        f"Humanoid{name.capitalize()}Gait": {
            "config": {"gait": f"humanoid_{name}", "physics_hz": 300, "deviation_limit": 0.5}
        }
        for name in ("walk", "run")
    },
)

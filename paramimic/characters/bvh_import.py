"""A user's motion capture (BVH) as a humanoid clip in DeepMimic's format.

The file is parsed with pybvh (numpy-native, per-joint Euler orders, forward kinematics, up-axis
detection, resampling and mirroring, maintained; bvhio's per-joint transform objects are slower
and need PyGLM). The source skeleton's joints are mapped onto the humanoid's by one of the
built-in maps or a user's YAML map (`detect_map`), and the motion is retargeted by positions:
for every frame, the humanoid's body frames are built from the source's joint positions, so a
source whose rest pose differs from the humanoid's (a T-pose against arms hanging down) needs no
rest-pose alignment:

- the pelvis from the hips' lateral axis and the spine, the chest from the shoulders and the
  neck, the neck from the head (the humanoid's +x forward, +y up, +z right);
- each thigh and upper arm along its bone, twisted so that the next bone lies in the plane of
  the 1-DOF knee or elbow: the knee (<= 0) and elbow (>= 0) angles are the angles between the
  bones, projected onto the hinge; a limb bent the wrong way or held straight keeps the twist of
  the pelvis or chest and is counted in the report;
- each foot along the ankle-to-toe direction, its pitch corrected by the source's rest foot
  (the rest foot is flat);
- the root's path scaled by the ratio of the legs' lengths (the humanoid's over the source's,
  which also converts the file's units), resampled to `fps`, and moved vertically so that the
  lowest foot point touches the floor whenever the source stands (pybvh's foot contacts):
  between contacts the offset is interpolated, so a jump still leaves the ground.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from paramimic.characters.humanoid import BASE_LEG, HUMANOID, SIDES
from paramimic.motion.clip import Clip, load_deepmimic

# the roles a map names: the humanoid's joints and what their frames are built from
ROLES = ("hips", "spine", "chest", "neck", "head") + tuple(
    f"{side}_{part}"
    for side in SIDES
    for part in ("thigh", "knee", "ankle", "toe", "upper_arm", "elbow", "wrist")
)
# DeepMimic's joint columns after the root (paramimic/data/deepmimic/README.md)
JOINT_COLUMNS = ("chest", "neck", "right_hip", "right_knee", "right_ankle", "right_shoulder",
                 "right_elbow", "left_hip", "left_knee", "left_ankle", "left_shoulder",
                 "left_elbow")  # fmt: skip
STRAIGHT = np.radians(5.0)  # a limb bent less than this keeps its parent's twist
MIN_FRAME_TIME, MAX_FRAME_TIME = 1.0 / 1000.0, 1.0  # s: motion capture runs at 1-1000 fps


@dataclass(frozen=True)
class SkeletonMap:
    """Source joint names of every role; `why` says how it was chosen."""

    name: str
    joints: dict[str, str]
    why: str = ""


def _sided(left: dict[str, str], right: dict[str, str], trunk: dict[str, str]) -> dict[str, str]:
    out = dict(trunk)
    for side, names in (("left", left), ("right", right)):
        out |= {f"{side}_{role}": name for role, name in names.items()}
    return out


def _limbs(prefix: str, side: str, names: tuple[str, ...]) -> dict[str, str]:
    roles = ("thigh", "knee", "ankle", "toe", "upper_arm", "elbow", "wrist")
    return {role: f"{prefix}{side}{n}" for role, n in zip(roles, names, strict=True)}


# CMU / 3ds Max: LeftShoulder is the upper arm (its parent LeftCollar the clavicle)
CMU = SkeletonMap("cmu", _sided(
    _limbs("", "Left", ("Hip", "Knee", "Ankle", "Toe", "Shoulder", "Elbow", "Wrist")),
    _limbs("", "Right", ("Hip", "Knee", "Ankle", "Toe", "Shoulder", "Elbow", "Wrist")),
    {"hips": "Hips", "spine": "Chest", "chest": "Chest2", "neck": "Neck", "head": "Head"},
))  # fmt: skip
# Mixamo and LAFAN1: LeftShoulder is the clavicle, LeftArm the upper arm
MIXAMO = SkeletonMap("mixamo", _sided(
    _limbs("mixamorig:", "Left", ("UpLeg", "Leg", "Foot", "ToeBase", "Arm", "ForeArm", "Hand")),
    _limbs("mixamorig:", "Right", ("UpLeg", "Leg", "Foot", "ToeBase", "Arm", "ForeArm", "Hand")),
    {"hips": "mixamorig:Hips", "spine": "mixamorig:Spine", "chest": "mixamorig:Spine2",
     "neck": "mixamorig:Neck", "head": "mixamorig:Head"},
))  # fmt: skip
LAFAN1 = SkeletonMap("lafan1", _sided(
    _limbs("", "Left", ("UpLeg", "Leg", "Foot", "Toe", "Arm", "ForeArm", "Hand")),
    _limbs("", "Right", ("UpLeg", "Leg", "Foot", "Toe", "Arm", "ForeArm", "Hand")),
    {"hips": "Hips", "spine": "Spine", "chest": "Spine2", "neck": "Neck", "head": "Head"},
))  # fmt: skip
# the humanoid's own skeleton, as `export_bvh` writes it
DEEPMIMIC = SkeletonMap("deepmimic", _sided(
    {"thigh": "left_hip", "knee": "left_knee", "ankle": "left_ankle", "toe": "EndSiteleft_ankle",
     "upper_arm": "left_shoulder", "elbow": "left_elbow", "wrist": "left_wrist"},
    {"thigh": "right_hip", "knee": "right_knee", "ankle": "right_ankle",
     "toe": "EndSiteright_ankle", "upper_arm": "right_shoulder", "elbow": "right_elbow",
     "wrist": "right_wrist"},
    {"hips": "root", "spine": "chest", "chest": "chest", "neck": "neck", "head": "EndSiteneck"},
))  # fmt: skip
MAPS = (CMU, MIXAMO, LAFAN1, DEEPMIMIC)


def _chains_fit(joints: dict[str, str], parent: dict[str, str | None]) -> bool:
    """The limbs are chains: each knee's and elbow's joint descends from its thigh or upper
    arm, each ankle and wrist from its knee or elbow (a name can mean different bones in
    different namings: CMU's LeftShoulder is an upper arm, Mixamo's and LAFAN1's a clavicle)."""

    def descends(child: str, ancestor: str) -> bool:
        node = parent.get(child)
        while node is not None:
            if node == ancestor:
                return True
            node = parent.get(node)
        return False

    pairs = [("thigh", "knee"), ("knee", "ankle"), ("ankle", "toe"), ("upper_arm", "elbow"),
             ("elbow", "wrist")]  # fmt: skip
    limbs = all(descends(joints[f"{s}_{b}"], joints[f"{s}_{a}"]) for s in SIDES for a, b in pairs)
    return limbs and all(descends(joints[f"{s}_upper_arm"], joints["chest"]) for s in SIDES)


def detect_map(names: list[str], parent: dict[str, str | None], skeleton: str = "auto"):
    """The skeleton map of a source: `skeleton` names a built-in map or a YAML file
    (role: source joint), or `auto` picks the built-in map whose names all exist and whose
    limbs are chains in the source's hierarchy. ValueError says what is missing."""
    if skeleton not in ("auto", *(m.name for m in MAPS)):
        path = Path(skeleton)
        try:
            joints = yaml.safe_load(path.read_text())
        except (OSError, yaml.YAMLError) as e:
            raise ValueError(f"--skeleton {skeleton}: cannot read the map: {e}") from None
        if not isinstance(joints, dict):
            raise ValueError(f"--skeleton {skeleton}: a map is 'role: source joint' lines")
        candidates = [SkeletonMap(path.stem, {str(k): str(v) for k, v in joints.items()})]
    else:
        candidates = [m for m in MAPS if skeleton in ("auto", m.name)]
    present = set(names)
    notes = []
    for m in candidates:
        unknown = sorted(set(m.joints) - set(ROLES))
        missing_roles = sorted(set(ROLES) - set(m.joints))
        if unknown or missing_roles:
            notes.append(f"{m.name}: roles {missing_roles} missing, {unknown} unknown")
            continue
        missing = sorted(n for n in m.joints.values() if n not in present)
        if missing:
            notes.append(f"{m.name}: no joint {', '.join(missing[:4])}")
            continue
        if not _chains_fit(m.joints, parent):
            notes.append(f"{m.name}: its names exist but its limbs are not chains here")
            continue
        why = f"every joint of the {m.name!r} map exists and its limbs are chains"
        if skeleton != "auto":
            why = f"{m.name!r} as asked; " + why
        return SkeletonMap(m.name, m.joints, why)
    raise ValueError(
        "no skeleton map fits this file (" + "; ".join(notes) + "); give one with "
        "--skeleton map.yaml (role: source joint name, roles: " + ", ".join(ROLES) + ")"
    )


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _orth(v: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """`v` without its component along the unit `axis`, normalized."""
    return _unit(v - (v * axis).sum(-1, keepdims=True) * axis)


def _frame(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    return np.stack([x, y, z], axis=-1)  # columns: the body's axes in the world


def _limb(base: np.ndarray, mid: np.ndarray, end: np.ndarray, parent: np.ndarray, bend: float):
    """(frame [F, 3, 3], hinge angle [F], projection error [F] in rad) of a two-bone limb: the
    upper bone along -y, twisted so that the lower bone lies in the x-y plane (the hinge's),
    bending to `bend` x (+1: forward, an elbow; -1: backward, a knee). A limb nearly straight
    (< STRAIGHT) or bent against its hinge takes its twist (measured from its `parent`'s frame
    [F, 3, 3], the parent's +x swung with the bone from the parent's -y) from the neighbouring
    frames, and its lower bone is projected onto the hinge's plane and range: the angle between
    the source's lower bone and the projection is the error."""
    d1, d2 = mid - base, end - mid
    axis = _unit(d1)
    y = -axis
    perp = d2 - (d2 * axis).sum(-1, keepdims=True) * axis
    angle = np.arctan2(np.linalg.norm(perp, axis=-1), (d2 * axis).sum(-1))
    x_bent = _unit(perp) * bend  # the lower bone goes toward +x for an elbow, -x for a knee
    fallback = _orth(_swing(parent[..., 0], -parent[..., 1], axis), y)
    usable = (angle > STRAIGHT) & ((x_bent * fallback).sum(-1) > -0.5)
    # the twist about the upper bone: where the limb bends, the one that puts the lower bone
    # in the hinge's plane; where it is straight (or bent the wrong way) the positions cannot
    # show it, and it is interpolated in time from the frames where they do
    side = np.cross(y, fallback)
    twist = np.arctan2((x_bent * side).sum(-1), (x_bent * fallback).sum(-1))
    if usable.any():
        k = np.arange(len(twist))
        twist = np.interp(k, k[usable], np.unwrap(twist[usable]))
    else:
        twist = np.zeros(len(twist))
    x = _orth(np.cos(twist)[:, None] * fallback + np.sin(twist)[:, None] * side, y)
    z = np.cross(x, y)
    lower = _unit(d2)
    u, v = (lower * x).sum(-1), (lower * y).sum(-1)
    hinge = np.arctan2(u, -v)  # the lower bone's angle in the hinge's plane
    hinge = np.minimum(hinge, 0.0) if bend < 0 else np.maximum(hinge, 0.0)
    projected = np.stack([np.sin(hinge), -np.cos(hinge), np.zeros_like(hinge)], -1)
    projected = np.einsum("fij,fj->fi", _frame(x, y, z), projected)
    error = np.arccos(np.clip((projected * lower).sum(-1), -1.0, 1.0))
    return _frame(x, y, z), hinge, error


@dataclass
class Imported:
    """The DeepMimic frames [n, 44] and what the import did."""

    frames: np.ndarray
    report: dict = field(default_factory=dict)
    # the source's nodes [F, N, 3] in the clip's frame (Y up, metres, the feet's lift applied)
    # and its bones (parent, child) node indices: what `paramimic clip render` draws beside it
    source: np.ndarray | None = None
    bones: tuple[tuple[int, int], ...] = ()

    def clip(self, name: str = "imported", loop: str = "none") -> Clip:
        return load_deepmimic(Path(f"{name}.txt"), name=name, text=self.text(loop))

    def text(self, loop: str = "none") -> str:
        rows = ",\n".join("[" + ", ".join(f"{v:.8f}" for v in row) + "]" for row in self.frames)
        return f'{{\n"Loop": "{loop}",\n"Frames":\n[\n{rows}\n]\n}}\n'


def import_bvh(
    path: str | Path,
    skeleton: str = "auto",
    start: float | None = None,
    end: float | None = None,
    fps: float = 30.0,
    scale: float | None = None,
    up: str = "auto",
    mirror: bool = False,
    loop: bool = False,
    ground: bool = True,
    forward: str = "auto",
) -> Imported:
    """Read a BVH file and retarget it onto the humanoid (see the module's docstring).
    `scale`: metres per file unit (default: the humanoid's leg length over the source's);
    `up`: the file's up axis ('+y', '+z', ...; auto: pybvh's detection); `start`/`end`: the
    seconds kept; `mirror`: left and right swapped; `loop`: the best gait cycle in what is
    kept, closed into a loop (`close_cycle`); `ground`: the feet moved onto the floor;
    `forward`: the direction the skeleton faces in its rest pose, in the file's axes ('+z',
    '-x', ...; auto: pybvh's detection from the rest pose), what the neck and ankles turn from."""
    import pybvh

    up, forward = _axis("--up", up), _axis("--forward", forward)
    try:
        bvh = pybvh.read_bvh_file(str(path), world_up="+y" if up == "auto" else up,
                                  warn_on_world_up_disagreement=False)  # fmt: skip
    except (OSError, ValueError, IndexError, KeyError, TypeError) as e:
        raise ValueError(f"{path}: not a readable BVH file: {e}") from None
    source_fps, frame_count = float(bvh.fps), int(bvh.frame_count)
    if frame_count < 2:
        raise ValueError(f"{path}: {frame_count} frames; a clip needs at least 2")
    if not 1.0 / MAX_FRAME_TIME <= source_fps <= 1.0 / MIN_FRAME_TIME:
        raise ValueError(f"{path}: Frame Time {1 / source_fps:g} s is not a motion capture rate "
                         f"({MIN_FRAME_TIME:g}-{MAX_FRAME_TIME:g} s)")  # fmt: skip
    channels = np.concatenate([bvh.root_pos.ravel(), bvh.joint_angles.ravel()])
    if not np.isfinite(channels).all():
        bad = int(np.argmax(~np.isfinite(bvh.joint_angles).reshape(frame_count, -1).all(1)
                            | ~np.isfinite(bvh.root_pos).all(1)))  # fmt: skip
        raise ValueError(f"{path}: frame {bad} holds a non-finite channel value")
    first = 0 if start is None else int(round(start * source_fps))
    last = frame_count if end is None else min(frame_count, int(round(end * source_fps)) + 1)
    if not 0 <= first < last - 1:
        raise ValueError(f"--start/--end keep no frames of the {frame_count / source_fps:.2f} s")
    if mirror:
        bvh = bvh.mirror()
    nodes = {n.name: n for n in bvh.nodes}
    parent = {n.name: (n.parent.name if n.parent is not None else None) for n in bvh.nodes}
    chosen = detect_map([n.name for n in bvh.nodes], parent, skeleton)
    if fps <= 0:
        raise ValueError(f"--fps must be positive, got {fps}")
    index = {name: i for i, name in enumerate(nodes)}
    positions = bvh.node_positions()[first:last]  # [F, N, 3], the file's frame and units
    positions = _resample(positions, source_fps, fps)
    rest = bvh.rest_pose_positions()
    if up == "auto":  # from the rest pose: the head above the feet (pybvh's guess reads motion)
        head = rest[index[chosen.joints["head"]]]
        feet = np.mean([rest[index[chosen.joints[f"{s}_ankle"]]] for s in SIDES], axis=0)
        axis = int(np.argmax(np.abs(head - feet)))
        up = ("+" if head[axis] > feet[axis] else "-") + "xyz"[axis]
    bvh.world_up = up
    if forward == "auto":
        forward = bvh.rest_forward
    if forward[-1] == up[-1]:
        raise ValueError(f"--forward {forward}: along the up axis {up}; give a horizontal axis")
    to_y_up = _to_y_up(up)
    positions, rest = positions @ to_y_up.T, rest @ to_y_up.T
    P = {role: positions[:, index[name]] for role, name in chosen.joints.items()}
    R0 = {role: rest[index[name]] for role, name in chosen.joints.items()}
    leg = np.mean([np.linalg.norm(R0[f"{s}_knee"] - R0[f"{s}_thigh"]) +
                   np.linalg.norm(R0[f"{s}_ankle"] - R0[f"{s}_knee"]) for s in SIDES])  # fmt: skip
    metres = BASE_LEG / leg if scale is None else scale
    leaves = _leaf_frames(bvh, chosen, first, last, fps, to_y_up, len(positions), forward)
    frames, flipped = _humanoid_frames(P, R0, metres, leaves)
    n = len(frames)
    frames[:, 0] = 1.0 / fps
    frames[-1, 0] = 0.0
    feet = [chosen.joints[f"{side}_ankle"] for side in SIDES]
    contacts = _contacts(bvh, feet, first, last, source_fps, fps, n)
    lift, lowest = _ground(frames, contacts)
    if ground:
        frames[:, 2] += lift
    else:
        lowest -= lift
    source = positions * metres  # the source skeleton in the clip's frame, lifted alike
    source[..., 1] += (lift if ground else np.zeros_like(lift))[:, None]
    names = list(nodes)
    bones = tuple((names.index(parent[n]), k) for k, n in enumerate(names) if parent[n])
    cycle = None
    if loop:
        a, b, residual = find_cycle(frames, fps)
        frames = close_cycle(frames[a : b + 1])
        frames[:, 0], frames[-1, 0] = 1.0 / fps, 0.0  # the last frame ends the clip
        lowest, contacts, source = lowest[a : b + 1], contacts[a : b + 1], source[a : b + 1]
        cycle = {"start_s": a / fps, "end_s": b / fps, "residual_before_closing": residual}
    report = {
        "file": str(path),
        "skeleton": chosen.name,
        "why": chosen.why,
        "source_fps": source_fps,
        "fps": fps,
        "frames": len(frames),
        "seconds": (len(frames) - 1) / fps,
        "up_axis": up,
        "forward_axis": forward,
        "metres_per_unit": float(metres),
        "units_guess": _units(metres),
        # the knees and elbows are 1-DOF: the angle (deg) between the source's lower bone and
        # the humanoid's, mean and max over the frames
        "hinge_error_deg": {
            k: [float(np.degrees(v.mean())), float(np.degrees(v.max()))] for k, v in flipped.items()
        },  # fmt: skip
        # the lowest foot point over the clip: 0 on the frames the source stands, never far
        # below the floor between them
        "lowest_foot_min_m": float(lowest.min()),
        # the file's joints no role reads (fingers, toes past the toe, extra spine joints);
        # end sites are not joints
        "dropped": [n for n in bvh.joint_names if n not in set(chosen.joints.values())],
        "contact_share": float(contacts.mean()),
        "cycle": cycle,
    }
    return Imported(frames, report, source, bones)


CYCLE_SECONDS = (0.6, 2.5)  # a gait cycle (two steps) lasts this long


def _pose_features(frames: np.ndarray) -> np.ndarray:
    """What a cycle's two ends must share: the joints' local rotations and angles, the root's
    height and its tilt (its heading and position advance from cycle to cycle)."""
    root = Rotation.from_quat(frames[:, 4:8], scalar_first=True)
    yaw = Rotation.from_euler("y", root.as_euler("YZX")[:, :1])
    tilt = (yaw.inv() * root).as_rotvec()
    return np.column_stack([frames[:, 8:], frames[:, 2:3], tilt])


def find_cycle(frames: np.ndarray, fps: float) -> tuple[int, int, float]:
    """(first, last frame, pose distance) of the cycle whose two ends are most alike, lasting
    CYCLE_SECONDS."""
    features = _pose_features(frames)
    lo, hi = (int(round(s * fps)) for s in CYCLE_SECONDS)
    best = (0, 0, np.inf)
    for a in range(len(frames) - lo):
        ends = np.arange(a + lo, min(len(frames), a + hi + 1))
        if not len(ends):
            break
        d = np.linalg.norm(features[ends] - features[a], axis=1)
        k = int(np.argmin(d))
        if d[k] < best[2]:
            best = (a, int(ends[k]), float(d[k]))
    if not np.isfinite(best[2]):
        raise ValueError(f"--loop: the clip is shorter than a gait cycle ({CYCLE_SECONDS[0]} s)")
    return best


def close_cycle(frames: np.ndarray) -> np.ndarray:
    """The cycle with its last frame's pose made its first's: the difference spread linearly
    over the cycle (joint quaternions and angles, the root's height and tilt); the root's
    heading and path keep advancing ("Loop": "wrap")."""
    out = frames.copy()
    u = np.linspace(0.0, 1.0, len(frames))[:, None]
    out[:, 8:] += u * (frames[0, 8:] - frames[-1, 8:])
    out[:, 2] += u[:, 0] * (frames[0, 2] - frames[-1, 2])
    col = 8
    for joint in JOINT_COLUMNS:
        if joint.endswith(("knee", "elbow")):
            col += 1
            continue
        out[:, col : col + 4] = _unit(out[:, col : col + 4])
        col += 4
    root = Rotation.from_quat(frames[:, 4:8], scalar_first=True)
    yaw = Rotation.from_euler("y", root.as_euler("YZX")[:, :1])
    tilt = yaw.inv() * root
    residual = (tilt[0] * tilt[-1].inv()).as_rotvec()
    fixed = yaw * Rotation.from_rotvec(u * residual) * tilt
    out[:, 4:8] = _quat(fixed.as_matrix())
    return out


def _resample(positions: np.ndarray, source_fps: float, fps: float) -> np.ndarray:
    """Joint positions at `fps` by linear interpolation in time."""
    t_source = np.arange(len(positions)) / source_fps
    t = np.arange(0.0, t_source[-1] + 1e-9, 1.0 / fps)
    flat = positions.reshape(len(positions), -1)
    out = np.stack([np.interp(t, t_source, col) for col in flat.T], axis=1)
    return out.reshape(len(t), *positions.shape[1:])


def _to_y_up(up: str) -> np.ndarray:
    """The rotation taking the file's up axis to +y (the humanoid file's frame)."""
    axis = {"x": 0, "y": 1, "z": 2}[up[-1]]
    vec = np.zeros(3)
    vec[axis] = -1.0 if up.startswith("-") else 1.0
    rot, _ = Rotation.align_vectors([[0.0, 1.0, 0.0]], [vec])
    return rot.as_matrix()


def _units(metres_per_unit: float) -> str:
    for name, value in (("metres", 1.0), ("decimetres", 0.1), ("centimetres", 0.01),
                        ("CMU's units (1/0.45 inch)", 0.0254 / 0.45), ("inches", 0.0254),
                        ("millimetres", 0.001)):  # fmt: skip
        if 0.85 < metres_per_unit / value < 1.15:
            return name
    return f"{metres_per_unit:.4g} m per unit (a skeleton of another size)"


LEAVES = ("neck", "right_ankle", "left_ankle")  # their twist is no bone's direction


def _axis(option: str, value: str) -> str:
    """'auto', or an axis as '+x' / '-z' ('y' is '+y')."""
    if value == "auto":
        return value
    if value.lstrip("+-") not in ("x", "y", "z") or len(value) > 2:
        raise ValueError(f"{option} {value!r}: auto, or an axis such as +y, -z, x")
    return value if value[0] in "+-" else "+" + value


def _leaf_frames(
    bvh, chosen: SkeletonMap, first: int, last: int, fps: float, to_y_up, n: int, forward: str
):
    """World frames [n, 3, 3] of the joints whose own twist positions cannot show (the neck
    about the head's axis, the ankle about the foot's): the source joint's rotation from its
    rest pose, which BVH defines as all angles zero, applied to the humanoid's rest frame
    facing the source's rest `forward` (an axis of the file, '+z'), resampled by slerp."""
    from scipy.spatial.transform import Slerp

    names = list(bvh.joint_names)
    parent = {n.name: (n.parent.name if n.parent is not None else None) for n in bvh.nodes}
    local = {}
    for j, name in enumerate(names):
        order = bvh.euler_orders[j].upper()  # BVH channels: intrinsic rotations in file order
        local[name] = Rotation.from_euler(order, bvh.joint_angles[first:last, j])  # radians
    world: dict[str, Rotation] = {}

    def world_of(name: str) -> Rotation:
        if name not in world:
            up = parent[name]
            world[name] = local[name] if up is None else world_of(up) * local[name]
        return world[name]

    facing = np.zeros(3)
    facing["xyz".index(forward[-1])] = -1.0 if forward.startswith("-") else 1.0
    forward = to_y_up @ facing
    forward = _unit(np.array([forward[0], 0.0, forward[2]]))
    rest = _frame(forward, np.array([0.0, 1.0, 0.0]), np.cross(forward, [0.0, 1.0, 0.0]))
    times = np.arange(last - first) / float(bvh.fps)
    t = np.clip(np.arange(n) / fps, 0.0, times[-1])
    out = {}
    for role in LEAVES:
        name = chosen.joints[role]
        if name not in local:  # an end site: no rotation of its own
            continue
        delta = Slerp(times, world_of(name))(t).as_matrix()
        out[role] = to_y_up @ delta @ to_y_up.T @ rest
    return out


def _humanoid_frames(P: dict, R0: dict, metres: float, leaves: dict | None = None):
    """DeepMimic frames [F, 44] (durations left to the caller) from source joint positions
    (`leaves`: world frames of the neck and ankles from the source's rotations, when known)."""
    leaves = leaves or {}
    y_root = _unit(P["spine"] - P["hips"])
    z_root = _orth(P["right_thigh"] - P["left_thigh"], y_root)
    root = _frame(np.cross(y_root, z_root), y_root, z_root)
    y_chest = _unit(P["neck"] - P["chest"])
    z_chest = _orth(P["right_upper_arm"] - P["left_upper_arm"], y_chest)
    chest = _frame(np.cross(y_chest, z_chest), y_chest, z_chest)
    y_neck = _unit(P["head"] - P["neck"])
    z_neck = _orth(z_chest, y_neck)
    neck = leaves.get("neck", _frame(np.cross(y_neck, z_neck), y_neck, z_neck))
    local = {"chest": _local(root, chest), "neck": _local(chest, neck)}
    hinge, flipped = {}, {}
    for side in SIDES:
        thigh, knee, flipped[f"{side}_knee"] = _limb(
            P[f"{side}_thigh"], P[f"{side}_knee"], P[f"{side}_ankle"], root, -1.0
        )
        shin = thigh @ _rz(knee)
        foot = leaves.get(f"{side}_ankle")
        if foot is None:
            foot = _foot(P[f"{side}_ankle"], P[f"{side}_toe"], shin, R0, side)
        arm, elbow, flipped[f"{side}_elbow"] = _limb(
            P[f"{side}_upper_arm"], P[f"{side}_elbow"], P[f"{side}_wrist"], chest, 1.0
        )
        local[f"{side}_hip"], local[f"{side}_ankle"] = _local(root, thigh), _local(shin, foot)
        local[f"{side}_shoulder"] = _local(chest, arm)
        hinge[f"{side}_knee"], hinge[f"{side}_elbow"] = knee, elbow
    n = len(root)
    frames = np.zeros((n, 44))
    frames[:, 1:4] = P["hips"] * metres
    frames[:, 4:8] = _quat(root)
    col = 8  # DeepMimic's column order (paramimic/data/deepmimic/README.md)
    for joint in JOINT_COLUMNS:
        if joint in hinge:
            frames[:, col] = hinge[joint]
            col += 1
        else:
            frames[:, col : col + 4] = _quat(local[joint])
            col += 4
    return frames, flipped


def _swing(v: np.ndarray, rest: np.ndarray, bone: np.ndarray) -> np.ndarray:
    """`v` [F, 3] turned by the shortest rotation that takes the unit `rest` to the unit `bone`
    (Rodrigues' formula; the twist-free motion of a bone)."""
    axis = np.cross(rest, bone)
    sin, cos = np.linalg.norm(axis, axis=-1, keepdims=True), (rest * bone).sum(-1, keepdims=True)
    k = axis / np.maximum(sin, 1e-12)
    return v * cos + np.cross(k, v) * sin + k * (k * v).sum(-1, keepdims=True) * (1.0 - cos)


def _rz(angle: np.ndarray) -> np.ndarray:
    return Rotation.from_euler("z", np.asarray(angle)[:, None]).as_matrix()


def _local(parent: np.ndarray, child: np.ndarray) -> np.ndarray:
    return np.swapaxes(parent, -1, -2) @ child


def _quat(matrices: np.ndarray) -> np.ndarray:
    """w-first quaternions, sign-continuous along the frames."""
    q = Rotation.from_matrix(matrices).as_quat(scalar_first=True)
    for k in range(1, len(q)):
        if q[k] @ q[k - 1] < 0:
            q[k] = -q[k]
    return q


def _foot(ankle: np.ndarray, toe: np.ndarray, shin: np.ndarray, R0: dict, side: str):
    """The foot's frame: +x toward the toe, its pitch corrected so that the source's rest foot
    is flat, +z the shin's lateral axis."""
    x = _unit(toe - ankle)
    z = _orth(shin[..., 2], x)
    y = np.cross(z, x)
    rest = R0[f"{side}_toe"] - R0[f"{side}_ankle"]
    pitch = np.arctan2(rest[1], np.hypot(rest[0], rest[2]))  # below the horizontal: < 0
    return _frame(x, y, z) @ Rotation.from_euler("z", -pitch).as_matrix()


def _contacts(bvh, feet, first: int, last: int, source_fps: float, fps: float, n: int):
    """Frames (at `fps`) where a foot of the source is on the ground (pybvh's detection from
    the `feet` joints' height and speed)."""
    labels = np.asarray(bvh.foot_contacts(foot_joints=feet))[first:last]  # [F, feet]
    on = labels.reshape(len(labels), -1).max(axis=1) > 0.5
    t = np.arange(n) / fps
    return np.interp(t, np.arange(len(on)) / source_fps, on.astype(float)) > 0.5


def kinematics(frames: np.ndarray):
    """(the base humanoid, body positions [F, bodies, 3], site positions [F, sites, 3]) of
    DeepMimic frames played on the humanoid, from MuJoCo's kinematics (world: z up)."""
    clip = load_deepmimic(Path("frames.txt"), text=json.dumps({"Frames": frames.tolist()}))
    body = HUMANOID.compile()
    qpos = HUMANOID.pose_qpos(body, clip.sample(np.cumsum(np.r_[0.0, clip.durations[:-1]])))
    data = mujoco.MjData(body.model)
    xpos, sites = [], []
    for q in qpos:
        data.qpos[:] = q
        mujoco.mj_kinematics(body.model, data)
        xpos.append(data.xpos.copy())
        sites.append(data.site_xpos.copy())
    return body, np.array(xpos), np.array(sites)


def _ground(frames: np.ndarray, contacts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertical offset [F] that puts the humanoid's lowest foot point on the floor at every
    contact frame (interpolated between them; the median where the source never stands), and
    the lowest foot point after it."""
    body, _, sites = kinematics(frames)
    lowest = sites[:, body.contact_site_ids, 2].min(axis=1)
    t = np.arange(len(lowest))
    if contacts.any():
        lift = np.interp(t, t[contacts], -lowest[contacts])
    else:
        lift = np.full(len(lowest), -np.median(lowest))
    return lift, lowest + lift


# end sites of the exported skeleton (m, in the parent joint's frame): the head's top, the
# foot's toe (its box's front, at the sole's height), the hand
_END_SITES = {"neck": (0.0, 0.25, 0.0), "right_ankle": (0.1335, -0.05, 0.0),
              "left_ankle": (0.1335, -0.05, 0.0), "right_wrist": (0.0, -0.1, 0.0),
              "left_wrist": (0.0, -0.1, 0.0)}  # fmt: skip


def clip_frames(clip: str) -> np.ndarray:
    """The DeepMimic frames [n, 44] of a humanoid clip: a built-in name (humanoid_walk, ...) or
    a clip file, checked as `env.clip` reads it."""
    from paramimic.characters.humanoid import CLIPS

    name = clip.removeprefix("humanoid_")
    path = CLIPS[name] if name in CLIPS else Path(clip)
    text = path.read_text()
    load_deepmimic(Path(str(path)), text=text)  # it parses as a clip
    return np.asarray(json.loads(text)["Frames"], np.float64)


def export_bvh(frames: np.ndarray, path: str | Path) -> Path:
    """DeepMimic humanoid frames [n, 44] (durations, root, local joint rotations; Y up, metres)
    as a BVH file of the humanoid's own skeleton: ZYX rotation channels in degrees, the knees'
    and elbows' hinge on Z, the same frame rate (the first frame's duration)."""
    skeleton = HUMANOID.skeleton
    children: dict[int, list[dict]] = {}
    for j in skeleton:
        children.setdefault(j["Parent"], []).append(j)
    lines = ["HIERARCHY"]

    def write(j: dict, depth: int) -> None:
        pad = "\t" * depth
        kind = "ROOT" if j["Parent"] < 0 else "JOINT"
        lines.append(f"{pad}{kind} {j['Name']}")
        lines.append(pad + "{")
        lines.append(f"{pad}\tOFFSET {j['AttachX']:.6f} {j['AttachY']:.6f} {j['AttachZ']:.6f}")
        position = "Xposition Yposition Zposition " if j["Parent"] < 0 else ""
        count = 6 if j["Parent"] < 0 else 3
        lines.append(f"{pad}\tCHANNELS {count} {position}Zrotation Yrotation Xrotation")
        for child in children.get(j["ID"], []):
            write(child, depth + 1)
        if j["Name"] in _END_SITES:
            x, y, z = _END_SITES[j["Name"]]
            end = [f"{pad}\tEnd Site", pad + "\t{", f"{pad}\t\tOFFSET {x} {y} {z}", pad + "\t}"]
            lines.extend(end)
        lines.append(pad + "}")

    write(skeleton[0], 0)
    order = [j["Name"] for j in _preorder(skeleton, children)]
    columns = _columns()
    rows = []
    for f in frames:
        values = list(f[1:4])
        for name in order:
            if name == "root":
                q = f[4:8]
            elif name in columns:
                start, width = columns[name]
                q = None if width == 1 else f[start : start + 4]
                if q is None:
                    values += [float(np.degrees(f[start])), 0.0, 0.0]
                    continue
            else:  # the wrists: fixed
                values += [0.0, 0.0, 0.0]
                continue
            zyx = Rotation.from_quat(q, scalar_first=True).as_euler("ZYX", degrees=True)
            values += list(zyx)
        rows.append(" ".join(f"{v:.6f}" for v in values))
    frame_time = float(frames[0, 0])
    lines += ["MOTION", f"Frames: {len(rows)}", f"Frame Time: {frame_time:.8f}", *rows]
    path = Path(path)
    path.write_text("\n".join(lines) + "\n")
    return path


def _preorder(skeleton: list[dict], children: dict[int, list[dict]]) -> list[dict]:
    out, stack = [], [skeleton[0]]
    while stack:
        j = stack.pop()
        out.append(j)
        stack.extend(reversed(children.get(j["ID"], [])))
    return out


def _columns() -> dict[str, tuple[int, int]]:
    """DeepMimic frame columns of each joint: (first column, 4 for a quaternion or 1)."""
    out, col = {}, 8
    for joint in JOINT_COLUMNS:
        width = 1 if joint.endswith(("knee", "elbow")) else 4
        out[joint] = (col, width)
        col += width
    return out


def render_clip(
    frames: np.ndarray,
    source: np.ndarray | None = None,
    bones=(),
    width: int = 320,
    height: int = 240,
    beside: float = 1.0,
) -> list[np.ndarray]:
    """A clip played on the base humanoid, kinematically (no physics, no policy), as RGB frames;
    with `source` ([F, N, 3], the clip's frame), the source skeleton drawn `beside` metres to
    the side (+x) as red bones, so that the retargeting can be seen."""
    from paramimic.motion.clip import Y_UP_TO_Z_UP

    body = HUMANOID.compile()
    clip = load_deepmimic(Path("frames.txt"), text=json.dumps({"Frames": frames.tolist()}))
    qpos = HUMANOID.pose_qpos(body, clip.sample(np.cumsum(np.r_[0.0, clip.durations[:-1]])))
    data = mujoco.MjData(body.model)
    renderer = mujoco.Renderer(body.model, height, width)
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    camera.trackbodyid = body.root_body_id
    camera.azimuth, camera.elevation, camera.distance = 90.0, -10.0, 4.5
    to_world = Y_UP_TO_Z_UP.as_matrix()
    red = np.array([0.85, 0.25, 0.2, 1.0], np.float32)
    images = []
    try:
        for k, q in enumerate(qpos):
            data.qpos[:] = q
            mujoco.mj_kinematics(body.model, data)
            renderer.update_scene(data, camera)
            if source is not None and k < len(source):
                points = source[k] @ to_world.T + np.array([beside, 0.0, 0.0])
                scene = renderer.scene
                for a, b in bones[: scene.maxgeom - scene.ngeom]:
                    geom = scene.geoms[scene.ngeom]
                    mujoco.mjv_initGeom(geom, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3),
                                        np.zeros(3), np.eye(3).ravel(), red)  # fmt: skip
                    mujoco.mjv_connector(geom, mujoco.mjtGeom.mjGEOM_CAPSULE, 0.02,
                                         points[a], points[b])  # fmt: skip
                    scene.ngeom += 1
            images.append(renderer.render().copy())
    finally:
        renderer.close()
    return images

"""What the constant hinge armature (0.01 kg m², `paramimic/characters/body.py`) does to each
body's limbs: their free swing slowed, on the base body and at the family's smallest and largest
corners. Not a timed test; no training.

For every hinge, MuJoCo's joint-space inertia at the reference pose (`mj_fullM`) gives the
effective inertia the joint swings: the limb's own inertia I about the axis (everything beyond
the joint, the rest of the body held) plus the armature a. A limb's small-swing period goes
with √(inertia), so a constant armature slows it by √((I + a) / I). An armature scaled with
each body as the limb's inertia is (a ∝ I, the volume-scaled value) would keep the base body's
factor at every size. Per body: the median and largest factor over its hinges, the base
body's factor for the same hinges, and the hinges whose armature exceeds their own inertia.

    python benchmarks/armature.py
        # -> benchmarks/results/armature/armature.json, docs/reproduce.md
"""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import numpy as np
from tabulate import tabulate

from paramimic import characters
from paramimic.envs.core import compiled_body

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "armature" / "armature.json"
DOCS = ROOT / "docs" / "reproduce.md"
MARKS = ("<!-- armature -->", "<!-- /armature -->")


def hinge_inertia(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """(inertia with armature, armature) of every hinge dof at qpos0."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    hinges = [model.jnt_dofadr[j] for j in range(model.njnt)
              if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]  # fmt: skip
    return np.diag(full)[hinges], model.dof_armature[hinges]


def body_rows(name: str) -> dict:
    reg = characters.registration(name)
    shapes = {p.name: (p.low, p.high) for p in reg.character.shape_params}
    out = {}
    base_total, arm = hinge_inertia(compiled_body(name, ()).model)
    base_factor = np.sqrt(base_total / (base_total - arm))
    for corner, pick in (("base", None), ("smallest", 0), ("largest", 1)):
        shape = () if pick is None else tuple((n, r[pick]) for n, r in shapes.items())
        total, arm = hinge_inertia(compiled_body(name, shape).model)
        own = total - arm
        factor = np.sqrt(total / own)
        out[corner] = {
            "hinges": int(len(own)),
            "median_factor": float(np.median(factor)),
            "max_factor": float(factor.max()),
            "base_median_factor": float(np.median(base_factor)),
            "armature_over_own_inertia": int((arm > own).sum()),
            "median_own_inertia": float(np.median(own)),
        }
    return out


def main() -> None:
    result = {name: body_rows(name) for name in characters.REGISTRY}
    OUT.write_text(json.dumps(result, indent=2))
    rows = [
        [name, corner, r["hinges"], f"{r['median_own_inertia']:.4f}", f"{r['median_factor']:.2f}",
         f"{r['max_factor']:.2f}", f"{r['base_median_factor']:.2f}",
         f"{r['armature_over_own_inertia']} of {r['hinges']}"]
        for name, corners in result.items()
        for corner, r in corners.items()
    ]  # fmt: skip
    header = ["character", "body", "hinges", "median own inertia (kg m²)",
              "swing period x (median)", "x (largest)", "x with a scaled armature",
              "armature > own inertia"]  # fmt: skip
    body = tabulate(rows, header, tablefmt="github")
    text = DOCS.read_text()
    head, rest = text.split(MARKS[0], 1)
    _, tail = rest.split(MARKS[1], 1)
    DOCS.write_text(f"{head}{MARKS[0]}\n{body}\n{MARKS[1]}{tail}")
    print(body)
    print(f"wrote {OUT} and {DOCS}")


if __name__ == "__main__":
    main()

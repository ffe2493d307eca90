"""What a skill episode records as it goes, for its measures ([L21] §4.2's task parameters,
hindsight a') and its fitness (Eq. 10): the rows of its `Trajectory`, one per control step."""

from __future__ import annotations

import mujoco
import numpy as np

from paramimic.characters import Body
from paramimic.motion.measures import Trajectory


class EpisodePath:
    """The episode's state after each control step, as the measures read it."""

    def __init__(self, model: mujoco.MjModel, body: Body, energy: bool, contact0: np.ndarray):
        """`energy`: record the kinetic energy (a task parameter measures it); `contact0`
        [n, F]: m0's foot contacts on the reference grid, the contact a row is judged by."""
        self.model, self.body, self.energy, self.contact0 = model, body, energy, contact0
        self._feet = body.contact_site_ids.reshape(len(body.definition.feet), 4)
        self.time: list[float] = []
        self.phase: list[float] = []
        self.com: list[np.ndarray] = []
        self.rot: list[np.ndarray] = []
        self.ee: list[np.ndarray] = []
        self.low: list[np.ndarray] = []  # each foot's lowest point
        self.kinetic: list[float] = []
        self.contact: list[np.ndarray] = []

    def add(self, data: mujoco.MjData, time: float, phase: float, phi: float) -> None:
        """One row: the state in `data` at `time` (s), clip phase `phase` (reference time φ)."""
        body, root = self.body, self.body.root_body_id
        self.time.append(time)
        self.phase.append(phase)
        self.com.append(data.subtree_com[root].copy())
        self.rot.append(data.xmat[root].reshape(3, 3).copy())
        self.ee.append(data.site_xpos[body.ee_site_ids].copy())
        self.low.append(data.site_xpos[self._feet, 2].min(axis=1))
        if self.energy:
            mujoco.mj_energyVel(self.model, data)
        self.kinetic.append(float(data.energy[1]) if self.energy else 0.0)
        self.contact.append(self.contact0[min(int(round(phi)), len(self.contact0) - 1)])

    def trajectory(self) -> Trajectory:
        """The episode so far."""
        ee = np.asarray(self.ee)
        return Trajectory(
            np.asarray(self.time), np.asarray(self.phase), np.asarray(self.com),
            np.asarray(self.rot),
            {n: ee[:, j] for j, n in enumerate(self.body.definition.end_effectors)},
            np.asarray(self.low), np.asarray(self.kinetic),
            float(mujoco.mj_getTotalmass(self.model)), np.asarray(self.contact),
        )  # fmt: skip

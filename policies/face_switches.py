"""Contact face switches of a pushed cuboid (IV-C), counted per world from the end-effector's contacts.

IV-C: "a face switch is considered when the robot switches contact to a different face of the cuboid". While the
end-effector touches the object, the contacted face is the vertical face of the cuboid whose outward
normal axis has the largest normalised end-effector coordinate in the object frame
(``argmax(|x| / (d_x / 2), |y| / (d_y / 2))`` with its sign: +x, -x, +y or -y); a touch from above the top
face counts as no vertical face. A face becomes *the contacted face* once it has been touched for
a hold time without interruption (so grazing an edge does not count), and a face switch is counted
whenever the contacted face changes to a different one. Face switches are undefined for cylinders, as in the paper.
"""

from __future__ import annotations

import numpy as np

FACE_NAMES = ("+x", "-x", "+y", "-y")  # vertical faces of a cuboid by outward normal (object frame)
NO_FACE = -1


def contact_face(ee_o: np.ndarray, dims: np.ndarray) -> np.ndarray:
    """Index into :data:`FACE_NAMES` of the vertical cuboid face at the end-effector, per row.

    ``ee_o`` (n, 3): end-effector point in the object frame [m]; ``dims`` (n, 3): full side lengths [m].
    :data:`NO_FACE` where the end-effector is above the top face.
    """
    half = 0.5 * np.asarray(dims, dtype=np.float64)
    u = ee_o[:, :2] / half[:, :2]
    axis = np.argmax(np.abs(u), axis=1)
    along = u[np.arange(len(u)), axis]
    face = 2 * axis + (along < 0)
    above_top = (ee_o[:, 2] > half[:, 2]) & (np.abs(along) <= 1.0)
    return np.where(above_top, NO_FACE, face)


class FaceTracker:
    """Contacted face and face-switch count of many worlds (see the module docstring).

    ``count``: worlds; ``hold_steps``: control steps a face must be touched without interruption to become the
    contacted face (at least 1).
    """

    def __init__(self, count: int, hold_steps: int):
        self.hold_steps = max(1, hold_steps)
        self.face = np.full(count, NO_FACE)  # the contacted face
        self.candidate = np.full(count, NO_FACE)  # face touched in the current uninterrupted run
        self.run = np.zeros(count, dtype=np.int64)  # steps of that run
        self.switches = np.zeros(count, dtype=np.int64)

    def update(self, touched: np.ndarray) -> None:
        """One control step: ``touched`` is each world's touched face, or :data:`NO_FACE`."""
        same = (touched == self.candidate) & (touched != NO_FACE)
        self.run = np.where(same, self.run + 1, (touched != NO_FACE).astype(np.int64))
        self.candidate = touched.copy()
        confirmed = (self.run >= self.hold_steps) & (touched != self.face)
        self.switches += confirmed & (self.face != NO_FACE)
        self.face = np.where(confirmed, touched, self.face)


def count_face_switches(faces: list[int] | np.ndarray, hold_steps: int) -> int:
    """Face switches of one contact sequence (a face index or :data:`NO_FACE` per control step)."""
    tracker = FaceTracker(1, hold_steps)
    for face in faces:
        tracker.update(np.array([face]))
    return int(tracker.switches[0])

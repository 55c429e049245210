"""User-chosen episodes: the object, its goal and the robot's start, for scenarios and tests."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .config import ConfigError, check_object_friction

SHAPES = ("cuboid", "cylinder")


@dataclass
class EpisodeSpec:
    """One episode in one world. Object at the env origin, resting on the floor; SI units, radians.

    ``dims`` are full side lengths (a cylinder uses ``dims[0]`` as its diameter); ``com_offset`` is
    the CoM in the object frame; ``friction`` the combined object-floor coefficient; ``goal`` and
    ``base`` are (x, y, yaw) in the world frame; ``arm_q`` the 5 initial arm joints (default pose if
    None); ``reach_target`` the reach target in the object frame (the centroid if None).
    """

    shape: str = "cuboid"
    dims: tuple[float, float, float] = (0.5, 0.5, 0.7)
    mass: float = 5.0
    com_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    friction: float = 0.8
    object_yaw: float = 0.0
    goal: tuple[float, float, float] = (1.0, 0.0, 0.0)
    base: tuple[float, float, float] = (-1.5, 0.0, 0.0)
    arm_q: tuple[float, ...] | None = None
    reach_target: tuple[float, float, float] | None = None
    base_mass_offset: float = 0.0
    first_push_step: int = 2**30  # no random push unless asked for

    ARRAY_FIELDS = ("shape", "dims", "mass", "com_o", "friction", "object_yaw", "reach_target_o", "goal", "base",
                    "arm_q", "base_mass_offset", "first_push_step")

    def validate(self, arm_default: np.ndarray, ground_friction: float) -> None:
        if self.shape not in SHAPES:
            raise ConfigError(f"episode.shape must be one of {SHAPES}, got {self.shape!r}")
        if len(self.dims) != 3 or not all(0.05 <= d <= 2.0 for d in self.dims):
            raise ConfigError(f"episode.dims must be 3 lengths in [0.05, 2.0] m, got {self.dims!r}")
        if not (math.isfinite(self.mass) and self.mass > 0.0):
            raise ConfigError(f"episode.mass must be > 0 kg, got {self.mass!r}")
        check_object_friction("episode.friction", self.friction, ground_friction)
        for name in ("com_offset", "goal", "base"):
            value = getattr(self, name)
            if len(value) != 3 or not all(math.isfinite(v) for v in value):
                raise ConfigError(f"episode.{name} must be 3 finite numbers, got {value!r}")
        if self.arm_q is not None and len(self.arm_q) != len(arm_default):
            raise ConfigError(f"episode.arm_q must have {len(arm_default)} entries, got {self.arm_q!r}")

    def as_arrays(self, arm_default: np.ndarray) -> dict[str, object]:
        """Values for ``dynpush.kernels.push.sampling.EpisodeSpec``, one world."""
        dims = (self.dims[0], self.dims[0], self.dims[2]) if self.shape == "cylinder" else self.dims
        return {
            "shape": SHAPES.index(self.shape),
            "dims": dims,
            "mass": self.mass,
            "com_o": self.com_offset,
            "friction": self.friction,
            "object_yaw": self.object_yaw,
            "reach_target_o": self.reach_target or (0.0, 0.0, 0.0),
            "goal": self.goal,
            "base": self.base,
            "arm_q": arm_default if self.arm_q is None else self.arm_q,
            "base_mass_offset": self.base_mass_offset,
            "first_push_step": self.first_push_step,
        }

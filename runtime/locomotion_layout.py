"""The locomotion ONNX's observation terms and their sizes: pure constants, no imports beyond numpy.

Shared by the runtime (``config.py`` checks a configured observation against them, ``locomotion.py`` builds
it) and the simulator's locomotion kernels (``kernels/locomotion/observations.py`` writes the actor observation
in this order), so both sides of the contract read one definition.
"""

from __future__ import annotations

from .observation import NUM_ARM_JOINTS

NUM_LEG_JOINTS = 12  # legs LF, RF, LH, RH; joints HAA, HFE, KFE (dynpush.assets_usd.LEG_JOINT_NAMES)
# Terms a locomotion ONNX observation may be built from, with their sizes (see locomotion.py).
LOCOMOTION_TERMS: dict[str, int] = {
    "base_linear_velocity_b": 3,
    "base_angular_velocity_b": 3,
    "projected_gravity_b": 3,
    "base_command": 6,
    "leg_joint_position": NUM_LEG_JOINTS,
    "leg_joint_velocity": NUM_LEG_JOINTS,
    "last_leg_actions": NUM_LEG_JOINTS,
    "arm_joint_position": NUM_ARM_JOINTS,
    "arm_joint_velocity": NUM_ARM_JOINTS,
}

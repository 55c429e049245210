"""Typed configuration of the locomotion environment (docs/legged.md).

The paper freezes a learned 6D-command locomotion policy under the push policy (III) but gives none of
its training numbers; defaults follow the CaT paper (Chane-Sane et al., IROS 2024) and legged_gym's
ANYmal set-up where they exist and are marked "ours" otherwise. The command ranges are the push task's
base-command limits (``ConstraintConfig``), so the locomotion policy is trained on exactly the
commands the push policy may send. Randomization (base pushes, base mass) repeats the push task's
(paper III-E).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from .config import (
    ConfigError, ConstraintConfig, MuJoCoConfig, NoiseHalfWidths, RandomizationConfig, check_positive, check_range,
    validate_env,
)

_PUSH_CONSTRAINTS = ConstraintConfig()
_PUSH_RANDOMIZATION = RandomizationConfig()


@dataclass
class CommandConfig:
    """6D base commands (vx, vy [m/s], yaw rate [rad/s], roll, pitch [rad], height [m]), uniform in range."""

    lower: tuple[float, ...] = _PUSH_CONSTRAINTS.base_command_lower  # the push task's command limits
    upper: tuple[float, ...] = _PUSH_CONSTRAINTS.base_command_upper
    resample_interval_s: tuple[float, float] = (5.0, 10.0)  # ours: two to four commands per episode
    standing_probability: float = 0.1  # ours: zero vx, vy, yaw rate (the push policy often stands)

    def validate(self, prefix: str = "commands") -> None:
        for name in ("lower", "upper"):
            if len(getattr(self, name)) != 6:
                raise ConfigError(f"{prefix}.{name} must have 6 entries (vx, vy, yaw rate, roll, pitch, height)")
        for i, (lo, hi) in enumerate(zip(self.lower, self.upper)):
            if not lo <= hi:
                raise ConfigError(f"{prefix}.lower[{i}] must be <= {prefix}.upper[{i}], got {lo} > {hi}")
        if not 0.2 <= self.lower[5] <= self.upper[5] <= 0.8:
            raise ConfigError(f"{prefix} height range must lie within [0.2, 0.8] m, got ({self.lower[5]}, {self.upper[5]})")
        check_range(f"{prefix}.resample_interval_s", self.resample_interval_s, lo=0.02)
        if not 0.0 <= self.standing_probability <= 1.0:
            raise ConfigError(f"{prefix}.standing_probability must lie in [0, 1], got {self.standing_probability!r}")


@dataclass
class LocomotionRandomizationConfig:
    """Disturbances the locomotion policy must reject."""

    push_interval_s: tuple[float, float] = _PUSH_RANDOMIZATION.push_interval_s  # paper III-E: every 7-10 s
    push_velocity: float = _PUSH_RANDOMIZATION.push_velocity  # [m/s] as the push task
    base_mass_offset: tuple[float, float] = _PUSH_RANDOMIZATION.base_mass_offset  # paper III-E: +-5 kg
    # Random arm motions (paper III: the locomotion policy is trained with them): targets uniform within
    # default +- amplitude [rad] per joint (SH_ROT, SH_FLE, EL_FLE, FA_ROT, WRIST_1), clipped to the joint limits,
    # a new one every interval. Ours: the largest |q - default| of the shipped push policy's arm, 128 worlds x
    # 8 s, rounded (0.17, 0.61, 0.95, 0.17, 0.49); 0.8 rad on every joint made walking fail (docs/experiments/legged_fidelity.md).
    arm_amplitude: tuple[float, ...] = (0.2, 0.6, 0.9, 0.2, 0.5)
    arm_interval_s: tuple[float, float] = (1.0, 3.0)  # ours
    leg_position_noise: float = 0.1  # ours: leg joints uniform within default +- 0.1 rad at reset
    # Force on the end-effector point (ours): a pushed object pushes back, and the paper's locomotion policy never felt
    # it (its leg-torque violations; our legged base stalls against the object, docs/legged.md). Horizontal, within +- spread
    # of the heading frame's -x (back towards the robot), magnitude uniform in [0, max] for a share `probability` of
    # the draws (else none), a new one every interval. Sliding the task's objects takes mu m g = 4-123 N.
    ee_force_max: float = 120.0  # [N]
    ee_force_probability: float = 0.75
    ee_force_spread: float = math.pi / 4  # [rad]
    ee_force_interval_s: tuple[float, float] = (1.0, 3.0)

    def validate(self, prefix: str = "randomization") -> None:
        check_range(f"{prefix}.push_interval_s", self.push_interval_s, lo=0.02)
        check_positive(f"{prefix}.push_velocity", self.push_velocity, allow_zero=True)
        check_range(f"{prefix}.base_mass_offset", self.base_mass_offset, lo=-20.0, hi=20.0)
        if len(self.arm_amplitude) != 5 or not all(0.0 <= a <= math.pi for a in self.arm_amplitude):
            raise ConfigError(f"{prefix}.arm_amplitude must be 5 amplitudes within [0, pi] rad, got {self.arm_amplitude!r}")
        check_range(f"{prefix}.arm_interval_s", self.arm_interval_s, lo=0.02)
        check_positive(f"{prefix}.leg_position_noise", self.leg_position_noise, allow_zero=True)
        check_positive(f"{prefix}.ee_force_max", self.ee_force_max, allow_zero=True)
        for name, high in (("ee_force_probability", 1.0), ("ee_force_spread", math.pi)):
            if not 0.0 <= getattr(self, name) <= high:
                raise ConfigError(f"{prefix}.{name} must lie in [0, {high:g}], got {getattr(self, name)!r}")
        check_range(f"{prefix}.ee_force_interval_s", self.ee_force_interval_s, lo=0.02)


@dataclass
class LocomotionRewardConfig:
    """Tracking rewards ``w exp(-e^2 / sigma)`` (CaT: rewards track the command, constraints do the rest) and
    legged_gym's stepping reward: without it training settled in standing still, which also avoids every
    foot-air-time violation (docs/experiments/legged_fidelity.md)."""

    linear_velocity_weight: float = 1.0  # legged_gym: 1.0, sigma 0.25
    yaw_rate_weight: float = 0.5  # legged_gym: 0.5, sigma 0.25
    attitude_weight: float = 0.5  # ours: roll and pitch commands
    height_weight: float = 0.5  # ours: height command
    sigma_linear_velocity: float = 0.25  # [m^2/s^2]
    sigma_yaw_rate: float = 0.25  # [rad^2/s^2]
    sigma_attitude: float = 0.02  # [rad^2] ours: e = 0.1 rad gives 0.61, 0.14 rad gives 0.37
    sigma_height: float = 0.005  # [m^2] ours: e = 0.07 m gives 0.37
    feet_air_time_weight: float = 1.0  # legged_gym: 1.0
    air_time_target: float = 0.3  # [s] ours (legged_gym: 0.5): every run that walked (docs/experiments/legged_fidelity.md)
    moving_command: float = 0.1  # legged_gym: |(vx, vy)| > 0.1; ours adds |yaw rate|
    # -sum_j (a_t - a_t-1)^2 over the leg actions; legged_gym: 0.01; ours 0.03: far fewer steps beyond CaT's leg
    # action-rate limit with the same velocity tracking (docs/experiments/legged_fidelity.md)
    action_rate_weight: float = 0.03
    base_vertical_velocity_weight: float = 0.0  # -w v_z^2; legged_gym lin_vel_z: 2.0; ours off
    base_roll_pitch_rate_weight: float = 0.0  # -w (omega_x^2 + omega_y^2); legged_gym ang_vel_xy: 0.05; ours off

    def validate(self, prefix: str = "rewards") -> None:
        for f in dataclasses.fields(self):
            check_positive(f"{prefix}.{f.name}", getattr(self, f.name),
                            allow_zero=f.name.endswith("weight") or f.name == "moving_command")

    @property
    def weights(self) -> tuple[float, ...]:
        """In ``REWARD_TERMS`` order."""
        return (self.linear_velocity_weight, self.yaw_rate_weight, self.attitude_weight, self.height_weight,
                self.feet_air_time_weight, self.action_rate_weight, self.base_vertical_velocity_weight,
                self.base_roll_pitch_rate_weight)


@dataclass
class LocomotionConstraintConfig:
    """CaT constraint limits (Chane-Sane et al. 2024, Table I, adapted to this robot)."""

    # Leg joint torque: the push task's nominal leg torque, so both tasks constrain the same number.
    leg_nominal_torque: tuple[float, float, float] = _PUSH_CONSTRAINTS.leg_nominal_torque
    velocity_fraction: float = 0.9  # ours: |qd| below 90 % of the USD velocity limit (7.5 rad/s)
    acceleration_limit: float = 800.0  # [rad/s^2] CaT: 800
    action_rate_limit: float = 40.0  # [1/s] ours: 0.8 action units (0.4 rad of target) per 20 ms step
    air_time_min: float = 0.25  # [s] CaT's foot air time (style) constraint
    # [N] ground contact force on one lower leg; ours: the robot's weight (56.7 kg with the arm), so a foot that
    # alone carries more than the whole robot stamps
    foot_force_limit: float = 556.0
    collision_margin: float = 0.01  # [m] ours: closer to the ground counts as touching it
    contact_margin: float = 0.01  # [m] ours: a foot this close to the ground is in contact

    def validate(self, prefix: str = "constraints") -> None:
        if len(self.leg_nominal_torque) != 3 or any(t <= 0 for t in self.leg_nominal_torque):
            raise ConfigError(f"{prefix}.leg_nominal_torque must be 3 positive numbers (HAA, HFE, KFE) [N m]")
        if not 0.0 < self.velocity_fraction <= 1.0:
            raise ConfigError(f"{prefix}.velocity_fraction must lie in (0, 1], got {self.velocity_fraction!r}")
        for name in ("acceleration_limit", "action_rate_limit", "air_time_min", "foot_force_limit"):
            check_positive(f"{prefix}.{name}", getattr(self, name))
        for name in ("collision_margin", "contact_margin"):
            check_positive(f"{prefix}.{name}", getattr(self, name), allow_zero=True)


@dataclass
class LocomotionNoiseConfig(NoiseHalfWidths):
    """Half-widths of the actor's additive uniform observation noise (legged_gym's, scale 1; ours for the arm
    as the push task's). Field names are the terms of ``dynpush.kernels.locomotion.observations.POLICY_TERMS``; the
    command and the last actions are noise-free."""

    base_linear_velocity_b: float = 0.1
    base_angular_velocity_b: float = 0.2
    projected_gravity_b: float = 0.05
    leg_joint_position: float = 0.01
    leg_joint_velocity: float = 1.5
    arm_joint_position: float = 0.01
    arm_joint_velocity: float = 0.5
    enabled: bool = True

    def half_width(self, term: str) -> float:
        return getattr(self, term, 0.0)


@dataclass
class LocomotionEnvConfig:
    """Everything that defines a locomotion environment (MuJoCo-Warp, flat ground)."""

    num_envs: int = 256
    device: str = "cpu"
    seed: int = 0
    control_dt: float = 0.02  # III: 50 Hz, the push policy's rate
    substeps: int = 4  # legged_gym: 5 ms physics step, decimation 4
    episode_length_s: float = 20.0  # legged_gym: 20 s
    randomize_first_episode_length: bool = False
    action_scale: float = 0.5  # legged_gym ANYmal: 0.5 rad per unit action
    action_clip: float = 10.0
    start_height: float = 0.52  # [m] base height at reset (the nominal stance is 0.50 m)
    base_tilt_deg: float = 60.0  # termination, as the push task
    base_min_height: float = 0.25  # [m] termination, as the push task
    mujoco: MuJoCoConfig = field(default_factory=MuJoCoConfig)
    noise: LocomotionNoiseConfig = field(default_factory=LocomotionNoiseConfig)
    commands: CommandConfig = field(default_factory=CommandConfig)
    randomization: LocomotionRandomizationConfig = field(default_factory=LocomotionRandomizationConfig)
    rewards: LocomotionRewardConfig = field(default_factory=LocomotionRewardConfig)
    constraints: LocomotionConstraintConfig = field(default_factory=LocomotionConstraintConfig)

    @property
    def max_episode_steps(self) -> int:
        return int(round(self.episode_length_s / self.control_dt))

    def validate(self) -> LocomotionEnvConfig:
        for name in ("action_scale", "action_clip", "start_height", "base_min_height"):
            check_positive(name, getattr(self, name))
        if not isinstance(self.substeps, int) or self.substeps < 1:
            raise ConfigError(f"substeps must be an integer >= 1, got {self.substeps!r}")
        if not 0.0 < self.base_tilt_deg < 180.0:
            raise ConfigError(f"base_tilt_deg must lie in (0, 180), got {self.base_tilt_deg!r}")
        return validate_env(self)

    @property
    def base_tilt(self) -> float:
        return math.radians(self.base_tilt_deg)

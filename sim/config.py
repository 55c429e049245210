"""Typed configuration of the push environment.

Defaults carry the paper's numbers (Dadiotis et al., ICRA 2025) with a comment naming the section or
table they come from; numbers the paper does not give are marked "ours" with the reason. Every
config validates itself and raises :class:`ConfigError` naming the field and the allowed values.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from dynpush.errors import UserError

SOLVERS = ("xpbd", "mujoco")


class ConfigError(UserError, ValueError):
    """An invalid configuration value; the message names the field and the allowed values."""


def check_range(name: str, pair: tuple[float, float], lo: float = -math.inf, hi: float = math.inf) -> None:
    """Raise :class:`ConfigError` unless ``pair`` is a finite ``(low, high)`` with ``lo <= low <= high <= hi``."""
    if len(pair) != 2 or not all(math.isfinite(v) for v in pair):
        raise ConfigError(f"{name} must be a finite (low, high) pair, got {pair!r}")
    if pair[0] > pair[1]:
        raise ConfigError(f"{name} must satisfy low <= high, got {pair!r}")
    if pair[0] < lo or pair[1] > hi:
        raise ConfigError(f"{name} must lie within [{lo}, {hi}], got {pair!r}")


def check_object_friction(name: str, friction: float, ground_friction: float) -> None:
    """Raise :class:`ConfigError` unless the object-floor coefficient ``friction`` is one Newton can make: it averages
    the two coefficients of a contact, so the object's own, ``2 * friction - ground_friction``, must stay >= 0."""
    if not (math.isfinite(friction) and 2.0 * friction >= ground_friction):
        raise ConfigError(f"{name} must be >= {0.5 * ground_friction:g} (half the floor's coefficient in ground.usda),"
                          f" got {friction!r}")


def check_positive(name: str, value: float, allow_zero: bool = False) -> None:
    """Raise :class:`ConfigError` unless ``value`` is finite and > 0 (>= 0 with ``allow_zero``)."""
    ok = value >= 0.0 if allow_zero else value > 0.0
    if not (math.isfinite(value) and ok):
        raise ConfigError(f"{name} must be a finite number {'>= 0' if allow_zero else '> 0'}, got {value!r}")


@dataclass
class SamplingConfig:
    """Reset sampling (paper III-B, Fig. 2A)."""

    robot_radius: tuple[float, float] = (1.2, 2.5)  # III-B: base in the annulus r in [1.2, 2.5] m
    goal_radius: tuple[float, float] = (0.0, 2.0)  # III-B: goal within r <= 2 m
    # Polar angles [rad] of the base and goal positions, and yaws; III-B: all uniform in [-pi, pi].
    # Narrower ranges give curricula and reduced tasks (tests), never the paper's evaluation.
    robot_bearing: tuple[float, float] = (-math.pi, math.pi)
    goal_bearing: tuple[float, float] = (-math.pi, math.pi)
    object_yaw: tuple[float, float] = (-math.pi, math.pi)
    goal_yaw: tuple[float, float] = (-math.pi, math.pi)
    base_yaw: tuple[float, float] = (-math.pi, math.pi)
    reach_target_on_surface: bool = True  # III-B; False = object centroid (Table I ablation)

    def validate(self, prefix: str = "sampling") -> None:
        check_range(f"{prefix}.robot_radius", self.robot_radius, lo=0.0)
        check_range(f"{prefix}.goal_radius", self.goal_radius, lo=0.0)
        for name in ("robot_bearing", "goal_bearing", "object_yaw", "goal_yaw", "base_yaw"):
            check_range(f"{prefix}.{name}", getattr(self, name), lo=-math.pi, hi=math.pi)


@dataclass
class RandomizationConfig:
    """Domain randomisation, resampled at every reset (paper III-E)."""

    friction: tuple[float, float] = (0.4, 1.25)  # III-E: combined object-floor coefficient
    mass: tuple[float, float] = (1.0, 10.0)  # III-E: object mass [kg]
    # III-E: CoM offset from the centroid as fractions of the object's dimensions (dx, dy, dz).
    com_fraction_x: tuple[float, float] = (-0.25, 0.25)
    com_fraction_y: tuple[float, float] = (-0.25, 0.25)
    com_fraction_z: tuple[float, float] = (-0.6, 0.25)
    size_x: tuple[float, float] = (0.25, 0.75)  # III-E: object dimensions [m]
    size_y: tuple[float, float] = (0.25, 0.75)
    size_z: tuple[float, float] = (0.4, 1.0)
    cylinder_probability: float = 0.5  # III-E trains cuboids and cylinders; ours: equal shares
    base_mass_offset: tuple[float, float] = (-5.0, 5.0)  # III-E: base mass +-5 kg
    push_interval_s: tuple[float, float] = (7.0, 10.0)  # III-E: random base pushes every 7-10 s
    push_velocity: float = 0.5  # ours: max xy velocity change of a push [m/s] (paper gives none)
    arm_joint_noise: float = 0.2  # ours: arm joints uniform +-0.2 rad around default at reset (III-E)

    def validate(self, prefix: str = "randomization") -> None:
        check_range(f"{prefix}.friction", self.friction, lo=0.0)
        check_range(f"{prefix}.mass", self.mass, lo=1e-3)
        for name in ("com_fraction_x", "com_fraction_y", "com_fraction_z"):
            check_range(f"{prefix}.{name}", getattr(self, name), lo=-1.0, hi=1.0)
        for name in ("size_x", "size_y", "size_z"):
            check_range(f"{prefix}.{name}", getattr(self, name), lo=0.05, hi=2.0)
        if not 0.0 <= self.cylinder_probability <= 1.0:
            raise ConfigError(f"{prefix}.cylinder_probability must lie in [0, 1], got {self.cylinder_probability!r}")
        check_range(f"{prefix}.base_mass_offset", self.base_mass_offset, lo=-20.0, hi=20.0)
        check_range(f"{prefix}.push_interval_s", self.push_interval_s, lo=0.02)
        check_positive(f"{prefix}.push_velocity", self.push_velocity, allow_zero=True)
        check_positive(f"{prefix}.arm_joint_noise", self.arm_joint_noise, allow_zero=True)


class NoiseHalfWidths:
    """The validation of both tasks' observation-noise configs: every field but ``enabled`` is a half-width >= 0."""

    def validate(self, prefix: str = "noise") -> None:
        for f in dataclasses.fields(self):
            if f.name != "enabled":
                check_positive(f"{prefix}.{f.name}", getattr(self, f.name), allow_zero=True)


@dataclass
class ObservationNoiseConfig(NoiseHalfWidths):
    """Half-widths of the actor's additive uniform noise (paper Table "Observations").

    Field names are the observation terms of ``dynpush.kernels.push.observations.POLICY_TERMS``.
    """

    ee_to_object_b: float = 0.02
    object_rotation_b: float = 0.01
    arm_joint_position: float = 0.01
    base_linear_velocity_b: float = 0.01
    base_angular_velocity_b: float = 0.20
    arm_joint_velocity: float = 0.50
    projected_gravity_b: float = 0.05
    object_to_goal_b: float = 0.02
    goal_rotation_o: float = 0.01
    enabled: bool = True


@dataclass
class ActionConfig:
    """Action = deviation about the default base state and arm configuration (paper III-C).

    The absolute command is ``default + scale * action``. Scales are ours (the paper gives none):
    one unit of action spans the locomotion command range.
    """

    # (vx [m/s], vy [m/s], yaw rate [rad/s], roll [rad], pitch [rad], height [m])
    base_default: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.5)  # III-C: zeros, height 0.5 m
    base_scale: tuple[float, ...] = (1.0, 0.6, 1.0, 0.2, 0.2, 0.1)
    arm_scale: float = 0.5  # rad per unit action
    clip: float = 10.0  # raw actions are clipped to +-clip before scaling

    def validate(self, prefix: str = "actions") -> None:
        for name in ("base_default", "base_scale"):
            if len(getattr(self, name)) != 6:
                raise ConfigError(f"{prefix}.{name} must have 6 entries (vx, vy, yaw rate, roll, pitch, height)")
        if any(s <= 0.0 for s in self.base_scale):
            raise ConfigError(f"{prefix}.base_scale entries must be > 0, got {self.base_scale!r}")
        check_positive(f"{prefix}.arm_scale", self.arm_scale)
        check_positive(f"{prefix}.clip", self.clip)


@dataclass
class BaseTrackingConfig:
    """Tracked-base locomotion model (docs/task.md, "Deviations from the paper"; ours, the paper uses a learned policy).

    The commanded 6D base state passes a first-order lag of ``time_constant`` (the locomotion
    controller's bandwidth) and a PD wrench tracks it, saturated at force/torque limits, so that
    a heavy object slows the robot down.
    """

    time_constant: float = 0.15  # s: ~1 Hz closed-loop bandwidth of legged velocity tracking
    velocity_gain: float = 8.0  # 1/s: horizontal velocity tracking
    yaw_rate_gain: float = 8.0  # 1/s
    height_frequency: float = 8.0  # rad/s: natural frequency of height/roll/pitch tracking
    damping_ratio: float = 1.0
    max_horizontal_force: float = 300.0  # N: about 0.5 x robot weight, a quadruped's traction
    max_vertical_force: float = 1500.0  # N
    max_torque: tuple[float, float, float] = (150.0, 250.0, 80.0)  # N m about heading x, y (roll, pitch) and world z
    # Effective inertia [kg m^2] scaling the attitude/yaw gains: a standing quadruped resists tilting
    # far more stiffly than its base's own inertia would suggest.
    attitude_inertia: tuple[float, float, float] = (10.0, 10.0, 5.0)

    def validate(self, prefix: str = "base") -> None:
        for name in ("time_constant", "velocity_gain", "yaw_rate_gain", "height_frequency", "damping_ratio",
                     "max_horizontal_force", "max_vertical_force"):
            check_positive(f"{prefix}.{name}", getattr(self, name))
        for name in ("max_torque", "attitude_inertia"):
            value = getattr(self, name)
            if len(value) != 3 or any(t <= 0.0 for t in value):
                raise ConfigError(f"{prefix}.{name} must be 3 positive numbers, got {value!r}")


@dataclass
class RewardConfig:
    """Rewards r1..r4 (paper Table "Rewards and constraints", III-D)."""

    task_weight: float = 2.5  # w1
    reach_weight: float = 1.25  # w2 (divided by 4 after 1500 iterations by the trainer)
    object_velocity_weight: float = 0.156  # w3
    action_rate_weight: float = 0.3  # w4
    # sigmas: not given in the paper (ours)
    sigma_reach: float = 1.0  # sigma_1 [m^0.5]
    sigma_velocity: float = 1.0  # sigma_2
    sigma_task: float = 1.0  # sigma_3 [m^0.5]
    sigma_base_rate: float = 1.0  # sigma_4,b
    sigma_arm_rate: float = 1.0  # sigma_4,a
    success_task_reward: float = 2.0  # III-D: r1 = 2 on success
    success_distance: float = 0.10  # III-B: d_success = 10 cm
    success_angle_deg: float = 10.0  # III-B: theta_success = 10 deg

    def validate(self, prefix: str = "rewards") -> None:
        for f in dataclasses.fields(self):
            check_positive(f"{prefix}.{f.name}", getattr(self, f.name), allow_zero=f.name.endswith("weight"))


@dataclass
class ConstraintConfig:
    """Constraint limits (paper Table "Rewards and constraints")."""

    # Limits of the locomotion command (the ranges the locomotion controller was trained on; ours,
    # the paper does not list them): (vx, vy, yaw rate, roll, pitch, height)
    base_command_lower: tuple[float, ...] = (-1.0, -0.6, -1.0, -0.2, -0.2, 0.4)
    base_command_upper: tuple[float, ...] = (1.0, 0.6, 1.0, 0.2, 0.2, 0.6)
    # Nominal (continuous) torque of the arm actuators [N m]; the paper uses nominal, not peak,
    # torques (IV-B). Ours: about 45 % of the peak efforts authored in robot.usda.
    arm_nominal_torque: tuple[float, ...] = (40.0, 40.0, 40.0, 12.0, 12.0)
    # Nominal leg joint torque [N m] for (HAA, HFE, KFE) of every leg; ours (ANYdrive-like).
    leg_nominal_torque: tuple[float, float, float] = (40.0, 40.0, 40.0)
    object_tilt_limit_deg: float = 10.0  # IV: theta_lim = 10 deg
    # c_theta is active while ||v_b|| > this [m/s]; the paper writes "> 0".
    base_moving_speed: float = 0.0
    contact_distance: float = 0.005  # m: a contact pair closer than this counts as touching (ours)
    # Ours: contacts are those of the state a control step ends in, the state its action leaves. Counted over the
    # step's substeps instead, a lasting contact violates from the first substep, which starts from the previous
    # step's state: every action inside the contact is then terminated alike (CaT), the one that ends it included,
    # and no action is credited with leaving it. Configs of runs started before it read as False (TrainConfig.from_dict).
    contacts_at_step_end: bool = True

    def validate(self, prefix: str = "constraints") -> None:
        for name in ("base_command_lower", "base_command_upper"):
            if len(getattr(self, name)) != 6:
                raise ConfigError(f"{prefix}.{name} must have 6 entries")
        for i, (lo, hi) in enumerate(zip(self.base_command_lower, self.base_command_upper)):
            if lo > hi:
                raise ConfigError(f"{prefix}.base_command_lower[{i}] must be <= base_command_upper[{i}], got {lo} > {hi}")
        if len(self.arm_nominal_torque) != 5 or any(t <= 0 for t in self.arm_nominal_torque):
            raise ConfigError(f"{prefix}.arm_nominal_torque must be 5 positive numbers, got {self.arm_nominal_torque!r}")
        if len(self.leg_nominal_torque) != 3 or any(t <= 0 for t in self.leg_nominal_torque):
            raise ConfigError(f"{prefix}.leg_nominal_torque must be 3 positive numbers")
        check_positive(f"{prefix}.object_tilt_limit_deg", self.object_tilt_limit_deg)
        check_positive(f"{prefix}.base_moving_speed", self.base_moving_speed, allow_zero=True)
        check_positive(f"{prefix}.contact_distance", self.contact_distance, allow_zero=True)
        if not isinstance(self.contacts_at_step_end, bool):
            raise ConfigError(f"{prefix}.contacts_at_step_end must be True or False, got {self.contacts_at_step_end!r}")


@dataclass
class TerminationConfig:
    """Unrecoverable falls that end an episode early (paper III-B; thresholds are ours).

    The object counts as toppled once its +z axis is tilted beyond ``object_topple_deg``: no
    sampled cuboid or cylinder recovers from lying on its side under pushing alone. The robot has
    fallen when its base tilts beyond ``base_tilt_deg`` or drops below ``base_min_height``.
    """

    object_topple_deg: float = 60.0
    base_tilt_deg: float = 60.0
    base_min_height: float = 0.25

    def validate(self, prefix: str = "terminations") -> None:
        for f in dataclasses.fields(self):
            check_positive(f"{prefix}.{f.name}", getattr(self, f.name))


@dataclass
class SimConfig:
    """Physics settings, chosen by measurement (docs/simulator.md, benchmarks/env_throughput.py)."""

    solver: str = "xpbd"
    substeps: int = 4  # per 20 ms control step
    xpbd_iterations: int = 4
    contacts_per_world: int = 48  # contact buffer budget; a resting box uses ~8, a push ~12

    def validate(self, prefix: str = "sim") -> None:
        if self.solver not in SOLVERS:
            raise ConfigError(f"{prefix}.solver must be one of {SOLVERS}, got {self.solver!r}")
        if self.substeps < 1 or self.substeps % 2:
            raise ConfigError(f"{prefix}.substeps must be an even integer >= 2, got {self.substeps!r}")
        if self.xpbd_iterations < 1:
            raise ConfigError(f"{prefix}.xpbd_iterations must be >= 1, got {self.xpbd_iterations!r}")
        if self.contacts_per_world < 8:
            raise ConfigError(f"{prefix}.contacts_per_world must be >= 8, got {self.contacts_per_world!r}")


@dataclass
class MuJoCoConfig:
    """MuJoCo-Warp solver settings of the legged robot, chosen by measurement (``benchmarks/locomotion_throughput.py``,
    docs/simulator.md): CG with 5 iterations runs faster than MuJoCo's defaults (Newton solver, default buffers); a
    robot uses at most 32 constraint rows and ~17 contact candidates."""

    solver: str = "cg"
    iterations: int = 5
    ls_iterations: int = 5
    nconmax: int = 24  # contacts per world
    njmax: int = 64  # constraint rows per world

    def validate(self, prefix: str = "mujoco") -> None:
        if self.solver not in ("cg", "newton"):
            raise ConfigError(f"{prefix}.solver must be 'cg' or 'newton', got {self.solver!r}")
        for name in ("iterations", "ls_iterations", "nconmax", "njmax"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ConfigError(f"{prefix}.{name} must be an integer >= 1, got {getattr(self, name)!r}")


@dataclass
class LeggedModeConfig:
    """Legged mode of the push task (docs/legged.md): ``robot_legged.usda`` on MuJoCo-Warp, its 12 leg joints driven by a
    frozen locomotion policy that turns the push policy's 6D base command into leg joint targets at the control
    rate, instead of the tracked base. The leg-torque constraint then uses the simulated PD torques."""

    enabled: bool = False
    # locomotion.onnx of a ``dynpush train --task locomotion`` run; "" = leg targets come from outside
    # (``PushEnv.set_leg_targets``: sim-to-sim, where the runtime runs the locomotion policy).
    locomotion_policy: str = ""
    # Newton's collision pipeline generates the contacts here (robot and object), up to sim.contacts_per_world per
    # world, and MuJoCo drops without an error what exceeds its buffers: with the locomotion task's 24 / 64 the
    # object lost its ground contacts whenever the legs moved. Each contact takes 4 constraint rows (pyramidal
    # friction cone). The locomotion task's 5 CG (and line-search) iterations do not converge the object's contacts
    # beside a walking robot: objects no robot part touched rose and tipped over (tests/test_locomotion.py); 30 topple
    # fewer at a third more time per step (docs/simulator.md).
    mujoco: MuJoCoConfig = field(default_factory=lambda: MuJoCoConfig(iterations=30, ls_iterations=30, nconmax=64,
                                                                      njmax=256))

    def validate(self, prefix: str = "legged") -> None:
        self.mujoco.validate(f"{prefix}.mujoco")
        if self.enabled and self.mujoco.njmax < 4 * self.mujoco.nconmax:
            raise ConfigError(f"{prefix}.mujoco.njmax ({self.mujoco.njmax}) must be >= 4 x {prefix}.mujoco.nconmax "
                              f"({4 * self.mujoco.nconmax}): every contact takes 4 constraint rows")


@dataclass
class PushEnvConfig:
    """Everything that defines a push environment."""

    num_envs: int = 256
    device: str = "cpu"
    seed: int = 0
    control_dt: float = 0.02  # III: push and locomotion policies at 50 Hz
    episode_length_s: float = 20.0  # III-B: 20 s episodes
    randomize_first_episode_length: bool = False  # training: desynchronize the first episodes' ends
    sim: SimConfig = field(default_factory=SimConfig)
    sampling: SamplingConfig = field(default_factory=SamplingConfig)
    randomization: RandomizationConfig = field(default_factory=RandomizationConfig)
    noise: ObservationNoiseConfig = field(default_factory=ObservationNoiseConfig)
    actions: ActionConfig = field(default_factory=ActionConfig)
    base: BaseTrackingConfig = field(default_factory=BaseTrackingConfig)
    rewards: RewardConfig = field(default_factory=RewardConfig)
    constraints: ConstraintConfig = field(default_factory=ConstraintConfig)
    terminations: TerminationConfig = field(default_factory=TerminationConfig)
    legged: LeggedModeConfig = field(default_factory=LeggedModeConfig)
    # Ours: the critic also reads whether the object is at its goal (kernels/push/observations.py says why). Configs
    # of runs started before it existed read as False (TrainConfig.from_dict), so that those runs resume as they were.
    critic_reads_object_at_goal: bool = True

    @property
    def max_episode_steps(self) -> int:
        return int(round(self.episode_length_s / self.control_dt))

    def validate(self) -> PushEnvConfig:
        validate_env(self)
        if not isinstance(self.critic_reads_object_at_goal, bool):
            raise ConfigError(
                f"critic_reads_object_at_goal must be True or False, got {self.critic_reads_object_at_goal!r}")
        # Older runs' configs carry the locomotion task's buffers in the legged section, unused while it is off.
        if self.legged.enabled and self.legged.mujoco.nconmax < self.sim.contacts_per_world:
            raise ConfigError(f"legged.mujoco.nconmax ({self.legged.mujoco.nconmax}) must be >= sim.contacts_per_world "
                              f"({self.sim.contacts_per_world}): MuJoCo would drop contacts that Newton generates")
        return self


def validate_env(cfg):
    """Checks what every environment config has (``num_envs``, ``device``, ``control_dt``, ``episode_length_s``)
    and validates each of its sections; returns ``cfg``."""
    if not isinstance(cfg.num_envs, int) or cfg.num_envs < 1:
        raise ConfigError(f"num_envs must be an integer >= 1, got {cfg.num_envs!r}")
    if not (cfg.device == "cpu" or cfg.device.startswith("cuda")):
        raise ConfigError(f"device must be 'cpu' or 'cuda[:N]', got {cfg.device!r}")
    check_positive("control_dt", cfg.control_dt)
    check_positive("episode_length_s", cfg.episode_length_s)
    if cfg.max_episode_steps < 1:
        raise ConfigError("episode_length_s must be at least one control step")
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if hasattr(value, "validate"):
            value.validate(f.name)
    return cfg

"""PushEnv: N push worlds in one Newton model, as an rsl_rl ``VecEnv``.

One control step (50 Hz) is one captured Warp graph: action processing (or, for :meth:`PushEnv.step_commands`,
commands given as they are, in a graph of their own), ``substeps`` physics
substeps (tracking wrench, collision, contact classification, solver), random pushes, joint
readings, rewards, constraints, terminations, auto-reset of finished worlds and observations. The
torch tensors handed to the trainer are zero-copy views of the Warp buffers.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable

import newton
import numpy as np
import torch
import warp as wp
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from dynpush.kernels.push import (
    actions as actions_k,
    base_tracking,
    constraints as constraints_k,
    contacts as contacts_k,
    observations as observations_k,
    rewards as rewards_k,
    sampling,
    terminations,
)
from dynpush.kernels.push.views import CONTACT_COLUMNS, NUM_ACTIONS, NUM_ARM_JOINTS, NUM_CRITIC_OBS, NUM_POLICY_OBS, PushTask, RobotView
from dynpush.runtime.actions import ActionMapping, ActionScaling
from dynpush.runtime.frames import yaw_quat

from .config import ConfigError, PushEnvConfig, check_object_friction
from .env_state import EnvBase, articulation_reset_mask
from .episode import EpisodeSpec
from .scene import build_scene

wp.config.enable_backward = False  # no adjoint kernels: a cold kernel compile took 36 s instead of 61 s (docs/simulator.md)

REWARD_TERMS = ("task", "reach", "object_velocity", "action_rate")
CONSTRAINT_GROUPS = constraints_k.CONSTRAINT_GROUPS


def set_sub_range(array: wp.array, what: str, field: str, configured: tuple[float, float], unit: str, low: float,
                  high: float) -> None:
    """Writes (``low``, ``high``) into the one-element vec2 ``array`` once it lies within the ``configured`` range of
    config ``field``; a ConfigError naming both otherwise."""
    if not configured[0] <= low <= high <= configured[1]:
        raise ConfigError(f"{what} must lie within {field} {configured} {unit} with low <= high, got ({low!r}, {high!r})")
    array.fill_(wp.vec2(low, high))


def range_value(array: wp.array) -> tuple[float, float]:
    """The (low, high) held by a one-element vec2 ``array``."""
    low, high = array.numpy()[0]
    return float(low), float(high)


class PushEnv(EnvBase, VecEnv):
    """Goal pushing with a tracked-base mobile manipulator (paper III); see the module docstring.

    Fills in :class:`~dynpush.sim.env_state.EnvBase`: the scene, solver, buffers and parameters (``_build``), the step
    kernels, episode sampling (``_reset_flagged``: draw, then ``_start_flagged``), observations, episodes ended by
    success or failure (``episode_success >= 0``) with success, toppled and the near-goal split, and the state
    arrays, whose loading first re-applies every world's saved episode. Robot-model hooks for
    :class:`~dynpush.sim.legged_push_env.LeggedPushEnv`: ``_build_scene``, ``_make_solver``, ``_drive_base``,
    ``_robot_constraints``, ``_start_robot_flagged``."""

    reward_names = REWARD_TERMS
    num_actions = NUM_ACTIONS
    _constraint_groups = CONSTRAINT_GROUPS
    cfg: PushEnvConfig

    # ------------------------------------------------------------------ construction
    def _build(self) -> None:
        cfg = self.cfg
        self.scene = self._build_scene()
        # How actions become commands (the runtime's numpy definition): the action kernel's parameters.
        a, arm_default = cfg.actions, self.scene.robot.arm_default[:NUM_ARM_JOINTS]
        self.action_mapping = ActionMapping(ActionScaling(a.base_default, a.base_scale),
                                            ActionScaling(arm_default, a.arm_scale), a.clip)
        check_object_friction("randomization.friction[0]", cfg.randomization.friction[0], self.scene.ground_friction)
        self._make_solver()
        self._make_buffers()
        self._make_params()

    def _build_scene(self):
        return build_scene(self.cfg.num_envs, self.cfg.device)

    def _make_solver(self) -> None:
        model = self.scene.model
        if self.cfg.sim.solver == "xpbd":
            # Contact weighting off: with it, a 0.3 m/s push moved a 5 kg box 0.16-0.27 m instead of ~0.9-1.0 m (docs/simulator.md).
            self.solver = newton.solvers.SolverXPBD(
                model, iterations=self.cfg.sim.xpbd_iterations, rigid_contact_con_weighting=False
            )
        else:
            # Body variants (the cuboid/cylinder object) need Newton's own contacts.
            self.solver = newton.solvers.SolverMuJoCo(model, use_mujoco_contacts=False)
        self.state_0 = model.state()
        self.state_1 = model.state()
        self.control = model.control()
        # Contact buffers sized per world: XPBD's contact kernels run over the whole buffer, and Newton's default
        # (hundreds per world for this scene) multiplied the solver's time (docs/simulator.md).
        self.collision = newton.CollisionPipeline(
            model, rigid_contact_max=self.cfg.sim.contacts_per_world * self.num_envs
        )
        self.contacts = self.collision.contacts()

    def _make_buffers(self) -> None:
        n, scene = self.num_envs, self.scene
        i32 = lambda a: wp.array(np.asarray(a, dtype=np.int32), dtype=int)  # noqa: E731
        zeros = lambda shape, dtype=float: wp.zeros(shape, dtype=dtype)  # noqa: E731

        task = PushTask()
        task.goal_pos = zeros(n, wp.vec3)
        task.goal_quat = wp.array(np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)), dtype=wp.quat)
        task.reach_target_o = zeros(n, wp.vec3)
        task.object_dims = wp.array(np.tile([0.5, 0.5, 0.7], (n, 1)), dtype=wp.vec3)
        task.object_shape = zeros(n, int)
        task.object_mass = wp.full(n, 1.0, dtype=float)
        task.object_com_o = zeros(n, wp.vec3)
        task.object_inertia = wp.array(np.ones((n, 3)), dtype=wp.vec3)
        task.object_friction = zeros(n)
        task.arm_default = wp.array(self.action_mapping.arm.default, dtype=float)
        task.actions = zeros((n, NUM_ACTIONS))
        task.last_actions = zeros((n, NUM_ACTIONS))
        task.base_command = zeros((n, 6))
        task.base_command_filtered = zeros((n, 6))
        # The base command the base receives: task.base_command clamped to the limits, written with it every step.
        self.base_target = zeros((n, 6))
        task.base_wrench_b = zeros(n, wp.spatial_vector)
        task.arm_command = zeros((n, NUM_ARM_JOINTS))
        task.contacts = zeros((n, CONTACT_COLUMNS), int)
        task.episode_step = zeros(n, int)
        task.reach_reward_held = zeros(n)
        task.next_push_step = zeros(n, int)
        task.rng_counter = zeros(n, int)
        r = self.cfg.rewards
        task.reward_weights = wp.array(
            [r.task_weight, r.reach_weight, r.object_velocity_weight, r.action_rate_weight], dtype=float
        )
        self.task = task
        self._reward_weights = task.reward_weights

        model = scene.model
        self.views = [self._robot_view(s) for s in (self.state_0, self.state_1)]
        self._make_step_buffers(NUM_POLICY_OBS, NUM_CRITIC_OBS, constraints_k.NUM_CONSTRAINTS)
        self.command_base = zeros((n, 6))  # step_commands: the base command and arm targets given as they are
        self.command_arm = zeros((n, NUM_ARM_JOINTS))
        self.success = zeros(n, int)
        self.episode_success = wp.full(n, -1, dtype=int)
        self.episode_toppled = zeros(n, int)
        self.episode_diverged = zeros(n, int)
        self.episode_fallen = zeros(n, int)
        self.variant = zeros(n, int)
        self.goal_difficulty = wp.ones(1, dtype=float)  # 1: the paper's goal distribution
        # (low, high) [kg] of the object masses drawn from now on: randomization.mass unless a training curriculum
        # narrows it; evaluation and export, which never set it, draw from the configured range.
        self.object_mass_range = wp.array([wp.vec2(*self.cfg.randomization.mass)], dtype=wp.vec2)
        # (low, high) [m] of the goal distances drawn from now on: sampling.goal_radius unless a training curriculum
        # narrows it; evaluation and export, which never set it, draw from the configured annulus.
        self.goal_radius_range = wp.array([wp.vec2(*self.cfg.sampling.goal_radius)], dtype=wp.vec2)
        # (share, radius [m], max_yaw [rad]) of near-goal starts, a training-only curriculum; share 0: the paper's
        # goal distribution, so evaluation and export, which never set it, use that.
        self.near_goal = zeros(1, wp.vec3)
        self.near_goal_start = zeros(n, int)  # 1: the world's episode started near its goal
        self.near_goal_ended = zeros(n, int)  # near_goal_start of the episode the world's last reset ended
        self._near_goal_share = 0.0  # the host's copy: episode statistics are split only while it is > 0
        self.behind_start = zeros(1, wp.vec2)  # (share, spread [rad]) of starts behind the object; share 0: the paper's
        self._episodes_ended = 0
        self._episodes_succeeded = 0
        spec = sampling.EpisodeSpec()
        for name in ("shape", "first_push_step"):
            setattr(spec, name, zeros(n, int))
        for name in ("mass", "friction", "object_yaw", "base_mass_offset"):
            setattr(spec, name, zeros(n))
        for name in ("dims", "com_o", "reach_target_o", "goal", "base"):
            setattr(spec, name, zeros(n, wp.vec3))
        spec.arm_q = zeros((n, NUM_ARM_JOINTS))
        self.spec = spec
        self.articulation_mask = wp.zeros(model.articulation_count, dtype=bool)
        self.shape_role = i32(scene.shape_role)
        self.shape_self_column = i32(scene.shape_self_column)
        self.object_body = i32(scene.object_body)
        self.object_shape = i32(scene.object_shape)
        self.robot_q_start = i32(scene.robot_q_start)
        self.robot_qd_start = i32(scene.robot_qd_start)
        self.object_q_start = i32(scene.object_q_start)
        self.object_qd_start = i32(scene.object_qd_start)

        # Zero-copy torch views.
        t = wp.to_torch
        self.command_base_t, self.command_arm_t = t(self.command_base), t(self.command_arm)
        columns = observations_k.critic_input_columns(self.cfg.critic_reads_object_at_goal)
        self.critic_input_columns = torch.tensor(columns, device=self.critic_obs_t.device)
        self.episode_success_t = t(self.episode_success)
        self.episode_toppled_t = t(self.episode_toppled)
        self.episode_diverged_t = t(self.episode_diverged)
        self.episode_fallen_t = t(self.episode_fallen)
        self.success_t = t(self.success)
        self.near_goal_ended_t = t(self.near_goal_ended)

    def _robot_view(self, state: newton.State) -> RobotView:
        scene, model = self.scene, self.scene.model
        i32 = lambda a: wp.array(np.asarray(a, dtype=np.int32), dtype=int)  # noqa: E731
        view = RobotView()
        view.body_q = state.body_q
        view.body_qd = state.body_qd
        view.body_com = model.body_com
        view.body_mass = model.body_mass
        view.joint_q = state.joint_q
        view.joint_qd = state.joint_qd
        view.base_body = i32(scene.base_body)
        view.object_body = i32(scene.object_body)
        view.ee_body = i32(scene.ee_body)
        view.arm_q_start = i32(scene.arm_q_start)
        view.arm_qd_start = i32(scene.arm_qd_start)
        view.robot_body_start = i32(scene.robot_body_start)
        view.robot_body_count = scene.robot_body_count
        view.ee_offset = wp.vec3(*scene.ee_offset)
        return view

    def _make_params(self) -> None:
        cfg, robot = self.cfg, self.scene.robot
        f32 = lambda a: wp.array(np.asarray(a, dtype=np.float32), dtype=float)  # noqa: E731
        self.base_default = f32(self.action_mapping.base.default)
        self.base_scale = f32(self.action_mapping.base.scale)

        b = cfg.base
        tracking = base_tracking.BaseTrackingParams()
        tracking.dt = cfg.control_dt / cfg.sim.substeps
        tracking.time_constant = b.time_constant
        tracking.velocity_gain = b.velocity_gain
        tracking.yaw_rate_gain = b.yaw_rate_gain
        tracking.attitude_stiffness = b.height_frequency**2
        tracking.attitude_damping = 2.0 * b.damping_ratio * b.height_frequency
        tracking.max_horizontal_force = b.max_horizontal_force
        tracking.max_vertical_force = b.max_vertical_force
        tracking.max_torque = wp.vec3(*b.max_torque)
        tracking.attitude_inertia = wp.vec3(*b.attitude_inertia)
        tracking.gravity = 9.81
        self.tracking_params = tracking

        r = cfg.rewards
        rp = rewards_k.RewardParams()
        rp.sigma_reach, rp.sigma_velocity, rp.sigma_task = r.sigma_reach, r.sigma_velocity, r.sigma_task
        rp.sigma_base_rate, rp.sigma_arm_rate = r.sigma_base_rate, r.sigma_arm_rate
        rp.success_task_reward = r.success_task_reward
        rp.success_distance = r.success_distance
        rp.arm_scale = cfg.actions.arm_scale
        self.reward_params = rp
        # [rad] the success angle of the steps from now on: success_angle_deg unless a training curriculum widens it;
        # evaluation and export, which never set it, count the configured one.
        self.success_angle = wp.array([math.radians(r.success_angle_deg)], dtype=float)

        c = cfg.constraints
        arm = constraints_k.ArmLimits()
        arm.lower = f32(robot.arm_lower[:NUM_ARM_JOINTS])
        arm.upper = f32(robot.arm_upper[:NUM_ARM_JOINTS])
        arm.velocity = f32(robot.arm_velocity_limit[:NUM_ARM_JOINTS])
        arm.stiffness = f32(robot.arm_stiffness[:NUM_ARM_JOINTS])
        arm.damping = f32(robot.arm_damping[:NUM_ARM_JOINTS])
        arm.peak_torque = f32(robot.arm_peak_torque[:NUM_ARM_JOINTS])
        arm.nominal_torque = f32(c.arm_nominal_torque)
        self.arm_limits = arm
        cp = constraints_k.ConstraintParams()
        cp.base_lower = f32(c.base_command_lower)
        cp.base_upper = f32(c.base_command_upper)
        # Articulated legs (LeggedPushEnv) overwrite the leg-torque columns with the simulated torques.
        torque_map = robot.leg_torque_map if robot.leg_torque_map is not None else np.zeros((12, 6))
        cp.leg_torque_map = wp.array(torque_map.astype(np.float32), dtype=float)
        cp.leg_nominal_torque = f32(np.tile(c.leg_nominal_torque, 4))
        cp.object_tilt_limit = math.radians(c.object_tilt_limit_deg)
        cp.base_moving_speed = c.base_moving_speed
        cp.arm_scale = cfg.actions.arm_scale
        cp.control_dt = cfg.control_dt
        self.constraint_params = cp
        # What the robot receives is clamped to the limits the exported contract carries (policies/export.py), as
        # the runtime's safety layer clamps it; the constraints above judge the unclamped commands.
        limits = actions_k.CommandLimits()
        limits.base_lower, limits.base_upper = cp.base_lower, cp.base_upper
        limits.arm_lower, limits.arm_upper = arm.lower, arm.upper
        self.command_limits = limits

        t = cfg.terminations
        tp = terminations.TerminationParams()
        tp.object_topple = math.radians(t.object_topple_deg)
        tp.base_tilt = math.radians(t.base_tilt_deg)
        tp.base_min_height = t.base_min_height
        tp.max_episode_steps = cfg.max_episode_steps
        self.termination_params = tp

        s, rnd = cfg.sampling, cfg.randomization
        sp = sampling.SamplingParams()
        for name in ("robot_radius", "robot_bearing", "goal_bearing", "object_yaw", "goal_yaw", "base_yaw"):
            setattr(sp, name, wp.vec2(*getattr(s, name)))
        sp.surface_target = int(s.reach_target_on_surface)
        sp.friction = wp.vec2(*rnd.friction)
        sp.ground_friction = self.scene.ground_friction
        sp.com_fraction_lo = wp.vec3(rnd.com_fraction_x[0], rnd.com_fraction_y[0], rnd.com_fraction_z[0])
        sp.com_fraction_hi = wp.vec3(rnd.com_fraction_x[1], rnd.com_fraction_y[1], rnd.com_fraction_z[1])
        sp.size_lo = wp.vec3(rnd.size_x[0], rnd.size_y[0], rnd.size_z[0])
        sp.size_hi = wp.vec3(rnd.size_x[1], rnd.size_y[1], rnd.size_z[1])
        sp.cylinder_probability = rnd.cylinder_probability
        sp.base_mass_offset = wp.vec2(*rnd.base_mass_offset)
        sp.push_interval_steps = wp.vec2(rnd.push_interval_s[0] / cfg.control_dt, rnd.push_interval_s[1] / cfg.control_dt)
        sp.push_velocity = rnd.push_velocity
        sp.arm_joint_noise = rnd.arm_joint_noise
        sp.base_height = cfg.actions.base_default[5]
        sp.frozen_joint_value = float(robot.arm_default[NUM_ARM_JOINTS])
        self.sampling_params = sp

        scales = []
        for name, size in observations_k.POLICY_TERMS:
            scales += [0.0 if name == "last_actions" else getattr(cfg.noise, name)] * size  # Table: a_{t-1} noise-free
        self.noise_scale = f32(scales)

    # ------------------------------------------------------------------ the step
    stage_timer: Callable[[str], contextlib.AbstractContextManager] | None = None
    """Benchmarks set this to time the stages of an uncaptured step (``physics``, ``collision``, ``kernels``)."""

    def _stage(self, name: str) -> contextlib.AbstractContextManager:
        return self.stage_timer(name) if self.stage_timer else contextlib.nullcontext()

    def step_uncaptured(self, actions: torch.Tensor) -> None:
        """One control step launched kernel by kernel (same result as :meth:`step`); for profiling."""
        self.actions_t.copy_(actions)
        with wp.ScopedDevice(self.wp_device):
            self._step_kernels()

    _graph_commands: wp.Graph | None = None
    """The step graph of :meth:`step_commands`, captured at its first call (training never pays for it)."""

    def step_commands(
        self, base_command: torch.Tensor | np.ndarray, arm_targets: torch.Tensor | np.ndarray,
        actions: torch.Tensor | np.ndarray | None = None,
    ) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """One control step on commands given as they are, mapped outside (sim-to-sim: the runtime's); same result as
        :meth:`step`.

        ``base_command`` (num_envs, 6) in ``BASE_COMMAND_NAMES`` order and units and ``arm_targets`` (num_envs, 5)
        [rad] go where the action mapping writes its own (``task.base_command``, ``task.arm_command``), unscaled, and
        are sent to the robot as the mapped ones are, clamped to the command limits (kernel ``apply_commands``). The
        action terms (the policy observation's ``last_actions``, the action-rate reward and the arm-rate constraint)
        are about the policy's output, which commands do not carry: ``actions`` (num_envs, 11), the raw policy output
        behind the commands if the caller has it, are recorded as :meth:`step` records its own (so that
        ``step_commands(*action_mapping.commands(a), a)`` is ``step(a)``); without them the history records zeros, a
        policy at rest, and those terms do not describe the commands. Commands must be finite.
        """
        base_command, arm_targets = (torch.as_tensor(c, dtype=torch.float32) for c in (base_command, arm_targets))
        if base_command.shape != self.command_base_t.shape or arm_targets.shape != self.command_arm_t.shape:
            raise ValueError(f"commands must have shapes {tuple(self.command_base_t.shape)} and"
                             f" {tuple(self.command_arm_t.shape)}, got {tuple(base_command.shape)} and"
                             f" {tuple(arm_targets.shape)}")
        if not (bool(torch.isfinite(base_command).all()) and bool(torch.isfinite(arm_targets).all())):
            raise ValueError("commands must be finite")
        self.command_base_t.copy_(base_command)
        self.command_arm_t.copy_(arm_targets)
        if actions is None:
            self.actions_t.zero_()
        else:
            self.actions_t.copy_(torch.as_tensor(actions, dtype=torch.float32))
        with wp.ScopedDevice(self.wp_device):
            if self._graph_commands is None:
                self._capture_commands()
            self._launch_command_step()
        return self._step_result()

    def _capture_commands(self) -> None:
        """Captures the step of :meth:`step_commands` into ``_graph_commands``."""
        with wp.ScopedCapture() as capture:
            self._apply_commands()
            self._physics_and_task()
        self._graph_commands = capture.graph

    def _launch_command_step(self) -> None:
        """Runs one control step of :meth:`step_commands` on the commands in ``command_base`` and ``command_arm``."""
        wp.capture_launch(self._graph_commands)

    def _physics_substeps(self) -> None:
        cfg = self.cfg
        dt = cfg.control_dt / cfg.sim.substeps
        states = [self.state_0, self.state_1]
        c = self.contacts
        at_step_end = cfg.constraints.contacts_at_step_end
        for sub in range(cfg.sim.substeps):
            state_in, state_out = states[sub % 2], states[(sub + 1) % 2]
            view = self.views[sub % 2]
            with self._stage("kernels"):
                self._drive_base(view, state_in)
            with self._stage("collision"):
                self.collision.collide(state_in, c)
                if not at_step_end:
                    self._classify_contacts(state_in)
            with self._stage("physics"):
                self.solver.step(state_in, state_out, self.control, c, dt)
            if at_step_end and sub == cfg.sim.substeps - 1:
                with self._stage("collision"):
                    # The last substep's pairs, their gaps measured in the state the step ends in.
                    self._classify_contacts(state_out)

    def _classify_contacts(self, state: newton.State) -> None:
        """Marks the contact columns of ``self.task`` for the pairs in ``self.contacts`` touching in ``state``."""
        c, model = self.contacts, self.scene.model
        wp.launch(
            contacts_k.classify_contacts,
            dim=c.rigid_contact_max,
            inputs=[c.rigid_contact_count, c.rigid_contact_shape0, c.rigid_contact_shape1, c.rigid_contact_point0,
                    c.rigid_contact_point1, c.rigid_contact_normal, c.rigid_contact_margin0, c.rigid_contact_margin1,
                    model.shape_body, model.shape_world, self.shape_role, self.shape_self_column, state.body_q,
                    self.cfg.constraints.contact_distance, self.task],
            device=self.wp_device,
        )

    def _drive_base(self, view: RobotView, state: newton.State) -> None:
        """The tracked base: the tracking wrench of the current command, on ``state`` (one substep)."""
        state.clear_forces()
        self._launch(base_tracking.apply_base_wrench, [view, self.task, self.base_target, self.tracking_params,
                                                       state.body_f])

    def _step_kernels(self) -> None:
        self._process_actions()
        self._physics_and_task()

    def _process_actions(self) -> None:
        mapping = self.action_mapping
        with self._stage("kernels"):
            self._launch(actions_k.process_actions, [self.raw_actions, self.views[0], self.task, self.base_default,
                                                     self.base_scale, float(mapping.arm.scale), mapping.clip,
                                                     self.command_limits, self.base_target,
                                                     self.control.joint_target_q])

    def _apply_commands(self) -> None:
        self._launch(actions_k.apply_commands, [self.raw_actions, self.command_base, self.command_arm, self.views[0],
                                                self.task, self.action_mapping.clip, self.command_limits,
                                                self.base_target, self.control.joint_target_q])

    def _physics_and_task(self) -> None:
        """Physics substeps, then rewards, constraints, terminations, resets and observations."""
        cfg, model, view = self.cfg, self.scene.model, self.views[0]
        seed = cfg.seed
        with self._stage("kernels"):
            self.task.contacts.zero_()
        self._physics_substeps()
        with self._stage("kernels"):
            self._launch(sampling.apply_pushes, [seed, self.sampling_params, view, self.task, self.state_0.body_qd])
            newton.eval_ik(model, self.state_0, self.state_0.joint_q, self.state_0.joint_qd)
            self._launch(rewards_k.compute_rewards, [view, self.task, self.reward_params, self.success_angle,
                                                     self.base_scale, self.reward, self.reward_terms, self.success])
            self._launch(constraints_k.compute_constraints, [view, self.task, self.arm_limits, self.constraint_params,
                                                             self.control.joint_target_q, self.constraints])
            self._robot_constraints()
            self._launch(terminations.compute_terminations, [view, self.task, self.termination_params, self.success,
                                                             self.reset_flags, self.time_out, self.episode_success,
                                                             self.episode_toppled, self.episode_diverged,
                                                             self.episode_fallen])
            self._reset_flagged()
            self._observe()

    def _reset_flagged(self) -> None:
        """Draws and starts new episodes for worlds with ``reset_flags != 0`` (inside the captured step)."""
        self._launch(sampling.sample_episodes, [self.reset_flags, self.cfg.seed, self.sampling_params, self.goal_difficulty,
                                                self.object_mass_range, self.goal_radius_range, self.near_goal,
                                                self.behind_start, self.task, self.spec, self.near_goal_start,
                                                self.near_goal_ended])
        self._start_flagged()

    def _start_flagged(self) -> None:
        """Applies ``self.spec`` to the flagged worlds: task buffers, object variant and properties, poses."""
        model, view = self.scene.model, self.views[0]
        self._launch(sampling.start_episodes, [
            self.reset_flags, self.spec, self.sampling_params, view, self.task, self.base_default,
            self.scene.robot.base_mass, self.robot_q_start, self.object_q_start, self.state_0.joint_q,
            model.body_mass, model.body_inv_mass, self.variant])
        self._start_robot_flagged()
        flags = model.select_body_variants(self.variant, bodies=self.object_body)
        self._launch(sampling.apply_object_properties, [
            self.reset_flags, self.task, self.object_body, self.object_shape, model.shape_scale,
            model.shape_collision_radius, model.shape_collision_aabb_lower, model.shape_collision_aabb_upper,
            model.shape_material_mu, model.body_mass, model.body_inv_mass, model.body_com, model.body_inertia,
            model.body_inv_inertia])
        self._launch(sampling.zero_velocities, [self.reset_flags, self.robot_qd_start, self.scene.robot_qd_count,
                                                self.object_qd_start, self.state_0.joint_qd])
        wp.launch(articulation_reset_mask, dim=model.articulation_count,
                  inputs=[self.reset_flags, model.articulation_world, self.articulation_mask], device=self.wp_device)
        newton.eval_fk(model, self.state_0.joint_q, self.state_0.joint_qd, self.state_0, mask=self.articulation_mask)
        self.solver.notify_model_changed(flags)

    def _robot_constraints(self) -> None:
        """Constraint columns a robot model computes itself (the tracked base has none beyond the kernels')."""

    def _start_robot_flagged(self) -> None:
        """Robot state beyond the free base and the arm for flagged worlds (the tracked base has none)."""

    def set_episodes(self, episodes: dict[int, EpisodeSpec]) -> TensorDict:
        """Starts user-chosen episodes (evaluation scenarios, tests) in the given worlds, now.

        Other worlds continue untouched. Returns the observations of all worlds.
        """
        for w in episodes:
            if not 0 <= w < self.num_envs:
                raise IndexError(f"world index must lie in [0, {self.num_envs}), got {w}")
        with wp.ScopedDevice(self.wp_device):
            arrays = {name: getattr(self.spec, name).numpy() for name in EpisodeSpec.ARRAY_FIELDS}
            flags = np.zeros(self.num_envs, dtype=np.int32)
            for w, episode in episodes.items():
                episode.validate(self.scene.robot.arm_default[:NUM_ARM_JOINTS], self.scene.ground_friction)
                for name, value in episode.as_arrays(self.scene.robot.arm_default[:NUM_ARM_JOINTS]).items():
                    arrays[name][w] = value
                flags[w] = 1
            for name, value in arrays.items():
                getattr(self.spec, name).assign(value)
            self.reset_flags.assign(flags)
            self._start_flagged()
            self._sync_targets_and_observe()
        started = torch.as_tensor(list(episodes), dtype=torch.long)
        self._constraint_stats.clear(started)
        return self.get_observations()

    def set_goals(self, goals: dict[int, tuple[float, float, float]]) -> TensorDict:
        """Gives the given worlds a new goal (x [m], y [m], yaw [rad], world frame) and restarts their
        episode clock, leaving robot and object where they are (goal sequences). Returns the
        observations of all worlds."""
        for w, goal in goals.items():
            if not 0 <= w < self.num_envs:
                raise IndexError(f"world index must lie in [0, {self.num_envs}), got {w}")
            if len(goal) != 3 or not all(math.isfinite(v) for v in goal):
                raise ConfigError(f"goal of world {w} must be 3 finite numbers (x, y, yaw), got {goal!r}")
        with wp.ScopedDevice(self.wp_device):
            position, quat = self.task.goal_pos.numpy(), self.task.goal_quat.numpy()
            steps, height = self.task.episode_step.numpy(), self.task.object_dims.numpy()[:, 2]
            for w, (x, y, yaw) in goals.items():
                position[w] = (x, y, 0.5 * height[w])
                quat[w] = yaw_quat(yaw)
                steps[w] = 0
            self.task.goal_pos.assign(position)
            self.task.goal_quat.assign(quat)
            self.task.episode_step.assign(steps)
            self._observe()
        return self.get_observations()

    def _observe(self) -> None:
        self._launch(observations_k.compute_observations, [self.views[0], self.task, self.noise_scale,
                                                           int(self.cfg.noise.enabled), self.cfg.seed,
                                                           self.reward_params.success_distance, self.success_angle,
                                                           self.policy_obs, self.critic_obs])

    # ------------------------------------------------------------------ checkpointing
    def _state_arrays(self) -> dict[str, wp.array]:
        arrays = {f"task.{k}": getattr(self.task, k) for k in PushTask.vars}
        arrays |= {f"spec.{k}": getattr(self.spec, k) for k in sampling.EpisodeSpec.vars}
        for k in ("body_q", "body_qd", "joint_q", "joint_qd"):
            arrays[f"state.{k}"] = getattr(self.state_0, k)
        arrays["control.joint_target_q"] = self.control.joint_target_q
        arrays["goal_difficulty"] = self.goal_difficulty
        arrays["policy_obs"] = self.policy_obs
        arrays["critic_obs"] = self.critic_obs
        return arrays

    def _upgraded_state(self, state: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """A state saved before the critic buffer held ``object_at_goal`` (one column fewer) gains that column as
        zeros: the runs that saved it have critics that do not read it (``env.critic_reads_object_at_goal`` reads
        False from their configs), and the next step writes it, so they continue exactly."""
        critic = state.get("critic_obs")
        if critic is None or critic.ndim != 2 or critic.shape[1] != NUM_CRITIC_OBS - 1:
            return state
        return {**state, "critic_obs": np.concatenate([critic, np.zeros((critic.shape[0], 1), critic.dtype)], axis=1)}

    def _before_state_load(self, arrays: dict[str, wp.array], state: dict[str, np.ndarray]) -> None:
        """Re-applies every world's saved episode (object variants, geometry and mass properties) before the saved state."""
        for name, array in arrays.items():
            if name.startswith("spec."):
                array.assign(state[name])
        self.reset_flags.fill_(1)
        self._start_flagged()

    def _after_state_load(self) -> None:
        self.reset_flags.zero_()

    def set_goal_difficulty(self, difficulty: float) -> None:
        """Scales the yaw change the goal of episodes drawn from now on asks for (a training
        curriculum; ``kernels/push/sampling.py``). 1 is the paper's task."""
        if not 0.0 <= difficulty <= 1.0:
            raise ConfigError(f"goal difficulty must lie in [0, 1], got {difficulty!r}")
        self.goal_difficulty.fill_(difficulty)

    @property
    def goal_difficulty_value(self) -> float:
        return float(self.goal_difficulty.numpy()[0])

    def set_object_mass_range(self, low: float, high: float) -> None:
        """Objects of episodes drawn from now on weigh U(``low``, ``high``) [kg], a sub-range of ``randomization.mass``
        (a training curriculum, ``policies/curriculum.py``)."""
        set_sub_range(self.object_mass_range, "object mass range", "randomization.mass", self.cfg.randomization.mass,
                      "kg", low, high)

    @property
    def object_mass_range_value(self) -> tuple[float, float]:
        return range_value(self.object_mass_range)

    def set_success_angle(self, degrees: float) -> None:
        """From the next step on, an object within ``degrees`` of its goal's rotation (and within the success
        distance) succeeds: ``rewards.success_angle_deg`` or more, up to 180 (a training curriculum,
        ``policies/curriculum.py``)."""
        configured = self.cfg.rewards.success_angle_deg
        if not configured <= degrees <= 180.0:
            raise ConfigError(f"success angle must lie in [rewards.success_angle_deg = {configured:g}, 180] deg,"
                              f" got {degrees!r}")
        self.success_angle.fill_(math.radians(degrees))

    @property
    def success_angle_deg_value(self) -> float:
        return math.degrees(float(self.success_angle.numpy()[0]))

    def set_goal_radius_range(self, low: float, high: float) -> None:
        """Goals of episodes drawn from now on lie ``low``-``high`` [m] from the object's start (uniform by area), a
        sub-range of ``sampling.goal_radius`` (a training curriculum, ``policies/curriculum.py``)."""
        set_sub_range(self.goal_radius_range, "goal radius range", "sampling.goal_radius", self.cfg.sampling.goal_radius,
                      "m", low, high)

    @property
    def goal_radius_range_value(self) -> tuple[float, float]:
        return range_value(self.goal_radius_range)

    def set_near_goal_starts(self, share: float, radius: float, max_yaw: float) -> None:
        """Episodes drawn from now on start near their goal with probability ``share``: the goal uniform (by area)
        within ``radius`` [m] of the object's start, its yaw the object's plus U(-``max_yaw``, ``max_yaw``) [rad]
        (a training-only start-state curriculum; ``kernels/push/sampling.py``). Share 0 is the paper's task."""
        if not (0.0 <= share <= 1.0 and radius >= 0.0 and max_yaw >= 0.0):
            raise ConfigError(f"near-goal starts need share in [0, 1], radius >= 0, max_yaw >= 0; got {share!r},"
                              f" {radius!r}, {max_yaw!r}")
        self.near_goal.fill_(wp.vec3(share, radius, max_yaw))
        self._near_goal_share = share

    def set_behind_starts(self, share: float, spread: float) -> None:
        """Episodes drawn from now on start with the robot behind the object, opposite the goal, with probability
        ``share``; bearing and heading within ``spread`` [rad] of the aligned ones (a training-only start-state
        curriculum; ``kernels/push/sampling.py``). Share 0 is the paper's task."""
        if not (0.0 <= share <= 1.0 and 0.0 <= spread <= math.pi):
            raise ConfigError(f"behind starts need share in [0, 1] and spread in [0, pi]; got {share!r}, {spread!r}")
        self.behind_start.fill_(wp.vec2(share, spread))

    def take_episode_counts(self) -> tuple[int, int]:
        """(ended, succeeded): the episodes that ended since the last call, and how many of them succeeded."""
        counts = self._episodes_ended, self._episodes_succeeded
        self._episodes_ended = self._episodes_succeeded = 0
        return counts

    def _ended_episodes(self) -> torch.Tensor:
        return self.episode_success_t >= 0

    def _ended_episode_log(self, ended: torch.Tensor) -> dict[str, torch.Tensor]:
        """Success, toppled, robot fallen and diverged at the end (success counted for :meth:`take_episode_counts`),
        and the near-goal split."""
        succeeded = (self.episode_success_t[ended] == 1).float()
        self._episodes_ended += int(succeeded.numel())
        self._episodes_succeeded += int(succeeded.sum())
        log = {"/episode/success": succeeded, "/episode/toppled": self.episode_toppled_t[ended].float(),
               "/episode/fallen": self.episode_fallen_t[ended].float(),
               "/episode/diverged": self.episode_diverged_t[ended].float()}
        log.update(self._near_goal_log(ended, succeeded))
        return log

    def _near_goal_log(self, ended: torch.Tensor, succeeded: torch.Tensor) -> dict[str, torch.Tensor]:
        """Success (``succeeded``, one per ``ended`` world) of the ended episodes that started near their goal and of
        the others while near-goal starts are on (a plain run logs what it always did); each key only when such
        episodes ended."""
        if self._near_goal_share == 0.0:
            return {}
        near = self.near_goal_ended_t[ended] == 1
        split = {"/episode/near_goal/success": succeeded[near], "/episode/other/success": succeeded[~near]}
        return {key: value for key, value in split.items() if value.numel()}

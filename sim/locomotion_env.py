"""LocomotionEnv: N legged robots tracking 6D base commands under random arm motions, as an rsl_rl ``VecEnv``.

Physics is MuJoCo-Warp through Newton (``SolverMuJoCo`` with MuJoCo's own contacts): XPBD's joint drives
are not the PD law and its legged robot sinks (docs/simulator.md, "Known simulator behaviour": the solver cross-check). One control step (50 Hz)
is one captured Warp graph: actions -> leg and arm joint targets and the end-effector force's wrench, ``substeps``
solver steps, feet, rewards, the ground's contact force on each lower leg (Newton's ``SensorContact`` on MuJoCo's
contact forces of the last substep), constraints, terminations, auto-reset, scheduled events (commands, arm
targets, pushes, end-effector forces) and observations. Kernels and layouts: :mod:`dynpush.kernels.locomotion`.
"""

from __future__ import annotations

import newton
import numpy as np
import torch
import warp as wp
from newton.sensors import SensorContact
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from dynpush.kernels.locomotion import (
    actions as actions_k,
    constraints as constraints_k,
    contacts as contacts_k,
    observations as observations_k,
    rewards as rewards_k,
    sampling as sampling_k,
    terminations as terminations_k,
    views as views_k,
)
from dynpush.runtime.actions import BASE_COMMAND_NAMES

from .config import ConfigError
from .env_state import EnvBase, articulation_reset_mask
from .legged_scene import build_legged_scene, legged_view, locomotion_task, mujoco_solver
from .locomotion_config import LocomotionEnvConfig

wp.config.enable_backward = False

CONSTRAINT_GROUPS = constraints_k.CONSTRAINT_GROUPS
REWARD_TERMS = rewards_k.REWARD_TERMS
COMMAND_NAMES = BASE_COMMAND_NAMES  # the locomotion command is the push policy's base command


class LocomotionEnv(EnvBase, VecEnv):
    """Command tracking with the legged robot; see the module docstring.

    Fills in :class:`~dynpush.sim.env_state.EnvBase`: the scene, MuJoCo solver, foot contact sensor, buffers,
    parameters and base masses (``_build``), the step kernels, episode starts (``_reset_flagged``), observations,
    episodes ended by any reset with ``/episode/fell``, and the state arrays, after whose loading MuJoCo takes the
    restored base masses."""

    reward_names = REWARD_TERMS
    num_actions = views_k.NUM_LEG_JOINTS
    _constraint_groups = CONSTRAINT_GROUPS
    cfg: LocomotionEnvConfig

    # ------------------------------------------------------------------ construction
    def _build(self) -> None:
        cfg = self.cfg
        self.scene = build_legged_scene(cfg.num_envs, cfg.device)
        model = self.scene.model
        # MuJoCo's contacts: feet, knees and base against the ground plane only (no self-collisions).
        self.solver = mujoco_solver(model, cfg.mujoco, use_mujoco_contacts=True)
        self.state_0, self.state_1 = model.state(), model.state()
        # Ground contact force on each lower leg (foot sphere and shank), from MuJoCo's constraint forces
        # of the control step's last substep, for the foot contact force constraint.
        self.contacts = newton.CollisionPipeline(model, rigid_contact_max=self.solver.get_max_contact_count(),
                                                 soft_contact_max=0).contacts()
        self.foot_sensor = SensorContact(model, sensing_bodies=[int(b) for b in self.scene.shank_body.reshape(-1)],
                                         request_contact_attributes=False)
        self.solver_observables = self.solver.observables(contacts=self.contacts,
                                                          kinds=self.foot_sensor.solver_observable_kinds)
        self.control = model.control()
        self._make_buffers()
        self._make_params()
        self._randomize_base_masses()

    def _make_buffers(self) -> None:
        n, scene = self.num_envs, self.scene
        self.task = locomotion_task(n)
        self.view = legged_view(self.state_0, scene.base_body, scene.base_q_start, scene.base_qd_start, scene.robot_qd_count,
                                scene.leg_q, scene.leg_qd, scene.arm_q, scene.arm_qd, scene.shank_body)

        self.ee_body = wp.array(np.asarray(scene.ee_body, dtype=np.int32), dtype=int)
        self._make_step_buffers(observations_k.NUM_POLICY_OBS, observations_k.NUM_CRITIC_OBS, constraints_k.NUM_CONSTRAINTS)
        self.tracking_error = wp.zeros((n, views_k.NUM_COMMANDS), dtype=float)
        self.foot_force = wp.zeros((n, views_k.NUM_FEET), dtype=float)  # [N]
        self.articulation_mask = wp.zeros(self.scene.model.articulation_count, dtype=bool)
        self.tracking_error_t = wp.to_torch(self.tracking_error)  # (N, 6) command - measured, COMMAND_NAMES order

    def _make_params(self) -> None:
        cfg, robot = self.cfg, self.scene.robot
        f32 = lambda a: wp.array(np.asarray(a, dtype=np.float32), dtype=float)  # noqa: E731
        steps = lambda pair: wp.vec2(pair[0] / cfg.control_dt, pair[1] / cfg.control_dt)  # noqa: E731
        rnd = cfg.randomization
        p = views_k.LocomotionParams()
        p.leg_default, p.leg_lower, p.leg_upper = f32(robot.leg_default), f32(robot.leg_lower), f32(robot.leg_upper)
        p.arm_default, p.arm_lower, p.arm_upper = f32(robot.arm_default), f32(robot.arm_lower), f32(robot.arm_upper)
        p.action_scale, p.clip = cfg.action_scale, cfg.action_clip
        p.command_lower, p.command_upper = f32(cfg.commands.lower), f32(cfg.commands.upper)
        p.standing_probability = cfg.commands.standing_probability
        p.command_interval = steps(cfg.commands.resample_interval_s)
        p.arm_amplitude = f32(rnd.arm_amplitude)
        p.arm_interval = steps(rnd.arm_interval_s)
        p.push_interval = steps(rnd.push_interval_s)
        p.push_velocity = rnd.push_velocity
        p.ee_force_interval = steps(rnd.ee_force_interval_s)
        p.ee_force_probability, p.ee_force_max = rnd.ee_force_probability, rnd.ee_force_max
        p.ee_force_spread = rnd.ee_force_spread
        p.disturbance_scale = f32([1.0])
        p.start_height = cfg.start_height
        p.leg_position_noise = rnd.leg_position_noise
        self.params = p

        c = cfg.constraints
        lim = views_k.LeggedLimits()
        lim.stiffness, lim.damping = f32(robot.leg_stiffness), f32(robot.leg_damping)
        lim.effort_limit = f32(robot.leg_effort_limit)
        lim.nominal_torque = f32(np.tile(c.leg_nominal_torque, 4))
        lim.velocity_limit = f32(c.velocity_fraction * robot.leg_velocity_limit)
        lim.acceleration_limit = c.acceleration_limit
        lim.action_rate_limit = c.action_rate_limit
        lim.air_time_min = c.air_time_min
        lim.foot_force_limit = c.foot_force_limit
        lim.control_dt = cfg.control_dt
        lim.foot_offset = wp.vec3(*robot.foot_offset)
        lim.foot_radius = robot.foot_radius
        lim.contact_margin = c.contact_margin
        lim.knee_radius = robot.knee_radius
        lim.shank_end = wp.vec3(*robot.shank_end)
        lim.shank_radius = robot.shank_radius
        lim.base_half_extents = wp.vec3(*robot.base_half_extents)
        lim.collision_margin = c.collision_margin
        lim.base_tilt = cfg.base_tilt
        lim.base_min_height = cfg.base_min_height
        lim.max_episode_steps = cfg.max_episode_steps
        self.limits = lim

        r = cfg.rewards
        rp = rewards_k.LocomotionRewardParams()
        rp.sigma_linear_velocity, rp.sigma_yaw_rate = r.sigma_linear_velocity, r.sigma_yaw_rate
        rp.sigma_attitude, rp.sigma_height = r.sigma_attitude, r.sigma_height
        rp.air_time_target, rp.moving_command = r.air_time_target, r.moving_command
        rp.weights = f32(r.weights)
        self.reward_params = rp
        self._reward_weights = rp.weights

        scales = []
        for name, size in observations_k.POLICY_TERMS:
            scales += [cfg.noise.half_width(name)] * size
        self.noise_scale = f32(scales)

    def set_disturbance_scale(self, scale: float) -> None:
        """Scales the random arm motions, base pushes and end-effector forces (``randomization.arm_amplitude``,
        ``push_velocity``, ``ee_force_max``) by ``scale`` in [0, 1] from their next draw on; the training curriculum's (``schedules.disturbance_scale_at``)."""
        if not 0.0 <= scale <= 1.0:
            raise ConfigError(f"disturbance scale must lie in [0, 1], got {scale!r}")
        self.params.disturbance_scale.fill_(scale)

    # ------------------------------------------------------------------ the step
    def _step_kernels(self) -> None:
        cfg = self.cfg
        self._launch(actions_k.process_leg_actions, [self.raw_actions, self.params, self.view, self.task,
                                                     self.control.joint_target_q])
        self._launch(actions_k.write_arm_targets, [self.view, self.task, self.control.joint_target_q])
        self._launch(actions_k.write_ee_force, [self.view, self.task, self.ee_body, wp.vec3(*self.scene.ee_offset),
                                                self.scene.model.body_com, self.state_0.body_f, self.state_1.body_f])
        dt = cfg.control_dt / cfg.substeps
        for sub in range(cfg.substeps):
            state_in, state_out = (self.state_0, self.state_1) if sub % 2 == 0 else (self.state_1, self.state_0)
            last = sub == cfg.substeps - 1
            self.solver.step(state_in, state_out, self.control, self.contacts if last else None, dt,
                             observables=self.solver_observables if last else None)
        if cfg.substeps % 2:  # the view reads state_0
            for name in ("body_q", "body_qd", "joint_q", "joint_qd"):
                getattr(self.state_0, name).assign(getattr(self.state_1, name))
        self._launch(contacts_k.update_feet, [self.view, self.limits, self.task])
        self._launch(rewards_k.compute_rewards, [self.view, self.task, self.reward_params, self.reward, self.reward_terms,
                                                 self.tracking_error])
        self.foot_sensor.update(None, self.contacts, observables=self.solver_observables)
        self._launch(contacts_k.gather_foot_forces, [self.foot_sensor.total_force, self.foot_force])
        self._launch(constraints_k.compute_constraints, [self.view, self.task, self.limits, self.foot_force,
                                                         self.constraints])
        self._launch(terminations_k.compute_terminations, [self.view, self.task, self.limits, self.reset_flags,
                                                           self.time_out])
        self._reset_flagged()
        self._launch(sampling_k.apply_events, [cfg.seed, self.params, self.view, self.task])
        self._observe()

    def _reset_flagged(self) -> None:
        model = self.scene.model
        self._launch(sampling_k.start_episodes, [self.reset_flags, self.cfg.seed, self.params, self.view, self.task])
        wp.launch(articulation_reset_mask, dim=model.articulation_count,
                  inputs=[self.reset_flags, model.articulation_world, self.articulation_mask], device=self.wp_device)
        newton.eval_fk(model, self.state_0.joint_q, self.state_0.joint_qd, self.state_0, mask=self.articulation_mask)

    def _randomize_base_masses(self) -> None:
        """Draws every world's base mass offset once (as legged_gym): updating MuJoCo's model costs about as much as
        the physics of a step, too much for every reset."""
        low, high = self.cfg.randomization.base_mass_offset
        offsets = np.random.default_rng(self.cfg.seed).uniform(low, high, self.num_envs)
        model, bodies = self.scene.model, self.scene.base_body
        mass, inv_mass = model.body_mass.numpy(), model.body_inv_mass.numpy()
        mass[bodies] = self.scene.robot.base_mass + offsets
        inv_mass[bodies] = 1.0 / mass[bodies]
        model.body_mass.assign(mass)
        model.body_inv_mass.assign(inv_mass)
        self.task.base_mass_offset.assign(offsets.astype(np.float32))
        self.solver.notify_model_changed(newton.ModelFlags.BODY_INERTIAL_PROPERTIES)

    def _observe(self) -> None:
        self._launch(observations_k.compute_observations, [self.view, self.task, self.params, self.noise_scale,
                                                           int(self.cfg.noise.enabled), self.cfg.seed, self.policy_obs,
                                                           self.critic_obs])

    # ------------------------------------------------------------------ VecEnv
    def set_commands(self, commands: np.ndarray, hold: bool = True) -> TensorDict:
        """Gives every world the 6D command ``commands`` (num_envs, 6), now; with ``hold`` it is not resampled
        for the rest of the episode (evaluation). Returns the observations."""
        commands = np.asarray(commands, dtype=np.float32)
        if commands.shape != (self.num_envs, views_k.NUM_COMMANDS) or not np.all(np.isfinite(commands)):
            raise ValueError(f"commands must be finite with shape ({self.num_envs}, 6), got {commands.shape}")
        with wp.ScopedDevice(self.wp_device):
            self.task.command.assign(commands)
            if hold:
                self.task.next_command_step.fill_(np.iinfo(np.int32).max)
            self._observe()
        return self.get_observations()

    def _ended_episodes(self) -> torch.Tensor:
        return self.reset_t != 0

    def _ended_episode_log(self, ended: torch.Tensor) -> dict[str, torch.Tensor]:
        """Fell: the episode ended before its time ran out."""
        return {"/episode/fell": (self.time_out_t[ended] == 0).float()}

    # ------------------------------------------------------------------ checkpointing
    def _state_arrays(self) -> dict[str, wp.array]:
        arrays = {f"task.{name}": getattr(self.task, name) for name in views_k.LocomotionTask.vars}
        for name in ("body_q", "body_qd", "joint_q", "joint_qd"):
            arrays[f"state.{name}"] = getattr(self.state_0, name)
        arrays["control.joint_target_q"] = self.control.joint_target_q
        arrays["model.body_mass"] = self.scene.model.body_mass
        arrays["model.body_inv_mass"] = self.scene.model.body_inv_mass
        arrays["policy_obs"], arrays["critic_obs"] = self.policy_obs, self.critic_obs
        arrays["mujoco.qacc_warmstart"] = self.solver.mjw_data.qacc_warmstart  # the solver starts from it
        return arrays

    def _after_state_load(self) -> None:
        """MuJoCo's model takes the restored base masses."""
        self.solver.notify_model_changed(newton.ModelFlags.BODY_INERTIAL_PROPERTIES)

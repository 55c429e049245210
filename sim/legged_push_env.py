"""LeggedPushEnv: the push task with articulated legs and a frozen locomotion policy in the loop (docs/legged.md).

Everything of :class:`~dynpush.sim.push_env.PushEnv` is kept (sampling, object, rewards, constraints,
terminations, observations of the push policy) except the base: ``robot_legged.usda`` stands on its feet on
MuJoCo-Warp (Newton's contacts, which the object's body variants need), and at every control step (50 Hz,
the push policy's rate) the push policy's 6D base command goes to the locomotion policy, whose 12 outputs
become the leg joint targets of the PD drives. The leg-torque constraint columns hold the simulated PD
torques ``|tau| - tau_nominal`` instead of the tracked base's quasi-static estimate.

One control step is two captured graphs around the locomotion network (onnxruntime, all worlds in one
call): (1) push actions -> base command and arm targets (or those commands given: ``step_commands``), and
the locomotion observation of every world; (2) leg actions -> leg targets, physics, then the push task's
rewards, constraints, terminations, resets and observations. Without a locomotion policy
(``legged.locomotion_policy = ""``) the leg targets are given, as they are, by :meth:`LeggedPushEnv.set_leg_targets`
(sim-to-sim: the runtime runs the locomotion ONNX and maps its actions to targets).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import torch
import warp as wp

from dynpush.kernels.locomotion import (
    actions as loco_actions,
    constraints as loco_constraints,
    observations as loco_observations,
    sampling as loco_sampling,
    views as loco_views,
)
from dynpush.kernels.push.constraints import CONSTRAINT_GROUPS
from dynpush.runtime.locomotion_contract import LocomotionContract

from .push_env import PushEnv
from .legged_scene import legged_view, locomotion_task, mujoco_solver
from .scene import build_scene

LEG_TORQUE_COLUMN = sum(size for _, size in itertools.takewhile(lambda group: group[0] != "leg_joint_torque", CONSTRAINT_GROUPS))


class LocomotionNetwork:
    """A ``locomotion.onnx`` (``dynpush export`` of a locomotion run) run by onnxruntime on all worlds at once.

    Its contract is read as the runtime reads it (``dynpush.runtime.locomotion_contract``); the simulator writes
    the observation of ``kernels/locomotion/observations.py`` (``POLICY_TERMS``, unscaled), so the network must read
    that one.
    """

    def __init__(self, path: str):
        from .onnx_session import batched_session, load_onnx, read_metadata

        model = load_onnx(Path(path))
        self.contract = LocomotionContract.from_metadata(read_metadata(model), path)
        observation = list(self.contract.observation)
        terms = [(name, 1.0) for name, _ in loco_observations.POLICY_TERMS]
        if observation != terms:
            raise ValueError(f"{path}: observation {observation} differs from the simulator's {terms}")
        self.session = batched_session(model, "obs", loco_observations.NUM_POLICY_OBS, "actions",
                                       loco_views.NUM_LEG_JOINTS, path)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Leg actions [B, 12] (float32) of the locomotion observations ``obs`` [B, 61] (float32)."""
        return self.session.run(["actions"], {"obs": obs})[0]


class LeggedPushEnv(PushEnv):
    """See the module docstring. Beyond :class:`~dynpush.sim.push_env.PushEnv` it supplies the legged scene and
    solver, the two step graphs (``_capture``) and their launch around the locomotion network (``_launch_step``), the
    leg hooks and the locomotion task's state arrays."""

    def __init__(self, cfg):
        path = cfg.legged.locomotion_policy
        self.locomotion = LocomotionNetwork(path) if path else None
        super().__init__(cfg)

    # ------------------------------------------------------------------ construction
    def _build_scene(self):
        return build_scene(self.cfg.num_envs, self.cfg.device, legged=True)

    def _make_solver(self) -> None:
        import newton

        model = self.scene.model
        self.solver = mujoco_solver(model, self.cfg.legged.mujoco, use_mujoco_contacts=False)
        self.state_0, self.state_1 = model.state(), model.state()
        self.control = model.control()
        self.collision = newton.CollisionPipeline(model, rigid_contact_max=self.cfg.sim.contacts_per_world * self.num_envs)
        self.contacts = self.collision.contacts()

    def _make_buffers(self) -> None:
        super()._make_buffers()
        n, scene = self.num_envs, self.scene
        self.leg_view = legged_view(self.state_0, scene.base_body, scene.robot_q_start, scene.robot_qd_start,
                                    scene.robot_qd_count, scene.leg_q, scene.leg_qd, scene.arm_q, scene.arm_qd, scene.shank_body)
        # The push policy's absolute 6D command, clamped to its limits (as the runtime sends it), is the locomotion
        # command.
        self.leg_task = locomotion_task(n, command=self.base_target)
        self.leg_actions = wp.zeros((n, loco_views.NUM_LEG_JOINTS), dtype=float)
        self.leg_obs = wp.zeros((n, loco_observations.NUM_POLICY_OBS), dtype=float)
        self.leg_critic_obs = wp.zeros((n, loco_observations.NUM_CRITIC_OBS), dtype=float)
        self.leg_actions_t = wp.to_torch(self.leg_actions)
        # The leg targets [rad] of set_leg_targets, when no locomotion policy runs here; the legs' defaults at first.
        self.leg_targets = wp.array(np.tile(self.scene.robot.legged.leg_default, (n, 1)).astype(np.float32), dtype=float)

    def _make_params(self) -> None:
        super()._make_params()
        legs = self.scene.robot.legged
        f32 = lambda a: wp.array(np.asarray(a, dtype=np.float32), dtype=float)  # noqa: E731
        action_scale = 0.0  # no leg actions without a locomotion policy: the leg targets are given (set_leg_targets)
        if self.locomotion is not None:
            contract = self.locomotion.contract
            if not np.allclose(contract.default_joint_positions, legs.leg_default, atol=1e-5):
                raise ValueError(f"{self.cfg.legged.locomotion_policy}: default_joint_positions"
                                 f" {list(contract.default_joint_positions)} differ from robot_legged.usda's"
                                 f" {legs.leg_default.tolist()}")
            action_scale = contract.action_scale
        # Leg actions -> leg targets [rad]: the parameters of process_leg_actions.
        p = loco_views.LocomotionParams()
        p.leg_default, p.leg_lower, p.leg_upper = f32(legs.leg_default), f32(legs.leg_lower), f32(legs.leg_upper)
        p.arm_default = f32(self.scene.robot.arm_default)
        p.action_scale, p.clip = float(action_scale), self.cfg.actions.clip
        self.leg_params = p
        lim = loco_views.LeggedLimits()
        lim.stiffness, lim.damping, lim.effort_limit = f32(legs.leg_stiffness), f32(legs.leg_damping), f32(legs.leg_effort_limit)
        lim.nominal_torque = f32(np.tile(self.cfg.constraints.leg_nominal_torque, 4))
        self.leg_limits = lim
        self.noise_free = f32(np.zeros(loco_observations.NUM_POLICY_OBS))

    def _capture_front(self, take_commands) -> wp.Graph:
        """The first graph of a step: ``take_commands`` (push actions or given commands), the locomotion observation."""
        with wp.ScopedCapture() as capture:
            take_commands()
            self._launch(loco_observations.compute_observations, [self.leg_view, self.leg_task, self.leg_params,
                                                                  self.noise_free, 0, self.cfg.seed, self.leg_obs,
                                                                  self.leg_critic_obs])
        return capture.graph

    def _capture_commands(self) -> None:
        """step_commands shares the second graph; only its first is its own."""
        self._graph_commands = self._capture_front(self._apply_commands)

    def _capture(self) -> None:
        self._graph_actions = self._capture_front(self._process_actions)
        with wp.ScopedCapture() as capture:
            if self.locomotion is not None:
                self._launch(loco_actions.process_leg_actions, [self.leg_actions, self.leg_params, self.leg_view,
                                                                self.leg_task, self.control.joint_target_q])
            else:
                self._launch(loco_actions.write_leg_targets, [self.leg_targets, self.leg_view, self.leg_task,
                                                              self.control.joint_target_q])
            self._physics_and_task()
        self._graph = capture.graph

    # ------------------------------------------------------------------ checkpointing
    def _state_arrays(self) -> dict[str, wp.array]:
        """The push task's state, the locomotion task's (its command is the push task's base command) and the
        last leg actions and observation, and MuJoCo's warm start."""
        arrays = super()._state_arrays()
        arrays |= {f"leg_task.{name}": getattr(self.leg_task, name) for name in loco_views.LocomotionTask.vars
                   if name != "command"}
        arrays["leg_actions"], arrays["leg_obs"] = self.leg_actions, self.leg_obs
        arrays["mujoco.qacc_warmstart"] = self.solver.mjw_data.qacc_warmstart
        return arrays

    # ------------------------------------------------------------------ the step
    def _drive_base(self, view, state) -> None:
        """The legs carry the base: no tracking wrench."""

    def _robot_constraints(self) -> None:
        self._launch(loco_constraints.write_leg_torque_constraints, [self.leg_view, self.leg_task, self.leg_limits,
                                                                     self.constraints, LEG_TORQUE_COLUMN])

    def _start_robot_flagged(self) -> None:
        self._launch(loco_sampling.start_legs, [self.reset_flags, self.leg_params, self.leg_view, self.leg_task])

    def set_leg_targets(self, targets: np.ndarray) -> None:
        """Leg joint targets [rad] (num_envs, 12, ``LEG_JOINT_NAMES`` order) for the next steps, when no locomotion
        policy runs inside the environment: they go to the legs' PD drives as given (the runtime that computed them
        has applied the locomotion contract's action mapping and checked them)."""
        if self.locomotion is not None:
            raise RuntimeError("set_leg_targets: this environment runs its own locomotion policy")
        targets = np.asarray(targets, dtype=np.float32)
        if targets.shape != (self.num_envs, loco_views.NUM_LEG_JOINTS) or not np.all(np.isfinite(targets)):
            raise ValueError(f"leg targets must be finite with shape ({self.num_envs}, 12), got {targets.shape}")
        self.leg_targets.assign(targets)

    def _launch_step(self, front: wp.Graph | None = None) -> None:
        """The actions graph (or ``front``), the locomotion network on the leg observations (if it runs here), the
        physics graph."""
        wp.capture_launch(self._graph_actions if front is None else front)
        if self.locomotion is not None:
            self.leg_actions_t.copy_(torch.from_numpy(self.locomotion(self.leg_obs.numpy())))
        wp.capture_launch(self._graph)

    def _launch_command_step(self) -> None:
        self._launch_step(self._graph_commands)

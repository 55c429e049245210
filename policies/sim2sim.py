"""The simulator side of sim-to-sim: a one-world PushEnv plays the robot and the motion capture system.

``dynpush sim2sim`` (``dynpush.runtime.sim2sim``) starts this module in its own process,
``python -m dynpush.policies.sim2sim ...``, and runs the deployment runtime against it over loopback UDP
with the runtime's own datagrams (``dynpush.runtime.packets``):

- **commands in** (``DPC1``): the onboard locomotion is the tracked base, so the 6D base command and
  the 5 arm targets go to the PushEnv as its own commands (``PushEnv.step_commands``: the runtime applied the action
  mapping, the environment does not apply it again, and clamps them to its command limits as it clamps its own;
  the policy's contract must still hold the environment's parameters). The packets carry no policy actions, so the
  environment's action terms (its ``last_actions`` observation, action-rate reward and arm-rate constraint) see a
  policy at rest; nothing here reads them. Mode stop (or no command yet): the default base command (zero
  velocities), arm targets at the measured joint positions.
- **mocap out** (``DPM1``), once per control step: base and object poses (world Z-up, m, (x, y, z, w))
  plus Gaussian position noise (``mocap_noise_m`` std per axis) and a random rotation (rotation vector
  with ``mocap_noise_rad`` std per axis); each frame dropped with probability ``drop`` and delivered
  ``latency_s`` later, rounded to whole control steps.
- **robot state out** (``DPS1``), once per control step: IMU orientation = the true base orientation,
  the base twist in the base frame (of the base frame origin), the end-effector point in the base frame
  (the arm's forward kinematics on hardware), arm joint positions and velocities; leg joint positions and
  velocities with a legged robot (``env.legged.enabled``), none with the tracked base.
- **legged robot** (``env.legged.enabled``, the runtime runs a locomotion ONNX): the command's 12 leg
  targets go to the leg drives as they are (the base command is then only the push policy's, which the
  environment ignores); before the first command, or without leg targets, the legs hold their default.
- **goals out** (``DPG1``): the episode's goal when it starts.
- **record** (``record``, optional): per step, the environment's own observations of the state the runtime acts on,
  the poses and each episode's start state, written when the run ends (``chain_record.py``).

Episodes: the environment the policy was trained in (``policies.trained_env.env_config_for``: the
training config of the policy's metadata, one world, observation noise off, ``env.field=value``
overrides). The first episode starts when the runtime reports an operating state (its start-up ramp
is over); an episode ends at the environment's time-out, topple or fall (auto-reset inside the step)
and succeeds if the success flag is set at its last step, as in ``dynpush eval``. Every episode is
reported as one stdout line ``SIM2SIM {json}`` (outcome, object and goal); ``{"event": "done"}`` ends the
run, also early when the runtime reports its latched STOPPED state. With ``trajectory_png`` the paths of
base, end-effector and object of every episode are drawn as ``dynpush play`` draws them.

Clock: real time (an absolute-deadline ticker at the control rate), or lock-step (one step per command
received, for tests). In real time the simulator reports its own pace, ``{"event": "clock", "deadline": k,
"steps": n}`` (at a wait for deadline ``k``, after ``n`` steps) about every ``CLOCK_REPORT_PERIODS`` control
periods (:class:`ClockReporter`) and with ``done`` (``"clock": [k, n]`` of its last wait); the runtime's side
judges from them whether it kept the control rate (``dynpush.runtime.sim2sim.RateCheck``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from dynpush.runtime.contract import PolicyContract
from dynpush.runtime.frames import quat_multiply
from dynpush.runtime.observation import NUM_ARM_JOINTS, quat_to_matrix
from dynpush.runtime.packets import (
    GOAL_SET, MODE_STOP, GoalCommand, MocapBody, MocapFrame, PacketError, Proprioception, RobotCommand,
    decode_command, encode_goal, encode_mocap, encode_state,
)
from dynpush.runtime.safety import State
from dynpush.runtime.sim2sim import EVENT_PREFIX
from dynpush.runtime.timing import RealClock, Ticker
from dynpush.runtime.udp import UdpEndpoint

from dynpush.sim.envs import make_push_env

from .chain_record import StepRecorder
from .env_probe import EnvProbe, yaw_of
from .onnx_policy import OnnxPolicy
from .play import TrajectoryObserver, concatenate_episodes, episode_row, episode_setup, plot_play
from .trained_env import env_config_for

OPERATING_STATES = (State.PUSH, State.HOLD, State.MOCAP_LOST)
CLOCK_REPORT_PERIODS = 10  # real time: a clock report every 10 control periods (0.2 s at 50 Hz), 1/5 of a window


class ClockReporter:
    """Real time: the simulator's pace, as the runtime's ``RateCheck`` reads it.

    At each wait for a control deadline, :meth:`record` takes the deadline's index (control periods since the
    ticker's first) and the steps taken before it, and emits a ``clock`` event when ``every`` periods have passed
    since the last one. A deadline index that runs ahead of the steps means the ticker skipped deadlines: stepping
    is too slow for the control rate.
    """

    def __init__(self, emit_event: Callable[[dict], None], every: int = CLOCK_REPORT_PERIODS):
        self._emit = emit_event
        self.every = every  # [control periods]
        self.last: tuple[int, int] | None = None  # (deadline index, steps before it) of the last wait
        self._reported = -every  # the first wait is reported

    def record(self, deadline: int, steps: int) -> None:
        """One wait: ``deadline`` [control periods], ``steps`` [simulator steps taken before it]."""
        self.last = (deadline, steps)
        if deadline - self._reported >= self.every:
            self._emit({"event": "clock", "deadline": deadline, "steps": steps})
            self._reported = deadline


@dataclass
class SimToSimConfig:
    """The simulator's side of one sim-to-sim run (ports are the runtime's, on ``runtime_host``)."""

    policy: str
    state_port: int
    mocap_port: int
    goal_port: int
    runtime_host: str = "127.0.0.1"
    episodes: int = 1
    mocap_noise_m: float = 0.0
    mocap_noise_rad: float = 0.0
    latency_s: float = 0.0
    drop: float = 0.0
    lockstep: bool = False
    seed: int = 0
    base_body: str = "base"
    object_body: str = "object"
    overrides: list[str] = field(default_factory=list)  # env.field=value
    command_timeout_s: float = 10.0  # lock-step: give up when the runtime is silent this long
    trajectory_png: str | None = None  # top-down picture of the episodes (dynpush.policies.play.plot_play)
    record: str | None = None  # .npz of what the simulator saw, step by step (dynpush.policies.chain_record)


def check_contract_matches_env(contract: PolicyContract, env) -> None:
    """The contract's action mapping must be the environment's (the runtime maps the policy's actions with the
    contract's; the environment's training used its own, so a mismatch would run the policy on other commands)."""
    mapping = env.action_mapping
    pairs = {
        "base_command_default": (contract.base_command_default, mapping.base.default),
        "base_command_scale": (contract.base_command_scale, mapping.base.scale),
        "arm_action_scale": (contract.arm_action_scale, mapping.arm.scale),
        "arm_default_joint_positions": (contract.arm_default_joint_positions, mapping.arm.default),
        "action_clip": (contract.action_clip, mapping.clip),
        "control_period_s": (contract.control_period_s, env.cfg.control_dt),
    }
    for name, (ours, theirs) in pairs.items():
        if not np.allclose(ours, theirs, rtol=1e-6, atol=1e-9):
            raise ValueError(f"policy contract {name} {np.asarray(ours).tolist()} differs from the simulator's"
                             f" {np.asarray(theirs).tolist()}")


def _rotation_vector_quat(v: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(v))
    if angle < 1e-12:
        return np.array([0.0, 0.0, 0.0, 1.0])
    return np.concatenate([v / angle * math.sin(0.5 * angle), [math.cos(0.5 * angle)]])


class SimRobot:
    """The PushEnv world, its datagrams and its episodes (see the module docstring)."""

    def __init__(self, cfg: SimToSimConfig):
        self.cfg = cfg
        policy = OnnxPolicy(cfg.policy)
        self.contract = policy.contract
        self.env = make_push_env(env_config_for(policy, 1, noise=False, seed=cfg.seed, overrides=cfg.overrides,
                                               legs_from_outside=True))
        check_contract_matches_env(self.contract, self.env)
        self.probe = EnvProbe(self.env)
        scene = self.env.scene
        self._body_com = scene.model.body_com.numpy()[scene.base_body[0]].astype(np.float64)
        self._arm_qd = scene.arm_qd_start[0] + np.arange(NUM_ARM_JOINTS)
        self._base_body = scene.base_body[0]
        self.legged = self.env.cfg.legged.enabled
        self._leg_default = scene.robot.legged.leg_default if self.legged else None
        self.dt = self.env.cfg.control_dt
        self._latency_steps = int(round(cfg.latency_s / self.dt))
        self._rng = np.random.default_rng(cfg.seed)
        self._mocap_queue: deque[tuple[int, bytes]] = deque()
        self.endpoint = UdpEndpoint("127.0.0.1", 0)
        self.command: RobotCommand | None = None
        self.malformed_commands = 0
        self.step = 0
        self._seq = 0
        self.clock = ClockReporter(emit)  # real time only: lock-step waits for commands, not deadlines
        meta = {"policy": cfg.policy, "seed": cfg.seed, "overrides": list(cfg.overrides)}
        self.recorder = StepRecorder(self.env, self.probe, meta) if cfg.record else None

    # ------------------------------------------------------------------ commands in
    def receive_commands(self) -> None:
        for datagram in self.endpoint.drain():
            try:
                command = decode_command(datagram.data)
            except PacketError:
                self.malformed_commands += 1
                continue
            if not (np.all(np.isfinite(command.base_command)) and np.all(np.isfinite(command.arm_targets))):
                self.malformed_commands += 1  # the environment takes finite commands only; the last good one stays
                continue
            self.command = command

    def commands(self) -> tuple[np.ndarray, np.ndarray]:
        """The base command (1, 6) and arm targets (1, 5) [rad] of the latest command, for ``env.step_commands``."""
        command = self.command
        if command is None or command.mode == MODE_STOP:
            base_command, arm_targets = self.env.action_mapping.base.default, self.probe.arm_q()[0]
        else:
            base_command, arm_targets = command.base_command, command.arm_targets
        if self.legged:
            given = command is not None and len(command.leg_targets) == len(self._leg_default)
            self.env.set_leg_targets((command.leg_targets if given else self._leg_default)[None])
        return np.asarray(base_command, dtype=np.float32)[None], np.asarray(arm_targets, dtype=np.float32)[None]

    # ------------------------------------------------------------------ measurements -> datagrams
    def _runtime(self, port: int) -> tuple[str, int]:
        return (self.cfg.runtime_host, port)

    def robot_state(self) -> Proprioception:
        base = self.probe.base()[0]
        p_b, q_b = base[:3], base[3:]
        R_b = quat_to_matrix(q_b)
        qd = self.env.state_0.body_qd.numpy()[self._base_body].astype(np.float64)  # CoM velocity, angular velocity
        v_origin = qd[:3] + np.cross(qd[3:], p_b - (p_b + R_b @ self._body_com))
        joint_q, joint_qd = self.env.state_0.joint_q.numpy(), self.env.state_0.joint_qd.numpy()
        leg_q = joint_q[self.env.scene.leg_q[0]].astype(np.float64) if self.legged else np.zeros(0)
        leg_qd = joint_qd[self.env.scene.leg_qd[0]].astype(np.float64) if self.legged else np.zeros(0)
        return Proprioception(
            seq=self._seq, stamp_s=self.step * self.dt, base_quat_xyzw=q_b, base_linear_velocity_b=R_b.T @ v_origin,
            base_angular_velocity_b=R_b.T @ qd[3:], ee_position_b=R_b.T @ (self.probe.ee_position()[0] - p_b),
            arm_q=self.probe.arm_q()[0], arm_qd=joint_qd[self._arm_qd].astype(np.float64),
            leg_q=leg_q, leg_qd=leg_qd,
        )

    def _measured(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        position = pose[:3] + self._rng.normal(0.0, self.cfg.mocap_noise_m, 3)
        quat = quat_multiply(pose[3:], _rotation_vector_quat(self._rng.normal(0.0, self.cfg.mocap_noise_rad, 3)))
        return position, quat

    def publish(self) -> None:
        """Mocap (noisy, maybe dropped, delayed) then the robot state of the current step."""
        self._seq += 1
        if self._rng.random() >= self.cfg.drop:
            bodies = [MocapBody(name, *self._measured(pose)) for name, pose in
                      ((self.cfg.base_body, self.probe.base()[0]), (self.cfg.object_body, self.probe.object()[0]))]
            frame = MocapFrame(seq=self._seq, stamp_s=self.step * self.dt, bodies=bodies)
            self._mocap_queue.append((self.step + self._latency_steps, encode_mocap(frame)))
        while self._mocap_queue and self._mocap_queue[0][0] <= self.step:
            self.endpoint.send(self._mocap_queue.popleft()[1], self._runtime(self.cfg.mocap_port))
        self.endpoint.send(encode_state(self.robot_state()), self._runtime(self.cfg.state_port))

    def send_goal(self) -> None:
        x, y = (float(v) for v in self.env.task.goal_pos.numpy()[0][:2])
        yaw = float(yaw_of(self.env.task.goal_quat.numpy()[0].astype(np.float64)))
        self.endpoint.send(encode_goal(GoalCommand(seq=self._seq, kind=GOAL_SET, x=x, y=y, yaw=yaw)),
                           self._runtime(self.cfg.goal_port))

    # ------------------------------------------------------------------ the run
    def _wait(self, ticker: Ticker | None) -> None:
        if ticker is not None:
            self.clock.record(ticker.wait().index, self.step)
        elif not self.endpoint.wait_readable(self.cfg.command_timeout_s):
            raise TimeoutError(f"lock-step: no command from the runtime for {self.cfg.command_timeout_s} s")

    def _start_episode_record(self) -> tuple[TrajectoryObserver | None, dict]:
        """At an episode's start: its object and goal, and a path recorder when a picture is asked for."""
        if self.recorder is not None:
            self.recorder.episode_started()
        return (TrajectoryObserver(self.env) if self.cfg.trajectory_png else None), episode_setup(self.env, 0)

    def serve(self) -> None:
        """Steps until ``episodes`` episodes ended; one ``SIM2SIM`` line per episode, then ``done``."""
        env = self.env
        emit({"event": "ready", "command_port": self.endpoint.port, "control_dt": self.dt})
        ticker = None if self.cfg.lockstep else Ticker(RealClock(), self.dt)
        started, episode_steps, first_success, results = False, 0, 0, 0
        rows, paths, observer, setup = [], [], None, None
        self.publish()
        while results < self.cfg.episodes:
            self._wait(ticker)
            self.receive_commands()
            if self.command is not None and self.command.state == State.STOPPED:
                break  # latched until the runtime restarts: the remaining episodes cannot run
            if self.recorder is not None:
                self.recorder.before_step(self.step)
            env.step_commands(*self.commands())
            if self.recorder is not None:
                self.recorder.after_commands()
            self.step += 1
            if started:
                episode_steps += 1
                if first_success == 0 and int(env.success_t[0]) != 0:
                    first_success = episode_steps
                ended = int(env.reset_t[0]) != 0
                if observer is not None:
                    observer.observe(episode_steps - 1, torch.tensor([True]), torch.tensor([not ended]))
                if ended:
                    results += 1
                    toppled, fallen = bool(env.episode_toppled_t[0]), bool(env.episode_fallen_t[0])
                    success = int(env.episode_success_t[0]) == 1
                    rows.append(episode_row(setup, self.dt, success, toppled, episode_steps, first_success))
                    if observer is not None:
                        paths.append(observer.paths)
                    emit({"event": "episode", "index": results - 1, **rows[-1], "first_success_step": first_success,
                          "steps": episode_steps, "fallen": fallen})
                    episode_steps, first_success = 0, 0
                    if results < self.cfg.episodes:
                        self.send_goal()
                        observer, setup = self._start_episode_record()
            elif self.command is not None and self.command.state in OPERATING_STATES:
                env.reset()
                started = True
                self.send_goal()
                observer, setup = self._start_episode_record()
            self.publish()
        if paths:
            plot_play({"policy": self.cfg.policy, "episodes": rows}, concatenate_episodes(paths), Path(self.cfg.trajectory_png))
        emit({"event": "done", "steps": self.step, "episodes": results, "runtime_stopped": results < self.cfg.episodes,
              "malformed_commands": self.malformed_commands, "clock": self.clock.last,
              "trajectory_png": self.cfg.trajectory_png if paths else None})

    def close(self) -> None:
        if self.recorder is not None:
            self.recorder.write(self.cfg.record)
        self.endpoint.close()


def emit(event: dict) -> None:
    print(EVENT_PREFIX + json.dumps(event), flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m dynpush.policies.sim2sim", description=__doc__.split("\n")[0])
    parser.add_argument("--config", required=True, help="SimToSimConfig as JSON")
    cfg = SimToSimConfig(**json.loads(parser.parse_args(argv).config))
    torch.set_num_threads(1)
    robot = SimRobot(cfg)
    try:
        robot.serve()
    finally:
        robot.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())

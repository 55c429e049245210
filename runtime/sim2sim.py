"""``dynpush sim2sim``: the deployment runtime, exactly as on the robot, against the simulator.

This process runs :class:`~dynpush.runtime.app.Runtime` (numpy + onnxruntime only); the simulator
(``dynpush.policies.sim2sim``: Newton, Warp, torch) runs in a child process and plays the robot and the
mocap system over loopback UDP. The runtime's config is the given one (or the defaults) with the
parts that wire it to the simulator replaced: mocap source ``udp`` on an ephemeral loopback port with
bodies ``base`` and ``object`` in the runtime's conventions, the robot link on an ephemeral loopback port
taking state from loopback only and replying to the simulator, goals from ``DPG1`` commands only, the locomotion and the clock (real time by
default, lock-step on request).

Locomotion: ``onboard`` (default), the simulator's tracked base takes the 6D command; or a locomotion ONNX
(``locomotion_policy``, exported from a ``dynpush train --task locomotion`` run): this runtime runs it, as it
would on the robot, and sends all 17 joint targets (12 legs, 5 arm) to the simulator's legged robot
(``env.legged.enabled``), which reports its leg joints back. The runtime's ``locomotion.onnx`` section, leg
joint names and safety leg limits come from the file's contract.

The report (JSON) gives the success rate over the episodes (success flag at an episode's last
step), the episodes, the simulated conditions and the runtime's own summary (timing, states, drops).
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path

from .app import Runtime
from .config import LOOPBACK, GoalsConfig, MocapConfig, RuntimeConfig, RuntimeConfigError, load_config
from .locomotion import read_locomotion_contract

EVENT_PREFIX = "SIM2SIM "


@dataclass
class SimToSimOptions:
    policy: str
    episodes: int = 1
    mocap_noise_m: float = 0.0  # std of the position noise per axis [m]
    mocap_noise_rad: float = 0.0  # std of the rotation-vector noise per axis [rad]
    latency_s: float = 0.0  # mocap latency, rounded to whole control periods
    drop: float = 0.0  # probability that a mocap frame is lost
    lockstep: bool = False  # simulated time: one tick per simulator step (tests); default real time
    seed: int = 0
    config: str | None = None  # a runtime YAML to start from (safety, rates, timeouts...)
    overrides: list[str] = field(default_factory=list)  # simulator environment overrides, env.field=value
    log_dir: str = "runs/sim2sim"
    trajectory_png: str | None = None  # the simulator draws the episodes' paths here
    locomotion_policy: str | None = None  # locomotion.onnx: the runtime runs it, the simulator is legged

    def validate(self) -> None:
        if self.episodes < 1:
            raise RuntimeConfigError(f"episodes must be >= 1, got {self.episodes}")
        for name in ("mocap_noise_m", "mocap_noise_rad", "latency_s"):
            if not getattr(self, name) >= 0.0:
                raise RuntimeConfigError(f"{name} must be >= 0, got {getattr(self, name)}")
        if not 0.0 <= self.drop < 1.0:
            raise RuntimeConfigError(f"drop must lie in [0, 1), got {self.drop}")


def runtime_config(options: SimToSimOptions) -> RuntimeConfig:
    """The runtime config wired to the simulator (see the module docstring)."""
    policy = str(Path(options.policy).resolve())
    cfg = load_config(options.config, {"push_policy": {"path": policy}}) if options.config else RuntimeConfig()
    if cfg.locomotion.mode != "onboard":
        raise RuntimeConfigError("locomotion.mode must be 'onboard' in a sim2sim config; a locomotion ONNX is given as"
                                 f" sim2sim's locomotion_policy (--locomotion onnx), got {cfg.locomotion.mode!r}")
    cfg.push_policy.path = policy
    if options.locomotion_policy:
        section, contract = read_locomotion_contract(str(Path(options.locomotion_policy).resolve()))
        cfg.locomotion.mode, cfg.locomotion.onnx = "onnx", section
        cfg.robot.leg_joint_names = list(section.joint_names)
        cfg.safety.leg_joint_lower = [float(v) for v in contract["joint_lower"]]
        cfg.safety.leg_joint_upper = [float(v) for v in contract["joint_upper"]]
    cfg.mocap = MocapConfig(source="udp", port=0, timeout_s=cfg.mocap.timeout_s)
    cfg.robot.bind_address, cfg.robot.port, cfg.robot.robot_address = LOOPBACK, 0, ""
    cfg.robot.allowed_senders = [LOOPBACK]  # the simulator, whatever robot the config names
    cfg.goals = GoalsConfig(command_port=0)
    cfg.rates.clock = "lockstep" if options.lockstep else "realtime"
    cfg.log.directory = options.log_dir
    return cfg.validate()


def _simulator_config(options: SimToSimOptions, runtime: Runtime) -> dict:
    """Fields of ``dynpush.policies.sim2sim.SimToSimConfig``."""
    mocap = runtime.cfg.mocap
    return {
        "policy": options.policy, "state_port": runtime.link.endpoint.port, "mocap_port": runtime.mocap.endpoint.port,
        "goal_port": runtime.goals.endpoint.port, "episodes": options.episodes, "mocap_noise_m": options.mocap_noise_m,
        "mocap_noise_rad": options.mocap_noise_rad, "latency_s": options.latency_s, "drop": options.drop,
        "lockstep": options.lockstep, "seed": options.seed, "base_body": mocap.base_body,
        "object_body": mocap.object_body,
        "overrides": list(options.overrides) + (["env.legged.enabled=True"] if options.locomotion_policy else []),
        "trajectory_png": str(Path(options.trajectory_png).resolve()) if options.trajectory_png else None,
    }


def _read_events(process: subprocess.Popen, episodes: list[dict], done: list[dict], stop: threading.Event) -> None:
    for line in process.stdout:
        if line.startswith(EVENT_PREFIX):
            event = json.loads(line[len(EVENT_PREFIX):])
            if event["event"] == "episode":
                episodes.append(event)
            elif event["event"] == "done":
                done.append(event)
                stop.set()
    stop.set()  # the simulator exited


def run_sim2sim(options: SimToSimOptions) -> dict:
    """Runs the simulator and the runtime until the episodes are done; returns the report."""
    options.validate()
    stop = threading.Event()
    runtime = Runtime(runtime_config(options), stop)
    command = [sys.executable, "-m", "dynpush.policies.sim2sim", "--config", json.dumps(_simulator_config(options, runtime))]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    episodes: list[dict] = []
    done: list[dict] = []
    reader = threading.Thread(target=_read_events, args=(process, episodes, done, stop), daemon=True)
    reader.start()
    try:
        summary = runtime.run()
    finally:
        stop.set()
        try:
            process.wait(timeout=30.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        reader.join(timeout=5.0)
    count = len(episodes)
    rate = lambda key: sum(bool(e[key]) for e in episodes) / count if count else None  # noqa: E731
    return {
        "policy": options.policy,
        "episodes": count,
        "success_rate": rate("success"),
        "reached_rate": sum(e["first_success_step"] > 0 for e in episodes) / count if count else None,
        "toppled_rate": rate("toppled"),
        "completed": bool(done) and count == options.episodes,
        "simulator_exit_code": process.returncode,
        "conditions": {"clock": "lockstep" if options.lockstep else "realtime",
                       "locomotion": options.locomotion_policy or "onboard (tracked base)", "mocap_noise_m": options.mocap_noise_m,
                       "mocap_noise_rad": options.mocap_noise_rad, "latency_s": options.latency_s,
                       "drop": options.drop, "seed": options.seed, "overrides": options.overrides},
        "episode_results": episodes,
        "trajectory_png": done[0]["trajectory_png"] if done else None,
        "simulator": done[0] if done else None,
        "runtime": summary,
    }

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

Real time needs a simulator that steps once per control period. The simulator reports, about every 0.2 s,
its deadline index and the steps it had taken by then (``clock`` events); :class:`RateCheck` judges every window of
``rate_window_s`` (default 1 s). A window in which it stepped fewer than ``min_rate`` (default 90 %) of the control
periods means the machine cannot run this simulator in real time (its ticker skips the deadlines it missed, so the
robot is controlled at a fraction of the rate it was trained for). Then one line says so on stderr and, by
``on_slow``, the run starts again in lock-step (``lockstep``, default) or ends (``stop``). The report's ``timing``
says what the result is: ``realtime``, ``lockstep`` (asked for), ``lockstep_fallback`` or ``stopped_slow``;
``realtime_check`` holds the measured rate.

The report (JSON) gives the success rate over the episodes (success flag at an episode's last
step), the episodes, the simulated conditions and the runtime's own summary (timing, states, drops).
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path

from dynpush.errors import UserError

from .app import Runtime
from .config import LOOPBACK, GoalsConfig, MocapConfig, RuntimeConfig, RuntimeConfigError, load_config
from .locomotion_contract import LocomotionContract

EVENT_PREFIX = "SIM2SIM "
ON_SLOW = ("lockstep", "stop")  # what a real-time run does once the simulator falls behind the control rate


class SimulatorTooSlowError(UserError, RuntimeError):
    """A real-time run stopped (``on_slow="stop"``) because the simulator could not keep the control rate."""


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
    record: str | None = None  # the simulator writes what it saw, step by step, to this .npz (dynpush.policies.chain_record)
    locomotion_policy: str | None = None  # locomotion.onnx: the runtime runs it, the simulator is legged
    on_slow: str = "lockstep"  # real time, the simulator falls behind: rerun in lock-step, or stop
    min_rate: float = 0.9  # real time needs the simulator to step this fraction of the control periods...
    rate_window_s: float = 1.0  # ...in every window of this length [s]

    def validate(self) -> None:
        if self.episodes < 1:
            raise RuntimeConfigError(f"episodes must be >= 1, got {self.episodes}")
        if self.on_slow not in ON_SLOW:
            raise RuntimeConfigError(f"on_slow must be one of {', '.join(ON_SLOW)}, got {self.on_slow!r}")
        if not 0.0 < self.min_rate <= 1.0:
            raise RuntimeConfigError(f"min_rate must lie in (0, 1], got {self.min_rate}")
        if not self.rate_window_s > 0.0:
            raise RuntimeConfigError(f"rate_window_s must be > 0, got {self.rate_window_s}")
        for name in ("mocap_noise_m", "mocap_noise_rad", "latency_s"):
            if not getattr(self, name) >= 0.0:
                raise RuntimeConfigError(f"{name} must be >= 0, got {getattr(self, name)}")
        if not 0.0 <= self.drop < 1.0:
            raise RuntimeConfigError(f"drop must lie in [0, 1), got {self.drop}")
        for name in ("trajectory_png", "record"):
            path = getattr(self, name)
            if path and not Path(path).resolve().parent.is_dir():
                raise RuntimeConfigError(f"{name}: folder {Path(path).resolve().parent} does not exist")


def runtime_config(options: SimToSimOptions) -> RuntimeConfig:
    """The runtime config wired to the simulator (see the module docstring)."""
    policy = str(Path(options.policy).resolve())
    cfg = load_config(options.config, {"push_policy": {"path": policy}}) if options.config else RuntimeConfig()
    if cfg.locomotion.mode != "onboard":
        raise RuntimeConfigError("locomotion.mode must be 'onboard' in a sim2sim config; a locomotion ONNX is given as"
                                 f" sim2sim's locomotion_policy (--locomotion onnx), got {cfg.locomotion.mode!r}")
    cfg.push_policy.path = policy
    if options.locomotion_policy:
        path = str(Path(options.locomotion_policy).resolve())
        contract = LocomotionContract.read(path)
        cfg.locomotion.mode, cfg.locomotion.onnx = "onnx", contract.section(path)
        cfg.robot.leg_joint_names = list(contract.joint_names)
        cfg.safety.leg_joint_lower, cfg.safety.leg_joint_upper = list(contract.joint_lower), list(contract.joint_upper)
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
        "record": str(Path(options.record).resolve()) if options.record else None,
    }


class RateCheck:
    """Does the simulator keep the control rate in real time? Judged on the simulator's own clock reports.

    A report ``(deadline, steps)`` is taken at one of the simulator's waits for a control deadline: the deadline's
    index (control periods since its first) and the steps taken before it. On time, ``steps`` grows by one per
    period; a simulator that overruns skips the deadlines it missed (no catch-up burst), so over the reports ``a`` and
    ``b`` its rate is ``(steps_b - steps_a) / (deadline_b - deadline_a)`` of the control rate. Every window of
    ``window`` periods is judged; the first one below ``min_rate`` is the verdict (:attr:`slow_rate`).
    """

    def __init__(self, min_rate: float, window: int, control_rate_hz: float):
        self.min_rate = min_rate
        self.window = max(1, window)  # [control periods]
        self.control_rate_hz = control_rate_hz
        self._first: tuple[int, int] | None = None
        self._start: tuple[int, int] | None = None  # the report that opens the current window
        self._last: tuple[int, int] | None = None
        self.windows = 0  # windows judged
        self.slowest: float | None = None  # the lowest window rate [fraction of the control rate]
        self.slow_rate: float | None = None  # the rate of the first window below min_rate: not real time

    @property
    def fell_behind(self) -> bool:
        return self.slow_rate is not None

    def add(self, deadline: int, steps: int) -> bool:
        """Takes one report; True once the simulator has fallen behind."""
        if self._start is None:
            self._first = self._start = self._last = (deadline, steps)
            return False
        self._last = (deadline, steps)
        if deadline - self._start[0] >= self.window:
            self._judge(self._start, self._last)
            self._start = self._last
        return self.fell_behind

    def finish(self) -> bool:
        """At the end of the run, also judges what no window covered: the whole run when it was shorter than a
        window (a simulator so slow that the runtime stopped at once), else a last stretch of at least half a
        window (shorter stretches are left out: one period more or less would swing them)."""
        if self._start is not None and self._last[0] > self._start[0]:
            if self.windows == 0 or self._last[0] - self._start[0] >= self.window / 2:
                self._judge(self._start, self._last)
                self._start = self._last
        return self.fell_behind

    def _judge(self, start: tuple[int, int], end: tuple[int, int]) -> None:
        rate = (end[1] - start[1]) / (end[0] - start[0])
        self.windows += 1
        self.slowest = rate if self.slowest is None else min(self.slowest, rate)
        if rate < self.min_rate and self.slow_rate is None:
            self.slow_rate = rate

    def rate(self) -> float | None:
        """Steps per control period over the whole run (fraction of the control rate); None before two reports."""
        if self._first is None or self._last[0] == self._first[0]:
            return None
        return (self._last[1] - self._first[1]) / (self._last[0] - self._first[0])

    def message(self, on_slow: str) -> str:
        """The one line that says the run is not real time and what happens next."""
        then = ("switching to lock-step (simulated time)" if on_slow == "lockstep"
                else "stopping (--on-slow lockstep reruns in lock-step; --lockstep runs in simulated time)")
        return (f"sim2sim: the simulator keeps {100.0 * self.slow_rate:.0f} % of the {self.control_rate_hz:.0f} Hz"
                f" control rate on this machine (real time needs {100.0 * self.min_rate:.0f} %); {then}")

    def summary(self) -> dict:
        periods = self._last[0] - self._first[0] if self._first is not None else 0
        return {"control_rate_hz": self.control_rate_hz, "min_rate": self.min_rate,
                "window_s": self.window / self.control_rate_hz, "windows": self.windows, "periods": periods,
                "steps": self._last[1] - self._first[1] if self._first is not None else 0, "rate": self.rate(),
                "slowest_window_rate": self.slowest, "fell_behind": self.fell_behind,
                "slow_window_rate": self.slow_rate}


@dataclass
class _Attempt:
    """One run of simulator and runtime: what the simulator reported and the runtime's summary."""

    runtime: dict
    episodes: list[dict]
    done: list[dict]
    exit_code: int | None
    check: RateCheck | None  # None in lock-step


def _read_events(process: subprocess.Popen, episodes: list[dict], done: list[dict], check: RateCheck | None,
                 stop: threading.Event) -> None:
    for line in process.stdout:
        if line.startswith(EVENT_PREFIX):
            event = json.loads(line[len(EVENT_PREFIX):])
            if event["event"] == "episode":
                episodes.append(event)
            elif event["event"] == "clock" and check is not None:
                if check.add(event["deadline"], event["steps"]):
                    stop.set()  # not real time: this attempt ends here, run_sim2sim decides what follows
            elif event["event"] == "done":
                if check is not None and event.get("clock"):
                    check.add(*event["clock"])  # the simulator's last wait
                done.append(event)
                stop.set()
    stop.set()  # the simulator exited


def _run_attempt(options: SimToSimOptions) -> _Attempt:
    """Runs the simulator and the runtime until the episodes are done, the runtime stops, or (real time) the
    simulator falls behind."""
    stop = threading.Event()
    runtime = Runtime(runtime_config(options), stop)
    period = runtime.cfg.control_period_s
    window = round(options.rate_window_s / period)  # [control periods]
    check = None if options.lockstep else RateCheck(options.min_rate, window, 1.0 / period)
    command = [sys.executable, "-m", "dynpush.policies.sim2sim", "--config", json.dumps(_simulator_config(options, runtime))]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    episodes: list[dict] = []
    done: list[dict] = []
    reader = threading.Thread(target=_read_events, args=(process, episodes, done, check, stop), daemon=True)
    reader.start()
    try:
        summary = runtime.run()
    finally:
        stop.set()
        if not done:  # stopped early (too slow, a runtime error): a real-time simulator would step on until its end
            process.terminate()
        try:
            process.wait(timeout=30.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        reader.join(timeout=5.0)
    if check is not None:
        check.finish()
    return _Attempt(summary, episodes, done, process.returncode, check)


def _report(options: SimToSimOptions, attempt: _Attempt, timing: str, check: RateCheck | None) -> dict:
    """The JSON report of the attempt whose episodes are the result; ``timing`` says how it was clocked."""
    episodes, done = attempt.episodes, attempt.done
    count = len(episodes)
    rate = lambda key: sum(bool(e[key]) for e in episodes) / count if count else None  # noqa: E731
    return {
        "policy": options.policy,
        "timing": timing,
        "realtime_check": (check.summary() | {"message": check.message(options.on_slow) if check.fell_behind else None}
                           if check is not None else None),
        "episodes": count,
        "success_rate": rate("success"),
        "reached_rate": sum(e["first_success_step"] > 0 for e in episodes) / count if count else None,
        "toppled_rate": rate("toppled"),
        "completed": bool(done) and count == options.episodes and timing != "stopped_slow",
        "simulator_exit_code": attempt.exit_code,
        "conditions": {"clock": "lockstep" if options.lockstep else "realtime",
                       "locomotion": options.locomotion_policy or "onboard (tracked base)", "mocap_noise_m": options.mocap_noise_m,
                       "mocap_noise_rad": options.mocap_noise_rad, "latency_s": options.latency_s,
                       "drop": options.drop, "seed": options.seed, "overrides": options.overrides},
        "episode_results": episodes,
        "trajectory_png": done[0]["trajectory_png"] if done else None,
        "simulator": done[0] if done else None,
        "runtime": attempt.runtime,
    }


def run_sim2sim(options: SimToSimOptions) -> dict:
    """Runs the simulator and the runtime until the episodes are done; returns the report.

    In real time a simulator that falls behind the control rate (:class:`RateCheck`) ends the attempt with one line
    on stderr; then the episodes run again in lock-step (``on_slow="lockstep"``, ``timing: lockstep_fallback``, the
    real-time attempt's runtime summary under ``realtime_attempt``) or the report ends there (``"stop"``,
    ``timing: stopped_slow``, not completed; the command raises :class:`SimulatorTooSlowError` after writing it).
    """
    options.validate()
    attempt = _run_attempt(options)
    check = attempt.check
    if check is None:
        return _report(options, attempt, "lockstep", None)
    if not check.fell_behind:  # unmeasured: the simulator ended before one control period passed on its clock
        return _report(options, attempt, "realtime" if check.windows else "realtime_unmeasured", check)
    if options.on_slow == "stop":
        return _report(options, attempt, "stopped_slow", check)
    print(check.message(options.on_slow), file=sys.stderr, flush=True)
    lockstep = dataclasses.replace(options, lockstep=True)
    report = _report(lockstep, _run_attempt(lockstep), "lockstep_fallback", check)
    report["realtime_attempt"] = {"episodes": len(attempt.episodes), "simulator_exit_code": attempt.exit_code,
                                  "runtime": attempt.runtime}
    return report


def describe_timing(report: dict) -> str:
    """One line for a printed summary: how the result was clocked, with the simulator's measured rate."""
    check, timing = report["realtime_check"], report["timing"]
    if check is None:
        return "timing: lock-step (simulated time, as asked)"
    hz = f"{check['control_rate_hz']:.0f} Hz control rate"
    if check["fell_behind"]:
        what = {"lockstep_fallback": "lock-step fallback", "stopped_slow": "stopped"}[timing]
        return (f"timing: {what}, not real time: the simulator kept {100.0 * check['slow_window_rate']:.0f} % of the"
                f" {hz} in a {check['window_s']:.1f} s window (real time needs {100.0 * check['min_rate']:.0f} %)")
    if check["rate"] is None:
        return "timing: real time, unmeasured (the simulator ended before one control period)"
    return f"timing: real time (the simulator kept {100.0 * check['rate']:.0f} % of the {hz})"

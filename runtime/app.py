"""The deployment loop: mocap + robot state + goal -> controller -> robot link, at the control rate.

Each tick (absolute deadline, timing.py): take in whatever arrived (mocap, robot state, goal
commands, stamped with the tick's start time), run the controller, send the command, write the tick
log record, record lateness, compute time and mocap age. ``run`` returns a summary (p50/p99/max of
the timings, state counts, dropped datagrams, the log path) when stopped, also after a tick that raised
(a bug): that tick's exception latches STOPPED, a stop command goes out, and the run ends.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import threading
import time
from collections import Counter

from .config import RuntimeConfig
from .controller import Controller
from .errors import StartupError
from .goals import GoalManager
from .locomotion import OnnxLocomotion
from .locomotion_layout import NUM_LEG_JOINTS
from .mocap import open_mocap
from .policy import load_push_policy
from .robot_link import open_robot_link
from .safety import State
from .tick_log import RecordLayout, TickLogWriter
from .timing import Clock, LockstepClock, RealClock, Ticker, TimingStats

_LOG = logging.getLogger(__name__)


def open_tick_log(cfg: RuntimeConfig, layout: RecordLayout, meta: dict) -> TickLogWriter:
    """A new tick log in ``log.directory`` named by the start time; StartupError naming the field if it cannot be made."""
    try:
        return TickLogWriter.new_in(cfg.log.directory, time.strftime("runtime-%Y%m%d-%H%M%S"), layout, meta,
                                    cfg.rates.log_flush_s)
    except OSError as error:
        raise StartupError(f"log.directory {cfg.log.directory}: cannot create a tick log there: {error}") from error


class Runtime:
    """Everything of one deployment run; build (start-up checks happen here), then :meth:`run`."""

    def __init__(self, cfg: RuntimeConfig, stop: threading.Event | None = None):
        self.cfg = cfg
        self.stop = stop or threading.Event()
        push, self.contract = load_push_policy(cfg)  # raises StartupError before anything is opened
        locomotion = OnnxLocomotion(cfg.locomotion.onnx, self.contract) if cfg.locomotion.mode == "onnx" else None
        self.controller = Controller(cfg, self.contract, push, locomotion)
        with contextlib.ExitStack() as resources:
            self.link = open_robot_link(cfg.robot, NUM_LEG_JOINTS if locomotion else 0)
            resources.callback(self.link.close)
            self.clock: Clock = (RealClock() if cfg.rates.clock == "realtime"
                                 else LockstepClock(self.link.wait_for_state, self.stop))
            self.mocap = open_mocap(cfg.mocap, self.clock.now)
            resources.callback(self.mocap.close)
            self.goals = GoalManager(cfg.goals)
            resources.callback(self.goals.close)
            meta = {"config": cfg.to_dict(), "contract": dataclasses.asdict(self.contract),
                    "states": {s.name: int(s) for s in State}, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
            self.log = open_tick_log(cfg, self.controller.layout, meta)
            resources.callback(self.log.close)
            self._close = resources.pop_all()
        self.ticker = Ticker(self.clock, cfg.control_period_s)
        self.stats = TimingStats()
        self.state_ticks: Counter[str] = Counter()
        self.ticks = 0
        self.error: Exception | None = None  # what ended the run early (a bug), if anything

    def tick(self) -> None:
        """Waits for the next deadline and runs one control tick."""
        timing = self.ticker.wait()
        if self.stop.is_set():  # a lock-step wait ends early when stopped
            return
        started = time.perf_counter()
        now = timing.start
        self.mocap.poll(now)
        self.link.poll(now)
        goal_changed = self.goals.poll(now, self.controller.safety.reached_since)
        command = self.controller.step(timing, self.mocap.base, self.mocap.object, self.link.latest, self.goals.goal,
                                       goal_changed)
        self.link.send(command)
        compute = time.perf_counter() - started
        record = self.controller.record
        self.controller.layout.view(record, "compute_s")[0] = compute
        self.log.write(record)
        self.stats.add(timing.lateness, compute, self.controller.mocap_age)
        self.state_ticks[State(command.state).name] += 1
        self.ticks += 1

    def run(self, max_ticks: int | None = None) -> dict:
        """Ticks until :attr:`stop` is set (or ``max_ticks``); closes everything; returns the summary."""
        try:
            while not self.stop.is_set() and (max_ticks is None or self.ticks < max_ticks):
                self.tick()
        except Exception as error:  # a bug: the robot is stopped, and the summary still comes
            self.error = error
            _LOG.error("tick %d failed; the robot is sent a stop command", self.ticks, exc_info=error)
            self.link.send(self.controller.stop(self.clock.now(), f"tick failed: {type(error).__name__}: {error}"))
        finally:
            self._close.close()
        return self.summary()

    def summary(self) -> dict:
        safety = self.controller.safety
        return {
            "timing": self.stats.summary(self.ticker.skipped) | {"overrun": self.controller.overruns.summary()},
            "states": dict(self.state_ticks),
            "final_state": safety.state.name,
            "final_reason": safety.reason,
            "mocap": dataclasses.asdict(self.mocap.stats),
            "robot_link": dataclasses.asdict(self.link.stats),
            "goal_commands": dataclasses.asdict(self.goals.stats),
            "log": str(self.log.path),
            "log_records": self.log.records,
        }

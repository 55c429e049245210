"""Clocks, the absolute-deadline ticker and per-tick timing statistics.

Tick ``k`` is due at ``t0 + k * period`` (``t0``: the first tick). A tick that overruns past later
deadlines does not cause a burst of catch-up ticks: the ticker runs the newest missed deadline at
once (late by less than one period) and counts the older ones as skipped. Times are seconds of the
clock in use: ``time.perf_counter`` in real time, simulated time in lock-step.

:class:`OverrunGuard` judges the rate the runtime itself keeps from the skipped deadlines: too many within a
window of control periods is a fault, and the controller stops the robot. In lock-step a deadline is reached when
the robot's next state arrives, however long a tick computed, so no deadline is ever skipped and the guard cannot
trip there.
"""

from __future__ import annotations

import threading
import time
from array import array
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np


class Clock(Protocol):
    def now(self) -> float: ...

    def sleep_until(self, deadline: float) -> None: ...


class RealClock:
    """``time.perf_counter`` and ``time.sleep``."""

    def now(self) -> float:
        return time.perf_counter()

    def sleep_until(self, deadline: float) -> None:
        remaining = deadline - time.perf_counter()
        if remaining > 0.0:
            time.sleep(remaining)


class LockstepClock:
    """Simulated time driven by the robot: reaching a deadline means waiting for its next state.

    ``wait_for_state(timeout)`` blocks until new state is waiting; ``stop`` ends a wait early. Once
    the robot has spoken, silence for ``timeout_s`` of wall time raises ``TimeoutError`` (before its
    first state, e.g. while a simulator starts, the clock waits for as long as it takes).
    """

    def __init__(self, wait_for_state: Callable[[float], bool], stop: threading.Event, timeout_s: float = 10.0):
        self._wait = wait_for_state
        self._stop = stop
        self._timeout_s = timeout_s
        self._t = 0.0
        self._started = False

    def now(self) -> float:
        return self._t

    def sleep_until(self, deadline: float) -> None:
        give_up = time.monotonic() + self._timeout_s
        while not self._wait(0.05):
            if self._stop.is_set():
                return
            if self._started and time.monotonic() > give_up:
                raise TimeoutError(f"lock-step clock: no robot state for {self._timeout_s} s")
        self._started = True
        self._t = max(self._t, deadline)


@dataclass
class TickTiming:
    index: int  # deadline index k
    deadline: float  # t0 + k * period
    start: float  # when the tick began
    lateness: float  # start - deadline
    skipped: int  # deadlines skipped so far


class Ticker:
    """Waits for the next absolute deadline; see the module docstring for overruns."""

    def __init__(self, clock: Clock, period: float):
        self.clock = clock
        self.period = period
        self._t0: float | None = None
        self._index = -1
        self.skipped = 0

    def wait(self) -> TickTiming:
        clock = self.clock
        if self._t0 is None:
            self._t0 = clock.now()
            index = 0
        else:
            index = self._index + 1
            now = clock.now()
            newest_due = int((now - self._t0) / self.period + 1e-9)  # a deadline reached to within rounding counts
            if newest_due > index:
                self.skipped += newest_due - index
                index = newest_due
        deadline = self._t0 + index * self.period
        clock.sleep_until(deadline)
        start = clock.now()
        self._index = index
        return TickTiming(index=index, deadline=deadline, start=start, lateness=start - deadline, skipped=self.skipped)


class OverrunGuard:
    """More than ``max_skipped`` deadlines skipped among the last ``window`` deadlines is a fault.

    The window holds the current tick's deadline and the ``window - 1`` before it (``window`` control periods, 1 s
    at 50 Hz with the default 50), so skips age out as the loop runs on time. A tick computing past the next
    deadline makes the following tick late; past the one after, deadlines are skipped, and a computer that stays
    too slow keeps skipping them.
    """

    def __init__(self, max_skipped: int, window: int):
        self.max_skipped = max_skipped
        self.window = window  # [control periods]
        self._skipped: deque[int] = deque()  # indices of the skipped deadlines within the window
        self._total = 0  # TickTiming.skipped of the previous tick
        self.worst = 0  # the most deadlines skipped within one window so far

    def add(self, timing: TickTiming) -> str | None:
        """Takes one tick; the fault in one line with its figures while the window holds more than
        ``max_skipped`` skipped deadlines, else None."""
        new = timing.skipped - self._total
        self._total = timing.skipped
        oldest = timing.index - self.window + 1  # the first deadline within the window
        self._skipped.extend(range(max(timing.index - new, oldest), timing.index))
        while self._skipped and self._skipped[0] < oldest:
            self._skipped.popleft()
        count = len(self._skipped)
        self.worst = max(self.worst, count)
        if count <= self.max_skipped:
            return None
        return (f"control rate: {count} deadlines skipped in the last {self.window} control periods"
                f" (limit {self.max_skipped})")

    def summary(self) -> dict:
        """The limit and the most deadlines skipped within one window so far."""
        return {"max_skipped": self.max_skipped, "window_periods": self.window, "worst_window_skipped": self.worst}


class TimingStats:
    """Per-tick lateness, compute time and mocap age, summarised as p50/p99/max in milliseconds."""

    NAMES = ("lateness", "compute", "mocap_age")

    def __init__(self):
        self._samples = {name: array("d") for name in self.NAMES}

    def add(self, lateness: float, compute: float, mocap_age: float) -> None:
        for name, value in zip(self.NAMES, (lateness, compute, mocap_age)):
            self._samples[name].append(value)

    def summary(self, skipped: int) -> dict:
        result: dict = {"ticks": len(self._samples["compute"]), "skipped": skipped}
        for name, samples in self._samples.items():
            values = np.frombuffer(samples, dtype=np.float64) if len(samples) else np.zeros(0)
            finite = values[np.isfinite(values)]
            entry = {"samples": int(finite.size)}
            if finite.size:
                p50, p99 = np.percentile(finite, [50.0, 99.0])
                entry |= {"p50_ms": 1e3 * p50, "p99_ms": 1e3 * p99, "max_ms": 1e3 * float(finite.max())}
            result[name] = entry
        return result

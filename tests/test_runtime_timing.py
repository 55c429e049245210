"""The absolute-deadline ticker with a fake clock: on-time ticks, overruns skip missed deadlines (never a
burst of catch-up ticks), no drift; the lock-step clock; the p50/p99/max summary."""

import threading
import time

import numpy as np
import pytest

from dynpush.runtime.timing import LockstepClock, Ticker, TimingStats
from test_runtime_helpers import FakeClock

PERIOD = 0.02


def run(compute_times: list[float]):
    clock = FakeClock()
    ticker = Ticker(clock, PERIOD)
    ticks = []
    for compute in compute_times:
        ticks.append(ticker.wait())
        clock.work(compute)
    return ticks, ticker


def test_on_time_ticks_have_absolute_deadlines_without_drift():
    ticks, ticker = run([0.013] * 500)
    assert [t.index for t in ticks] == list(range(500)) and ticker.skipped == 0
    np.testing.assert_allclose([t.start for t in ticks], 100.0 + PERIOD * np.arange(500), atol=1e-9)
    assert max(abs(t.lateness) for t in ticks) < 1e-9


def test_overrun_skips_missed_deadlines_without_burst():
    compute = [0.005] * 10
    compute[3] = 0.051  # tick 3 starts at 0.06 and ends at 0.111: deadlines 4 (0.08) and 5 (0.10) have passed
    ticks, ticker = run(compute)
    indices = [t.index for t in ticks]
    assert indices == [0, 1, 2, 3, 5, 6, 7, 8, 9, 10]
    assert ticker.skipped == 1 and ticks[4].skipped == 1
    late = ticks[4]
    assert late.deadline == pytest.approx(100.10) and late.lateness == pytest.approx(0.011), "newest missed deadline runs at once"
    assert all(abs(t.lateness) < 1e-9 for t in ticks[5:]), "then back on the absolute grid"
    starts = np.array([t.start for t in ticks])
    assert (np.diff(starts) >= 0.009).all(), "no two ticks back to back (no catch-up burst)"


@pytest.mark.parametrize("overrun_periods", [1.2, 3.7, 50.5])
def test_long_overruns_run_one_late_tick(overrun_periods):
    compute = [0.001, overrun_periods * PERIOD, 0.001, 0.001, 0.001]
    ticks, ticker = run(compute)
    late = [t for t in ticks if t.lateness > 1e-9]
    assert len(late) == 1 and late[0].lateness < PERIOD
    assert ticker.skipped == int(overrun_periods) - 1
    assert all(b.index > a.index for a, b in zip(ticks, ticks[1:]))


def test_lockstep_clock_advances_with_robot_state():
    arrivals = iter([True, False, False, True, True])
    clock = LockstepClock(lambda timeout: next(arrivals), threading.Event(), timeout_s=5.0)
    ticker = Ticker(clock, PERIOD)
    assert ticker.wait().start == 0.0
    assert ticker.wait().start == pytest.approx(PERIOD) and ticker.wait().start == pytest.approx(2 * PERIOD)
    spoke = threading.Event()

    def once_then_silent(timeout: float) -> bool:
        if not spoke.is_set():
            spoke.set()
            return True
        time.sleep(timeout)
        return False

    silent = LockstepClock(once_then_silent, threading.Event(), timeout_s=0.1)
    silent.sleep_until(0.0)
    with pytest.raises(TimeoutError, match="no robot state"):
        silent.sleep_until(1.0)
    stop = threading.Event()
    stop.set()
    stopped = LockstepClock(lambda timeout: False, stop, timeout_s=60.0)
    stopped.sleep_until(1.0)
    assert stopped.now() == 0.0, "a stop ends the wait without advancing time"


def test_timing_summary_percentiles():
    stats = TimingStats()
    for i in range(100):
        stats.add(lateness=i * 1e-4, compute=1e-3, mocap_age=float("inf") if i < 10 else 0.005)
    summary = stats.summary(skipped=3)
    assert summary["ticks"] == 100 and summary["skipped"] == 3
    assert summary["compute"]["p99_ms"] == pytest.approx(1.0) and summary["lateness"]["max_ms"] == pytest.approx(9.9)
    assert summary["lateness"]["p50_ms"] == pytest.approx(4.95)
    assert summary["mocap_age"]["samples"] == 90, "ticks without any mocap pose are counted out"

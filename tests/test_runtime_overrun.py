"""The runtime's own overruns (``rates.overrun``): the guard over skipped deadlines with a fake clock (on time, the
bound crossed, the window sliding, lock-step), the loop latching STOPPED when it trips, and a lock-step loop whose
ticks take longer than a period running on."""

import logging
import threading
import time

import numpy as np
import pytest

from dynpush.runtime.app import Runtime
from dynpush.runtime.config import config_from_dict
from dynpush.runtime.controller import Controller
from dynpush.runtime.packets import MODE_STOP
from dynpush.runtime.safety import State
from dynpush.runtime.tick_log import read_log
from dynpush.runtime.timing import LockstepClock, OverrunGuard, Ticker, TickTiming
from test_runtime_helpers import FakeClock, lockstep_config, run_with_robot, write_policy

PERIOD = 0.02
ON_TIME = 0.005  # compute of a tick [s]


def overrun(skipped: int) -> float:
    """Compute time of a tick after which the ticker skips ``skipped`` deadlines [s]."""
    return (skipped + 1) * PERIOD + 0.001


def judge(guard: OverrunGuard, compute_times: list[float]) -> list[tuple[TickTiming, str | None]]:
    """Each tick's timing and the guard's verdict, the ticks computing ``compute_times`` on a fake clock."""
    clock = FakeClock()
    ticker = Ticker(clock, PERIOD)
    verdicts = []
    for compute in compute_times:
        timing = ticker.wait()
        verdicts.append((timing, guard.add(timing)))
        clock.work(compute)
    return verdicts


def test_on_time_ticks_are_no_fault():
    guard = OverrunGuard(max_skipped=0, window=50)
    verdicts = judge(guard, [ON_TIME] * 500)
    assert all(fault is None for _, fault in verdicts) and guard.worst == 0
    late = judge(OverrunGuard(max_skipped=0, window=50), [ON_TIME, 1.9 * PERIOD, ON_TIME, ON_TIME])
    assert late[2][0].lateness == pytest.approx(0.9 * PERIOD) and all(fault is None for _, fault in late), \
        "a late tick whose deadline still ran skips nothing"


def test_fault_exactly_when_the_bound_is_crossed():
    guard = OverrunGuard(max_skipped=5, window=50)
    compute = [ON_TIME] * 30
    compute[5], compute[12], compute[20] = overrun(3), overrun(2), overrun(1)  # 3 + 2 = 5 allowed, then the 6th
    verdicts = judge(guard, compute)
    faults = [i for i, (_, fault) in enumerate(verdicts) if fault is not None]
    assert [t.skipped for t, _ in verdicts][20:22] == [5, 6]
    assert faults == list(range(21, 30)), "from the tick after the 6th skipped deadline on, not one tick before"
    assert verdicts[21][1] == "control rate: 6 deadlines skipped in the last 50 control periods (limit 5)"
    assert guard.worst == 6


@pytest.mark.parametrize("later, trips", [(57, True), (58, False)])
def test_the_window_slides_and_old_skips_age_out(later, trips):
    """Deadlines 10..14 are skipped (tick 9 overruns), one more when the tick of deadline ``later`` overruns; the
    tick of deadline later + 2 sees the 50 deadlines later - 47 .. later + 2."""
    compute = [ON_TIME] * 60
    compute[9] = overrun(5)
    position = later - 5  # of the tick of deadline ``later`` in the list: 5 deadlines were skipped before it
    compute[position] = overrun(1)
    verdicts = judge(OverrunGuard(max_skipped=5, window=50), compute)
    tick, fault = verdicts[position + 1]
    assert tick.index == later + 2 and tick.skipped == 6
    assert (fault is not None) == trips
    assert all(fault is None for _, fault in verdicts[: position + 1]), "5 in any window is allowed"


def test_a_stall_longer_than_the_window_counts_only_the_window():
    guard = OverrunGuard(max_skipped=5, window=50)
    verdicts = judge(guard, [ON_TIME, 10_000 * PERIOD, ON_TIME, ON_TIME])
    assert verdicts[2][0].skipped == 9_999 and verdicts[2][1].startswith("control rate: 49 deadlines skipped")
    assert verdicts[3][1] == "control rate: 48 deadlines skipped in the last 50 control periods (limit 5)", \
        "the oldest skipped deadline left the window"


def test_lockstep_never_trips_however_slow_the_robot():
    """Simulated time: a deadline is reached when the robot's state arrives, whatever the wall time in between."""
    answers = iter([True, False, False, False] * 100)
    ticker = Ticker(LockstepClock(lambda timeout: next(answers), threading.Event(), timeout_s=60.0), PERIOD)
    guard = OverrunGuard(max_skipped=0, window=50)
    verdicts = [guard.add(ticker.wait()) for _ in range(100)]
    assert verdicts == [None] * 100 and ticker.skipped == 0


def test_default_and_config_round_trip():
    cfg = config_from_dict({"push_policy": {"path": "p.onnx"}})
    assert (cfg.rates.overrun.max_skipped, cfg.rates.overrun.window_periods) == (5, 50)
    again = config_from_dict(cfg.to_dict())  # as a tick log's header holds it
    assert again.rates.overrun == cfg.rates.overrun


def test_the_loop_stops_when_its_ticks_overrun(tmp_path, caplog):
    """The real-time loop on a fake clock: the tick that crosses the bound sends a stop command and latches STOPPED;
    the summary and the tick log record it."""
    cfg = lockstep_config(write_policy(tmp_path / "p.onnx"), tmp_path, rates={"clock": "realtime"},
                          goals={"sequence": [{"x": 1.0, "y": 0.0}]})
    runtime = Runtime(cfg)
    clock = FakeClock()
    runtime.ticker = Ticker(clock, cfg.control_period_s)
    step = runtime.controller.step
    overruns = {5: overrun(3), 10: overrun(2), 15: overrun(1)}  # after these ticks: 3, 5 and 6 skipped
    commands = []

    def slow_step(*args):
        commands.append(step(*args))
        clock.work(overruns.get(runtime.ticks, ON_TIME))
        return commands[-1]

    runtime.controller.step = slow_step
    with caplog.at_level(logging.ERROR, logger="dynpush.runtime"):
        summary = runtime.run(max_ticks=30)
    reason = "control rate: 6 deadlines skipped in the last 50 control periods (limit 5)"
    assert summary["final_state"] == "STOPPED" and summary["final_reason"] == reason
    assert summary["states"] == {"STARTUP": 16, "STOPPED": 14}
    assert summary["timing"]["skipped"] == 6 and summary["timing"]["overrun"] == {
        "max_skipped": 5, "window_periods": 50, "worst_window_skipped": 6}
    assert all(c.mode == MODE_STOP for c in commands) and commands[16].state == State.STOPPED
    assert [r.getMessage() for r in caplog.records] == [f"{reason}; stopping"], "one line, once"
    log = read_log(runtime.log.path)
    states = log.column("state")[:, 0]
    assert (states[:16] == State.STARTUP).all() and (states[16:] == State.STOPPED).all()
    np.testing.assert_array_equal(log.column("skipped")[15:17, 0], [5, 6])


def test_slow_ticks_in_lockstep_do_not_stop_the_robot(tmp_path, monkeypatch):
    """Lock-step with a limit of 0 skipped deadlines and every tick computing longer than a control period (wall
    time): simulated time waits for the robot, so nothing is skipped and the robot is not stopped."""
    cfg = lockstep_config(write_policy(tmp_path / "p.onnx"), tmp_path, goals={"sequence": [{"x": 1.0, "y": 0.0}]},
                          rates={"overrun": {"max_skipped": 0, "window_periods": 50}})
    step = Controller.step

    def slow_step(self, *args):
        time.sleep(1.5 * PERIOD)
        return step(self, *args)

    monkeypatch.setattr(Controller, "step", slow_step)
    summary, robot, _ = run_with_robot(cfg, 15)
    assert summary["timing"]["compute"]["p50_ms"] > 1e3 * PERIOD, "every tick computed longer than a period"
    assert summary["timing"]["skipped"] == 0 and summary["final_state"] == "PUSH"
    assert State.STOPPED not in {c.state for c in robot.commands}

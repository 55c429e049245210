"""Real-time sim2sim notices a simulator that cannot keep the control rate (issue 33): the rate check on synthetic
clock reports, the events that feed it, and the report's ``timing`` (real time, lock-step fallback, stopped) with
the two simulator runs replaced by canned attempts, so no simulator runs here."""

import io
import json
import threading

import pytest

from dynpush.cli import main
from dynpush.runtime import sim2sim
from dynpush.runtime.config import RuntimeConfigError
from dynpush.runtime.sim2sim import EVENT_PREFIX, RateCheck, SimToSimOptions, describe_timing, run_sim2sim

WINDOW = 50  # control periods: 1 s at 50 Hz


def reports(rate: float, periods: int, every: int = 10, start: tuple[int, int] = (0, 0)) -> list[tuple[int, int]]:
    """Clock reports of a simulator stepping ``rate`` of the control periods, one every ``every`` periods."""
    d0, s0 = start
    return [(d0 + d, s0 + int(rate * d)) for d in range(0, periods + 1, every)]


def feed(check: RateCheck, samples: list[tuple[int, int]]) -> list[bool]:
    return [check.add(deadline, steps) for deadline, steps in samples]


def test_a_simulator_on_time_is_real_time():
    check = RateCheck(0.9, WINDOW, 50.0)
    assert not any(feed(check, reports(1.0, 500)))
    assert not check.finish() and check.windows == 10 and check.rate() == 1.0 and check.slowest == 1.0
    summary = check.summary()
    assert summary["fell_behind"] is False and summary["periods"] == 500 and summary["steps"] == 500
    assert summary["window_s"] == 1.0 and summary["slow_window_rate"] is None


def test_a_third_of_the_rate_is_caught_in_the_first_window():
    """The issue's run: 233 simulator steps against 651 runtime ticks."""
    check = RateCheck(0.9, WINDOW, 50.0)
    verdicts = feed(check, reports(233 / 651, 651))
    assert verdicts.index(True) == 5, "judged when the first 50-period window closes (report 5, deadline 50)"
    assert check.slow_rate == pytest.approx(0.34, abs=0.01)
    assert check.message("lockstep") == ("sim2sim: the simulator keeps 34 % of the 50 Hz control rate on this machine"
                                         " (real time needs 90 %); switching to lock-step (simulated time)")
    assert check.message("stop").startswith("sim2sim: the simulator keeps 34 % of the 50 Hz control rate")
    assert "stopping" in check.message("stop")


def test_the_threshold_and_the_window_are_the_configured_ones():
    just_below, just_above = reports(0.88, 100), reports(0.92, 100)
    assert feed(RateCheck(0.9, WINDOW, 50.0), just_below)[-1] and not feed(RateCheck(0.9, WINDOW, 50.0), just_above)[-1]
    assert not feed(RateCheck(0.85, WINDOW, 50.0), just_below)[-1], "min_rate 0.85 accepts 88 %"
    check = RateCheck(0.9, 100, 50.0)  # a 2 s window
    assert feed(check, reports(0.5, 100)) == [False] * 10 + [True] and check.windows == 1


def test_a_slowdown_later_in_the_run_is_caught():
    check = RateCheck(0.9, WINDOW, 50.0)
    fast = reports(1.0, 300)
    slow = reports(0.5, 200, start=fast[-1])[1:]
    verdicts = feed(check, fast + slow)
    assert not any(verdicts[: len(fast)]) and verdicts[-1]
    assert check.slow_rate == pytest.approx(0.5) and check.slowest == pytest.approx(0.5)
    assert check.rate() == pytest.approx(400 / 500)


def test_missed_deadlines_inside_a_window_are_averaged_not_judged_alone():
    """One overrun of three periods (two deadlines skipped) in a window of 50 keeps 96 %: still real time."""
    samples = [(0, 0), (10, 10), (22, 20), (32, 30), (42, 40), (52, 50), (62, 60)]
    check = RateCheck(0.9, WINDOW, 50.0)
    assert not any(feed(check, samples)) and check.slowest == pytest.approx(50 / 52)


def test_a_run_shorter_than_a_window_is_judged_at_its_end():
    """A simulator so slow that the runtime stopped at once: one step, then its next wait was 20 periods later."""
    check = RateCheck(0.9, WINDOW, 50.0)
    assert not any(feed(check, [(0, 0), (20, 1)])) and check.windows == 0
    assert check.finish() and check.slow_rate == pytest.approx(0.05)
    short = RateCheck(0.9, WINDOW, 50.0)
    feed(short, [(0, 0), (10, 10), (12, 12)])
    assert not short.finish() and short.windows == 1 and short.rate() == 1.0


def test_a_last_stretch_counts_only_from_half_a_window():
    tail_short = RateCheck(0.9, WINDOW, 50.0)
    feed(tail_short, reports(1.0, 50) + [(60, 55)])  # 10 periods, 5 steps: too short to judge on its own
    assert not tail_short.finish() and tail_short.windows == 1
    tail_long = RateCheck(0.9, WINDOW, 50.0)
    feed(tail_long, reports(1.0, 50) + [(80, 65)])  # 30 periods, 15 steps
    assert tail_long.finish() and tail_long.slow_rate == pytest.approx(0.5) and tail_long.windows == 2


def test_no_report_is_no_measurement():
    check = RateCheck(0.9, WINDOW, 50.0)
    assert not check.finish() and check.rate() is None and check.summary()["windows"] == 0


class FakeProcess:
    def __init__(self, events: list[dict]):
        self.stdout = io.StringIO("".join(EVENT_PREFIX + json.dumps(e) + "\n" for e in events) + "warp says hello\n")


def test_clock_events_feed_the_check_and_a_slow_simulator_stops_the_attempt():
    events = [{"event": "clock", "deadline": d, "steps": s} for d, s in reports(0.3, 60)]
    check, stop, episodes, done = RateCheck(0.9, WINDOW, 50.0), threading.Event(), [], []
    reader = threading.Thread(target=sim2sim._read_events, args=(FakeProcess(events), episodes, done, check, stop))
    reader.start()
    assert stop.wait(5.0)
    reader.join(5.0)
    assert check.fell_behind and check.slow_rate == pytest.approx(0.3) and not done


def test_the_done_event_brings_the_simulator_last_wait():
    events = [{"event": "clock", "deadline": 0, "steps": 0}, {"event": "episode", "index": 0},
              {"event": "done", "steps": 21, "clock": [20, 1]}]
    check, stop, episodes, done = RateCheck(0.9, WINDOW, 50.0), threading.Event(), [], []
    sim2sim._read_events(FakeProcess(events), episodes, done, check, stop)
    assert stop.is_set() and len(episodes) == 1 and done[0]["steps"] == 21
    assert check.finish() and check.slow_rate == pytest.approx(0.05)


# ---------------------------------------------------------------------- the report, with canned attempts


def canned_attempt(options: SimToSimOptions, rate: float | None) -> sim2sim._Attempt:
    """What ``_run_attempt`` returns: one completed episode; in real time, clock reports at ``rate``."""
    check = None
    if not options.lockstep:
        check = RateCheck(options.min_rate, round(options.rate_window_s / 0.02), 50.0)
        feed(check, reports(rate, 200))
        check.finish()
    episode = {"index": 0, "success": True, "toppled": False, "first_success_step": 40, "time_to_success_s": 0.8,
               "shape": "cuboid", "mass_kg": 2.0, "goal": [1.0, 0.0, 0.0]}
    return sim2sim._Attempt({"clock": "lockstep" if options.lockstep else "realtime"}, [episode],
                            [{"event": "done", "trajectory_png": None}], 0, check)


@pytest.fixture
def attempts(monkeypatch):
    """Replaces the simulator runs; ``attempts.rate`` is the real-time simulator's; ``attempts.runs`` the options."""

    class Attempts:
        rate = 1.0
        runs: list[SimToSimOptions] = []

    def run(options):
        Attempts.runs.append(options)
        return canned_attempt(options, Attempts.rate)

    Attempts.runs = []
    monkeypatch.setattr(sim2sim, "_run_attempt", run)
    return Attempts


def test_a_real_time_run_is_reported_as_real_time(attempts, capsys):
    attempts.rate = 0.98
    report = run_sim2sim(SimToSimOptions(policy="p.onnx"))
    assert report["timing"] == "realtime" and report["conditions"]["clock"] == "realtime" and report["completed"]
    assert report["realtime_check"]["rate"] == pytest.approx(0.98, abs=0.01) and len(attempts.runs) == 1
    assert describe_timing(report) == "timing: real time (the simulator kept 98 % of the 50 Hz control rate)"
    assert capsys.readouterr().err == ""


def test_a_slow_simulator_falls_back_to_lock_step(attempts, capsys):
    attempts.rate = 0.34
    report = run_sim2sim(SimToSimOptions(policy="p.onnx", episodes=1))
    assert [o.lockstep for o in attempts.runs] == [False, True], "the episodes ran again, in lock-step"
    assert report["timing"] == "lockstep_fallback" and report["conditions"]["clock"] == "lockstep"
    assert report["runtime"] == {"clock": "lockstep"} and report["realtime_attempt"]["runtime"] == {"clock": "realtime"}
    check = report["realtime_check"]
    assert check["fell_behind"] and check["slow_window_rate"] == pytest.approx(0.34) and report["completed"]
    err = capsys.readouterr().err.splitlines()
    assert err == [check["message"]] and err[0].startswith("sim2sim: the simulator keeps 34 % of the 50 Hz")
    assert describe_timing(report).startswith("timing: lock-step fallback, not real time: the simulator kept 34 %")


def test_a_slow_simulator_with_on_slow_stop_is_not_completed(attempts):
    attempts.rate = 0.5
    report = run_sim2sim(SimToSimOptions(policy="p.onnx", episodes=1, on_slow="stop"))
    assert len(attempts.runs) == 1 and report["timing"] == "stopped_slow" and not report["completed"]
    assert report["realtime_check"]["message"].endswith("stopping (--on-slow lockstep reruns in lock-step;"
                                                        " --lockstep runs in simulated time)")


def test_lock_step_asked_for_is_not_checked(attempts):
    report = run_sim2sim(SimToSimOptions(policy="p.onnx", episodes=1, lockstep=True))
    assert report["timing"] == "lockstep" and report["realtime_check"] is None
    assert describe_timing(report) == "timing: lock-step (simulated time, as asked)"


def test_sim2sim_command_stops_with_one_line_and_writes_the_report(attempts, capsys, tmp_path):
    attempts.rate = 0.34
    out = tmp_path / "report.json"
    assert main(["sim2sim", "p.onnx", "--episodes", "1", "--on-slow", "stop", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.err == ("dynpush: sim2sim: the simulator keeps 34 % of the 50 Hz control rate on this machine"
                            " (real time needs 90 %); stopping (--on-slow lockstep reruns in lock-step; --lockstep runs"
                            " in simulated time)\n")
    assert json.loads(out.read_text())["timing"] == "stopped_slow" == json.loads(captured.out)["timing"]


def test_demo_prints_and_records_the_fallback(attempts, capsys, tmp_path):
    attempts.rate = 0.34
    assert main(["demo", "--episodes", "1", "--out", str(tmp_path)]) == 0
    out, err = capsys.readouterr()
    assert "sim2sim: the simulator keeps 34 % of the 50 Hz control rate on this machine" in err
    lines = out.splitlines()
    assert lines[1] == "success 100 % of 1 episodes"
    assert lines[2] == ("timing: lock-step fallback, not real time: the simulator kept 34 % of the 50 Hz control rate"
                        " in a 1.0 s window (real time needs 90 %)")
    assert json.loads((tmp_path / "demo.json").read_text())["timing"] == "lockstep_fallback"


def test_demo_min_rate_is_the_threshold(attempts, capsys, tmp_path):
    attempts.rate = 0.34
    assert main(["demo", "--episodes", "1", "--out", str(tmp_path), "--min-rate", "0.3"]) == 0
    assert len(attempts.runs) == 1 and attempts.runs[0].min_rate == 0.3, "34 % passes --min-rate 0.3: no fallback"
    assert json.loads((tmp_path / "demo.json").read_text())["timing"] == "realtime"
    assert "timing: real time (the simulator kept 34 % of the 50 Hz control rate)" in capsys.readouterr().out


def test_options_refuse_a_bad_rate_check():
    with pytest.raises(RuntimeConfigError, match="on_slow must be one of lockstep, stop"):
        SimToSimOptions(policy="p.onnx", on_slow="ignore").validate()
    with pytest.raises(RuntimeConfigError, match=r"min_rate must lie in \(0, 1\]"):
        SimToSimOptions(policy="p.onnx", min_rate=0.0).validate()


# ---------------------------------------------------------------------- the simulator's side, on a simulated clock


class SteppedClock:
    """A clock that moves only when told: ``sleep_until`` jumps to the deadline, a simulator step adds its cost."""

    def __init__(self):
        self.t = 0.0  # [s]

    def now(self) -> float:
        return self.t

    def sleep_until(self, deadline: float) -> None:
        self.t = max(self.t, deadline)


def simulator_events(step_periods: float, periods: int) -> list[dict]:
    """The ``SIM2SIM`` events of a real-time simulator whose every step costs ``step_periods`` control periods, over
    about ``periods`` periods: its real ticker and clock reports, time simulated (no machine speed in the test)."""
    from dynpush.policies.sim2sim import ClockReporter
    from dynpush.runtime.timing import Ticker

    period = 0.02  # [s]
    clock, events = SteppedClock(), []
    ticker, reporter, steps = Ticker(clock, period), ClockReporter(events.append), 0
    while clock.t < periods * period:
        reporter.record(ticker.wait().index, steps)
        clock.t += step_periods * period  # the step itself
        steps += 1
    return events + [{"event": "done", "steps": steps, "clock": list(reporter.last)}]


@pytest.mark.parametrize("step_periods, slow", [(0.3, False), (0.95, False), (2.8, True)])
def test_a_slowed_simulator_reports_a_pace_the_check_catches(step_periods, slow):
    """2.8 periods a step is the issue's run (233 steps for 651 ticks, 36 %); a step within its period is on time."""
    events = simulator_events(step_periods, 300)
    check, stop, episodes, done = RateCheck(0.9, WINDOW, 50.0), threading.Event(), [], []
    sim2sim._read_events(FakeProcess(events), episodes, done, check, stop)
    assert stop.is_set() and check.fell_behind == slow and check.windows >= 1
    if slow:
        assert check.slow_rate == pytest.approx(1.0 / 2.8, abs=0.02)
        assert check.message("lockstep").startswith("sim2sim: the simulator keeps 36 % of the 50 Hz control rate")
    else:
        assert check.finish() is False and check.rate() == 1.0 and len(done) == 1

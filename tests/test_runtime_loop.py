"""The whole runtime loop against a fake lock-step robot on loopback UDP (goals, success stop, resume,
mocap loss, goal commands, robot state with or without leg joints, a tick that raises), the real-time loop
with the motioncapture package's mock system, and the proof that running the runtime never imports torch,
warp or newton."""

import json
import subprocess
import sys
import textwrap
import threading

import numpy as np

from dynpush.runtime.app import Runtime
from dynpush.runtime.config import config_from_dict
from dynpush.runtime.packets import MODE_STOP
from dynpush.runtime.safety import State
from dynpush.runtime.tick_log import read_log
from test_runtime_helpers import (
    FakeRobot, free_ports, lockstep_config, robot_state, run_with_robot, streaming_config, write_policy,
)

HEAVY = ("torch", "warp", "newton")


def states(robot: FakeRobot) -> list[str]:
    """The runtime states reported in the commands, without repeats."""
    names = [State(c.state).name for c in robot.commands]
    return [s for i, s in enumerate(names) if i == 0 or names[i - 1] != s]


def test_success_stop_then_next_goal_then_goal_command(tmp_path):
    cfg = lockstep_config(write_policy(tmp_path / "p.onnx"), tmp_path,
                          goals={"sequence": [{"x": 1.0, "y": 0.0}, {"x": 2.0, "y": 1.0, "yaw_deg": 90.0}],
                                 "advance_after_s": 0.2})

    def script(step, robot):
        if step == 20:
            robot.object = (np.array([1.02, -0.03, 0.35]), robot.object[1])  # onto the first goal
        if step == 60:
            robot.send_goal(-1.0, 0.5, 0.0)

    summary, robot, runtime = run_with_robot(cfg, 80, script)
    assert states(robot) == ["RAMP", "PUSH", "HOLD", "PUSH"]
    log = read_log(runtime.log.path)
    goals = log.column("goal")
    held = np.flatnonzero(log.column("state")[:, 0] == State.HOLD)
    assert held.size == 10 and goals[held[-1] + 1, 0] == 2.0, "0.2 s after success the next goal of the sequence"
    np.testing.assert_allclose(goals[-1], [-1.0, 0.5, 0.0], err_msg="a DPG1 command sets the goal")
    assert summary["goal_commands"] == {"malformed": 0, "foreign": 0, "replayed": 0, "accepted": 1, "refused": 0}
    hold_commands = [c for c in robot.commands if c.state == State.HOLD]
    assert all(np.array_equal(c.base_command, [0, 0, 0, 0, 0, 0.5]) for c in hold_commands)
    assert summary["timing"]["ticks"] == 80 and log.records == 80
    assert summary["robot_link"]["malformed"] == 0 and summary["mocap"]["malformed"] == 0


def test_mocap_loss_and_recovery_in_the_loop(tmp_path):
    cfg = lockstep_config(write_policy(tmp_path / "p.onnx"), tmp_path, goals={"sequence": [{"x": 1.0, "y": 0.0}]})

    def script(step, robot):
        robot.mocap_on = not 20 <= step < 40

    summary, robot, runtime = run_with_robot(cfg, 60, script)
    assert states(robot) == ["RAMP", "PUSH", "MOCAP_LOST", "PUSH"]
    ages = read_log(runtime.log.path).column("base_age_s")[:, 0]
    lost = [i for i, c in enumerate(robot.commands) if c.state == State.MOCAP_LOST]
    assert ages[lost[0]] > 0.1 and ages[lost[0] - 1] <= 0.1, "stale once the newest pose is older than the timeout"
    assert summary["states"]["MOCAP_LOST"] == len(lost)


def test_onboard_runtime_takes_robot_state_with_or_without_leg_joints(tmp_path):
    """DPS1 reports 12 leg joints or none; with the robot's own locomotion both are valid, and the log keeps the legs."""
    cfg = lockstep_config(write_policy(tmp_path / "p.onnx"), tmp_path, goals={"sequence": [{"x": 1.0, "y": 0.0}]})

    def script(step, robot):
        robot.state = robot_state(legs=12 if step % 2 else 0)
        robot.state.leg_q[:] = 0.3

    summary, robot, runtime = run_with_robot(cfg, 20, script)
    assert summary["robot_link"]["malformed"] == 0 and summary["robot_link"]["states"] >= 19
    assert "PUSH" in summary["states"] and summary["final_state"] == "PUSH"
    legs = read_log(runtime.log.path).column("robot_state")[:, 23:35]  # after base (13) and arm (2 x 5)
    assert (legs == 0.3).all(axis=1).any() and np.isnan(legs).all(axis=1).any(), "reported legs logged, others NaN"


def test_a_tick_that_raises_stops_the_robot_and_the_summary_still_comes(tmp_path):
    """A bug in a tick: ``dynpush run`` sends a stop command, prints the summary naming the error, exits with 1."""
    mocap_port, state_port = free_ports(2)
    config = tmp_path / "runtime.yaml"
    config.write_text(json.dumps({"push_policy": {"path": str(write_policy(tmp_path / "p.onnx"))},
                                  "mocap": {"port": mocap_port}, "robot": {"port": state_port, "robot_address": ""},
                                  "goals": {"command_port": None, "sequence": [{"x": 1.0}]},
                                  "log": {"directory": str(tmp_path / "logs")}}))
    code = textwrap.dedent(f"""
        import sys
        from dynpush.cli import main
        from dynpush.runtime.controller import Controller
        def broken(self, *args):
            raise ValueError("a bug")
        Controller.step = broken
        sys.exit(main(["run", {str(config)!r}, "--max-seconds", "5"]))
    """)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 1, result.stderr
    summary = json.loads(result.stdout)
    assert summary["final_state"] == "STOPPED" and summary["final_reason"] == "tick failed: ValueError: a bug"
    assert "Traceback" in result.stderr and "tick 0 failed" in result.stderr, "the bug keeps its traceback"


def test_a_tick_that_raises_sends_the_robot_a_stop_command(tmp_path):
    cfg = lockstep_config(write_policy(tmp_path / "p.onnx"), tmp_path, goals={"sequence": [{"x": 1.0, "y": 0.0}]})
    runtime = Runtime(cfg)
    step = runtime.controller.step

    def failing_step(*args):
        if runtime.ticks == 10:
            raise ValueError("a bug")
        return step(*args)

    runtime.controller.step = failing_step
    robot = FakeRobot(runtime)
    robot.start()
    try:
        summary = runtime.run(max_ticks=30)
    finally:
        robot.close()
    assert isinstance(runtime.error, ValueError) and summary["timing"]["ticks"] == 10
    assert robot.commands[-1].mode == MODE_STOP and robot.commands[-1].state == State.STOPPED
    assert np.isfinite(robot.commands[-1].arm_targets).all() and summary["final_state"] == "STOPPED"


def test_realtime_loop_with_motioncapture_mock(tmp_path):
    """The motioncapture package's mock system (poses every 10 ms, wxyz in its option string)."""
    cfg = config_from_dict({
        "push_policy": {"path": str(write_policy(tmp_path / "p.onnx"))},
        "mocap": {"source": "mock", "options": {"rigid_bodies": "base(-1,0,0.5,1,0,0,0);object(0,0,0.35,1,0,0,0)"}},
        "robot": {"port": 0}, "goals": {"command_port": 0, "sequence": [{"x": 1.0, "y": 0.0}]},
        "log": {"directory": str(tmp_path)},
    })
    stop = threading.Event()
    runtime = Runtime(cfg, stop)
    threading.Timer(0.5, stop.set).start()
    summary = runtime.run()
    assert summary["mocap"]["frames"] > 20 and summary["final_state"] == "STARTUP", "no robot: it waits"
    log = read_log(runtime.log.path)
    np.testing.assert_allclose(log.column("base_position")[-1], [-1.0, 0.0, 0.5])
    ages = log.column("base_age_s")[:, 0]
    assert ages[np.isfinite(ages)].max() < 0.05, "mock frames arrive every 10 ms"
    assert summary["timing"]["ticks"] >= 20


def run_in_fresh_process(tmp_path, run_code: str) -> dict:
    """Runs ``run_code`` (which sets ``summary``) beside a streaming robot in a new interpreter; its states and
    the heavy modules it imported."""
    config, robot_code = streaming_config(tmp_path / "runtime.yaml", write_policy(tmp_path / "p.onnx"), tmp_path / "logs")
    code = robot_code + textwrap.dedent(f"""
        import contextlib, io, json, sys
        import dynpush.runtime.replay, dynpush.runtime.sim2sim
        config = {str(config)!r}
    """) + textwrap.dedent(run_code) + textwrap.dedent(f"""
        heavy = sorted(m for m in sys.modules if m.split(".")[0] in {HEAVY!r})
        print(json.dumps({{"states": summary["states"], "heavy": heavy}}))
    """)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.strip().splitlines()[-1])


def test_running_the_runtime_never_imports_torch_warp_or_newton(tmp_path):
    report = run_in_fresh_process(tmp_path, """
        import threading
        from dynpush.runtime.app import Runtime
        from dynpush.runtime.config import load_config
        stop = threading.Event()
        threading.Timer(0.6, stop.set).start()
        summary = Runtime(load_config(config), stop).run()
    """)
    assert report["states"].get("PUSH", 0) > 0, report
    assert report["heavy"] == [], f"the runtime imported {report['heavy']}"


def test_dynpush_run_never_imports_torch_warp_or_newton(tmp_path):
    report = run_in_fresh_process(tmp_path, """
        from dynpush.cli import main
        stdout = io.StringIO()
        with contextlib.redirect_stdout(stdout):
            assert main(["run", config, "--max-seconds", "0.6"]) == 0
        summary = json.loads(stdout.getvalue())
    """)
    assert report["states"].get("PUSH", 0) > 0, report
    assert report["heavy"] == [], f"`dynpush run` imported {report['heavy']}"

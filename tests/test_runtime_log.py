"""The tick log survives a killed process (write, SIGKILL, read back), drops a torn last record, and feeds
``dynpush replay`` (zero deviation for the logged policy, the largest deviation for another) and the
replay mocap source; runs started in the same second never overwrite each other's log, and an unwritable
log folder or a log without its config end in one line naming them."""

import contextlib
import io
import json
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from dynpush.cli import main
from dynpush.runtime import app as runtime_app
from dynpush.runtime.app import Runtime
from dynpush.runtime.config import MocapConfig
from dynpush.runtime.errors import StartupError
from dynpush.runtime.mocap import ReplayMocapSource
from dynpush.runtime.replay import replay
from dynpush.runtime.safety import State
from dynpush.runtime.tick_log import RecordLayout, TickLogError, TickLogWriter, read_log
from dynpush.runtime.udp import UdpEndpoint
from test_runtime_helpers import (
    FakeRobot, free_ports, lockstep_config, run_with_robot, streaming_config, write_policy,
)


def test_log_survives_sigkill(tmp_path):
    config, robot_code = streaming_config(tmp_path / "runtime.yaml", write_policy(tmp_path / "p.onnx"), tmp_path / "logs")
    code = robot_code + textwrap.dedent(f"""
        from dynpush.runtime.app import Runtime
        from dynpush.runtime.config import load_config
        runtime = Runtime(load_config({str(config)!r}))
        print("started", flush=True)
        runtime.run()
    """)
    process = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert process.stdout.readline().strip() == "started"
        time.sleep(1.6)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    assert process.returncode == -signal.SIGKILL
    (path,) = (tmp_path / "logs").glob("*.dplog")
    log = read_log(path)
    assert log.records >= 25, "at most one flush period (1 s) of the 1.6 s run may be lost"
    ticks = log.column("tick")[:, 0]
    assert ticks[0] == 0 and (np.diff(ticks) >= 1).all()
    assert (log.column("state")[:, 0] == State.PUSH).any(), "the killed run was pushing"
    assert log.meta["config"]["rates"]["control_hz"] == 50.0 and log.meta["states"]["PUSH"] == int(State.PUSH)


def test_torn_record_is_dropped_and_foreign_files_rejected(tmp_path):
    layout = RecordLayout([("time_s", 1), ("obs", 3)])
    writer = TickLogWriter(tmp_path / "a.dplog", layout, {"note": np.float32(1.5)}, flush_s=1.0)
    for k in range(5):
        record = layout.new_record()
        layout.view(record, "time_s")[0] = k
        layout.view(record, "obs")[:] = (k, 2 * k, 3 * k)
        writer.write(record)
    writer.close()
    with open(tmp_path / "a.dplog", "ab") as f:
        f.write(b"\x00" * 13)  # a record cut short by a crash
    log = read_log(tmp_path / "a.dplog")
    assert log.records == 5 and log.partial_bytes == 13 and log.meta == {"note": 1.5}
    np.testing.assert_array_equal(log.column("obs")[4], [4, 8, 12])
    (tmp_path / "b.dplog").write_bytes(b"PK\x03\x04 a zip file")
    with pytest.raises(TickLogError, match="not a dynpush tick log"):
        read_log(tmp_path / "b.dplog")
    with pytest.raises(ValueError, match="must have 4 values"):
        TickLogWriter(tmp_path / "c.dplog", layout, {}).write(np.zeros(3))


def test_tick_logs_started_in_the_same_second_never_overwrite_each_other(tmp_path, monkeypatch):
    layout = RecordLayout([("time_s", 1)])
    first = TickLogWriter.new_in(tmp_path, "runtime-same-second", layout, {"run": 1})
    second = TickLogWriter.new_in(tmp_path, "runtime-same-second", layout, {"run": 2})
    for writer in (first, second):
        writer.write(np.zeros(1))
        writer.close()
    assert (first.path.name, second.path.name) == ("runtime-same-second.dplog", "runtime-same-second-2.dplog")
    with pytest.raises(FileExistsError):
        TickLogWriter(first.path, layout, {"run": 3})  # never opened for writing again
    assert [read_log(w.path).meta["run"] for w in (first, second)] == [1, 2]

    monkeypatch.setattr(runtime_app.time, "strftime", lambda _: "same-second")  # two runs, one clock second
    cfg = lockstep_config(write_policy(tmp_path / "p.onnx"), tmp_path / "logs")
    paths = []
    for _ in range(2):
        runtime = Runtime(cfg)
        runtime.run(max_ticks=0)
        paths.append(runtime.log.path)
    assert paths[0] != paths[1] and all(read_log(path).meta["config"] for path in paths)


def test_unwritable_log_directory_stops_startup_naming_the_field(tmp_path):
    (tmp_path / "taken").write_text("a file where the log folder should be")
    ports = free_ports(3)
    cfg = lockstep_config(write_policy(tmp_path / "p.onnx"), tmp_path / "taken", mocap={"port": ports[0]},
                          robot={"port": ports[1]}, goals={"command_port": ports[2]})
    with pytest.raises(StartupError, match=f"log.directory {tmp_path / 'taken'}: cannot create a tick log there"):
        Runtime(cfg)
    for port in ports:  # the sockets opened before the failure were closed again
        UdpEndpoint("127.0.0.1", port).close()


@pytest.fixture(scope="module")
def pushing_log(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("replay")
    cfg = lockstep_config(write_policy(tmp_path / "p.onnx", bias=np.full(11, 0.3)), tmp_path,
                          goals={"sequence": [{"x": 1.0, "y": 0.5, "yaw_deg": 30.0}]})

    def script(step, robot: FakeRobot):
        robot.base = (np.array([-1.0 + 0.01 * step, 0.0, 0.5]), robot.base[1])
        robot.mocap_on = step % 7 != 3  # a few frames lost: replayed as lost

    _, _, runtime = run_with_robot(cfg, 60, script)
    return runtime.log.path, tmp_path


def test_replay_reproduces_the_logged_actions(pushing_log):
    path, tmp_path = pushing_log
    report = replay(path)
    assert report["records"] == 60 and report["push_policy"]["compared_ticks"] >= 50
    assert report["push_policy"]["max_abs_deviation"] == 0.0
    other = replay(path, write_policy(tmp_path / "other.onnx", seed=1))
    assert other["push_policy"]["max_abs_deviation"] > 1e-3 and other["push_policy"]["worst_tick"] is not None
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        assert main(["replay", str(path)]) == 0
    assert json.loads(stdout.getvalue())["push_policy"]["max_abs_deviation"] == 0.0
    assert main(["replay", str(tmp_path / "p.onnx")]) == 2, "not a log: message and exit status 2"


def test_replay_of_a_log_without_its_config_names_what_is_missing(tmp_path, capsys):
    layout = RecordLayout([("obs", 54), ("actions", 11)])
    TickLogWriter(tmp_path / "bare.dplog", layout, {"note": "written by another tool"}).close()
    assert main(["replay", str(tmp_path / "bare.dplog")]) == 2
    err = capsys.readouterr().err
    assert err == f"dynpush: {tmp_path / 'bare.dplog'}: the tick log's header lacks push_policy.path (not written by" \
                  " dynpush run or sim2sim)\n"
    assert main(["replay", str(tmp_path / "none.dplog")]) == 2
    assert capsys.readouterr().err == f"dynpush: tick log {tmp_path / 'none.dplog'} does not exist\n"


def test_replay_mocap_source_repeats_the_recorded_stream(pushing_log):
    path, _ = pushing_log
    log = read_log(path)
    source = ReplayMocapSource(MocapConfig(source="replay", replay_log=str(path)))
    times = log.column("time_s")[:, 0]
    for k in range(len(times)):
        source.poll(1000.0 + times[k] - times[0])
        np.testing.assert_allclose(source.base.pose.position, log.column("base_position")[k])
        np.testing.assert_allclose(1000.0 + times[k] - times[0] - source.base.receive_time, log.column("base_age_s")[k, 0],
                                   atol=1e-9, err_msg="ages as recorded")
    assert source.stats.frames < 2 * len(times), "lost frames are not invented"

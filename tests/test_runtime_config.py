"""Runtime config validation (errors name the field and the allowed values: network settings, non-finite, unbounded
or wrongly typed values) and start-up checks of the push policy (its contract's own numbers, the contract against the
config, ONNX input/output names and shapes) and of a locomotion ONNX."""

from pathlib import Path

import pytest
import yaml

from dynpush.runtime.app import Runtime
from dynpush.runtime.config import RuntimeConfig, RuntimeConfigError, config_from_dict, load_config
from dynpush.runtime.errors import StartupError
from dynpush.runtime.policy import load_push_policy
from dynpush.runtime.udp import UdpEndpoint
from test_runtime_helpers import contract, free_ports, write_gemm, write_policy

CONFIGS = sorted((Path(__file__).parents[1] / "configs").glob("runtime_*.yaml"))
LEGS = [f"{leg}_{joint}" for leg in ("LF", "RF", "LH", "RH") for joint in ("HAA", "HFE", "KFE")]


def minimal(**sections) -> dict:
    data = {"push_policy": {"path": "policy.onnx"}}
    for key, value in sections.items():
        data[key] = {**data.get(key, {}), **value}
    return data


def onnx_locomotion(**changes) -> dict:
    spec = {"path": "loco.onnx", "observation": [{"name": "base_command"}, {"name": "leg_joint_position", "scale": 1.0}],
            "joint_names": LEGS, "default_joint_positions": [0.0, 0.6, -1.2] * 4, "action_scale": 0.5}
    return {"mode": "onnx", "onnx": {**spec, **changes}}


@pytest.mark.parametrize("data, message", [
    (minimal(mocap={"source": "kinect"}), r"mocap.source must be one of \['udp', 'replay', 'vicon'"),
    (minimal(mocap={"frames": {"up_axis": "x"}}), r"mocap.frames.up_axis must be one of \['z', 'y'\], got 'x'"),
    (minimal(mocap={"frames": {"quaternion_order": "zyxw"}}), r"mocap.frames.quaternion_order must be one of \['xyzw', 'wxyz'\]"),
    (minimal(mocap={"frames": {"units": "cm"}}), r"mocap.frames.units must be one of \['m', 'mm'\]"),
    (minimal(mocap={"source": "vicon", "frames": {"quaternion_order": "wxyz"}}), "must be 'xyzw' for the motioncapture"),
    (minimal(mocap={"source": "replay"}), "mocap.replay_log must name a tick log"),
    (minimal(mocap={"timeout_s": 0}), "mocap.timeout_s must be a finite number > 0"),
    (minimal(mocap={"base_body": "box", "object_body": "box"}), "two different non-empty names"),
    (minimal(mocap={"base_offset": {"position": [0, 0]}}), r"mocap.base_offset.position must have 3 entries"),
    (minimal(mocap={"port": 70000}), r"mocap.port must be a UDP port in \[0, 65535\]"),
    (minimal(mocap={"colour": "red"}), r"unknown field mocap.colour \(allowed: \['source'"),
    (minimal(mocap={"timeout_s": "fast"}), "mocap.timeout_s must be of type float, got 'fast'"),
    (minimal(robot={"link": "ethercat"}), r"robot.link must be one of \['udp'\]"),
    (minimal(robot={"arm_joint_names": ["a", "b"]}), "robot.arm_joint_names must have 5 entries"),
    (minimal(push_policy={"path": ""}), "push_policy.path must name the push policy ONNX file"),
    (minimal(locomotion={"mode": "wheels"}), r"locomotion.mode must be one of \['onboard', 'onnx'\]"),
    (minimal(locomotion=onnx_locomotion(observation=[{"name": "joint_torque"}])),
     r"locomotion.onnx.observation\[0\].name must be one of \['base_linear_velocity_b'"),
    (minimal(locomotion=onnx_locomotion(joint_names=LEGS[:6])), "locomotion.onnx.joint_names must have 12 entries"),
    (minimal(locomotion=onnx_locomotion(), robot={"leg_joint_names": LEGS}), "safety.leg_joint_lower must have 12 entries"),
    (minimal(locomotion=onnx_locomotion(), robot={"leg_joint_names": LEGS[::-1]},
             safety={"leg_joint_lower": [-3.0] * 12, "leg_joint_upper": [3.0] * 12}),
     "robot.leg_joint_names .* must equal locomotion.onnx.joint_names"),
    (minimal(rates={"clock": "sundial"}), r"rates.clock must be one of \['realtime', 'lockstep'\]"),
    (minimal(rates={"log_flush_s": 5.0}), "rates.log_flush_s must be <= 1 s"),
    (minimal(rates={"overrun": {"max_skipped": 50}}),
     r"rates.overrun.max_skipped must be an integer in \[0, 49\] \(fewer than rates.overrun.window_periods\), got 50"),
    (minimal(rates={"overrun": {"max_skipped": -1}}), r"rates.overrun.max_skipped must be an integer in \[0, 49\]"),
    (minimal(rates={"overrun": {"window_periods": 0}}),
     r"rates.overrun.window_periods must be an integer in \[1, 500\], got 0"),
    (minimal(rates={"overrun": {"window_periods": 5.5}}), "rates.overrun.window_periods must be of type int, got 5.5"),
    (minimal(safety={"max_tilt_deg": 95}), r"safety.max_tilt_deg must lie in \(0, 90\)"),
    (minimal(safety={"arm_joint_lower": [0.0] * 5, "arm_joint_upper": [1.0, 1.0, -1.0, 1.0, 1.0]}),
     r"safety.arm_joint_lower\[2\] must be <= safety.arm_joint_upper\[2\]"),
    (minimal(safety={"base_command_lower": [0.0] * 6}), "must both be given or both be empty"),
    (minimal(goals={"command_port": None}), "otherwise the robot never gets a goal"),
    (minimal(goals={"advance_after_s": 1.0}), "goals.advance_after_s needs goals in goals.sequence"),
    (minimal(goals={"sequence": [{"x": 1.0, "z": 2.0}]}), r"unknown field goals.sequence\[0\].z"),
    ({"push_policy": {"path": "p.onnx"}, "extras": {}}, r"unknown field extras \(allowed: \['mocap'"),
])
def test_invalid_configs_name_field_and_allowed_values(data, message):
    with pytest.raises(RuntimeConfigError, match=message):
        config_from_dict(data)


@pytest.mark.parametrize("data, message", [
    (minimal(robot={"bind_address": "0.0.0.0"}), r"robot.bind_address must name one interface's address .* not '0.0.0.0'"),
    (minimal(goals={"bind_address": "0.0.0.0"}), "goals.bind_address must name one interface's address"),
    (minimal(mocap={"bind_address": "robot.local"}), "mocap.bind_address must be an IPv4 address"),
    (minimal(mocap={"allowed_senders": []}), "mocap.allowed_senders must list at least one sender address"),
    (minimal(robot={"allowed_senders": ["127.0.0.1", "10.0.0.300"]}), r"robot.allowed_senders\[1\] must be an IPv4"),
    (minimal(robot={"robot_address": "the-robot"}), "robot.robot_address must be an IPv4 address"),
    (minimal(goals={"workspace": {"x_min": 2.0, "x_max": -2.0}}), "goals.workspace.x_min and goals.workspace.x_max must"),
    (minimal(goals={"sequence": [{"x": 1e6, "y": -1e6}]}), r"goals.sequence\[0\]: x 1000000.0 m outside the workspace"),
    (minimal(goals={"sequence": [{"x": float("nan")}]}), r"goals.sequence\[0\]: x nan not finite"),
])
def test_network_settings_and_goals_are_checked(data, message):
    """Sockets bind to one named address and take datagrams from listed senders; goals lie in the workspace."""
    with pytest.raises(RuntimeConfigError, match=message):
        config_from_dict(data)


@pytest.mark.parametrize("data, message", [
    (minimal(mocap={"base_offset": {"position": [float("nan"), 0.0, 0.0]}}),
     r"mocap.base_offset.position\[0\] must be finite, got nan"),
    (minimal(mocap={"object_offset": {"quat_xyzw": [0.0, 0.0, float("inf"), 1.0]}}),
     r"mocap.object_offset.quat_xyzw\[2\] must be finite"),
    (minimal(mocap={"timeout_s": 1e9}), "mocap.timeout_s must be <= 1.0, got 1000000000.0"),
    (minimal(robot={"timeout_s": 1e9}), "robot.timeout_s must be <= 1.0"),
    (minimal(safety={"arm_ramp_s": 1e9}), "safety.arm_ramp_s must be <= 60.0"),
    (minimal(goals={"sequence": [{"x": 1.0}], "advance_after_s": 1e9}), r"goals.advance_after_s must be null or a number"),
    (minimal(locomotion=onnx_locomotion(default_joint_positions=[float("nan")] * 12)),
     r"locomotion.onnx.default_joint_positions\[0\] must be finite"),
    (minimal(mocap={"options": {"rigid_bodies": ["base", "object"]}}), "mocap.options.rigid_bodies must be of type str"),
    (minimal(robot={"arm_joint_names": ["SH_ROT", "SH_FLE", 3, "FA_ROT", "WRIST_1"]}),
     r"robot.arm_joint_names\[2\] must be of type str, got 3"),
])
def test_non_finite_unbounded_or_wrongly_typed_values_name_their_field(data, message):
    with pytest.raises(RuntimeConfigError, match=message):
        config_from_dict(data)


def test_defaults_and_yaml_loading(tmp_path):
    cfg = config_from_dict(minimal())
    assert cfg.mocap.bind_address == "127.0.0.1" and cfg.rates.control_hz == 50.0 and cfg.rates.clock == "realtime"
    assert cfg.locomotion.mode == "onboard" and cfg.goals.command_port == 9873
    path = tmp_path / "sub" / "runtime.yaml"
    path.parent.mkdir()
    path.write_text(yaml.safe_dump(minimal(locomotion=onnx_locomotion(), robot={"leg_joint_names": LEGS},
                                           safety={"leg_joint_lower": [-3.0] * 12, "leg_joint_upper": [3.0] * 12})))
    cfg = load_config(path)
    assert cfg.push_policy.path == str(path.parent / "policy.onnx"), "input paths are relative to the config file"
    assert cfg.locomotion.onnx.observation_size == 6 + 12
    path.write_text("push_policy: {path: p.onnx}\nmocap: {timeout_s: 5e-2}\n")
    assert load_config(path).mocap.timeout_s == 0.05, "YAML reads 5e-2 as a string; it is taken as a number"
    path.write_text("mocap: [1, 2")
    with pytest.raises(RuntimeConfigError, match="cannot read runtime config"):
        load_config(path)


@pytest.mark.parametrize("path", CONFIGS, ids=[p.name for p in CONFIGS])
def test_example_configs_are_valid(path):
    assert isinstance(load_config(path), RuntimeConfig)


def test_example_configs_exist():
    assert {p.name for p in CONFIGS} >= {"runtime_vicon_onboard.yaml", "runtime_optitrack_onnx.yaml", "runtime_sim2sim.yaml"}


# ---------------------------------------------------------------------------------------------- start-up checks
@pytest.mark.parametrize("changes, message", [
    ({"arm_joint_names": ["SH_FLE", "SH_ROT", "EL_FLE", "FA_ROT", "WRIST_1"]}, "arm_joint_names .* differ from robot.arm_joint_names"),
    ({"control_period_s": 0.01}, "control_period_s 0.01 s differs from rates.control_hz 50.0"),
    ({"action_layout": [["base_command", 5], ["arm_joint_position", 6]]}, "action_layout .* differs"),
    ({"base_command_names": ["vx", "vy", "yaw_rate", "pitch", "roll", "height"]}, "base_command_names"),
])
def test_contract_mismatch_stops_startup(tmp_path, changes, message):
    cfg = config_from_dict(minimal(push_policy={"path": str(write_policy(tmp_path / "p.onnx", contract(**changes)))},
                                   log={"directory": str(tmp_path / "logs")}))
    with pytest.raises(StartupError, match=message):
        load_push_policy(cfg)
    with pytest.raises(StartupError, match=message):
        Runtime(cfg)
    assert not (tmp_path / "logs").exists(), "start-up checks come before any socket or log is opened"


@pytest.mark.parametrize("changes, message", [
    ({"base_command_default": [0.0, 0.0, 0.0, 0.0, 0.0, float("nan")]}, r"base_command_default\[5\] must be a finite"
     " number, got nan"),
    ({"base_command_scale": [1.0, float("inf"), 1.0, 0.2, 0.2, 0.1]}, r"base_command_scale\[1\] must be a finite number > 0"),
    ({"base_command_lower": [2.0, -0.6, -1.0, -0.2, -0.2, 0.4]}, r"base_command_lower\[0\] 2.0 must be <= base_command_upper"),
    ({"arm_default_joint_positions": [0.0, 1.0, 2.1, 0.0, 0.6]}, r"arm_default_joint_positions\[1\] 1.0 must lie within"
     r" arm_joint_lower/_upper \[-2.5, 0.5\]"),
    ({"action_clip": float("nan")}, "action_clip must be a finite number > 0, got nan"),
    ({"arm_joint_upper": [3.0, 0.5, "far", 3.0, 2.0]}, r"arm_joint_upper\[2\] must be a finite number, got 'far'"),
    ({"base_command_lower": 5}, "base_command_lower must have 6 entries, got 5"),
])
def test_nan_or_inverted_contract_numbers_stop_startup(tmp_path, changes, message):
    """The policy's own numbers are checked before anything opens: one line naming the file and the field."""
    path = write_policy(tmp_path / "p.onnx", contract(**changes))
    cfg = config_from_dict(minimal(push_policy={"path": str(path)}, log={"directory": str(tmp_path / "logs")}))
    with pytest.raises(StartupError, match=message) as error:
        Runtime(cfg)
    assert str(error.value).startswith(f"push_policy {path}: ") and "\n" not in str(error.value)
    assert not (tmp_path / "logs").exists()


def test_config_limits_must_lie_within_the_contract(tmp_path):
    policy = write_policy(tmp_path / "p.onnx")
    cfg = config_from_dict(minimal(push_policy={"path": str(policy)},
                                   safety={"base_command_lower": [-2.0, -0.6, -1.0, -0.2, -0.2, 0.4],
                                           "base_command_upper": [1.0, 0.6, 1.0, 0.2, 0.2, 0.6]}))
    with pytest.raises(StartupError, match="safety.base_command_lower/_upper .* must lie within the policy's"):
        load_push_policy(cfg)


@pytest.mark.parametrize("kwargs, message", [
    ({"input_name": "observation"}, r"the ONNX input must be named 'obs', found \['observation'\]"),
    ({"output_name": "mu"}, "the ONNX output must be named 'actions'"),
    ({"input_shape": [1, 53]}, r"ONNX input 'obs' must be float32 \[1, 54\], got tensor\(float\) \[1, 53\]"),
])
def test_onnx_names_and_shapes_checked(tmp_path, kwargs, message):
    if "input_shape" in kwargs:
        path = write_gemm(tmp_path / "p.onnx", 53, 11, metadata=contract().to_metadata(), **kwargs)
    else:
        path = write_policy(tmp_path / "p.onnx", **kwargs)
    with pytest.raises(StartupError, match=message):
        load_push_policy(config_from_dict(minimal(push_policy={"path": str(path)})))


def test_symbolic_batch_dimension_is_accepted(tmp_path):
    path = write_policy(tmp_path / "p.onnx", input_shape=["batch", 54])
    model, _ = load_push_policy(config_from_dict(minimal(push_policy={"path": str(path)})))
    assert model.run().shape == (11,)


def test_missing_or_broken_contract_and_files(tmp_path):
    bare = write_gemm(tmp_path / "bare.onnx", 54, 11)
    with pytest.raises(StartupError, match="policy metadata lacks 'observation_layout'"):
        load_push_policy(config_from_dict(minimal(push_policy={"path": str(bare)})))
    with pytest.raises(StartupError, match="does not exist"):
        load_push_policy(config_from_dict(minimal(push_policy={"path": str(tmp_path / "none.onnx")})))
    (tmp_path / "junk.onnx").write_bytes(b"not a model")
    with pytest.raises(StartupError, match="cannot load"):
        load_push_policy(config_from_dict(minimal(push_policy={"path": str(tmp_path / "junk.onnx")})))


def test_locomotion_onnx_checked_at_startup(tmp_path):
    policy = write_policy(tmp_path / "p.onnx")
    write_gemm(tmp_path / "loco.onnx", 17, 12)  # the config's observation has 6 + 12 = 18 entries
    data = minimal(push_policy={"path": str(policy)}, robot={"leg_joint_names": LEGS, "port": 0},
                   locomotion=onnx_locomotion(path=str(tmp_path / "loco.onnx")), mocap={"port": 0},
                   goals={"command_port": 0}, log={"directory": str(tmp_path)},
                   safety={"leg_joint_lower": [-3.0] * 12, "leg_joint_upper": [3.0] * 12})
    with pytest.raises(StartupError, match=r"locomotion.onnx: ONNX input 'obs' must be float32 \[1, 18\]"):
        Runtime(config_from_dict(data))


def test_busy_port_stops_startup_and_closes_what_was_opened(tmp_path):
    busy = UdpEndpoint("127.0.0.1", 0)
    (robot_port,) = free_ports(1)
    data = minimal(push_policy={"path": str(write_policy(tmp_path / "p.onnx"))}, robot={"port": robot_port},
                   mocap={"port": busy.port}, goals={"command_port": 0}, log={"directory": str(tmp_path / "logs")})
    with pytest.raises(StartupError, match=f"cannot listen on UDP 127.0.0.1:{busy.port}"):
        Runtime(config_from_dict(data))
    UdpEndpoint("127.0.0.1", robot_port).close()  # the robot link opened before the failure was closed again
    busy.close()

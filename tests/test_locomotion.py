"""Locomotion task end to end: a tiny CaT-PPO run -> locomotion.onnx (parity, contract) -> the runtime's
locomotion (its numpy observation equals the Warp kernel's) -> the legged push environment (the network in the
loop, simulated leg torques as constraints) -> sim2sim with the runtime running the locomotion ONNX."""

import dataclasses
import json

import numpy as np
import pytest
import torch

from dynpush.assets_usd import LEG_JOINT_NAMES
from dynpush.cli import main
from dynpush.kernels.locomotion import (
    constraints as loco_constraints,
    observations as loco_observations,
    views as loco_views,
)
from dynpush.policies.actor import load_actor
from dynpush.policies.locomotion_export import export_locomotion
from dynpush.policies.locomotion_train import LocomotionTrainConfig
from dynpush.policies.tasks import load_run_config
from dynpush.policies.overrides import apply_overrides
from dynpush.runtime.errors import StartupError
from dynpush.runtime.locomotion import OnnxLocomotion
from dynpush.runtime.locomotion_contract import LocomotionContract
from dynpush.runtime.frames import tilt_angle
from dynpush.runtime.observation import quat_to_matrix
from dynpush.runtime.packets import Proprioception
from dynpush.runtime.tick_log import read_log
from dynpush.sim.config import ConfigError, LeggedModeConfig, MuJoCoConfig, PushEnvConfig
from dynpush.sim.legged_push_env import LEG_TORQUE_COLUMN
from dynpush.sim.locomotion_config import LocomotionEnvConfig, LocomotionNoiseConfig
from dynpush.sim.locomotion_env import LocomotionEnv
from dynpush.sim.envs import make_push_env
from test_export import observations, torch_actions
from test_runtime_helpers import write_policy


@pytest.fixture(scope="module")
def robot_contract():
    """The push policy contract ``dynpush export`` writes for the robot (arm defaults of robot.usda)."""
    from dynpush.policies.export import build_contract
    from dynpush.policies.train import TrainConfig

    return build_contract(TrainConfig.preset_config("cpu"))


@pytest.fixture(scope="module")
def locomotion_run(tmp_path_factory):
    """Two CaT-PPO iterations on 16 legged worlds with small networks (``dynpush train --task locomotion``), exported
    to locomotion.onnx."""
    runs = tmp_path_factory.mktemp("locomotion")
    assert main(["train", "--task", "locomotion", "--runs", str(runs), "--name", "run", "--set", "env.num_envs=16",
                 "iterations=2", "num_steps_per_env=8", "save_interval=1", "disturbance_ramp=(0, 2)",
                 "network.actor_hidden=(32, 16)", "network.critic_hidden=(32, 16)"]) == 0
    return runs / "run", export_locomotion(runs / "run")


def test_locomotion_onnx_equals_the_actor_and_carries_its_contract(locomotion_run, robot_contract):
    run, path = locomotion_run
    cfg = load_run_config(run)
    assert isinstance(cfg, LocomotionTrainConfig) and (run / "model_1.pt").exists()
    actor = load_actor(run / "model_1.pt", cfg, loco_observations.NUM_POLICY_OBS, loco_views.NUM_LEG_JOINTS)
    assert int(actor.obs_normalizer.count) > 0
    obs = observations(actor, 16, seed=2)
    contract_ = LocomotionContract.read(str(path))
    section = contract_.section(str(path))
    runtime = OnnxLocomotion(section, robot_contract)
    for o, expected in zip(obs, torch_actions(actor, obs)):
        runtime.model.input[0] = o
        assert np.abs(runtime.model.run() - expected).max() < 1e-5
    assert [t.name for t in section.observation] == [name for name, _ in loco_observations.POLICY_TERMS]
    assert section.joint_names == list(LEG_JOINT_NAMES) and section.action_scale == cfg.env.action_scale
    assert contract_.values["command_lower"] == list(cfg.env.commands.lower) and len(contract_.joint_lower) == 12


def test_runtime_refuses_a_config_that_disagrees_with_the_contract(locomotion_run, robot_contract):
    _, path = locomotion_run
    section = LocomotionContract.read(str(path)).section(str(path))
    swapped = dataclasses.replace(section, joint_names=[section.joint_names[1], section.joint_names[0], *section.joint_names[2:]])
    with pytest.raises(StartupError, match=r"locomotion.onnx.joint_names"):
        OnnxLocomotion(swapped, robot_contract)
    with pytest.raises(StartupError, match=r"locomotion.onnx.action_scale: config has 0.25"):
        OnnxLocomotion(dataclasses.replace(section, action_scale=0.25), robot_contract)


def test_runtime_observation_equals_the_warp_kernel(locomotion_run, robot_contract):
    """The runtime builds the locomotion observation from measured quantities; on the same states it must equal
    the environment's (noise off), term by term."""
    _, path = locomotion_run
    env = LocomotionEnv(LocomotionEnvConfig(num_envs=4, seed=3, noise=LocomotionNoiseConfig(enabled=False)))
    torch.manual_seed(1)
    for _ in range(30):
        env.step(0.5 * torch.randn(4, 12))
    runtime = OnnxLocomotion(LocomotionContract.read(str(path)).section(str(path)), robot_contract)
    scene = env.scene
    body_q, body_qd = env.state_0.body_q.numpy(), env.state_0.body_qd.numpy()
    joint_q, joint_qd = env.state_0.joint_q.numpy(), env.state_0.joint_qd.numpy()
    for w in range(4):
        quat = body_q[scene.base_body[w], 3:].astype(np.float64)
        R = quat_to_matrix(quat)
        twist = body_qd[scene.base_body[w]].astype(np.float64)
        state = Proprioception(seq=0, stamp_s=0.0, base_quat_xyzw=quat, base_linear_velocity_b=R.T @ twist[:3],
                               base_angular_velocity_b=R.T @ twist[3:], ee_position_b=np.zeros(3),
                               arm_q=joint_q[scene.arm_q[w, :5]].astype(np.float64),
                               arm_qd=joint_qd[scene.arm_qd[w, :5]].astype(np.float64),
                               leg_q=joint_q[scene.leg_q[w]].astype(np.float64), leg_qd=joint_qd[scene.leg_qd[w]].astype(np.float64))
        runtime.last_actions = env.task.actions.numpy()[w].astype(np.float64)
        runtime.step(state, env.task.command.numpy()[w].astype(np.float64))
        start = 0
        for name, size in loco_observations.POLICY_TERMS:
            np.testing.assert_allclose(runtime.model.input[0, start:start + size], env.policy_obs_t[w, start:start + size].numpy(),
                                       rtol=1e-5, atol=1e-5, err_msg=f"world {w}: {name}")
            start += size


def test_the_runner_ramps_the_disturbances(locomotion_run):
    progress = [json.loads(line) for line in (locomotion_run[0] / "progress.jsonl").read_text().splitlines()]
    assert [row["/curriculum/disturbance_scale"] for row in progress] == [0.0, 0.5]


def test_locomotion_env_state_round_trip():
    """state_dict / load_state_dict continue the simulation exactly (resumed training)."""
    env = LocomotionEnv(LocomotionEnvConfig(num_envs=4, seed=5))
    torch.manual_seed(0)
    actions = [torch.randn(4, 12) for _ in range(10)]
    for a in actions[:5]:
        env.step(a)
    saved = env.state_dict()
    first = [env.step(a)[0]["critic"].clone() for a in actions[5:]]
    env.load_state_dict(saved)
    again = [env.step(a)[0]["critic"].clone() for a in actions[5:]]
    for a, b in zip(first, again):
        torch.testing.assert_close(a, b)
    assert env.constraints_t.shape == (4, loco_constraints.NUM_CONSTRAINTS)
    with pytest.raises(ValueError, match="same num_envs"):
        env.load_state_dict({**saved, "task.command": np.zeros((5, 6), np.float32)})
    with pytest.raises(ConfigError, match=r"disturbance scale must lie in \[0, 1\], got 1.5"):
        env.set_disturbance_scale(1.5)


def test_legged_push_env_runs_the_locomotion_policy_and_constrains_simulated_leg_torques(locomotion_run):
    _, path = locomotion_run
    env = make_push_env(PushEnvConfig(num_envs=2, seed=1, legged=LeggedModeConfig(enabled=True, locomotion_policy=str(path))))
    session = type(env.locomotion)(str(path))
    actions = torch.zeros(2, 11)
    actions[:, 0] = 0.5
    for _ in range(6):
        env.step(actions)
    # leg_obs: the locomotion observation the step's network ran on (taken after the push actions, before physics)
    expected = np.clip(session(env.leg_obs.numpy()), -env.cfg.actions.clip, env.cfg.actions.clip)
    np.testing.assert_allclose(env.leg_task.actions.numpy(), expected, rtol=1e-5, atol=1e-5,
                               err_msg="the leg actions are the locomotion network's on the observation of the step")
    np.testing.assert_allclose(env.leg_obs.numpy()[:, 9:15], env.task.base_command.numpy(), atol=0,
                               err_msg="the locomotion command is the push policy's base command")
    # The leg-torque columns hold the simulated PD torques: k_p (q* - q) - k_d qd, clipped, minus the nominal.
    legs = env.scene.robot.legged
    q, qd = env.state_0.joint_q.numpy()[env.scene.leg_q], env.state_0.joint_qd.numpy()[env.scene.leg_qd]
    tau = np.clip(legs.leg_stiffness * (env.leg_task.leg_target.numpy() - q) - legs.leg_damping * qd,
                  -legs.leg_effort_limit, legs.leg_effort_limit)
    np.testing.assert_allclose(env.constraints_t[:, LEG_TORQUE_COLUMN:LEG_TORQUE_COLUMN + 12].numpy(),
                               np.abs(tau) - np.tile(env.cfg.constraints.leg_nominal_torque, 4), rtol=1e-4, atol=1e-3)
    with pytest.raises(RuntimeError, match="runs its own locomotion policy"):
        env.set_leg_targets(np.zeros((2, 12)))
    # MuJoCo solves every contact Newton generated (a clipped buffer dropped the object's ground contacts)
    assert int(env.solver.mjw_data.nacon.numpy()[0]) == int(env.contacts.rigid_contact_count.numpy()[0]) > 8
    with pytest.raises(ConfigError, match=r"legged.mujoco.nconmax \(24\) must be >= sim.contacts_per_world \(48\)"):
        PushEnvConfig(legged=LeggedModeConfig(enabled=True, mujoco=MuJoCoConfig(nconmax=24, njmax=96))).validate()
    with pytest.raises(ConfigError, match=r"legged.mujoco.njmax \(64\) must be >= 4 x legged.mujoco.nconmax"):
        PushEnvConfig(legged=LeggedModeConfig(enabled=True, mujoco=MuJoCoConfig(nconmax=48, njmax=64))).validate()
    PushEnvConfig(legged=LeggedModeConfig(mujoco=MuJoCoConfig(nconmax=24, njmax=64))).validate()  # unused when disabled


def test_legged_push_training_env_state_round_trip(locomotion_run):
    """Training in legged mode builds the legged environment, and its state_dict continues it exactly (resume)."""
    from dynpush.policies.train import TrainConfig
    from dynpush.sim.legged_push_env import LeggedPushEnv

    _, path = locomotion_run
    cfg = TrainConfig.preset_config("cpu")
    cfg.env = PushEnvConfig(num_envs=2, seed=3, legged=LeggedModeConfig(enabled=True, locomotion_policy=str(path)))
    env = cfg.make_env(cfg.env)
    assert isinstance(env, LeggedPushEnv)
    torch.manual_seed(0)
    actions = [torch.randn(2, 11) for _ in range(8)]
    for a in actions[:4]:
        env.step(a)
    saved = env.state_dict()
    assert {"leg_task.foot_air_time", "leg_actions", "mujoco.qacc_warmstart"} <= set(saved)
    first = [env.step(a)[0]["critic"].clone() for a in actions[4:]]
    legs_first = env.leg_obs.numpy().copy()
    env.load_state_dict(saved)
    again = [env.step(a)[0]["critic"].clone() for a in actions[4:]]
    for a, b in zip(first, again):
        torch.testing.assert_close(a, b)
    np.testing.assert_array_equal(env.leg_obs.numpy(), legs_first)
    cfg.env = PushEnvConfig(legged=LeggedModeConfig(enabled=True))
    with pytest.raises(ConfigError, match="env.legged.locomotion_policy must name a locomotion.onnx to train in legged mode"):
        cfg.validate()


def test_sim2sim_with_the_runtime_running_the_locomotion_onnx(locomotion_run, robot_contract, tmp_path, capsys):
    """``dynpush sim2sim --locomotion onnx``: the runtime runs both networks and sends 17 joint targets; the legged
    simulator applies the leg targets and reports its leg joints, which the next locomotion observation uses."""
    _, path = locomotion_run
    push = write_policy(tmp_path / "push.onnx", robot_contract)
    config = tmp_path / "runtime.yaml"
    config.write_text(json.dumps({"safety": {"arm_ramp_s": 0.2, "max_tilt_deg": 80.0}}))
    out = tmp_path / "report.json"
    main(["sim2sim", str(push), "--episodes", "1", "--lockstep", "--config", str(config), "--locomotion", "onnx",
          "--locomotion-policy", str(path), "--set", "env.episode_length_s=0.5", "--log-dir", str(tmp_path / "logs"),
          "--out", str(out)])
    report = json.loads(out.read_text())
    assert report["simulator_exit_code"] == 0 and report["conditions"]["locomotion"] == str(path)
    assert main(["sim2sim", str(push), "--locomotion-policy", str(path)]) == 2  # the tracked base would ignore it
    assert f"--locomotion-policy {path} needs --locomotion onnx" in capsys.readouterr().err
    log = read_log(report["runtime"]["log"])
    obs, targets = log.column("locomotion_obs"), log.column("leg_targets")
    assert len(obs) >= 20 and np.isfinite(obs).all() and np.isfinite(targets).all()
    leg_q = obs[:, 15:27]  # leg_joint_position: q - default, as the simulator reported q
    assert np.abs(leg_q).max() > 1e-3 and np.ptp(leg_q, axis=0).max() > 1e-3, "the simulator's leg joints reach the runtime"
    contract = LocomotionContract.read(str(path))
    # the logged raw outputs, clipped at the push policy's action_clip as the legged simulator clips them
    clipped = np.clip(log.column("locomotion_actions"), -robot_contract.action_clip, robot_contract.action_clip)
    expected = np.asarray(contract.default_joint_positions) + contract.action_scale * clipped
    np.testing.assert_allclose(targets, expected, atol=1e-5)


def test_eval_of_a_locomotion_onnx_writes_tracking_errors_under_the_requested_disturbances(locomotion_run, tmp_path, capsys):
    _, path = locomotion_run
    main(["eval-locomotion", str(path), "--num-envs", "4", "--seconds", "2.1", "--out", str(tmp_path),
          "--set", "env.randomization.arm_amplitude=(0.3, 0.3, 0.3, 0.3, 0.1)"])
    summary = json.loads((tmp_path / "locomotion_eval.json").read_text())
    assert summary["arm_amplitude_rad"] == [0.3, 0.3, 0.3, 0.3, 0.1] and summary["push_velocity_m_s"] == 0.5
    assert summary["overrides"] == ["env.randomization.arm_amplitude=(0.3, 0.3, 0.3, 0.3, 0.1)"]
    assert set(summary["tracking_rms"]) == {"vx", "vy", "yaw_rate", "roll", "pitch", "height"}
    assert all(np.isfinite(v) and v > 0 for v in summary["tracking_rms"].values())
    for name, share in summary["violated_percent_of_steps"].items():  # two computations of the same steps agree
        p50, p90, p99 = (summary["largest_excess_percentiles"][name][q] for q in ("p50", "p90", "p99"))
        assert p50 <= p90 <= p99 and summary["constraint_units"][name]
        assert (share >= 50.0 if p50 > 0 else share <= 50.0) and (share >= 1.0 if p99 > 0 else share <= 1.0), name
    assert (tmp_path / "locomotion_eval.png").read_bytes()[:4] == b"\x89PNG"
    assert main(["eval-locomotion", str(path), "--out", str(tmp_path), "--set", "ppo.learning_rate=0.1"]) == 2
    assert "a locomotion evaluation takes env.* overrides only, got 'ppo.learning_rate=0.1'" in capsys.readouterr().err


def test_ship_of_a_locomotion_run_writes_its_onnx_tracking_evaluation_and_provenance(locomotion_run, tmp_path, capsys):
    from dynpush.sim.legged_push_env import LocomotionNetwork

    run, _ = locomotion_run
    out = tmp_path / "locomotion"
    assert main(["ship", str(run), "--to", str(out), "--worlds", "4"]) == 0
    assert "shipped run/model_1.pt (2 iterations" in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["learning_curve.png", "locomotion.onnx", "locomotion_eval.json",
                                                    "locomotion_eval.png", "training.json", "training_config.json"]
    record, evaluation = (json.loads((out / name).read_text()) for name in ("training.json", "locomotion_eval.json"))
    assert record["commands"] == [json.loads((run / "launches.jsonl").read_text())["command"]]
    assert record["commands"][0].startswith("dynpush train --task locomotion")
    assert record["iterations"] == 2 and record["world_steps"] == 2 * 8 * 16 and record["imitation"] is None
    assert record["evaluation"]["tracking_rms"] == evaluation["tracking_rms"] and evaluation["worlds"] == 4
    assert record["evaluation"]["fell_percent"] == evaluation["fell_percent"]
    training_config = json.loads((out / "training_config.json").read_text())
    assert LocomotionNetwork(str(out / "locomotion.onnx")).contract.values["training_config"] == training_config
    assert training_config == json.loads((run / "config.json").read_text())


def test_foot_contact_forces_carry_the_standing_robot():
    """The foot contact force constraint reads the solver's contact forces: standing still (no arm motions or
    pushes), the vertical forces on the four lower legs together carry the robot's weight, its randomised base
    mass included; the constraint takes each leg's whole force, friction included."""
    env = LocomotionEnv(LocomotionEnvConfig(num_envs=4, seed=2))
    env.set_disturbance_scale(0.0)
    vertical = []
    for step in range(100):
        env.step(torch.zeros(4, 12))
        force = env.foot_sensor.total_force.numpy().reshape(4, 4, 3)  # (world, leg, xyz) [N]
        vertical.append(force[..., 2].sum(axis=1))
    model = env.scene.model
    world_mass = np.bincount(model.body_world.numpy(), weights=model.body_mass.numpy(), minlength=4)[:4]
    np.testing.assert_allclose(np.mean(vertical[-40:], axis=0), 9.81 * world_mass, rtol=0.02)
    np.testing.assert_allclose(env.foot_force.numpy(), np.linalg.norm(force, axis=2), rtol=1e-5)
    limit = env.cfg.constraints.foot_force_limit
    np.testing.assert_allclose(env.constraints_t[:, -4:].numpy(), env.foot_force.numpy() - limit, rtol=1e-6)


def test_the_end_effector_force_acts_on_the_end_effector_point():
    """In free fall (started 3 m up, no contacts) each control step changes the robot's linear momentum by
    ``F_w dt`` and its angular momentum about its centre of mass ``c`` by ``(p_ee - c) x F_w dt``, with ``F_w``
    the drawn heading-frame force turned by the base's yaw: Newton's solver applies the force, at the end-effector
    point. The arm moves (random targets) and the force changes every step."""
    n, dt = 4, 0.02
    cfg = LocomotionEnvConfig(num_envs=n, seed=3, start_height=3.0)
    cfg.randomization.push_velocity = 0.0
    cfg.randomization.ee_force_probability = 1.0
    cfg.randomization.ee_force_interval_s = (dt, dt)
    env = LocomotionEnv(cfg)
    model, scene = env.scene.model, env.scene
    world, mass = model.body_world.numpy(), model.body_mass.numpy().astype(np.float64)
    com, inertia = model.body_com.numpy(), model.body_inertia.numpy().astype(np.float64)

    def momenta():
        """Per world: linear momentum, angular momentum about the centre of mass, the centre of mass [SI, world]."""
        q, qd = env.state_0.body_q.numpy().astype(np.float64), env.state_0.body_qd.numpy().astype(np.float64)
        R = quat_to_matrix(q[:, 3:7])
        c = q[:, :3] + np.einsum("nij,nj->ni", R, com)
        P, L, C = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
        for w in range(n):
            b, m = world == w, mass[world == w, None]
            C[w] = (m * c[b]).sum(0) / m.sum()
            P[w] = (m * qd[b, :3]).sum(0)
            spin = np.einsum("nij,njk,nlk,nl->i", R[b], inertia[b], R[b], qd[b, 3:])
            L[w] = spin + np.cross(c[b] - C[w], m * (qd[b, :3] - P[w] / m.sum())).sum(0)
        return P, L, C

    total_mass = np.array([mass[world == w].sum() for w in range(n)])
    checked = 0
    for _ in range(12):
        force_h = env.task.ee_force_h.numpy().astype(np.float64)
        base_q = env.state_0.body_q.numpy()[scene.base_body].astype(np.float64)
        heading_x = quat_to_matrix(base_q[:, 3:7])[:, :, 0]
        yaw = np.arctan2(heading_x[:, 1], heading_x[:, 0])
        force_w = np.column_stack([np.cos(yaw) * force_h[:, 0] - np.sin(yaw) * force_h[:, 1],
                                   np.sin(yaw) * force_h[:, 0] + np.cos(yaw) * force_h[:, 1], force_h[:, 2]])
        ee_q = env.state_0.body_q.numpy()[scene.ee_body].astype(np.float64)
        p_ee = ee_q[:, :3] + np.einsum("nij,j->ni", quat_to_matrix(ee_q[:, 3:7]), scene.ee_offset)
        P0, L0, C0 = momenta()
        env.step(torch.zeros(n, 12))
        P1, L1, _ = momenta()
        gravity = np.outer(total_mass, [0.0, 0.0, -9.81])
        np.testing.assert_allclose((P1 - P0) / dt - gravity, force_w, rtol=0.01, atol=0.5)
        np.testing.assert_allclose((L1 - L0) / dt, np.cross(p_ee - C0, force_w), rtol=0.03, atol=0.3)
        checked += int((np.linalg.norm(force_w, axis=1) > 20.0).sum())
    assert checked > 20, "most steps carry a sizeable force"
    assert (env.state_0.body_q.numpy()[scene.base_body, 2] > 1.0).all(), "still in the air"


@pytest.mark.parametrize("field, value, message", [
    ("ee_force_max", -1.0, r"randomization.ee_force_max must be a finite number >= 0, got -1.0"),
    ("ee_force_probability", 1.5, r"randomization.ee_force_probability must lie in \[0, 1\], got 1.5"),
    ("ee_force_spread", 4.0, r"randomization.ee_force_spread must lie in \[0, 3.14159\], got 4.0"),
    ("ee_force_interval_s", (2.0, 1.0), r"randomization.ee_force_interval_s must satisfy low <= high"),
])
def test_end_effector_force_config_errors_name_the_field(field, value, message):
    cfg = LocomotionEnvConfig()
    setattr(cfg.randomization, field, value)
    with pytest.raises(ConfigError, match=message):
        cfg.validate()


@pytest.mark.parametrize("override, message", [
    ("task='push'", r"^task must be 'locomotion', got 'push'$"),
    ("env.num_envs=0", r"^num_envs must be an integer >= 1, got 0$"),
    ("save_interval=0", r"^save_interval must be an integer >= 1, got 0$"),
    ("p_max_ramp_fraction=1.5", r"^p_max_ramp_fraction must lie in \[0, 1\], got 1.5$"),
    ("p_max={'collision': (0.0, 0.0)}", r"^p_max must name exactly the constraint groups"),
])
def test_locomotion_train_config_errors_name_the_field(override, message):
    with pytest.raises(ConfigError, match=message):
        apply_overrides(LocomotionTrainConfig.preset_config("cpu"), [override]).validate()


def test_given_leg_targets_reach_the_drives_as_given():
    """External leg targets (sim-to-sim: the runtime runs the locomotion policy) go to the legs' joint drives exactly,
    beyond any leg action's reach too (nothing maps them back into actions and clips them); a wrong shape or a
    non-finite target is refused."""
    env = make_push_env(PushEnvConfig(num_envs=2, legged=LeggedModeConfig(enabled=True)))
    legs = env.scene.robot.legged
    drives = lambda: env.control.joint_target_q.numpy()[env.scene.leg_q]  # noqa: E731
    env.reset(randomize_episode_step=False)
    env.step(torch.zeros(2, env.num_actions))
    np.testing.assert_array_equal(drives(), np.tile(legs.leg_default, (2, 1)).astype(np.float32))
    targets = np.stack([legs.leg_upper, legs.leg_default + 6.0]).astype(np.float32)
    env.set_leg_targets(targets)
    env.step(torch.zeros(2, env.num_actions))
    np.testing.assert_array_equal(drives(), targets)
    np.testing.assert_array_equal(env.leg_task.leg_target.numpy(), targets)
    for bad in (np.zeros((1, 12)), np.where(np.eye(2, 12) > 0, np.nan, targets)):
        with pytest.raises(ValueError, match=r"^leg targets must be finite with shape \(2, 12\)"):
            env.set_leg_targets(bad)


def test_objects_left_alone_stand_still_beside_stamping_legged_robots():
    """Legged mode, the legs driven from outside through a trot-like stamping (2 Hz, thighs +-0.4 rad, knees lifting
    0.6 rad) for 1 s, the arm at its default, every object more than a metre away: no object tilts. The legged
    mode's default 30 CG iterations converge the object's contacts; with the locomotion task's 5 the same run tips
    objects by up to 0.077 rad (and untouched objects toppled in legged evaluations)."""
    n, dt = 32, 0.02
    env = make_push_env(PushEnvConfig(num_envs=n, seed=0, legged=LeggedModeConfig(enabled=True)))
    env.reset(randomize_episode_step=False)
    object_body = env.scene.object_body
    start = env.state_0.body_q.numpy()[object_body].copy()
    assert (np.linalg.norm(start[:, :2] - env.state_0.body_q.numpy()[env.scene.base_body, :2], axis=1) > 1.0).all()
    default = env.scene.robot.legged.leg_default
    trot = np.array([0.0, np.pi, np.pi, 0.0])  # LF, RF, LH, RH
    largest_tilt, restarted = np.zeros(n), np.zeros(n, dtype=bool)
    for step in range(50):
        swing = np.sin(2 * np.pi * 2.0 * step * dt + trot)
        targets = np.tile(default, (n, 1))
        targets[:, 1::3] += 0.4 * swing
        targets[:, 2::3] -= 0.6 * np.maximum(swing, 0.0)
        env.set_leg_targets(targets)
        env.step(torch.zeros(n, env.num_actions))
        restarted |= env.reset_t.numpy() != 0  # a stamping robot may fall: its world starts a new episode
        largest_tilt = np.maximum(largest_tilt, tilt_angle(env.state_0.body_q.numpy()[object_body, 3:7]))
    assert largest_tilt.max() < 0.02, f"objects tilted by up to {largest_tilt.max():.3f} rad"
    moved = np.linalg.norm(env.state_0.body_q.numpy()[object_body, :3] - start[:, :3], axis=1)[~restarted]
    assert moved.size >= n // 2 and moved.max() < 0.01, f"{moved.size} objects, moved by up to {moved.max():.3f} m"

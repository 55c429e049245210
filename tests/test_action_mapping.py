"""The action mapping is defined once, in numpy (``dynpush.runtime.actions``); the Warp kernels are its twins.

The kernels ``process_actions`` (push policy) and ``process_leg_actions`` (locomotion policy) are launched on random
actions with random parameters and compared with the runtime's :class:`ActionMapping` / :class:`ActionScaling` of
the same parameters, and what ``process_actions`` sends to the robot with what the runtime's safety layer sends
(:class:`~dynpush.runtime.safety.CommandLimits`); the push environment is checked to launch its kernel with its own
``action_mapping``. (The kernels' independent references from the paper are in test_kernels.py and
test_locomotion_kernels.py.)
"""

import numpy as np
import torch
import warp as wp

from dynpush.kernels.push import actions as actions_k
from dynpush.kernels.locomotion import actions as loco_actions, views as loco_views
from dynpush.kernels.push.views import PushTask, RobotView
from dynpush.runtime.actions import NUM_BASE_COMMANDS, ActionMapping, ActionScaling
from dynpush.runtime.observation import NUM_ACTIONS, NUM_ARM_JOINTS
from dynpush.runtime.safety import CommandLimits
from test_kernels import random_command_limits
from test_locomotion_kernels import loco_params, random_scene, structs
from warp_numpy_helpers import arr, close, launch, make_struct

wp.config.quiet = True
Q = 12  # joint coordinates per world; the arm's start at ARM_Q
ARM_Q = 7


def random_mapping(rng) -> ActionMapping:
    """Parameters as float32 values, so that the kernel sees exactly the mapping's numbers."""
    f32 = lambda a: np.float32(a).astype(np.float64)  # noqa: E731
    base = ActionScaling(f32(rng.uniform(-0.5, 0.5, NUM_BASE_COMMANDS)), f32(rng.uniform(0.1, 1.0, NUM_BASE_COMMANDS)))
    arm = ActionScaling(f32(rng.uniform(-1.0, 1.0, NUM_ARM_JOINTS)), f32(rng.uniform(0.2, 0.8)))
    return ActionMapping(base, arm, float(f32(rng.uniform(1.0, 3.0))))


def test_process_actions_equals_the_runtime_mapping():
    rng = np.random.default_rng(4)
    n = 256
    for _ in range(3):
        mapping = random_mapping(rng)
        raw = (2.0 * rng.normal(size=(n, NUM_ACTIONS))).astype(np.float32)
        assert (np.abs(raw) > mapping.clip).any() and (np.abs(raw) < mapping.clip).any()
        robot = make_struct(RobotView, arm_q_start=np.arange(n) * Q + ARM_Q)
        task = make_struct(PushTask, arm_default=mapping.arm.default, actions=np.zeros((n, NUM_ACTIONS)),
                           last_actions=np.zeros((n, NUM_ACTIONS)), base_command=np.zeros((n, NUM_BASE_COMMANDS)),
                           arm_command=np.zeros((n, NUM_ARM_JOINTS)))
        limits, bounds = random_command_limits(rng)
        joint_target_q, base_target = arr(np.zeros(n * Q)), arr(np.zeros((n, NUM_BASE_COMMANDS)))
        launch(actions_k.process_actions, n, arr(raw), robot, task, arr(mapping.base.default), arr(mapping.base.scale),
               float(mapping.arm.scale), mapping.clip, limits, base_target, joint_target_q)

        base_command, arm_targets = mapping.commands(raw)
        close(task.actions.numpy(), mapping.clipped(raw), atol=0)
        close(task.base_command.numpy(), base_command, rtol=1e-6, atol=1e-6)
        close(task.arm_command.numpy(), arm_targets, rtol=1e-6, atol=1e-6)
        # What the runtime sends, row by row: its safety layer clamps the mapped commands.
        safety = CommandLimits(*bounds, leg_lower=np.zeros(0), leg_upper=np.zeros(0))
        asked_base, asked_arm = base_command.copy(), arm_targets.copy()
        for row in range(n):
            assert safety.clamp(base_command[row], arm_targets[row], np.zeros(0)) is None  # clamps in place
        assert (asked_base != base_command).any() and (asked_arm != arm_targets).any()
        arm_q = np.arange(n)[:, None] * Q + ARM_Q + np.arange(NUM_ARM_JOINTS)
        close(base_target.numpy(), base_command, rtol=1e-6, atol=1e-6)
        close(joint_target_q.numpy()[arm_q], arm_targets, rtol=1e-6, atol=1e-6)


def test_the_inverse_gives_back_the_clipped_actions():
    rng = np.random.default_rng(5)
    mapping = random_mapping(rng)
    raw = 3.0 * rng.normal(size=(100, NUM_ACTIONS))
    close(mapping.actions(*mapping.commands(raw)), mapping.clipped(raw), rtol=1e-9, atol=1e-12)
    close(mapping.actions(mapping.base.default, mapping.arm.default), np.zeros(NUM_ACTIONS), atol=1e-12)


def test_process_leg_actions_equals_the_runtime_leg_scaling():
    """Within the clip range the kernel's leg targets are what the runtime sends: ``default + action_scale * output``
    clamped by its safety layer to the joints' ranges."""
    rng = np.random.default_rng(6)
    n = 64
    view_np, task_np = random_scene(rng, n)
    params, p = loco_params(rng, leg_lower=rng.uniform(-1.5, -0.8, 12), leg_upper=rng.uniform(0.8, 1.5, 12))
    legs = ActionScaling(p["leg_default"], p["action_scale"])
    raw = rng.uniform(-p["clip"], p["clip"], (n, loco_views.NUM_LEG_JOINTS)).astype(np.float32)
    view, task = structs(view_np, task_np)
    launch(loco_actions.process_leg_actions, n, arr(raw), params, view, task, arr(np.zeros(view_np["joint_q"].size)))
    sent = legs.targets(raw)
    safety = CommandLimits(np.full(6, -np.inf), np.full(6, np.inf), np.full(5, -np.inf), np.full(5, np.inf),
                           p["leg_lower"], p["leg_upper"])
    clamped = 0
    for row in sent:
        asked = row.copy()
        assert safety.clamp(np.zeros(6), np.zeros(5), row) is None  # clamps in place
        clamped += int((asked != row).any())
    assert 0 < clamped < n
    close(task.leg_target.numpy(), sent, rtol=1e-6, atol=1e-6)
    unclamped = (sent > p["leg_lower"]) & (sent < p["leg_upper"])
    close(legs.actions(task.leg_target.numpy())[unclamped], raw[unclamped], rtol=1e-5, atol=1e-5)


def test_the_push_environment_launches_its_action_mapping(small_env):
    """A step maps the actions with ``env.action_mapping`` (worlds that reset within the step start over)."""
    env = small_env
    actions = np.random.default_rng(7).normal(size=(env.num_envs, NUM_ACTIONS)).astype(np.float32)
    env.step(torch.from_numpy(actions))
    kept = env.reset_t.numpy() == 0
    assert kept.any()
    base_command, arm_targets = env.action_mapping.commands(actions)
    close(env.task.base_command.numpy()[kept], base_command[kept], rtol=1e-6, atol=1e-6)
    close(env.task.arm_command.numpy()[kept], arm_targets[kept], rtol=1e-6, atol=1e-6)
    # The base receives the command clamped to the limits the exported contract carries (the runtime's).
    lower, upper = np.array(env.cfg.constraints.base_command_lower), np.array(env.cfg.constraints.base_command_upper)
    assert ((base_command < lower) | (base_command > upper))[kept].any()
    close(env.base_target.numpy()[kept], np.clip(base_command, lower, upper)[kept], rtol=1e-6, atol=1e-6)

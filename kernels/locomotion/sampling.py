"""Episode starts, command sampling and disturbances of the locomotion task.

A new episode places the base at the origin with a uniform yaw, the legs at their default plus uniform noise and
draws a command ``(vx, vy, yaw rate, roll, pitch, height)`` (vx, vy [m/s] in the heading frame, yaw rate [rad/s]
about world z, roll and pitch [rad], height [m]). Disturbances (``apply_events``, scaled by the training
curriculum's ``disturbance_scale``): random arm targets, base pushes, and a horizontal force on the end-effector
point, the push-back of a pushed object (``sample_ee_force``, heading frame, applied as a wrench by
``actions.write_ee_force``).
"""

import warp as wp

from ..frames import fork_rng, next_rng, yaw_quat
from .views import NUM_ARM_JOINTS, NUM_COMMANDS, NUM_FEET, NUM_LEG_JOINTS, LeggedView, LocomotionParams, LocomotionTask, vec12

wp.set_module_options({"enable_backward": False})


@wp.func
def sample_command(rng: wp.uint32, params: LocomotionParams, task: LocomotionTask, w: int):
    """A new command for world ``w``; ``rng``: a forked stream (``frames.fork_rng``)."""
    standing = wp.randf(rng) < params.standing_probability
    for i in range(NUM_COMMANDS):
        value = wp.randf(rng, params.command_lower[i], params.command_upper[i])
        if standing and i < 3:
            value = 0.0
        task.command[w, i] = value


@wp.func
def sample_arm_target(rng: wp.uint32, params: LocomotionParams, task: LocomotionTask, w: int):
    """A new arm target for world ``w``; ``rng``: a forked stream (``frames.fork_rng``)."""
    for j in range(NUM_ARM_JOINTS):
        amplitude = params.arm_amplitude[j] * params.disturbance_scale[0]
        target = params.arm_default[j] + wp.randf(rng, -amplitude, amplitude)
        task.arm_target[w, j] = wp.clamp(target, params.arm_lower[j], params.arm_upper[j])
    task.arm_target[w, NUM_ARM_JOINTS] = params.arm_default[NUM_ARM_JOINTS]


@wp.func
def sample_ee_force(rng: wp.uint32, params: LocomotionParams, task: LocomotionTask, w: int):
    """A new end-effector force for world ``w`` (heading frame); ``rng``: a forked stream (``frames.fork_rng``)."""
    force = wp.vec3(0.0, 0.0, 0.0)
    if wp.randf(rng) < params.ee_force_probability:
        magnitude = wp.randf(rng, 0.0, params.ee_force_max * params.disturbance_scale[0])
        angle = wp.pi + wp.randf(rng, -params.ee_force_spread, params.ee_force_spread)
        force = wp.vec3(magnitude * wp.cos(angle), magnitude * wp.sin(angle), 0.0)
    for i in range(3):
        task.ee_force_h[w, i] = force[i]


@wp.func
def steps_in(u: float, interval: wp.vec2):
    """``u`` in [0, 1) (a ``wp.randf(rng)`` of the caller) mapped onto a whole number of steps in ``interval``."""
    return int(interval[0] + u * (interval[1] - interval[0]))


@wp.func
def reset_legs(params: LocomotionParams, view: LeggedView, task: LocomotionTask, w: int, noise: vec12):
    """Legs of world ``w`` at their default plus ``noise`` [rad], targets there, no action history, feet down."""
    for j in range(NUM_LEG_JOINTS):
        q = params.leg_default[j] + noise[j]
        view.joint_q[view.leg_q[w, j]] = q
        task.leg_target[w, j] = q
        task.leg_velocity_last[w, j] = 0.0
        task.actions[w, j] = 0.0
        task.last_actions[w, j] = 0.0
    for f in range(NUM_FEET):
        task.foot_contact[w, f] = 1
        task.foot_air_time[w, f] = 0.0
        task.touchdown_air_time[w, f] = -1.0


@wp.kernel
def start_episodes(
    reset: wp.array(dtype=int),
    seed: int,
    params: LocomotionParams,
    view: LeggedView,
    task: LocomotionTask,
):
    """Starts a new episode in every world with ``reset[w] != 0``.

    Base at the origin, ``start_height`` above the ground, uniform yaw; legs at their default plus
    uniform noise, the arm at its default; all velocities zero; no end-effector force; a new command,
    arm target and event schedule. The environment runs forward kinematics afterwards.
    """
    w = wp.tid()
    if reset[w] == 0:
        return
    rng = next_rng(seed, task.rng_counter, w)
    q0 = view.base_q_start[w]
    pose = wp.transform(wp.vec3(0.0, 0.0, params.start_height), yaw_quat(wp.randf(rng, -wp.pi, wp.pi)))
    for i in range(7):
        view.joint_q[q0 + i] = pose[i]
    for i in range(view.robot_qd_count):
        view.joint_qd[view.base_qd_start[w] + i] = 0.0
    noise = vec12()
    for j in range(NUM_LEG_JOINTS):
        noise[j] = wp.randf(rng, -params.leg_position_noise, params.leg_position_noise)
    reset_legs(params, view, task, w, noise)
    for j in range(NUM_ARM_JOINTS + 1):
        view.joint_q[view.arm_q[w, j]] = params.arm_default[j]
        task.arm_target[w, j] = params.arm_default[j]
    for i in range(3):
        task.ee_force_h[w, i] = 0.0
    sample_command(fork_rng(wp.randi(rng)), params, task, w)
    task.episode_step[w] = 0
    task.next_command_step[w] = steps_in(wp.randf(rng), params.command_interval)
    task.next_arm_step[w] = steps_in(wp.randf(rng), params.arm_interval)
    task.next_push_step[w] = steps_in(wp.randf(rng), params.push_interval)
    task.next_ee_force_step[w] = steps_in(wp.randf(rng), params.ee_force_interval)


@wp.kernel
def start_legs(reset: wp.array(dtype=int), params: LocomotionParams, view: LeggedView, task: LocomotionTask):
    """Legs of every world with ``reset[w] != 0`` at their default (the legged push task's episode start)."""
    w = wp.tid()
    if reset[w] != 0:
        reset_legs(params, view, task, w, vec12())


@wp.kernel
def apply_events(seed: int, params: LocomotionParams, view: LeggedView, task: LocomotionTask):
    """Scheduled events of a running episode: a new command, a new arm target, a base push (a uniform
    horizontal velocity change of the free joint), a new end-effector force."""
    w = wp.tid()
    step = task.episode_step[w]
    if step >= task.next_command_step[w]:
        rng = next_rng(seed, task.rng_counter, w)
        sample_command(fork_rng(wp.randi(rng)), params, task, w)
        task.next_command_step[w] = step + steps_in(wp.randf(rng), params.command_interval)
    if step >= task.next_arm_step[w]:
        rng = next_rng(seed, task.rng_counter, w)
        sample_arm_target(fork_rng(wp.randi(rng)), params, task, w)
        task.next_arm_step[w] = step + steps_in(wp.randf(rng), params.arm_interval)
    if step >= task.next_push_step[w]:
        rng = next_rng(seed, task.rng_counter, w)
        d0 = view.base_qd_start[w]
        push = params.push_velocity * params.disturbance_scale[0]
        view.joint_qd[d0 + 0] = view.joint_qd[d0 + 0] + wp.randf(rng, -push, push)
        view.joint_qd[d0 + 1] = view.joint_qd[d0 + 1] + wp.randf(rng, -push, push)
        task.next_push_step[w] = step + steps_in(wp.randf(rng), params.push_interval)
    if step >= task.next_ee_force_step[w]:
        rng = next_rng(seed, task.rng_counter, w)
        sample_ee_force(fork_rng(wp.randi(rng)), params, task, w)
        task.next_ee_force_step[w] = step + steps_in(wp.randf(rng), params.ee_force_interval)

"""How fast does a pushed object turn in the simulator, against quasi-static pushing theory?

A push off the object's centre of mass turns it; the turn per metre the object travels (kappa, rad/m) bounds how
fast any controller can correct the object's yaw on the way to its goal, where the scripted teacher and the shipped
policy fail most (``goal_error`` of ``dynpush eval``: at the goal with the rotation off). The scripted pusher pushes
each box from behind toward a far goal with a large yaw error, so that it pushes at its largest contact offset
(``ScriptedPusherConfig.max_offset``). From the first end-effector contact until the box has turned
``TURN_WINDOW_DEG`` or travelled ``TRAVEL_WINDOW_M`` the script measures kappa and the end-effector's mean offset
from the box's centre across the push. Quasi-static pushing (a frictionless point pusher, Coulomb friction where the
box rests; Mason 1986) predicts kappa at that offset for two ways the box rests on the floor: on its four bottom
corners (the contacts Newton generates for a box on a plane, counted here) and on a uniform pressure over its
bottom face. Prints one JSON object.

    python benchmarks/object_turning.py [--steps 600]
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import torch

TURN_WINDOW_DEG = 20.0  # the face stays within this angle of the push direction, as the model assumes
TRAVEL_WINDOW_M = 1.0
BOXES = (  # (label, full side lengths along and across the push, height) [m]
    ("square 0.5 m", (0.5, 0.5, 0.6)),
    ("square 0.3 m", (0.3, 0.3, 0.6)),
    ("square 0.7 m", (0.7, 0.7, 0.6)),
    ("0.68 x 0.29 m on its short face", (0.68, 0.29, 0.6)),
    ("0.29 x 0.68 m on its long face", (0.29, 0.68, 0.6)),
)


def friction_wrench(support: np.ndarray, cor: np.ndarray, sign: float) -> np.ndarray:
    """Floor friction on an object that turns about centres of rotation ``cor`` (m, 2) [m] (counter-clockwise for
    ``sign`` +1): force (x, y) and moment about the origin, per unit of mu times the total normal load shared equally
    by the support points ``support`` (k, 2) [m]. Returns (m, 3)."""
    offset = support[None] - cor[:, None]  # (m, k, 2)
    velocity = sign * np.stack([-offset[..., 1], offset[..., 0]], axis=-1)
    force = -velocity / np.maximum(np.linalg.norm(velocity, axis=-1, keepdims=True), 1e-12)
    moment = support[None, :, 0] * force[..., 1] - support[None, :, 1] * force[..., 0]
    return np.concatenate([force.mean(1), moment.mean(1, keepdims=True)], axis=1)


def quasi_static_centre_of_rotation(support: np.ndarray, contact: np.ndarray, push: np.ndarray) -> tuple[np.ndarray | None, float]:
    """Where an object resting on ``support`` points (k, 2) [m] turns about when a frictionless point at
    ``contact`` (2,) [m] pushes it along the unit ``push``: the centre of rotation whose friction wrench balances the
    push wrench, found on a polar grid about the origin (1 mm to 1 km) refined three times. Returns the centre (None
    for a pure translation: a push through the origin of a support symmetric about it) and the residual (norm of the
    difference of the unit wrenches; 0 at an exact balance)."""
    push_moment = contact[0] * push[1] - contact[1] * push[0]
    if abs(push_moment) < 1e-12:
        return None, 0.0
    target = -np.array([push[0], push[1], push_moment])
    target /= np.linalg.norm(target)
    log_radius, angle = (np.log(1e-3), np.log(1e3)), (0.0, 2.0 * np.pi)
    best = (np.inf, 0.0, 0.0)
    for _ in range(4):
        radii, angles = np.exp(np.linspace(*log_radius, 120)), np.linspace(*angle, 120)
        r, a = (g.ravel() for g in np.meshgrid(radii, angles))
        cor = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
        for sign in (1.0, -1.0):
            wrench = friction_wrench(support, cor, sign)
            error = np.linalg.norm(wrench / np.linalg.norm(wrench, axis=1, keepdims=True) - target, axis=1)
            k = int(np.argmin(error))
            if error[k] < best[0]:
                best = (float(error[k]), float(r[k]), float(a[k]))
        log_step, angle_step = (log_radius[1] - log_radius[0]) / 119, (angle[1] - angle[0]) / 119
        log_radius = (np.log(best[1]) - 3 * log_step, np.log(best[1]) + 3 * log_step)
        angle = (best[2] - 3 * angle_step, best[2] + 3 * angle_step)
    return best[1] * np.array([math.cos(best[2]), math.sin(best[2])]), best[0]


def bottom_supports(length: float, width: float, points: int = 31) -> dict[str, np.ndarray]:
    """The two support models of a ``length`` x ``width`` box centred at the origin (x along the push) [m]."""
    x, y = np.linspace(-length / 2, length / 2, points), np.linspace(-width / 2, width / 2, points)
    return {"corners": np.array([[sx * length / 2, sy * width / 2] for sx in (-1, 1) for sy in (-1, 1)]),
            "uniform": np.stack(np.meshgrid(x, y), axis=-1).reshape(-1, 2)}


def measure(steps: int) -> list[dict]:
    """Pushes every box of ``BOXES`` in its own world with the scripted pusher; per box the measured kappa [rad/m],
    the end-effector's mean offset across the push [m] and the object-floor contacts at the start."""
    from dynpush.policies.evaluate import yaw_of
    from dynpush.policies.scripted import ScriptedPusher, ScriptedPusherConfig
    from dynpush.sim.config import ObservationNoiseConfig, PushEnvConfig
    from dynpush.sim.episode import EpisodeSpec
    from dynpush.sim.push_env import PushEnv

    n = len(BOXES)
    env = PushEnv(PushEnvConfig(num_envs=n, seed=0, noise=ObservationNoiseConfig(enabled=False)))
    # A goal 3 m ahead with 1.2 rad to turn: the pusher holds its largest offset, to the right of the push (+x).
    env.set_episodes({w: EpisodeSpec(dims=dims, mass=5.0, friction=0.8, goal=(3.0, 0.0, 1.2), base=(-1.6, 0.0, 0.0))
                      for w, (_, dims) in enumerate(BOXES)})
    pusher = ScriptedPusher(env, ScriptedPusherConfig())
    floor_contacts = object_floor_contacts(env)
    start_yaw = np.full(n, np.nan)
    turned, travelled, offset_sum, contact_steps = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    previous = pusher.probe.object()[:, :2].copy()
    for _ in range(steps):
        env.step(torch.from_numpy(pusher(None)))
        obj = pusher.probe.object()
        touching = env.task.contacts.numpy()[:, -1] > 0
        start_yaw = np.where(np.isnan(start_yaw) & touching, yaw_of(obj[:, 3:]), start_yaw)
        open_window = (~np.isnan(start_yaw) & (np.abs(turned) < math.radians(TURN_WINDOW_DEG))
                       & (travelled < TRAVEL_WINDOW_M))
        travelled += open_window * np.linalg.norm(obj[:, :2] - previous, axis=1)
        turned = np.where(open_window, yaw_of(obj[:, 3:]) - start_yaw, turned)
        in_contact = open_window & touching
        offset_sum += in_contact * (pusher.probe.ee_position()[:, 1] - obj[:, 1])
        contact_steps += in_contact
        previous = obj[:, :2].copy()
    return [{"box": label, "dims_m": list(dims), "object_floor_contacts": int(floor_contacts[w]),
             "measured_kappa_rad_per_m": float(abs(turned[w]) / max(travelled[w], 1e-9)),
             "turned_deg": float(math.degrees(turned[w])), "travelled_m": float(travelled[w]),
             "ee_offset_across_push_m": float(offset_sum[w] / max(contact_steps[w], 1))}
            for w, (label, dims) in enumerate(BOXES)]


def object_floor_contacts(env) -> np.ndarray:
    """Per world: the rigid contacts between the object and the floor (after a step)."""
    env.step(torch.zeros(env.num_envs, env.num_actions))
    model, contacts = env.scene.model, env.contacts
    count = int(contacts.rigid_contact_count.numpy()[0])
    shape0, shape1 = contacts.rigid_contact_shape0.numpy()[:count], contacts.rigid_contact_shape1.numpy()[:count]
    body, world = model.shape_body.numpy(), model.shape_world.numpy()
    per_world = np.zeros(env.num_envs, dtype=int)
    for w, object_body in enumerate(env.scene.object_body):
        for a, b in ((shape0, shape1), (shape1, shape0)):
            per_world[w] += int(((body[a] == object_body) & (world[b] < 0)).sum())
    return per_world


def run(steps: int) -> dict:
    rows = measure(steps)
    for row in rows:
        length, width, _ = row["dims_m"]
        contact = np.array([-length / 2, row["ee_offset_across_push_m"]])
        for name, support in bottom_supports(length, width).items():
            centre, residual = quasi_static_centre_of_rotation(support, contact, np.array([1.0, 0.0]))
            kappa = 0.0 if centre is None else 1.0 / float(np.linalg.norm(centre))  # |omega| / |omega x centre|
            row[f"quasi_static_kappa_{name}_rad_per_m"] = kappa
            row[f"measured_over_{name}"] = row["measured_kappa_rad_per_m"] / kappa if kappa > 0 else None
            row[f"residual_{name}"] = residual
    return {"turn_window_deg": TURN_WINDOW_DEG, "travel_window_m": TRAVEL_WINDOW_M, "steps": steps, "boxes": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=600, help="control steps (50 Hz) to push for")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(json.dumps(run(args.steps), indent=1))


if __name__ == "__main__":
    main()

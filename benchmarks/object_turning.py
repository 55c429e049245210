"""How fast does a pushed object turn in the simulator, against quasi-static pushing theory?

A push off the object's centre of mass turns it; the turn per metre the object travels (kappa, rad/m) bounds how
fast any controller can correct the object's yaw on the way to its goal, where the scripted teacher and the shipped
policy fail most (``goal_error`` of ``dynpush eval``: at the goal with the rotation off). The scripted pusher pushes
each box from behind toward a far goal with a large yaw error, so that it pushes at its largest contact offset
(``ScriptedPusherConfig.max_offset``). From the first end-effector contact until the box has turned
``TURN_WINDOW_DEG`` or travelled ``TRAVEL_WINDOW_M`` the script measures kappa and the end-effector's mean offset
from the box's centre across the push. Quasi-static pushing (Coulomb friction where the box rests; Mason 1986)
predicts kappa at that offset for two pushers, a frictionless point (the contact slides along the face) and one the
contact sticks to, and two ways the box rests on the floor: on its four bottom corners (the contacts Newton generates
for a box on a plane, counted here) and on a uniform pressure over its bottom face, with the weight shared equally
or moved toward the front by the push (``pushed_load``: the push at the end-effector's measured height with the full
sliding friction, an upper bound on the transfer). The sticking contact needs the push force within the
end-effector-object friction cone (``push_force_angle_deg`` against ``ee_object_friction``, the mean of the two
shapes' coefficients). Prints one JSON object.

    python benchmarks/object_turning.py [--steps 600] [--set sim.solver=mujoco sim.substeps=8]   # PushEnvConfig fields
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import torch

TURN_WINDOW_DEG = 20.0  # the face stays within this angle of the push direction, as the model assumes
TRAVEL_WINDOW_M = 1.0
OBJECT_FLOOR_FRICTION = 0.8
BOXES = (  # (label, full side lengths along and across the push, height) [m]
    ("square 0.5 m", (0.5, 0.5, 0.6)),
    ("square 0.3 m", (0.3, 0.3, 0.6)),
    ("square 0.7 m", (0.7, 0.7, 0.6)),
    ("0.68 x 0.29 m on its short face", (0.68, 0.29, 0.6)),
    ("0.29 x 0.68 m on its long face", (0.29, 0.68, 0.6)),
)


def friction_wrench(support: np.ndarray, cor: np.ndarray, sign: float | np.ndarray,
                    load: np.ndarray | None = None) -> np.ndarray:
    """Floor friction on an object that turns about centres of rotation ``cor`` (m, 2) [m] (counter-clockwise for
    ``sign`` +1; one sign for all centres or one per centre, (m,)): force (x, y) and moment about the origin, per unit of mu times the total normal load, which the
    support points ``support`` (k, 2) [m] carry in the shares ``load`` (k,) (equal shares if None). Returns (m, 3)."""
    load = np.full(len(support), 1.0 / len(support)) if load is None else load
    offset = support[None] - cor[:, None]  # (m, k, 2)
    velocity = np.reshape(sign, (-1, 1, 1)) * np.stack([-offset[..., 1], offset[..., 0]], axis=-1)
    force = -velocity / np.maximum(np.linalg.norm(velocity, axis=-1, keepdims=True), 1e-12) * load[None, :, None]
    moment = support[None, :, 0] * force[..., 1] - support[None, :, 1] * force[..., 0]
    return np.concatenate([force.sum(1), moment.sum(1, keepdims=True)], axis=1)


def pushed_load(support: np.ndarray, push_height: float, friction: float) -> np.ndarray:
    """Load shares (k,) of the support points (k, 2) [m] (x along the push) of an object pushed ``push_height`` [m]
    above the floor with the full sliding friction ``friction`` times its weight: a pressure linear in x, zero behind
    where the rear lifts, whose moment balances the push's, ``sum(load * x) = friction * push_height`` (x from the
    support's centre); all on the front-most points where even that cannot balance it (the object tips)."""
    x = support[:, 0] - support[:, 0].mean()
    target = friction * push_height
    if target >= x.max():
        load = (x == x.max()).astype(float)
        return load / load.sum()
    behind, ahead = -1e6, float(x.max())  # the pressure max(0, x - zero) vanishes at ``zero``; its centroid grows with it
    for _ in range(200):
        zero = 0.5 * (behind + ahead)
        load = np.maximum(x - zero, 0.0)
        behind, ahead = (zero, ahead) if (load * x).sum() / load.sum() < target else (behind, zero)
    return load / load.sum()


PUSHERS = ("frictionless", "sticking")


def _grid_search(error, bounds: list[tuple[float, float]], rounds: int = 4, points: int = 120) -> tuple[np.ndarray, float]:
    """Minimises ``error`` (m, d) -> (m,) over the box ``bounds`` on a grid of ``points`` per axis, zoomed ``rounds``
    times onto +-3 cells about the best point. Returns the best point (d,) and its error."""
    best, best_error = None, np.inf
    for _ in range(rounds):
        axes = [np.linspace(lo, hi, points) for lo, hi in bounds]
        grid = np.stack([g.ravel() for g in np.meshgrid(*axes)], axis=1)
        errors = error(grid)
        k = int(np.argmin(errors))
        if errors[k] < best_error:
            best, best_error = grid[k], float(errors[k])
        bounds = [(x - 3 * (hi - lo) / (points - 1), x + 3 * (hi - lo) / (points - 1)) for x, (lo, hi) in zip(best, bounds)]
    return best, best_error


def quasi_static_centre_of_rotation(support: np.ndarray, contact: np.ndarray, push: np.ndarray,
                                    pusher: str = "frictionless", load: np.ndarray | None = None
                                    ) -> tuple[np.ndarray | None, float]:
    """Where an object resting on ``support`` points (k, 2) [m] (load shares ``load``, equal if None) turns about
    when a point pushes it at ``contact`` (2,) [m] along the unit ``push``:

    - ``frictionless``: the push force is along ``push`` and the contact may slide along the face; the centre of
      rotation is where the floor's friction wrench is opposite to the push wrench (a polar grid about the origin,
      1 mm to 1 km);
    - ``sticking``: friction holds the contact on the pusher, which moves along ``push``; the centre lies on the line
      through the contact across the push, where the friction wrench has no moment about the contact (a point
      pushes with a force, not a torque).

    Returns the centre (None for a pure translation: a push through the origin of a support symmetric about it and
    loaded symmetrically across the push) and the residual of the balance (0 when exact)."""
    push_moment = contact[0] * push[1] - contact[1] * push[0]
    if abs(push_moment) < 1e-12:
        return None, 0.0
    if pusher == "frictionless":
        target = -np.array([push[0], push[1], push_moment]) / math.hypot(1.0, push_moment)

        def error(grid):  # (log radius, angle) of the centre; the better of the two senses of rotation
            cor = np.exp(grid[:, :1]) * np.stack([np.cos(grid[:, 1]), np.sin(grid[:, 1])], axis=1)
            wrenches = [friction_wrench(support, cor, sign, load) for sign in (1.0, -1.0)]
            return np.min([np.linalg.norm(w / np.linalg.norm(w, axis=1, keepdims=True) - target, axis=1)
                           for w in wrenches], axis=0)

        (log_radius, angle), residual = _grid_search(error, [(math.log(1e-3), math.log(1e3)), (0.0, 2.0 * math.pi)])
        return math.exp(log_radius) * np.array([math.cos(angle), math.sin(angle)]), residual
    if pusher != "sticking":
        raise ValueError(f"pusher must be one of {PUSHERS}, got {pusher!r}")
    across = np.array([-push[1], push[0]])

    def error(grid):  # the centre at contact + sinh(t) * across; the contact moves along +push for sign(t)
        along = np.sinh(grid[:, 0])
        cor = contact[None] + along[:, None] * across[None]
        wrench = friction_wrench(support, cor, np.where(along > 0, 1.0, -1.0), load)
        moment_about_contact = wrench[:, 2] - (contact[0] * wrench[:, 1] - contact[1] * wrench[:, 0])
        return np.abs(moment_about_contact) / np.linalg.norm(wrench[:, :2], axis=1)

    (t,), residual = _grid_search(error, [(-8.0, 8.0)], points=4000)
    return contact + math.sinh(t) * across, residual


def push_force_angle_deg(support: np.ndarray, centre: np.ndarray, contact: np.ndarray, push: np.ndarray,
                         load: np.ndarray | None = None) -> float:
    """Angle [deg] between the force the pusher applies (balancing the floor's friction while the object turns
    about ``centre`` with its contact moving along ``push``) and ``push``: within the pusher-object friction cone
    (atan mu) for a sticking contact."""
    offset = contact - centre
    sign = 1.0 if (-offset[1] * push[0] + offset[0] * push[1]) > 0 else -1.0  # contact velocity along +push
    force = -friction_wrench(support, centre[None], sign, load)[0, :2]
    return math.degrees(math.atan2(abs(push[0] * force[1] - push[1] * force[0]), force @ push))


def bottom_supports(length: float, width: float, points: int = 31) -> dict[str, np.ndarray]:
    """The two support models of a ``length`` x ``width`` box centred at the origin (x along the push) [m]."""
    x, y = np.linspace(-length / 2, length / 2, points), np.linspace(-width / 2, width / 2, points)
    return {"corners": np.array([[sx * length / 2, sy * width / 2] for sx in (-1, 1) for sy in (-1, 1)]),
            "uniform": np.stack(np.meshgrid(x, y), axis=-1).reshape(-1, 2)}


def measure(steps: int, overrides: tuple[str, ...] = ()) -> list[dict]:
    """Pushes every box of ``BOXES`` in its own world with the scripted pusher; per box the measured kappa [rad/m],
    the end-effector's mean offset across the push and height above the floor while touching [m], the object-floor
    contacts at the start and the end-effector-object friction coefficient. ``overrides``: ``PushEnvConfig`` fields
    (``sim.solver=mujoco``), with the training config's parser."""
    from dynpush.kernels.push.contacts import ROLE_EE
    from dynpush.policies.env_probe import yaw_of
    from dynpush.policies.scripted import ScriptedPusher, ScriptedPusherConfig
    from dynpush.policies.train import apply_overrides
    from dynpush.sim.config import ObservationNoiseConfig, PushEnvConfig
    from dynpush.sim.episode import EpisodeSpec
    from dynpush.sim.push_env import PushEnv

    n = len(BOXES)
    env_cfg = apply_overrides(PushEnvConfig(num_envs=n, seed=0, noise=ObservationNoiseConfig(enabled=False)), overrides)
    env = PushEnv(env_cfg)
    # A goal 3 m ahead with 1.2 rad to turn: the pusher holds its largest offset, to the right of the push (+x).
    env.set_episodes({w: EpisodeSpec(dims=dims, mass=5.0, friction=OBJECT_FLOOR_FRICTION, goal=(3.0, 0.0, 1.2),
                                     base=(-1.6, 0.0, 0.0))
                      for w, (_, dims) in enumerate(BOXES)})
    pusher = ScriptedPusher(env, ScriptedPusherConfig())
    floor_contacts = object_floor_contacts(env)
    model = env.scene.model
    mu, world = model.shape_material_mu.numpy(), model.shape_world.numpy()
    ee_shapes = np.flatnonzero(env.scene.shape_role == ROLE_EE)
    ee_mu = dict(zip(world[ee_shapes].tolist(), mu[ee_shapes].tolist()))
    start_yaw = np.full(n, np.nan)
    turned, travelled, offset_sum, height_sum, contact_steps = (np.zeros(n) for _ in range(5))
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
        ee = pusher.probe.ee_position()
        offset_sum += in_contact * (ee[:, 1] - obj[:, 1])
        height_sum += in_contact * ee[:, 2]
        contact_steps += in_contact
        previous = obj[:, :2].copy()
    return [{"box": label, "dims_m": list(dims), "object_floor_contacts": int(floor_contacts[w]),
             "ee_object_friction": 0.5 * (ee_mu[w] + float(mu[env.scene.object_shape[w]])),
             "measured_kappa_rad_per_m": float(abs(turned[w]) / max(travelled[w], 1e-9)),
             "turned_deg": float(math.degrees(turned[w])), "travelled_m": float(travelled[w]),
             "ee_offset_across_push_m": float(offset_sum[w] / max(contact_steps[w], 1)),
             "ee_height_m": float(height_sum[w] / max(contact_steps[w], 1))}
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


def run(steps: int, overrides: tuple[str, ...] = ()) -> dict:
    rows = measure(steps, overrides)
    for row in rows:
        length, width, _ = row["dims_m"]
        contact, push = np.array([-length / 2, row["ee_offset_across_push_m"]]), np.array([1.0, 0.0])
        for support_name, support in bottom_supports(length, width).items():
            loads = {"equal": None, "pushed": pushed_load(support, row["ee_height_m"], OBJECT_FLOOR_FRICTION)}
            for pusher in PUSHERS:
                for load_name, load in loads.items():
                    centre, residual = quasi_static_centre_of_rotation(support, contact, push, pusher, load)
                    kappa = 0.0 if centre is None else 1.0 / float(np.linalg.norm(centre))  # |omega| / |omega x centre|
                    row[f"model_{pusher}_{support_name}_{load_name}_load"] = {
                        "kappa_rad_per_m": kappa,
                        "measured_over_model": row["measured_kappa_rad_per_m"] / kappa if kappa else None,
                        "push_force_angle_deg": None if centre is None else push_force_angle_deg(support, centre, contact, push, load),
                        "residual": residual}
    return {"turn_window_deg": TURN_WINDOW_DEG, "travel_window_m": TRAVEL_WINDOW_M, "steps": steps,
            "overrides": list(overrides), "boxes": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=600, help="control steps (50 Hz) to push for")
    parser.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE",
                        help="PushEnvConfig overrides, e.g. sim.solver=mujoco sim.xpbd_iterations=8")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(json.dumps(run(args.steps, tuple(args.set)), indent=1))


if __name__ == "__main__":
    main()

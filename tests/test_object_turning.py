"""`benchmarks/object_turning.py`: its quasi-static pushing model against an independent wrench balance, and the
object-floor contacts it reports."""

import math

import numpy as np
import pytest

from dynpush.sim.episode import EpisodeSpec


def coulomb_wrench(support, centre, sign, load=None):
    """Independent reference, point by point: force and moment about the origin of unit-load Coulomb friction at
    each support point of an object turning about ``centre`` (counter-clockwise for sign +1), the points carrying
    the shares ``load`` (equal if None)."""
    total = np.zeros(3)
    for k, (x, y) in enumerate(support):
        vx, vy = -sign * (y - centre[1]), sign * (x - centre[0])
        speed = math.hypot(vx, vy)
        share = 1.0 / len(support) if load is None else load[k]
        fx, fy = -share * vx / speed, -share * vy / speed
        total += [fx, fy, x * fy - y * fx]
    return total


@pytest.mark.parametrize("support_model", ["corners", "uniform"])
@pytest.mark.parametrize("offset", [-0.15, 0.06, 0.19])
def test_frictionless_push_is_balanced(load_benchmark, support_model, offset):
    """Turning about the returned centre, the floor's friction wrench opposes the push wrench, and the pushed point
    moves along the push (a pusher cannot pull)."""
    turning = load_benchmark("object_turning")
    support = turning.bottom_supports(0.5, 0.4, points=15)[support_model]
    contact, push = np.array([-0.25, offset]), np.array([1.0, 0.0])
    centre, residual = turning.quasi_static_centre_of_rotation(support, contact, push, "frictionless")
    assert residual < 1e-3
    push_wrench = np.array([push[0], push[1], contact[0] * push[1] - contact[1] * push[0]])
    balancing = []
    for sign in (1.0, -1.0):
        friction = coulomb_wrench(support, centre, sign)
        cosine = -friction @ push_wrench / (np.linalg.norm(friction) * np.linalg.norm(push_wrench))
        contact_velocity = sign * np.array([-(contact[1] - centre[1]), contact[0] - centre[0]])
        balancing.append(cosine > 1.0 - 1e-5 and contact_velocity @ push > 0.0)
    assert any(balancing)
    assert turning.push_force_angle_deg(support, centre, contact, push) == pytest.approx(0.0, abs=0.5)


@pytest.mark.parametrize("support_model", ["corners", "uniform"])
@pytest.mark.parametrize("offset", [-0.15, 0.06, 0.19])
def test_sticking_push_is_balanced(load_benchmark, support_model, offset):
    """The centre lies across the push from the contact, the contact moves along the push, and the floor's friction
    has no moment about the contact; the push force's angle from the push direction is the friction force's."""
    turning = load_benchmark("object_turning")
    support = turning.bottom_supports(0.5, 0.4, points=15)[support_model]
    contact, push = np.array([-0.25, offset]), np.array([1.0, 0.0])
    centre, residual = turning.quasi_static_centre_of_rotation(support, contact, push, "sticking")
    assert residual < 1e-6
    assert centre[0] == pytest.approx(contact[0])
    sign = 1.0 if centre[1] > contact[1] else -1.0  # counter-clockwise about a centre to the left moves it along +x
    friction = coulomb_wrench(support, centre, sign)
    assert friction[2] - (contact[0] * friction[1] - contact[1] * friction[0]) == pytest.approx(0.0, abs=1e-6)
    assert -friction[0] > 0.0  # the pusher pushes forward
    expected = math.degrees(math.atan2(abs(friction[1]), -friction[0]))
    assert turning.push_force_angle_deg(support, centre, contact, push) == pytest.approx(expected, abs=1e-6)


@pytest.mark.parametrize("pusher", ["frictionless", "sticking"])
def test_turning_grows_with_the_offset_and_a_uniform_support(load_benchmark, pusher):
    """kappa = 1 / |centre|: zero through the centre, the same for mirrored offsets, larger for a larger offset, and
    larger on a uniform pressure than on the four corners (less friction moment per unit load)."""
    turning = load_benchmark("object_turning")
    supports, push = turning.bottom_supports(0.5, 0.5, points=15), np.array([1.0, 0.0])

    def kappa(model, offset):
        centre, _ = turning.quasi_static_centre_of_rotation(supports[model], np.array([-0.25, offset]), push, pusher)
        return 0.0 if centre is None else 1.0 / np.linalg.norm(centre)

    for model in ("corners", "uniform"):
        assert kappa(model, 0.0) == 0.0
        assert kappa(model, -0.15) == pytest.approx(kappa(model, 0.15), rel=1e-3)
        assert 0.0 < kappa(model, 0.05) < kappa(model, 0.1) < kappa(model, 0.2)
    assert kappa("uniform", 0.15) > 1.3 * kappa("corners", 0.15)


def test_sticking_turns_a_square_less_than_a_sliding_contact(load_benchmark):
    """A square on its corners pushed near the end of a face (the teacher's case): friction that holds the contact on
    the pusher also resists the turn (not in general: on the long face of a slender box the order flips)."""
    turning = load_benchmark("object_turning")
    support, push, contact = turning.bottom_supports(0.5, 0.5)["corners"], np.array([1.0, 0.0]), np.array([-0.25, -0.15])
    radius = {pusher: np.linalg.norm(turning.quasi_static_centre_of_rotation(support, contact, push, pusher)[0])
              for pusher in turning.PUSHERS}
    assert radius["sticking"] > 1.2 * radius["frictionless"]
    with pytest.raises(ValueError, match="pusher must be one of"):
        turning.quasi_static_centre_of_rotation(support, contact, push, "rolling")


def test_a_cuboid_rests_on_four_contacts(small_env, load_benchmark):
    """Newton puts a box on the floor at four contacts (its bottom corners): the support the benchmark's corner
    model assumes."""
    small_env.set_episodes({w: EpisodeSpec(dims=(0.5, 0.4 + 0.1 * w, 0.6)) for w in range(small_env.num_envs)})
    assert load_benchmark("object_turning").object_floor_contacts(small_env).tolist() == [4] * small_env.num_envs


def test_pushed_load_balances_the_push_moment(load_benchmark):
    """The push ``h`` above the floor with friction ``mu`` times the weight moves weight to the front: shares sum to
    1 and their moment about the centre along the push is mu h (corners: the front pair carries 1/2 + mu h / L);
    beyond what a linear pressure can balance the rear lifts, and beyond L / 2 all rests on the front."""
    turning = load_benchmark("object_turning")
    supports = turning.bottom_supports(0.5, 0.4, points=21)
    for support in supports.values():
        load = turning.pushed_load(support, push_height=0.18, friction=0.8)
        assert load.sum() == pytest.approx(1.0)
        assert (load * support[:, 0]).sum() == pytest.approx(0.8 * 0.18)
    corners = supports["corners"]
    front = turning.pushed_load(corners, 0.18, 0.8)[corners[:, 0] > 0].sum()
    assert front == pytest.approx(0.5 + 0.8 * 0.18 / 0.5)
    tipping = turning.pushed_load(corners, 0.5, 1.0)
    assert tipping[corners[:, 0] < 0].tolist() == [0.0, 0.0] and tipping.sum() == pytest.approx(1.0)
    uniform = supports["uniform"]  # 0.144 m is beyond the L / 6 of a linear pressure: only a front strip carries it
    lifted = turning.pushed_load(uniform, 0.18, 0.8)
    assert lifted[uniform[:, 0] < -0.1].max() == 0.0 and lifted[uniform[:, 0] > 0.2].min() > 0.0


def test_loaded_wrench_and_centre(load_benchmark):
    """With unequal shares the wrench is the load-weighted sum (independent reference), and the sticking balance
    still holds about the contact; moving weight to the front corners slows a square's turn."""
    turning = load_benchmark("object_turning")
    corners, push, contact = turning.bottom_supports(0.5, 0.5)["corners"], np.array([1.0, 0.0]), np.array([-0.25, -0.15])
    load = turning.pushed_load(corners, 0.18, 0.8)
    centre = np.array([-0.25, 0.6])
    assert turning.friction_wrench(corners, centre[None], 1.0, load)[0] == pytest.approx(coulomb_wrench(corners, centre, 1.0, load))
    loaded, residual = turning.quasi_static_centre_of_rotation(corners, contact, push, "sticking", load)
    assert residual < 1e-6
    friction = coulomb_wrench(corners, loaded, 1.0 if loaded[1] > contact[1] else -1.0, load)
    assert friction[2] - (contact[0] * friction[1] - contact[1] * friction[0]) == pytest.approx(0.0, abs=1e-6)
    equal, _ = turning.quasi_static_centre_of_rotation(corners, contact, push, "sticking")
    assert np.linalg.norm(loaded) > 1.2 * np.linalg.norm(equal)

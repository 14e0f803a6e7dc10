"""Characters and their animations: smooth in time, a periodic walk, a fall that tumbles and
lands on the ground, transitions that hand one clip over to another, clear errors."""
import numpy as np
import pytest

from casadi_keyframe.scenes.animations import Fall, Walk, fall, transition, walk
from casadi_keyframe.scenes.skeleton import CAPSULES, Character, Pose, capsule_clearance

CHARACTER = Character()
WALK = walk(CHARACTER)
FALL = fall(CHARACTER)
BLEND = transition(WALK, FALL, t_a=0.7, t_b=0.0, window=0.4)


def points(animation, t):
    """Every capsule end point at time t, (2 * capsules, 3)."""
    seg = CHARACTER.segments(animation.pose(t))
    return np.array([p for name in CAPSULES for p in seg[name]])


TIMES = np.linspace(-0.2, 2.5, 163)  # before, through and after the fall and the window


@pytest.mark.parametrize("animation", [WALK, FALL, BLEND], ids=["walk", "fall", "transition"])
def test_poses_are_continuous_and_difference_velocities_are_consistent(animation):
    """No jump between t and t + 1e-6, and the colliders' central differences (h = 1e-5)
    agree with a Richardson-extrapolated wider difference: the velocity is well defined
    (the fall's start at t = 0, from rest, is only C^1 and sets the tolerance)."""
    worst_jump, worst_velocity = 0.0, 0.0
    for t in TIMES:
        jump = np.abs(points(animation, t + 1e-6) - points(animation, t)).max()
        worst_jump = max(worst_jump, jump)
        coarse = (points(animation, t + 1e-5) - points(animation, t - 1e-5)) / 2e-5
        d = lambda h: (points(animation, t + h) - points(animation, t - h)) / (2 * h)  # noqa: E731
        fine = (4 * d(2e-4) - d(4e-4)) / 3
        worst_velocity = max(worst_velocity, np.abs(coarse - fine).max())
    assert worst_jump < 3e-5  # under 30 m/s
    assert worst_velocity < 1e-3


def test_the_colliders_move_with_the_animation_and_report_its_velocity():
    capsules = CHARACTER.capsules(WALK)
    assert len(capsules) == len(CAPSULES)
    t = 0.37
    seg = CHARACTER.segments(WALK.pose(t))
    a, b, radius, va, *_ = capsules[1].geometry(t)
    np.testing.assert_allclose([a, b], seg["torso"], atol=1e-12)
    assert radius[0] == CHARACTER.torso_radius
    assert abs(va[1] - WALK.speed) < 0.3  # the torso travels forward at about walking speed
    ahead = CHARACTER.capsules(WALK, lead=0.1)[1].endpoints(t)
    np.testing.assert_allclose(ahead, CHARACTER.segments(WALK.pose(t + 0.1))["torso"], atol=1e-12)


def test_walk_is_periodic_up_to_its_forward_travel():
    step = np.array([0.0, WALK.speed * WALK.period, 0.0])
    for t in np.linspace(0, WALK.period, 7):
        np.testing.assert_allclose(points(WALK, t + WALK.period), points(WALK, t) + step,
                                   atol=1e-9)
    assert np.abs(points(WALK, WALK.period / 2) - points(WALK, 0)).max() > 0.2  # it moves
    turned = walk(CHARACTER, heading=np.pi / 2)  # walks along -x
    moved = turned.pose(1.0).position - turned.pose(0.0).position
    np.testing.assert_allclose(moved[:2], [-WALK.speed, 0.0], atol=0.05)


def test_walk_keeps_the_feet_near_the_ground():
    lows = [CHARACTER.lowest_point(WALK.pose(t)) for t in np.linspace(0, WALK.period, 23)]
    assert -0.01 < min(lows) < 0.02 and max(lows) < 0.1


def torso_axis(animation, t):
    a, b = CHARACTER.segments(animation.pose(t))["torso"]
    return (b - a) / np.linalg.norm(b - a)


@pytest.mark.parametrize("options", [{}, dict(pitch=-1.5 * np.pi, roll=2 * np.pi, seed=3),
                                     dict(height=3.0, yaw=-1.0, heading=1.0)])
def test_fall_tumbles_and_ends_lying_on_the_ground(options):
    motion = fall(CHARACTER, **options)
    radius = min(CHARACTER.radii.values())
    lows = np.array([CHARACTER.lowest_point(motion.pose(t))
                     for t in np.linspace(0, motion.end, 181)])
    assert lows.min() > -radius and lows.min() > -1e-9  # never through the ground
    assert lows[0] > motion.height - 0.01  # starts up in the air
    assert 0 <= lows[-1] < 0.05  # and ends on it
    end = motion.pose(motion.end)
    for name, (a, b) in CHARACTER.segments(end).items():
        assert min(a[2], b[2]) < 0.5, name  # lying: every part low
    turn = np.degrees(np.arccos(torso_axis(motion, 0) @ torso_axis(motion, motion.end)))
    assert turn > 60
    assert abs(torso_axis(motion, motion.end)[2]) < 0.2  # the torso lies flat
    # still once landed, flailing in the air
    np.testing.assert_allclose(points(motion, motion.end - 0.5), points(motion, motion.end),
                               atol=1e-6)
    half = motion.spin_duration / 2
    assert np.abs(motion.pose(half).angles - motion.pose(half + 0.05).angles).max() > 0.02


def test_fall_stands_still_before_it_starts():
    np.testing.assert_allclose(points(FALL, -0.3), points(FALL, 0.0), atol=1e-12)
    speed = np.abs(points(FALL, 1e-4) - points(FALL, -1e-4)).max() / 2e-4
    assert speed < 0.01  # starts at rest (C^1 with the still pose before)


def test_transition_plays_first_then_second_with_offset_and_blends_in_between():
    t_a, window = BLEND.t_a, BLEND.window
    for t in (-0.1, 0.3, t_a):
        np.testing.assert_allclose(points(BLEND, t), points(WALK, t), atol=1e-12)
    offset = WALK.pose(t_a).position - FALL.pose(0.0).position
    offset[2] = 0.0
    np.testing.assert_allclose(BLEND.offset, offset)
    for t in (t_a + window, t_a + window + 0.3, 2.0):
        np.testing.assert_allclose(points(BLEND, t), points(FALL, t - t_a) + offset, atol=1e-12)
    inside = np.linspace(t_a, t_a + window, 41)
    jumps = [np.abs(points(BLEND, t + 1e-6) - points(BLEND, t)).max() for t in inside]
    assert max(jumps) < 3e-5
    for edge in (t_a, t_a + window):  # C^1 across the window's edges
        before = (points(BLEND, edge) - points(BLEND, edge - 1e-4)) / 1e-4
        after = (points(BLEND, edge + 1e-4) - points(BLEND, edge)) / 1e-4
        assert np.abs(before - after).max() < 0.05
    middle = BLEND.pose(t_a + window / 2)
    assert not np.allclose(middle.angles, WALK.pose(t_a + window / 2).angles)
    np.testing.assert_allclose(middle.rotation @ middle.rotation.T, np.eye(3), atol=1e-12)
    assert BLEND.start == WALK.start and BLEND.end == FALL.end + t_a


def test_transition_with_an_explicit_offset_and_a_later_start_in_the_second_clip():
    later = transition(FALL, WALK, t_a=1.5, t_b=0.55, window=0.5, offset=(1.0, 2.0, 0.0))
    np.testing.assert_allclose(points(later, 2.2),
                               points(WALK, 2.2 - 1.5 + 0.55) + [1.0, 2.0, 0.0], atol=1e-12)
    # the shifted clip is the same animation later
    np.testing.assert_allclose(points(FALL.shifted(0.4), 1.0), points(FALL, 0.6), atol=1e-12)


def test_clearance_is_the_signed_distance_to_the_body():
    pose = WALK.pose(0.0)
    a, b = CHARACTER.segments(pose)["torso"]
    middle = (a + b) / 2
    probe = np.array([middle, middle + [0, -0.5, 0], middle + [0, -CHARACTER.torso_radius, 0]])
    gap = CHARACTER.clearance(pose, probe)
    assert gap[0] < -0.1 and abs(gap[1] - (0.5 - CHARACTER.torso_radius)) < 1e-3
    assert abs(gap[2]) < 1e-3
    one = capsule_clearance(probe, {"torso": (a, b)}, {"torso": CHARACTER.torso_radius})
    assert np.all(one >= gap - 1e-12)


def test_shoulder_points_ride_on_the_back_of_the_torso():
    path = CHARACTER.shoulder_points(WALK, [-0.1, 0.0, 0.1])
    for t in (0.0, 0.4):
        p = path(t)
        assert p.shape == (3, 3)
        np.testing.assert_allclose(np.linalg.norm(p[2] - p[0]), 0.2, atol=1e-12)  # rigid
        gap = CHARACTER.clearance(WALK.pose(t), p)
        assert np.all(gap > 0.005) and np.all(gap < 0.08)  # just behind the back
        forward = WALK.pose(t).rotation[:, 1]
        assert np.all((p - WALK.pose(t).position) @ forward < 0)
    assert CHARACTER.shoulder_points(FALL, 4)(0.0).shape == (4, 3)


@pytest.mark.parametrize("make, message", [
    (lambda: transition(WALK, FALL, 0.5, 2.9, 0.4), "outside the second clip"),
    (lambda: transition(FALL, WALK, 2.8, 0.0, 0.4), "outside the first clip"),
    (lambda: transition(WALK, FALL, -1.0, 0.0, 0.4), "outside the first clip"),
    (lambda: transition(WALK, FALL, 0.5, 0.0, 0.0), "window must be positive"),
    (lambda: transition(WALK, "fall", 0.5, 0.0, 0.3), "must be an Animation"),
    (lambda: transition(WALK, FALL, 0.5, 0.0, 0.3, offset=(1, 2)), "offset must be 3"),
    (lambda: transition(WALK, FALL, np.nan, 0.0, 0.3), "t_a must be finite"),
    (lambda: fall(CHARACTER, height=-1.0), "height must be >= 0"),
    (lambda: fall(CHARACTER, end=0.0), "end must be positive"),
    (lambda: walk(CHARACTER, period=0.0), "period must be positive"),
    (lambda: Character(torso_radius=-0.1), "torso_radius must be positive"),
    (lambda: CHARACTER.shoulder_points(WALK, 0), "k >= 1"),
])
def test_bad_input_is_refused_clearly(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_types():
    assert isinstance(WALK, Walk) and isinstance(FALL, Fall)
    assert isinstance(BLEND.pose(0.8), Pose)

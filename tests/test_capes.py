"""The cape on an animated character (reduced 8 x 6 cape, short clips): sewn to the shoulders,
never inside the body, not overstretched, and the walk and fall clips tell apart."""
import numpy as np
import pytest

from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.scenes.animations import fall, walk
from casadi_keyframe.scenes.capes import (CAPE_PARAMS, cape_contacts, cape_model, clip_report,
                                          hanging_state, simulate_clip)
from casadi_keyframe.scenes.skeleton import Character
from casadi_keyframe.simulate import simulate

ROWS, COLS, DT = 8, 6, 1 / 60
CHARACTER = Character()
TOLERANCE = 0.015  # m a particle may sink below a capsule's surface (contact layer 0.012 m)
# landing, the falling cape moves ~10 cm per step against the 1.2 cm layer, so a particle can
# start a step deep inside: 0.2-1.9 cm over four falls with a strut-like compression law,
# 2.9 cm on this fall (one particle, one frame) with the Choi-Ko law
LANDING_TOLERANCE = 0.03


@pytest.fixture(scope="module")
def clips():
    return {"walk": simulate_clip("walk", ROWS, COLS, seconds=0.6, dt=DT),
            "fall": simulate_clip("fall", ROWS, COLS, seconds=1.2, dt=DT)}


def deepest(traj, animation):
    """Deepest penetration (m) of any particle into any capsule, recomputed here in numpy:
    the distance of every particle to every capsule's segment, minus its radius."""
    radii = CHARACTER.radii
    depth = -np.inf
    for n, t in enumerate(traj.times):
        x = traj.x[n]
        for name, (a, b) in CHARACTER.segments(animation.pose(t)).items():
            ab = b - a
            s = np.clip((x - a) @ ab / (ab @ ab), 0, 1)
            dist = np.linalg.norm(x - a - s[:, None] * ab, axis=1)
            depth = max(depth, (radii[name] - dist).max())
    return depth


def attached(model):
    (attachment,) = model.attachments
    return attachment


@pytest.mark.parametrize("kind", ["walk", "fall"])
def test_attached_particles_follow_the_shoulders_exactly(clips, kind):
    model, traj, animation = clips[kind]
    a = attached(model)
    assert 3 <= a.particles.size < COLS and np.all(a.particles < COLS)  # the top edge's middle
    for n, t in enumerate(traj.times):
        np.testing.assert_allclose(traj.x[n, a.particles], a.path(t), atol=1e-9)
    line = CHARACTER.shoulder_points(animation, model.rest_positions[a.particles, 0])
    np.testing.assert_allclose(a.path(0.5), line(0.5), atol=1e-12)


@pytest.mark.parametrize("kind", ["walk", "fall"])
def test_the_cape_stays_out_of_the_body_and_is_not_overstretched(clips, kind):
    model, traj, animation = clips[kind]
    assert deepest(traj, animation) < (TOLERANCE if kind == "walk" else LANDING_TOLERANCE)
    assert max(model.max_stretch(x) for x in traj.x) < 1.5
    assert traj.x[:, :, 2].min() > -0.02  # nor through the ground
    report = clip_report(model, traj)
    assert report["penetration"] == pytest.approx(max(deepest(traj, animation), 0), abs=1e-9)


def test_the_check_does_catch_a_cape_that_passes_through_the_body():
    """Without body contact (the paper's penalty springs of stiffness ~0, no guard) the same
    fall sinks the cape into the body: the penetration measure above can fail."""
    animation = fall(CHARACTER)
    contacts = cape_contacts(0.4 / (ROWS * COLS), 0.12, DT)
    contacts["body"] = type(contacts["body"])(1e-6, 0.0, 0.012, 0.006)
    model = cape_model(CHARACTER, animation, rows=ROWS, cols=COLS, contacts=contacts,
                       collision="penalty")
    x0, v0 = hanging_state(model, CHARACTER, animation, 0.0)
    traj = simulate(LinearizedBackwardEuler(), model, x0, v0, np.zeros((70, model.n, 3)), DT)
    assert deepest(traj, animation) > 3 * TOLERANCE


def test_clips_start_settled(clips):
    """The pre-roll leaves the cape moving with the shoulders (swinging a little with the
    steps) and already streaming behind the walker; before the fall it hangs still."""
    for kind, (model, traj, animation) in clips.items():
        a = attached(model)
        shoulders = (a.path(1e-4) - a.path(-1e-4)).mean(0) / 2e-4
        assert np.abs(traj.v[0] - shoulders).max() < 0.8, kind
        assert model.max_stretch(traj.x[0]) < 1.1, kind
    model, traj, animation = clips["walk"]
    behind = traj.x[0, a.particles].mean(0)[1] - traj.x[0, -COLS:, 1].mean()
    assert behind > 0.1  # the hem trails the shoulders
    model, traj, _ = clips["fall"]
    assert np.abs(traj.v[0]).max() < 0.1  # standing still before the fall: settled


def test_the_fall_and_the_walk_clips_differ(clips):
    """The walking cape hangs and streams behind; the falling one is flung about and ends
    crumpled on the body lying on the ground."""
    walk_model, walk_traj, _ = clips["walk"]
    fall_model, fall_traj, fall_motion = clips["fall"]

    def shape(model, traj, n):  # positions relative to the shoulders' middle
        return traj.x[n] - traj.x[n, attached(model).particles].mean(0)

    n = walk_traj.steps
    gap = np.linalg.norm(shape(walk_model, walk_traj, n) - shape(fall_model, fall_traj, n), axis=1)
    assert gap.mean() > 0.2
    walk_height = np.ptp(walk_traj.x[-1, :, 2])
    fall_height = np.ptp(fall_traj.x[-1, :, 2])
    assert walk_height > 0.7 and fall_height < 0.5
    assert fall_traj.x[-1, :, 2].max() < 1.0  # down on the ground with the body
    speeds = [np.linalg.norm(traj.v, axis=2).max() for traj in (walk_traj, fall_traj)]
    assert speeds[1] > 2 * speeds[0]


def test_hanging_state_is_the_rest_shape_below_the_shoulders():
    animation = walk(CHARACTER)
    model = cape_model(CHARACTER, animation, rows=ROWS, cols=COLS)
    x, v = hanging_state(model, CHARACTER, animation, 0.3)
    assert model.max_stretch(x) < 1.01
    a = attached(model)
    np.testing.assert_allclose(x[a.particles], a.path(0.3), atol=1e-12)
    assert np.all(x[COLS:, 2] < x[:COLS, 2].min())  # hanging down
    assert np.allclose(v, v[0]) and abs(v[0, 1] - animation.speed) < 0.5


def test_contact_gains_scale_with_the_particle_mass():
    light, heavy = cape_contacts(0.001, 0.04), cape_contacts(0.004, 0.04)
    assert heavy["body"].stiffness == pytest.approx(4 * light["body"].stiffness)
    assert light["body"].stiffness * DT ** 2 / 0.001 == pytest.approx(50.0)
    assert light["body"].damping == pytest.approx(light["body"].stiffness * DT)
    assert light["self"].thickness == pytest.approx(0.016)
    assert CAPE_PARAMS.air_drag > 0


@pytest.mark.parametrize("make, message", [
    (lambda: simulate_clip("swim", ROWS, COLS), "kind must be one of"),
    (lambda: simulate_clip("walk", ROWS, COLS, seconds=0.0), "seconds and dt must be positive"),
    (lambda: simulate_clip("walk", ROWS, COLS, preroll=-1.0), "preroll must be >= 0"),
    (lambda: cape_model(CHARACTER, walk(CHARACTER), rows=1), "rows >= 2"),
    (lambda: cape_model(CHARACTER, walk(CHARACTER), rows=ROWS, cols=COLS, attach_width=0.01),
     "holds no particle"),
    (lambda: cape_contacts(-1.0, 0.04), "positive particle_mass"),
])
def test_bad_input_is_refused_clearly(make, message):
    with pytest.raises(ValueError, match=message):
        make()

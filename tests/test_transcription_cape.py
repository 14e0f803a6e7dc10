"""The cape (``cape_blend``) by the search in positions, on a small cape: the file's multiple
shooting left out for the transcription, self-contact left to the replay, the rest start
carried with the pins, and the command line end to end."""
import numpy as np
import pytest

import casadi_keyframe as ck
from casadi_keyframe import ControlProblem, StateKeyframe
from casadi_keyframe.controls import InitialVelocity, StepForces
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.models import ClothModel
from casadi_keyframe.models.contact.colliders import Contact
from casadi_keyframe.optimize.positions import Transcription, TranscriptionError
from casadi_keyframe.optimize.positions.defects import StepDefects
from casadi_keyframe.optimize.positions.method import start_positions
from casadi_keyframe.optimize.positions.replay import replay_controls
from casadi_keyframe.optimize.positions.rest import carrying_motion
from casadi_keyframe.optimize.settings import SolveSettings, settings_from

SMALL = {"rows": 6, "cols": 4, "steps": 12, "guess": "passive", "collision": "penalty"}


@pytest.fixture(scope="module")
def cape():
    return ck.load_problem("cape_blend", **SMALL)


def test_the_files_multiple_shooting_and_finish_are_left_out_for_the_transcription():
    """cape_blend's SOLVE from zero forces asks for multiple shooting, which the
    transcription cannot run (it crashed inside it); asked for on the command line, it is
    refused by name.  The file's finish (the effort lowered with the keyframe held, what
    the transcription's own search does) is left out too; one asked for still runs."""
    file = {"method": "lbfgsb", "shooting": {"segments": 6}, "finish": "effort"}
    assert settings_from(file, {"method": "transcription"}).shooting is None
    assert settings_from(file, {"method": "transcription"}).finish is None
    assert settings_from(file, {"method": "transcription",
                                "finish": "effort"}).finish is not None
    assert settings_from(file, {"method": "ipopt"}).shooting.segments == 6
    assert settings_from(file, {"method": "ipopt"}).finish is not None
    with pytest.raises(ValueError, match="--segments"):
        SolveSettings(method="transcription", shooting=4)


def test_self_contact_is_left_to_the_replay(cape):
    """The plan's step leaves self-contact out (no fixed pattern); the replay writes it, so
    the run of the returned controls lands on the plan; the rest of the step is the
    problem's own: the inverse step gives back zero forces on the passive run wherever no
    self-contact acts."""
    tr = Transcription(cape)
    assert "self-contact" in [f.name for f in cape.model.families]
    assert "self-contact" not in [f.name for f in tr.model.families]
    passive = cape.simulate(None, records=False).x
    free = cape.controls.idx
    selfc = cape.model.family("self-contact")
    quiet = [n for n in range(cape.steps) if selfc.find(passive[n])[0].size == 0]
    back = tr.controls(tr.unknowns(passive)).reshape(cape.steps, free.size, 3)
    weight = 9.81 * cape.model.masses.min()  # the passive step's linear solves' round-off:
    assert quiet and np.abs(back[quiet]).max() < 1e-6 * weight
    plan = start_positions(cape, "rest", None)
    replay = replay_controls(cape, plan)
    run = cape.simulate(replay.u, records=False).x
    assert np.max(np.linalg.norm(run - plan, axis=2)) < 1e-7


def test_the_control_jacobian_holds_through_the_moving_bodys_penalty_contact(cape):
    """On the passive run, where the cape lies in the body's penalty layer, the exact
    control Jacobian equals central differences of the forces, stable over three decades."""
    tr = Transcription(cape)
    z = tr.unknowns(cape.simulate(None, records=False).x)
    depth = [cape.model.penetration(f, k * cape.dt) for k, f in enumerate(tr.frames(z))]
    assert max(depth) > 0.0  # contact acts on this run
    d = np.random.default_rng(3).standard_normal(z.size)
    J = tr.control_jacobian(z) @ d
    for h in (1e-6, 1e-7, 1e-8):
        q = (tr.controls(z + h * d) - tr.controls(z - h * d)) / (2 * h)
        assert np.linalg.norm(q - J) <= 1e-5 * np.linalg.norm(J)


def test_the_rest_start_of_a_cape_is_held_still_relative_to_its_pins(cape):
    """Held still in space the cape would be torn from the moving shoulders; the rest start
    carries the start shape with them: the led particles on their path, no spring longer
    than at the start."""
    plan = start_positions(cape, "rest", None)
    (seam,) = cape.model.attachments
    for k in range(cape.steps + 1):
        assert np.allclose(plan[k, seam.particles], seam.positions(k * cape.dt), atol=1e-9)
    stretch = [cape.model.max_stretch(f) for f in plan]
    assert np.allclose(stretch, stretch[0], rtol=1e-9)


def test_the_rest_start_of_a_pinned_sheet_is_its_start_held_still():
    model = ClothModel.grid(4, 4, pinned=[0, 3])
    x0 = model.rest_positions
    prob = ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                          v0=np.zeros_like(x0), steps=5, dt=1 / 30, controls=StepForces(),
                          objective=StateKeyframe(5, x=x0, tolerance=0.01), name="sheet")
    assert np.array_equal(start_positions(prob, "rest", None),
                          np.repeat(x0[None], 6, axis=0))


def test_the_carrying_motion_is_kabschs_or_the_least_turn_of_a_line():
    rng = np.random.default_rng(0)
    R = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    R *= np.sign(np.linalg.det(R))
    points = rng.standard_normal((5, 3))
    found, t = carrying_motion(points, points @ R.T + 1.0)
    assert np.allclose(found, R) and np.allclose(t, 1.0)
    line = np.outer(np.linspace(-1, 1, 4), [1.0, 0.0, 0.0])
    turned = np.outer(np.linspace(-1, 1, 4), [0.0, 1.0, 0.0]) + [0.0, 0.0, 2.0]
    found, t = carrying_motion(line, turned)
    assert np.allclose(found @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    assert np.allclose(found @ [0.0, 0.0, 1.0], [0.0, 0.0, 1.0])  # no turn about the line
    assert np.allclose(t, [0.0, 0.0, 2.0])
    found, t = carrying_motion(line, line + 0.5)
    assert np.allclose(found, np.eye(3)) and np.allclose(t, 0.5)


def test_the_defects_refuse_self_contact_by_name():
    model = ClothModel.grid(4, 4, pinned=[0, 3], self_contact=Contact())
    x0 = model.rest_positions
    prob = ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                          v0=np.zeros_like(x0), steps=5, dt=1 / 30, controls=InitialVelocity(),
                          objective=StateKeyframe(5, x=x0, tolerance=0.01), name="sheet")
    with pytest.raises(TranscriptionError, match="self-contact"):
        StepDefects(prob)


def test_the_command_line_runs_the_cape_from_rest_and_its_controls_replay(tmp_path):
    """``solve cape_blend --method transcription --set guess=passive --set
    collision=penalty`` (a 6 x 4 cape, 12 steps) runs end to end, and the written controls
    replay the cape the search kept."""
    import json

    from casadi_keyframe.cli import main

    sets = [a for k, v in SMALL.items() for a in ("--set", f"{k}={v}")]
    code = main(["solve", "cape_blend", *sets, "--method", "transcription", "--option",
                 "start=rest", "--maxiter", "4", "--finish", "none", "--out", str(tmp_path),
                 "--quiet", "--no-animation", "--no-viewer"])
    assert code in (0, 1, 3)  # converged, missed the goal, or the iteration limit: ran
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["method"] == "transcription"
    assert "replayed within" in json.dumps(summary)

"""Typed views: a problem takes only a View, and a loose dict or the old scene= keyword is
refused with a message that says what to pass instead; a keyframe's marker says how the
goal judges it."""
import dataclasses

import numpy as np
import pytest

from casadi_keyframe import CenterOfMassKeyframe, ControlProblem, StepForces
from casadi_keyframe.integrators import SymplecticEuler
from casadi_keyframe.models import FlockModel, FlockParams
from casadi_keyframe.objectives import RegionTarget
from casadi_keyframe.shapes import square
from casadi_keyframe.objectives.keyframe_goal import KeyframeGoal
from casadi_keyframe.objectives.markers import Marker
from casadi_keyframe.views import ClothView, FlockView, Ring, view_of


def _problem(**kw):
    return ControlProblem(model=FlockModel(np.ones(3), 2, FlockParams()),
                          integrator=SymplecticEuler(), x0=np.eye(3, 2), v0=np.zeros((3, 2)),
                          steps=4, dt=0.1, controls=StepForces(),
                          objective=CenterOfMassKeyframe(4, x=[1.0, 0.0]), **kw)


def test_a_dict_or_the_old_scene_keyword_is_refused_with_the_fix():
    with pytest.raises(TypeError, match=r"FlockView\(highlight=\[0\]\)"):
        _problem(view={"highlight": [0]})
    with pytest.raises(TypeError, match=r"scene=.*is now view="):
        _problem(scene={"highlight": [0]})


def test_the_view_is_kept_through_rebuilt_problems():
    view = FlockView(highlight=[np.int64(2)])
    prob = _problem(view=view)
    assert prob.view is view and view.highlight == (2,)
    assert prob.resampled(0.05).view is view and prob.with_guess(None).view is view
    assert _problem().view is None


def test_views_are_frozen_checked_and_defaulted():
    view = ClothView(camera=[15, -80], ring=Ring(center=np.zeros(3), normal=(0, 0, 1), radius=1))
    assert view.camera == (15.0, -80.0) and view.ring.center == (0.0, 0.0, 0.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        view.camera = (0, 0)
    with pytest.raises(ValueError, match="radius"):
        Ring(center=(0, 0, 0), normal=(0, 0, 1), radius=0)
    with pytest.raises(ValueError, match="elevation, azimuth"):
        ClothView(camera=(1, 2, 3))
    prob = _problem()
    assert view_of(prob, FlockView) == FlockView()  # none given: the defaults
    with pytest.raises(TypeError, match="needs a ClothView.*a FlockView"):
        view_of(_problem(view=FlockView()), ClothView)


def test_a_marker_carries_how_the_goal_judges_its_keyframe():
    """A marker's check is the term's own miss and shortfall; a keyframe that checks
    nothing (fill 0, tolerance inf) is neither hit nor missed."""
    prob = _problem()
    traj = prob.simulate()
    term = prob.objective_terms.state_terms[0]
    check = term.marker().check(traj)
    assert check.met is (term.shortfall(traj) is None)
    assert [(m.key, m.value, m.tolerance) for m in check.misses] == [
        ("position_error", term.miss(traj)["position_error"], term.within[0])]
    free = RegionTarget(4, square((0, 0), 1), fill=0).bind(prob.model, prob.steps)
    loose = CenterOfMassKeyframe(4, x=[9.0, 9.0], tolerance=np.inf).bind(prob.model, 4)
    assert [t.marker().check(traj).verdict for t in (free, loose)] == ["no tolerance"] * 2
    assert loose.marker().position_tolerance is None
    assert Marker("m", 1, "center", [0.0, 0.0]).check(traj) is None  # no goal: says nothing
    with pytest.raises(ValueError, match="keyed by"):
        KeyframeGoal({"distance": 1.0}, True, term.miss, term.shortfall)

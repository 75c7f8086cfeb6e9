"""A knee or elbow bent backwards bent the right way (solver.tracking.hinge_starts), on a MakeHuman
subject's true pose: the flipped start keeps the limb's three joints where they were and measures the
opposite flexion and sideways bend (closed forms of a half turn about the upper segment's line), twice
flipped is the truth's limb again; the first frame's search fits it for a lost fit whose checks found
that hinge bent backwards."""
import numpy as np
import pytest

from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.tracking import checks
from articula.solver.tracking.hinge_starts import flipped_hinge_start
from articula.solver.tracking.joint_limits import hinge_angles, hinge_points

from .test_trunk_starts import subject  # noqa: F401  (fixture)


def _measured(model, pose, hinge):
    Rm, tm = forward_kinematics(model.skeleton, pose)
    return np.array(hinge_points(hinge, Rm[0], tm[0])), np.array(hinge_angles(hinge, Rm[0], tm[0]))


def test_a_flipped_hinge_keeps_its_limb_line_and_bends_the_other_way(subject):  # noqa: F811
    model, truth = subject
    hinges = checks.prepare(model).hinges
    assert {h.name for h in hinges} >= {"left elbow", "right elbow", "left knee", "right knee"}
    for hinge in hinges:
        joints, (flexion, side) = _measured(model, truth, hinge)
        once = flipped_hinge_start(model, truth, hinge)
        joints1, (flexion1, side1) = _measured(model, once, hinge)
        assert np.abs(joints1 - joints).max() < 1e-9, hinge.name
        assert flexion1 == pytest.approx(-flexion, abs=1e-6) and side1 == pytest.approx(-side, abs=1e-6)
        joints2, angles2 = _measured(model, flipped_hinge_start(model, once, hinge), hinge)
        assert np.abs(joints2 - joints).max() < 1e-9 and np.allclose(angles2, (flexion, side), atol=1e-6)
        untouched = np.ones(model.skeleton.num_bones, bool)
        untouched[[hinge.points[0][0], hinge.points[1][0]]] = False
        same = np.abs(np.sum(once.rotations[0, untouched] * truth.rotations[0, untouched], axis=-1))
        assert np.allclose(same, 1.0, atol=1e-12)           # other bones keep their local rotations


def test_the_search_fits_the_flipped_start_of_a_lost_fit_with_a_hinge_bent_backwards(subject):  # noqa: F811
    from articula.solver.track import first_frame
    model, truth = subject
    prepared = checks.prepare(model)
    elbow = next(h for h in prepared.hinges if h.name == "right elbow")
    finding = checks.Finding("joint_limit", "lost", "right elbow", "right elbow bent backwards beyond its limit",
                             {"joint": "right elbow", "bend": "backwards", "angle_deg": 70.0, "limit_deg": 30.0})
    lost = (truth, 1.0, 1, checks.FrameCheck("lost", [finding.text], [finding], [], {}))
    starts = first_frame._put_right(model, [lost], lambda item: item[1], prepared, 0)
    assert len(starts) == 1
    assert np.array_equal(starts[0].rotations, flipped_hinge_start(model, truth, elbow).rotations)
    good = (truth, 1.0, 0, checks.FrameCheck("good", [], [], [], {}))
    assert first_frame._put_right(model, [good, lost], lambda item: item[1], prepared, 0) == []

"""Real Kinect v1 frames (Skeltrack's test data, LGPL, in ../shared/data/depth/skeltrack_kinect: 12
poses of a person seen from the hips up, a second person in two of them) tracked with the template: no
foot above the hips, the legs flagged out of view in every frame, the second person named and not
tracked, nothing lost."""
import os

import numpy as np
import pytest

from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.roles import role_bones
from articula.solver.track_depth.pipeline import track_recording
from articula.solver.track_depth.source import DepthRecording

from ...conftest import SHARED_DATA

KINECT = os.path.join(SHARED_DATA, "depth", "skeltrack_kinect")


@pytest.fixture(scope="module")
def tracked():
    assert os.path.isdir(KINECT), f"missing test data: {KINECT}"
    rec = DepthRecording.from_folder(KINECT, preset="kinect_v1")
    return rec, track_recording(rec)


def test_no_foot_above_the_hips(tracked):
    rec, res = tracked
    sk = res.model.skeleton
    roles = role_bones(sk.names)
    Rm, tm = forward_kinematics(sk, res.poses)
    h = (np.einsum("nbij,bj->nbi", Rm, sk.heads) + tm) @ rec.up()
    feet = h[:, [roles["foot.L"], roles["foot.R"]]]
    assert (feet < h[:, [roles["hips"]]] - 0.3).all()
    assert (h[:, roles["head"]] > h[:, roles["hips"]] + 0.3).all()


def test_legs_flagged_and_nothing_lost(tracked):
    _, res = tracked
    rep = res.report()
    assert rep["frames"] == 12 and rep["lost"] == 0 and rep["no_person"] == 0
    assert rep["parts_out_of_view"]["left leg"] == 12 and rep["parts_out_of_view"]["right leg"] == 12
    assert any("out of the camera's view" in n and "left leg (12 frames)" in n for n in rep["notes"])


def test_second_person_named(tracked):
    _, res = tracked
    rep = res.report()
    first, last = res.frames[0]["name"], res.frames[-1]["name"]
    assert rep["others_in_view"] == [0, 11], rep["others_in_view"]
    note = next(n for n in rep["notes"] if n.startswith("another person"))
    assert first in note and last in note

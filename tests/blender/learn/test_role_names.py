"""articula.learn_rig names a learned humanoid's bones by role: MakeHuman scans imported and learned in
Blender give a rig whose control bones (and helpers) carry role names at the true joints, the report
and the summary say so, and the saved bundle keeps the names."""
import json

import bpy
import numpy as np
import pytest

from .test_learn_rig import import_sequence

pytestmark = pytest.mark.usefixtures("cache_home")


def test_learned_humanoid_rig_has_role_names(pkg, tmp_path):
    scans, faces, gt = pkg("sample_scenes.registered").posed_sequence("cmu_mb", None, 8, "rom", "lbs", seed=0)
    result, report = pkg("addon.learn.result"), pkg("addon.learn.report")
    options = pkg("solver.learn.options").LearnOptions(max_iterations=0, workers=2)
    ob = import_sequence(pkg, tmp_path, scans, faces, name="human")
    rig, _, outcome = result.learn_from_object(bpy.context, ob, options, name="Human")
    bones = rig.armature.data.bones
    for role in ("hips", "head", "thigh.L", "shin.R", "upper_arm.L", "forearm.R"):
        assert role in bones and "SW-" + role in bones, role
    stored = json.loads(rig.armature[report.REPORT_PROPERTY])
    assert stored["bone_names"]["scheme"] == "roles" and stored["options"]["name_roles"] is True
    assert "named by role" in report.summary_text(outcome)
    rest = outcome.report["rest_scan"]
    true = {str(k): gt["posed_heads"][rest, b] for k, b in zip(gt["major_joint_labels"], gt["major_joint_bones"])}
    world = np.array(rig.armature.matrix_world)
    for role, joint in (("upper_arm.L", "shoulder.L"), ("thigh.R", "hip.R"), ("forearm.R", "elbow.R")):
        head = world[:3, :3] @ np.array(bones[role].head_local) + world[:3, 3]
        assert np.linalg.norm(head - true[joint]) < 0.05, role
    path = str(tmp_path / "human.npz")
    result.save(path, outcome)
    names = list(pkg("solver.formats.bundle").load_bundle(path).model.skeleton.names)
    assert names == list(outcome.model.skeleton.names) and "thigh.L" in names

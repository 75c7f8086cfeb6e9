"""``articula.export_lbs``: the linear-blend rig Blender builds deforms exactly as solver.rig.linear_blend
predicts, and its reported deviation from the exact rig is that prediction (shrinking with more
segments where one joint twists per vertex)."""
import json
import os
import struct
import subprocess
import sys

import numpy as np
import pytest

import bpy

from ...conftest import REPO
from ..rig_helpers import bbox_diagonal, evaluate_frames, poses, subject


def _rig(pkg, model, p):
    rig = pkg("addon.rig.builder").build_rig(bpy.context, model, "Body")
    pkg("addon.rig.actions").write_action(rig.armature, model.skeleton.names, p)
    return rig


def _lbs_objects():
    lbs_arm = bpy.context.view_layer.objects.active
    return lbs_arm, next(ob for ob in lbs_arm.children if ob.type == 'MESH')


def test_lbs_rig_matches_its_prediction(pkg):
    model = subject(pkg, rings=8, segments=10)
    p = poses(pkg, model.skeleton.num_bones, 8, seed=6, max_twist_deg=120)
    rig = _rig(pkg, model, p)
    before = len(bpy.data.objects)
    assert bpy.ops.articula.export_lbs(armature=rig.armature.name, segments=3) == {'FINISHED'}
    assert len(bpy.data.objects) == before + 2
    lbs_arm, mesh = _lbs_objects()
    assert [m.type for m in mesh.modifiers] == ['ARMATURE'] and not mesh.modifiers[0].use_deform_preserve_volume
    le = pkg("solver.rig.linear_blend")
    read = pkg("addon.rig.reader").read_model(rig.armature)
    layout, W = pkg("addon.rig.linear_blend").lbs_rig_weights(read, 3, 4)       # the default: 4 influences
    groups = pkg("addon.scene.mesh_io").read_vertex_groups(mesh, [name for name, *_ in layout])
    np.testing.assert_allclose(groups, W, atol=1e-7)
    assert (groups > 0).sum(axis=1).max() == 4 and (le.lbs_weights(model, 3)[1] > 0).sum(axis=1).max() == 6
    Rm, tm = le.bone_maps(model, p, 3)
    predicted = pkg("solver.rig.skinning").lbs(model.rest_vertices, W, Rm, tm)
    got = evaluate_frames(pkg, mesh, range(1, 9))
    assert np.linalg.norm(got - predicted, axis=2).max() / bbox_diagonal(model.rest_vertices) < 1e-5
    worst, _ = le.deviation(model, p, 3, weights=W)
    full, _ = le.deviation(model, p, 3)
    assert abs(lbs_arm["articula_lbs_max_mm"] - 1000 * worst.max()) < 1e-3      # mm; rig read back as float32
    assert abs(lbs_arm["articula_lbs_unlimited_max_mm"] - 1000 * full.max()) < 1e-3
    assert lbs_arm["articula_lbs_max_influences"] == 4
    hybrid = evaluate_frames(pkg, rig.mesh, range(1, 9))
    assert abs(np.linalg.norm(got - hybrid, axis=2).max() - worst.max()) < 1e-4


@pytest.mark.parametrize("k", [0, 2, 4, 8])
def test_max_influences_option_of_the_operator(pkg, k):
    model = subject(pkg, rings=8, segments=10)
    rig = _rig(pkg, model, poses(pkg, model.skeleton.num_bones, 4, seed=2))
    assert bpy.ops.articula.export_lbs(armature=rig.armature.name, segments=4, max_influences=k) == {'FINISHED'}
    lbs_arm, mesh = _lbs_objects()
    layout, full = pkg("solver.rig.linear_blend").lbs_weights(model, 4)
    counts = (pkg("addon.scene.mesh_io").read_vertex_groups(mesh, [n for n, *_ in layout]) > 0).sum(axis=1)
    full_counts = (full > 0).sum(axis=1)
    assert counts.max() == (full_counts.max() if k in (0, 8) else k)
    assert np.all(counts[full_counts <= max(k, 1)] == full_counts[full_counts <= max(k, 1)])
    assert lbs_arm["articula_lbs_max_influences"] == k
    if k in (0, 8):
        assert lbs_arm["articula_lbs_max_mm"] == lbs_arm["articula_lbs_unlimited_max_mm"]


def test_more_segments_deviate_less_on_a_twisted_limb(pkg):
    tube = pkg("sample_scenes.synthetic")
    model = tube.cylinder()
    Poses = pkg("solver.rig.model").Poses
    q = np.array([[[1, 0, 0, 0], [np.cos(np.pi / 4), 0, np.sin(np.pi / 4), 0]]])     # 90° twist
    p = Poses(q, np.zeros((1, 3)), np.ones(1))
    dev = [pkg("solver.rig.linear_blend").deviation(model, p, n)[0].max() for n in (1, 2, 4, 8)]
    assert all(a > b for a, b in zip(dev, dev[1:]))
    assert dev[0] > 0.05 and dev[-1] < 0.006


def test_export_lbs_without_rig_reports(pkg):
    before = len(bpy.data.objects)
    try:
        result = bpy.ops.articula.export_lbs(armature="nothing")
    except RuntimeError as exc:
        result = {'CANCELLED'}
        assert "nothing" in str(exc)
    assert result == {'CANCELLED'} and len(bpy.data.objects) == before


def _glb_weights(path, names, rest):
    """Skin weights (V, len(names)) stored in a .glb, read from its JOINTS_0/WEIGHTS_0 accessors and
    matched to the rest vertices ``rest`` (V, 3) by position (glTF is Y up: (x, z, -y))."""
    from scipy.spatial import cKDTree
    data = open(path, "rb").read()
    (json_len,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20:20 + json_len])
    binary = data[28 + json_len:]

    def accessor(i):
        a = doc["accessors"][i]
        view = doc["bufferViews"][a["bufferView"]]
        dtype = {5121: np.uint8, 5123: np.uint16, 5126: np.float32}[a["componentType"]]
        width = {"VEC3": 3, "VEC4": 4}[a["type"]]
        assert view.get("byteStride", width * np.dtype(dtype).itemsize) == width * np.dtype(dtype).itemsize
        start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
        return np.frombuffer(binary, dtype, a["count"] * width, start).reshape(-1, width)

    [prim] = [p for m in doc["meshes"] for p in m["primitives"]]
    attrs = prim["attributes"]
    assert "JOINTS_1" not in attrs
    joint_names = [doc["nodes"][j]["name"] for j in doc["skins"][0]["joints"]]
    col = np.array([names.index(n) for n in joint_names])
    pos = accessor(attrs["POSITION"]) @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], np.float32)
    dist, vert = cKDTree(rest).query(pos)
    assert dist.max() < 1e-5 and len(np.unique(vert)) == len(rest)
    W = np.zeros((len(rest), len(names)))
    joints, weights = accessor(attrs["JOINTS_0"]).astype(int), accessor(attrs["WEIGHTS_0"])
    for slot in range(4):
        W[vert, col[joints[:, slot]]] += np.where(weights[:, slot] > 0, weights[:, slot], 0)
    return W


def _batch(args, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    return subprocess.run([sys.executable, os.path.join(REPO, "batch.py"), "export-lbs", *args],
                          capture_output=True, text=True, env=env, timeout=300)


def _rig_blend(pkg, tmp_path):
    """A .blend holding the tube-body rig with a 4-pose action; returns (path, its bytes, model read back)."""
    model = subject(pkg, rings=8, segments=10)
    rig = _rig(pkg, model, poses(pkg, model.skeleton.num_bones, 4, seed=2))
    path = tmp_path / "rig.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path, path.read_bytes(), pkg("addon.rig.reader").read_model(rig.armature)


def test_gltf_export_keeps_every_influence_of_the_limited_rig(pkg, tmp_path):
    """Batch ``export-lbs --out x.glb``: Blender's glTF exporter keeps 4 influences per vertex, so the
    limited rig (the default) arrives whole in JOINTS_0/WEIGHTS_0, while the unlimited one loses the
    smallest weights of its vertices with more than 4; the input .blend is untouched."""
    blend, original, read = _rig_blend(pkg, tmp_path)
    (tmp_path / "out").mkdir()
    stored = {}
    for k, flag in ((4, []), (0, ["--max-influences", "0"])):
        glb = tmp_path / "out" / f"body{k}.glb"
        res = _batch(["--blend", str(blend), "--out", str(glb), *flag], tmp_path)
        assert res.returncode == 0, res.stderr[-2000:]
        assert ("at most 4 influences per vertex" if k else "unlimited influences per vertex") in res.stdout
        assert "unlimited influences: max" in res.stdout and blend.read_bytes() == original
        layout, W = pkg("addon.rig.linear_blend").lbs_rig_weights(read, 4, k)
        stored[k] = (_glb_weights(str(glb), [name for name, *_ in layout], read.rest_vertices), W)
    np.testing.assert_allclose(stored[4][0], stored[4][1], atol=1e-6)
    assert (np.abs(stored[0][0] - stored[0][1]).max(axis=1) > 1e-3).sum() > 50


def test_batch_export_lbs_writes_a_blend(pkg, tmp_path):
    blend, original, read = _rig_blend(pkg, tmp_path)
    out = tmp_path / "lbs.blend"
    res = _batch(["--blend", str(blend), "--armature", "Body", "--segments", "2", "--max-influences", "8",
                  "--out", str(out)], tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    assert blend.read_bytes() == original
    bpy.ops.wm.open_mainfile(filepath=str(out))
    lbs_arm = bpy.data.objects["Body.lbs"]
    assert lbs_arm["articula_lbs_max_influences"] == 8 and "Body" in bpy.data.objects
    mesh = next(ob for ob in lbs_arm.children if ob.type == 'MESH')
    layout, W = pkg("addon.rig.linear_blend").lbs_rig_weights(read, 2, 8)
    groups = pkg("addon.scene.mesh_io").read_vertex_groups(mesh, [name for name, *_ in layout])
    np.testing.assert_allclose(groups, W, atol=1e-7)


@pytest.mark.parametrize("args,message", [
    (["--max-influences", "-1"], "--max-influences must be 0..32"),
    (["--out", "{tmp}/x.obj"], "unknown format '.obj'"),
    (["--out", "{tmp}/missing/x.glb"], "does not exist"),
    (["--armature", "Nope"], "no object named 'Nope'"),
])
def test_batch_export_lbs_refuses_bad_input(pkg, tmp_path, args, message):
    blend, original, _ = _rig_blend(pkg, tmp_path)
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    if "--out" not in args:
        args += ["--out", str(tmp_path / "x.glb")]
    res = _batch(["--blend", str(blend), *args], tmp_path)
    assert res.returncode == 2, res.stderr[-2000:]
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("articula export-lbs: error:") and message in last
    assert blend.read_bytes() == original and not (tmp_path / "x.glb").exists()

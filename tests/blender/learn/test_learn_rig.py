"""articula.learn_rig and ``learn-rig``: learning from an imported scan sequence (or files), the rig it
builds (one key per scan on the scan frames, evaluated mesh = solver's posed model, heat map), the
bundle and report of the batch command, bad input and cancellation leaving the scene unchanged.

Data: the small branching tube body of ``sample_scenes/tube_scans.py`` (509 vertices, 8 parts) posed by
the solver's hybrid skin, written as OBJ files and imported with ``articula.import_scans``.
"""
import argparse
import json
import os
import re
import sys
from types import SimpleNamespace

import bpy
import numpy as np
import pytest

from articula.sample_scenes.tube_scans import hybrid_truth
from ..rig_helpers import key_frames

pytestmark = pytest.mark.usefixtures("cache_home")   # a fresh ARTICULA_HOME per test

M_SCANS = 6
FRAME_START = 3


@pytest.fixture(scope="module")
def truth():
    """(model, poses, scans (M, V, 3)) of the synthetic subject."""
    return hybrid_truth(M=M_SCANS, seed=4, max_angle=0.6)


def write_scans(pkg, folder, scans, faces):
    os.makedirs(folder, exist_ok=True)
    writer = pkg("sample_scenes.mesh_files").SequenceWriter(faces, "obj")
    for k, s in enumerate(scans):
        writer.write(os.path.join(folder, f"pose{k + 1}.obj"), s)
    return folder


def import_sequence(pkg, tmp_path, scans, faces, name="body"):
    folder = write_scans(pkg, str(tmp_path / name), scans, faces)
    # the files hold the scans as given (Z up), not in OBJ's Y-up convention: import them as written
    assert bpy.ops.articula.import_scans(directory=folder, frame_start=FRAME_START, axis_forward='Y',
                                         axis_up='Z') == {'FINISHED'}
    return bpy.context.view_layer.objects.active


def scene_state():
    return ({k: len(getattr(bpy.data, k)) for k in ("objects", "meshes", "armatures", "actions", "collections")},
            bpy.context.scene.frame_start, bpy.context.scene.frame_end, bpy.context.scene.frame_current)


def evaluated(pkg, ob):
    return pkg("addon.scene.mesh_io").evaluated_positions(ob)


def blender_distances(pkg, rig_mesh, scans, faces):
    """(M, V): distance (metres) of scan k's vertices to the surface of the evaluated rig mesh at scan k's
    frame (the solver's report measures the same way, on its own posed model)."""
    sd = pkg("solver.geometry.surface_distance")
    out = []
    for k in range(len(scans)):
        bpy.context.scene.frame_set(FRAME_START + k)
        out.append(sd.distance_to_surface(scans[k], evaluated(pkg, rig_mesh), faces))
    return np.array(out)


# --------------------------------------------------------------------------- building (no solver run)

def test_build_from_the_true_model_replays_every_scan(pkg, tmp_path, truth):
    """result.build with the generating model and poses: one key per scan on the scan frames, the
    evaluated rig mesh equals scan k at frame k, a zero heat map, the report stored on the armature."""
    inputs, heat_map, solve = pkg("addon.learn.inputs"), pkg("addon.learn.heat_map"), pkg("addon.learn.solve")
    result, learn_report = pkg("addon.learn.result"), pkg("addon.learn.report")
    model, poses, scans = truth
    ob = import_sequence(pkg, tmp_path, scans, model.faces)
    inp = inputs.input_from_object(ob)
    assert inp.frame_start == FRAME_START and inp.scans.shape == scans.shape
    np.testing.assert_allclose(inp.scans, scans, atol=1e-6)          # OBJ keeps 6 decimals
    heat = heat_map.vertex_error_mm(model, poses, inp.scans)
    assert heat.max() < 1e-3                                          # sub-micrometre: OBJ rounding only
    report = {"error_mm": {"mean": 0.0, "median": 0.0, "max": 0.0}}
    outcome = solve.LearnOutcome(inp, SimpleNamespace(model=model, poses=poses, report=report), heat)
    with pkg("addon.jobs").scene_guard():
        rig, action = result.build(bpy.context, outcome, "Truth")
    assert rig.armature.name == "Truth" and rig.mesh.data[heat_map.SCALE_PROPERTY] > 0
    assert key_frames(pkg, rig.armature) == {tuple(range(FRAME_START, FRAME_START + M_SCANS))}
    assert (bpy.context.scene.frame_start, bpy.context.scene.frame_end) == (FRAME_START, FRAME_START + M_SCANS - 1)
    for k in range(M_SCANS):
        bpy.context.scene.frame_set(FRAME_START + k)
        np.testing.assert_allclose(evaluated(pkg, rig.mesh), scans[k], atol=2e-5)
        np.testing.assert_allclose(evaluated(pkg, ob), scans[k], atol=1e-6)   # the scans play on the same frames
    me = rig.mesh.data
    attr = me.attributes[heat_map.ERROR_ATTRIBUTE]
    assert (attr.domain, attr.data_type) == ('POINT', 'FLOAT')
    vals = np.empty(len(me.vertices), np.float32)
    attr.data.foreach_get("value", vals)
    np.testing.assert_allclose(vals, heat, atol=1e-6)
    assert me.color_attributes.active_color_name == heat_map.COLOR_ATTRIBUTE
    assert json.loads(rig.armature[learn_report.REPORT_PROPERTY])["error_mm"]["max"] == 0.0


def test_heat_map_colours_follow_the_ramp(pkg):
    heat_map = pkg("addon.learn.heat_map")
    me = bpy.data.meshes.new("m")
    me.vertices.add(3)
    scale = heat_map.add_heat_map(me, [0.0, 2.0, 4.0])
    assert scale == 4.0
    col = np.empty(12, np.float32)
    me.color_attributes[heat_map.COLOR_ATTRIBUTE].data.foreach_get("color", col)
    col = col.reshape(3, 4)
    np.testing.assert_allclose(col[0], [*heat_map.RAMP_COLORS[0], 1], atol=1e-6)   # 0 mm: blue
    np.testing.assert_allclose(col[1], [*heat_map.RAMP_COLORS[2], 1], atol=1e-6)   # half the scale: green
    np.testing.assert_allclose(col[2], [*heat_map.RAMP_COLORS[-1], 1], atol=1e-6)  # the top: red
    assert me.color_attributes.render_color_index == me.color_attributes.active_color_index


def make_armature(sk, location=(0.0, 0.0, 0.0)):
    """A plain armature with the bones of skeleton ``sk`` (created children first, so Blender's bone order
    differs from ``sk``'s), its object at ``location``."""
    arm = bpy.data.objects.new("Init", bpy.data.armatures.new("Init"))
    bpy.context.scene.collection.objects.link(arm)
    arm.location = location
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode='EDIT')
    made = {}
    for b in reversed(range(sk.num_bones)):
        eb = arm.data.edit_bones.new(sk.names[b])
        eb.head, eb.tail = sk.heads[b], sk.tails[b]
        made[b] = eb
    for b in range(1, sk.num_bones):
        made[b].parent = made[sk.parents[b]]
    bpy.ops.object.mode_set(mode='OBJECT')
    return arm


def test_initial_skeleton_from_an_armature(pkg, truth):
    """A plain armature (moved object, bones made in arbitrary order) becomes a skeleton in world
    coordinates, breadth-first, with frames equal to Blender's bone matrices."""
    inputs = pkg("addon.learn.inputs")
    sk = truth[0].skeleton
    arm = make_armature(sk, (0.1, -0.2, 0.3))
    got = inputs.skeleton_from_armature(arm)
    assert got.names[0] == sk.names[0] and sorted(got.names) == sorted(sk.names)
    assert all(got.parents[b] < b for b in range(1, got.num_bones))
    order = [got.names.index(n) for n in sk.names]
    np.testing.assert_allclose(got.heads[order], sk.heads + [0.1, -0.2, 0.3], atol=1e-6)
    np.testing.assert_allclose(got.tails[order], sk.tails + [0.1, -0.2, 0.3], atol=1e-6)
    for b, n in enumerate(sk.names):
        parent = arm.data.bones[n].parent
        assert (parent.name if parent else None) == (sk.names[sk.parents[b]] if b else None)
        np.testing.assert_allclose(got.frames[order[b]], np.array(arm.data.bones[n].matrix_local)[:3, :3], atol=1e-6)
    got.validate()


# --------------------------------------------------------------------------- settings

def test_operator_and_batch_command_defaults_are_the_options(pkg):
    """The operator's properties and the batch command's arguments default to LearnOptions' fields, and
    the operator's bounds are the fields' bounds."""
    opts = pkg("solver.learn.options").LearnOptions()
    props = bpy.ops.articula.learn_rig.get_rna_type().properties
    for name in ("parts", "alpha", "symmetry", "max_iterations", "key_scans", "joint_prior", "memory_limit_gb", "seed"):
        assert props[name].default == pytest.approx(getattr(opts, name), rel=1e-6), name
    # soft limits only (the slider): hard limits would clamp out-of-range values silently
    assert (props["parts"].soft_min, props["parts"].soft_max, props["parts"].hard_max) == (0, 64, 2 ** 31 - 1)
    assert (props["alpha"].soft_min, props["alpha"].soft_max) == (0.0, 1000.0)
    assert (props["key_scans"].soft_min, props["key_scans"].soft_max) == (0, 100000)
    parser = argparse.ArgumentParser()
    pkg("addon.cli.learn").add_commands(parser.add_subparsers())
    args = parser.parse_args(["learn-rig", "--scans", "scans", "--out", "model.npz"])
    assert (args.parts, args.alpha, not args.no_symmetry, args.iterations, args.seed, args.key_scans,
            args.threads, args.joint_prior, args.memory_limit) == (
        opts.parts, opts.alpha, opts.symmetry, opts.max_iterations, opts.seed, opts.key_scans, opts.workers,
        opts.joint_prior, opts.memory_limit_gb)


# --------------------------------------------------------------------------- bad input

@pytest.mark.parametrize("case, message", [
    ("missing", "no object named 'nowhere'"),
    ("not_sequence", "'Cube' is not a scan-sequence object"),
    ("unregistered", "'u': the scans are not registered .* needs registered scans"),
    ("two_frames", "2 scans; learning a rig needs at least 3"),
    ("nan", "scan 1 .* non-finite coordinate .* vertex 7"),
    ("no_armature", "initial armature: no object named 'ghost'"),
    ("bad_folder", "no scan files"),
    ("bundle_folder", "does not exist"),
    ("two_key_scans", "Key Scans: 2 given; learning a rig needs at least 3 scans"),
])
def test_bad_input_is_refused_and_leaves_scene_unchanged(pkg, tmp_path, truth, case, message):
    model, poses, scans = truth
    kwargs = {}
    if case == "missing":
        kwargs["source_object"] = "nowhere"
    elif case == "not_sequence":
        bpy.ops.mesh.primitive_cube_add()
        bpy.context.active_object.name = "Cube"
    elif case == "unregistered":
        folder = write_scans(pkg, str(tmp_path / "u"), scans[:3], model.faces)
        writer = pkg("sample_scenes.mesh_files").SequenceWriter(model.faces[:-5], "obj")
        writer.write(os.path.join(folder, "pose2.obj"), scans[1])      # one frame with fewer faces
        assert bpy.ops.articula.import_scans(directory=folder) == {'FINISHED'}
        assert not bpy.context.active_object.articula.registered
    elif case == "two_frames":
        import_sequence(pkg, tmp_path, scans[:2], model.faces)
    elif case == "nan":
        ob = import_sequence(pkg, tmp_path, scans[:4], model.faces)
        path = bpy.path.abspath(ob.articula.cache_file)
        frames = np.load(path)
        frames[1, 7, 2] = np.nan
        np.save(path, frames)
    elif case == "no_armature":
        import_sequence(pkg, tmp_path, scans[:3], model.faces)
        kwargs["initial_armature"] = "ghost"
    elif case == "bad_folder":
        os.makedirs(tmp_path / "empty")
        kwargs["directory"] = str(tmp_path / "empty")
    elif case == "bundle_folder":
        import_sequence(pkg, tmp_path, scans[:3], model.faces)
        kwargs["output_bundle"] = str(tmp_path / "no" / "such" / "model.npz")
    elif case == "two_key_scans":
        import_sequence(pkg, tmp_path, scans, model.faces)
        kwargs.update(key_scans=2, parts=8)
    before = scene_state()
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.articula.learn_rig(**kwargs)
    assert scene_state() == before


# --------------------------------------------------------------------------- learning (solver run)

def test_learn_from_a_scan_sequence(pkg, tmp_path, truth):
    """The operator on an imported sequence: a rig whose action has one key per scan on the scan frames;
    Blender's evaluated mesh reproduces the solver's posed model, and its distances to the scans give the
    solver's reported statistics and the heat map; the bundle holds the same model and poses."""
    inputs, heat_map, learn_report = pkg("addon.learn.inputs"), pkg("addon.learn.heat_map"), pkg("addon.learn.report")
    sd = pkg("solver.geometry.surface_distance")
    model, poses, scans = truth
    ob = import_sequence(pkg, tmp_path, scans, model.faces)
    out = str(tmp_path / "learned.npz")
    before = set(bpy.data.objects)
    assert bpy.ops.articula.learn_rig(source_object=ob.name, parts=8, max_iterations=1, seed=0, output_bundle=out,
                                      name="Learned") == {'FINISHED'}
    arm = bpy.data.objects["Learned"]
    assert arm.articula.kind == 'RIG_ARMATURE' and len(set(bpy.data.objects) - before) >= 3
    rig_mesh = pkg("addon.rig.reader").find_mesh(arm)
    assert key_frames(pkg, arm) == {tuple(range(FRAME_START, FRAME_START + M_SCANS))}

    bundle = pkg("solver.formats.bundle").load_bundle(out)
    assert len(bundle.poses) == M_SCANS and bundle.model.num_vertices == scans.shape[1]
    posed = pkg("solver.rig.skinning").hybrid_skin(bundle.model, bundle.poses)
    inp_scans = inputs.input_from_object(ob).scans
    dist = blender_distances(pkg, rig_mesh, inp_scans, model.faces)
    for k in range(M_SCANS):
        bpy.context.scene.frame_set(FRAME_START + k)
        np.testing.assert_allclose(evaluated(pkg, rig_mesh), posed[k], atol=5e-5)   # Blender = solver's skin

    report = json.loads(arm[learn_report.REPORT_PROPERTY])
    stats = learn_report.error_summary(report)
    ours = sd.error_statistics(1000 * dist)
    for key in ("mean", "std", "median", "mad", "iqr", "max"):
        assert stats[key] == pytest.approx(ours[key], rel=1e-3, abs=0.01), key   # Blender's float32 mesh
    assert stats["count"] == M_SCANS * scans.shape[1]
    assert stats["mean"] < 10.0                                  # a few mm at most on clean synthetic scans
    heat = np.empty(len(rig_mesh.data.vertices), np.float32)
    rig_mesh.data.attributes[heat_map.ERROR_ATTRIBUTE].data.foreach_get("value", heat)
    np.testing.assert_allclose(heat, 1000 * dist.mean(axis=0), rtol=1e-3, atol=0.01)
    assert heat.mean() == pytest.approx(stats["mean"], rel=1e-5)   # the heat map averages the same distances
    assert rig_mesh.data[heat_map.SCALE_PROPERTY] == pytest.approx(heat.max(), rel=1e-6)
    assert rig_mesh.data.color_attributes.active_color_name == heat_map.COLOR_ATTRIBUTE


def test_learn_matches_a_direct_solver_run(pkg, tmp_path, truth):
    """Same scans, same options: the operator's rig and report are those of solver.learn.pipeline.learn_rig."""
    inputs, learn_report = pkg("addon.learn.inputs"), pkg("addon.learn.report")
    model, poses, scans = truth
    folder = write_scans(pkg, str(tmp_path / "files"), scans, model.faces)
    inp = inputs.input_from_files(inputs.scan_paths(folder))
    direct = pkg("solver.learn.pipeline").learn_rig(inp.scans, inp.faces, parts=8, max_iterations=0, seed=1, symmetry=False)
    assert bpy.ops.articula.learn_rig(directory=folder, parts=8, max_iterations=0, seed=1, symmetry=False,
                                      name="Files") == {'FINISHED'}
    arm = bpy.data.objects["Files"]
    report = json.loads(arm[learn_report.REPORT_PROPERTY])
    for key, value in learn_report.error_summary(direct.report).items():
        assert learn_report.error_summary(report)[key] == pytest.approx(value, rel=1e-9), key
    got = pkg("addon.rig.reader").read_model(arm)
    assert got.skeleton.names == direct.model.skeleton.names
    np.testing.assert_allclose(got.skeleton.heads, direct.model.skeleton.heads, atol=1e-6)
    np.testing.assert_allclose(got.rest_vertices, direct.model.rest_vertices, atol=1e-6)
    assert key_frames(pkg, arm) == {tuple(range(1, M_SCANS + 1))}


def test_initial_armature_becomes_the_skeleton(pkg, tmp_path, truth):
    """initial_armature: the learned rig starts from (and with no optimisation round keeps) its bones."""
    inputs, learn_report = pkg("addon.learn.inputs"), pkg("addon.learn.report")
    model, poses, scans = truth
    ob = import_sequence(pkg, tmp_path, scans, model.faces)
    arm = make_armature(model.skeleton)
    assert bpy.ops.articula.learn_rig(source_object=ob.name, initial_armature=arm.name, max_iterations=0,
                                      name="FromArmature") == {'FINISHED'}
    got = pkg("addon.rig.reader").read_skeleton(bpy.data.objects["FromArmature"])
    given = inputs.skeleton_from_armature(arm)
    assert got.names == given.names
    np.testing.assert_allclose(got.heads, given.heads, atol=1e-6)
    assert json.loads(bpy.data.objects["FromArmature"][learn_report.REPORT_PROPERTY])["options"]["initial_skeleton"]


def test_failure_after_building_rolls_the_rig_back(pkg, tmp_path, truth):
    """The bundle cannot be written (its path is a folder): reported, and the rig already built is removed."""
    model, poses, scans = truth
    ob = import_sequence(pkg, tmp_path, scans, model.faces)
    os.makedirs(tmp_path / "taken.npz")
    before = scene_state()
    with pytest.raises(RuntimeError, match="taken.npz: cannot write the bundle"):
        bpy.ops.articula.learn_rig(source_object=ob.name, parts=8, max_iterations=0,
                                   output_bundle=str(tmp_path / "taken.npz"))
    assert scene_state() == before


def test_learn_from_object_for_scripts(pkg, tmp_path, truth):
    """The synchronous entry point the demo uses: same rig layout, poses on the scan frames."""
    heat_map, result, learn_report = pkg("addon.learn.heat_map"), pkg("addon.learn.result"), pkg("addon.learn.report")
    options = pkg("solver.learn.options")
    model, poses, scans = truth
    ob = import_sequence(pkg, tmp_path, scans, model.faces)
    rig, action, outcome = result.learn_from_object(bpy.context, ob, options.LearnOptions(parts=8, max_iterations=0),
                                                     name="Script")
    assert rig.armature.name == "Script" and rig.mesh.data.attributes.get(heat_map.ERROR_ATTRIBUTE) is not None
    assert tuple(action.frame_range) == (FRAME_START, FRAME_START + M_SCANS - 1)
    assert len(outcome.poses) == M_SCANS and outcome.vertex_error_mm.shape == (scans.shape[1],)
    assert "mean" in learn_report.error_summary(outcome.report)


def test_cancel_leaves_scene_unchanged(pkg, tmp_path, truth, monkeypatch):
    """Esc during the solver run (the job's Progress cancelled half-way) creates nothing."""
    jobs = pkg("addon.jobs")
    model, poses, scans = truth
    ob = import_sequence(pkg, tmp_path, scans, model.faces)
    seen = []

    class CancelHalfWay(jobs.Progress):
        def __call__(self, fraction, text=""):
            seen.append((fraction, text))
            if "Q = " in text:               # the initialisation's objective: before the first round
                self.cancel()
            super().__call__(fraction, text)

    monkeypatch.setattr(jobs, "Progress", CancelHalfWay)
    before = scene_state()
    assert bpy.ops.articula.learn_rig(source_object=ob.name, parts=8, max_iterations=1) == {'CANCELLED'}
    assert scene_state() == before
    assert any(f >= 0.09 for f, _ in seen) and not any(t == "done" for _, t in seen)
    assert any("Q = " in t for _, t in seen)          # the progress text carries the objective


@pytest.mark.skipif(not sys.platform.startswith("linux") or (os.cpu_count() or 1) < 2,
                    reason="the weight step forks its helper on Linux with two or more cores")
def test_forked_weight_helper_inside_blender_gives_the_in_process_result(pkg, tmp_path, truth,
                                                                         monkeypatch):
    """The operator with every weight sweep cut into halves (SPLIT_MIN_WORK 0): half of each sweep runs in
    a process forked from Blender, and the learned bundle equals the one computed with both halves in
    Blender's process."""
    wb, parallel = pkg("solver.learn.weights.sweeps"), pkg("solver.parallel")
    load_bundle = pkg("solver.formats.bundle").load_bundle
    model, poses, scans = truth
    ob = import_sequence(pkg, tmp_path, scans, model.faces)
    monkeypatch.setattr(wb, "SPLIT_MIN_WORK", 0)
    pids = []
    real_call = parallel.ForkedCall

    class Recorded(real_call):
        def __init__(self, fn):
            super().__init__(fn)
            pids.append(self.pid)

    class InProcess(real_call):
        def __init__(self, fn):
            self.fn, self.pid, self.fd = fn, None, None

    bundles = []
    for call in (Recorded, InProcess):
        monkeypatch.setattr(parallel, "ForkedCall", call)
        out = str(tmp_path / f"{call.__name__}.npz")
        assert bpy.ops.articula.learn_rig(source_object=ob.name, parts=8, max_iterations=1, seed=0,
                                          output_bundle=out, name=call.__name__) == {'FINISHED'}
        bundles.append(load_bundle(out))
    assert pids and all(p is not None for p in pids)                 # children were forked
    forked, here = bundles
    for name in ("rest_vertices", "twist_weights", "swing_weights"):
        np.testing.assert_allclose(getattr(forked.model, name), getattr(here.model, name), rtol=0, atol=1e-9)
    np.testing.assert_allclose(forked.poses.rotations, here.poses.rotations, rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- batch command

def test_batch_command_writes_bundle_and_report(pkg, tmp_path, truth):
    model, poses, scans = truth
    folder = write_scans(pkg, str(tmp_path / "scans"), scans, model.faces)
    cli = pkg("addon.cli.main")
    out, rep, blend = (str(tmp_path / "o" / n) for n in ("m.npz", "r.json", "l.blend"))
    os.makedirs(tmp_path / "o")
    assert cli.main(["learn-rig", "--scans", folder, "--parts", "8", "--iterations", "0", "--key-scans", "5",
                     "--joint-prior", "0.05", "--threads", "1", "--out", out, "--report", rep, "--blend", blend]) == 0
    bundle = pkg("solver.formats.bundle").load_bundle(out)
    assert len(bundle.poses) == M_SCANS and bundle.model.skeleton.num_bones == 8
    # the input's coordinates and vertex order: the posed model is near scan k vertex by vertex
    posed = pkg("solver.rig.skinning").hybrid_skin(bundle.model, bundle.poses)
    assert np.median(np.linalg.norm(posed - scans, axis=2)) < 0.01
    doc = json.load(open(rep))
    for key in ("mean", "std", "median", "mad", "iqr", "max"):
        assert np.isfinite(doc["error_mm"][key]), key
    assert doc["error_mm"]["median"] <= doc["error_mm"]["max"]
    assert doc["input"]["scans"] == M_SCANS and doc["options"]["parts"] == 8
    assert doc["options"]["key_scans"] == 5 and len(doc["key_scans"]) == 5 and doc["workers"] == 1
    assert doc["options"]["joint_prior"] == 0.05
    assert doc["timings_s"]["total"] > 0 and {"initialisation", "weights"} <= set(doc["timings_s"])
    assert doc["objective_log"][0][0] == "initial" and doc["objective_log"][0][1] > 0
    assert doc["vertex_error_mm"]["mean"] == pytest.approx(doc["error_mm"]["mean"], rel=1e-9)
    assert os.path.isfile(blend) and not os.path.exists(blend + "1")
    bpy.ops.wm.open_mainfile(filepath=blend)
    kinds = sorted(o.articula.kind for o in bpy.data.objects)
    assert kinds.count('SCAN_SEQUENCE') == 1 and kinds.count('RIG_ARMATURE') == 1


def test_batch_command_bad_input(pkg, tmp_path, truth, capsys):
    model, poses, scans = truth
    cli = pkg("addon.cli.main")
    out = str(tmp_path / "m.npz")
    assert cli.main(["learn-rig", "--scans", str(tmp_path / "nothing"), "--out", out]) == 2
    assert "nothing: file or folder not found" in capsys.readouterr().err
    folder = write_scans(pkg, str(tmp_path / "two"), scans[:2], model.faces)
    assert cli.main(["learn-rig", "--scans", folder, "--out", out]) == 2
    assert "2 scans; learning a rig needs at least 3" in capsys.readouterr().err
    assert cli.main(["learn-rig", "--scans", folder, "--out", str(tmp_path / "no" / "m.npz")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert not os.path.exists(out)


def test_key_scans_learn_from_some_and_pose_every_scan(pkg, tmp_path, truth):
    """key_scans below the scan count: the rig is learned from that many scans, every scan gets a baked pose
    (the others fitted with the learned rig), Blender replays the solver's posed model on every frame, and
    the report covers all scans and names the keys and the thread count."""
    learn_report = pkg("addon.learn.report")
    model, poses, scans = truth
    ob = import_sequence(pkg, tmp_path, scans, model.faces)
    out = str(tmp_path / "keys.npz")
    assert bpy.ops.articula.learn_rig(source_object=ob.name, parts=8, max_iterations=0, key_scans=4,
                                      joint_prior=0.0, output_bundle=out, name="Keys") == {'FINISHED'}
    arm = bpy.data.objects["Keys"]
    report = json.loads(arm[learn_report.REPORT_PROPERTY])
    keys = report["key_scans"]
    assert len(keys) == 4 and report["rest_scan"] in keys and report["options"]["key_scans"] == 4
    assert report["options"]["joint_prior"] == 0.0
    assert report["other_scans"]["scans"] == M_SCANS - 4 and report["workers"] >= 1
    assert learn_report.error_summary(report)["count"] == M_SCANS * scans.shape[1]
    assert key_frames(pkg, arm) == {tuple(range(FRAME_START, FRAME_START + M_SCANS))}
    bundle = pkg("solver.formats.bundle").load_bundle(out)
    posed = pkg("solver.rig.skinning").hybrid_skin(bundle.model, bundle.poses)
    rig_mesh = pkg("addon.rig.reader").find_mesh(arm)
    other = next(k for k in range(M_SCANS) if k not in keys)
    for k in (keys[0], other):
        bpy.context.scene.frame_set(FRAME_START + k)
        np.testing.assert_allclose(evaluated(pkg, rig_mesh), posed[k], atol=5e-5)
    assert np.sqrt(np.mean(np.sum((posed[other] - scans[other]) ** 2, axis=1))) < 0.01     # metres


@pytest.mark.parametrize("parts, message", [
    (10000, "10000 given; it must be from 0 to 64"),
    (30, "30 given for a mesh of 509 vertices; each part needs at least 20 vertices, so at most 25 parts"),
])
def test_operator_and_batch_command_refuse_the_same_parts(pkg, tmp_path, truth, capsys, parts, message):
    """The operator no longer clamps parts to its slider: it and the batch command refuse with the same
    message (naming the property "Parts" and the flag "--parts"), before reading more than the first file."""
    model, poses, scans = truth
    folder = write_scans(pkg, str(tmp_path / "scans"), scans, model.faces)
    before = scene_state()
    with pytest.raises(RuntimeError, match=re.escape("Parts: " + message)):
        bpy.ops.articula.learn_rig(directory=folder, parts=parts)
    assert scene_state() == before
    out = str(tmp_path / "m.npz")
    assert pkg("addon.cli.main").main(["learn-rig", "--scans", folder, "--parts", str(parts), "--out", out]) == 2
    assert "--parts: " + message in capsys.readouterr().err and not os.path.exists(out)


def test_operator_learns_with_a_separate_island(pkg, tmp_path):
    """A detached "eye" near the head: the operator learns, the rig's mesh has every vertex, and the
    summary and the stored report say the island was carried rigidly."""
    from ...solver.learn.test_islands import with_eye
    truth, scans = with_eye(6)
    folder = write_scans(pkg, str(tmp_path / "eye"), scans, truth.faces)
    assert bpy.ops.articula.learn_rig(directory=folder, parts=8, max_iterations=0, name="Eye") == {'FINISHED'}
    arm = bpy.data.objects["Eye"]
    report = json.loads(arm[pkg("addon.learn.report").REPORT_PROPERTY])
    assert report["islands"]["count"] == 1 and report["islands"]["vertices"] == 8
    meshes = [o for o in bpy.data.objects if o.type == 'MESH' and o.parent == arm]
    assert any(len(o.data.vertices) == truth.num_vertices for o in meshes)
    text = pkg("addon.learn.report").islands_text(report)
    assert text.startswith("1 separate island (8 vertices) carried rigidly by bone ")


def test_summary_says_how_the_parts_came_about(pkg):
    """The summary line's parts: the count and its two phases, the pairs, removed empty end bones, welded
    seam vertices; nothing for a report without them."""
    parts_text = pkg("addon.learn.report").parts_text
    report = {"parts": 22, "part_count": {"curve_parts": 14, "splits": [{}] * 8}, "mirror_pairs": [["a.L", "a.R"]] * 5,
              "empty_parts_removed": ["part_30"], "welded_vertices": 310}
    assert parts_text(report) == ("22 parts (14 from the error curve + 8 segments moving on their own), "
                                  "5 left/right pairs, 1 empty end bone removed, 310 seam vertices welded")
    assert parts_text({"parts": 8, "part_count": {"curve_parts": 8, "splits": []}}) == "8 parts"
    assert parts_text({}) == ""

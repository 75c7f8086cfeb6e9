"""``demo`` end to end, small: 4 MakeHuman scans, 6 depth frames, a learned rig of few parts and one
outer round, a small picture.  Run as users run it (``python batch.py demo ...`` in a fresh process),
then the saved ``demo.blend`` is opened here and checked: the learned rig is there beside the scans
with one baked key per scan, its report's error is small, its mesh carries the heat map, and the
picture shows heat-map colours (which no palette colour of the other exhibits reaches)."""
import json
import os
import re
import subprocess
import sys

import bpy
import numpy as np
import pytest

from ...conftest import REPO
from ..rig_helpers import key_frames

SCANS = 4
DEPTH_FRAMES = 6     # more than the scans: the frame range must cover the longer exhibit
TRACK = 2            # unregistered frames tracked with the learned rig


def _demo(tmp, *args):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp / "user"), ARTICULA_HOME=str(tmp / "home"))
    return subprocess.run([sys.executable, os.path.join(REPO, "batch.py"), "demo", "--out", str(tmp / "out"), *args],
                          capture_output=True, text=True, env=env, timeout=1800)


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """(stdout, output folder) of one small demo run, shared by the tests of this module."""
    tmp = tmp_path_factory.mktemp("demo")
    res = _demo(tmp, "--scans", str(SCANS), "--depth-frames", str(DEPTH_FRAMES), "--parts", "6", "--learn-iterations", "1",
                "--track-frames", str(TRACK), "--resolution", "480x270")
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-3000:]
    return res.stdout, tmp / "out"


def _centre_x(ob):
    mw = np.array(ob.matrix_world)
    return float((np.array(ob.bound_box) @ mw[:3, :3].T + mw[:3, 3])[:, 0].mean())


def test_demo_learns_a_rig_beside_the_scans(pkg, demo_run):
    stdout, out = demo_run
    heat_map, learn_report = pkg("addon.learn.heat_map"), pkg("addon.learn.report")
    demo = pkg("addon.cli.demo")
    line = next((ln for ln in stdout.splitlines() if ln.startswith("demo: learned rig")), "")
    assert "6 parts" in line and "mean" in line and "max" in line, stdout[-2000:]

    bpy.ops.wm.open_mainfile(filepath=str(out / "demo.blend"))
    arms = [ob for ob in bpy.data.objects if ob.type == 'ARMATURE' and learn_report.REPORT_PROPERTY in ob]
    assert [ob.name for ob in arms] == [demo.LEARNED_NAME]
    arm = arms[0]
    report = json.loads(arm[learn_report.REPORT_PROPERTY])
    err = learn_report.error_summary(report)
    assert report["parts"] == 6 and report["input"]["scans"] == SCANS
    assert f"mean {err['mean']:.2f}" in line

    scans = next(ob for ob in bpy.data.objects if ob.type == 'MESH' and ob.articula.kind == 'SCAN_SEQUENCE'
                 and ob.articula.frame_count == SCANS)
    frames, _ = pkg("addon.sequences.scans").scan_frames(scans)
    # What a rig that does not move would score: the mean vertex distance of the scans to the best single
    # scan (about 200 mm for these 4 range-of-motion poses).  6 parts after one round of the learner
    # measured 15.5 mm mean, 9.8 mm median; the bounds leave room for the learner's changes.
    static_mm = min(1e3 * np.linalg.norm(frames - frames[r], axis=2).mean() for r in range(len(frames)))
    assert static_mm > 100.0
    assert 0.0 < err["mean"] < min(30.0, 0.15 * static_mm) and err["median"] < 20.0, (err, static_mm)

    start = scans.articula.frame_start
    assert key_frames(pkg, arm) == {tuple(range(start, start + SCANS))}    # one baked pose per scan

    meshes = [ob for ob in bpy.data.objects if ob.type == 'MESH' and ob.parent == arm]
    assert len(meshes) == 1
    me = meshes[0].data
    assert me.color_attributes.active_color_name == heat_map.COLOR_ATTRIBUTE
    heat = np.empty(len(me.vertices), np.float32)
    me.attributes[heat_map.ERROR_ATTRIBUTE].data.foreach_get("value", heat)
    assert abs(float(heat.mean()) - err["mean"]) < 0.05 * err["mean"] + 1e-3   # same distances, averaged

    # Its own exhibit: one spacing to the right of the scans, at the frame the picture shows.
    bpy.context.scene.frame_set(bpy.context.scene.frame_current)
    dx = _centre_x(meshes[0]) - _centre_x(scans)
    assert abs(dx - demo.SPACING) < 0.1, dx
    labels = {ob.data.body for ob in bpy.data.objects if ob.type == 'FONT'}
    assert demo.TITLES["scans"] in labels
    assert demo.learned_title(me[heat_map.SCALE_PROPERTY]) in labels          # the heat map's scale in its title


def test_demo_tracks_the_unregistered_scans_with_the_learned_rig(pkg, demo_run):
    """A rig built from the learned rig's bundle plays the tracked walk over the unregistered captures:
    one key per captured frame, the report's median scan-to-model distance bounded, the rig's mesh where
    the captures are.  The bound is loose: 6 parts learned in one round from 4 range-of-motion scans
    cannot bend as the walk does (measured 34.6 mm; its rest pose placed on the captures by the
    initialisation's alignment: 170 mm)."""
    stdout, out = demo_run
    demo = pkg("addon.cli.demo")
    line = next((ln for ln in stdout.splitlines() if ln.startswith("demo: tracked rig")), "")
    assert f"{TRACK} frames" in line, stdout[-2000:]
    bpy.ops.wm.open_mainfile(filepath=str(out / "demo.blend"))
    arm = bpy.data.objects[demo.TRACKED_NAME]
    report = json.loads(arm["articula_track_report"])
    assert len(report["frames"]) == TRACK and report["skipped_frames"] == [] and report["lost_frames"] == []
    assert report["median_mm"] < 50.0, report["median_mm"]
    caps = next(ob for ob in bpy.data.objects if ob.type == 'MESH' and ob.articula.kind == 'SCAN_SEQUENCE'
                and ob.articula.frame_count == TRACK)
    start = caps.articula.frame_start
    assert key_frames(pkg, arm) == {tuple(range(start, start + TRACK))}
    bpy.context.scene.frame_set(start)
    mesh = next(ob for ob in bpy.data.objects if ob.type == 'MESH' and ob.parent == arm)
    assert abs(_centre_x(mesh) - _centre_x(caps)) < 0.15
    assert demo.TITLES["tracked"] in {ob.data.body for ob in bpy.data.objects if ob.type == 'FONT'}


def test_demo_prints_the_numbers_of_its_caption(pkg, demo_run):
    """One summary line holds what the README's caption quotes, read back here from the saved scene: the
    learned rig's control bones (one per part, swing helpers apart) and error statistics, the tracked frames' median, and every stage's time."""
    stdout, out = demo_run
    learn_report = pkg("addon.learn.report")
    line = next((ln for ln in stdout.splitlines() if ln.startswith("demo: summary:")), "")
    assert line, stdout[-2000:]
    bpy.ops.wm.open_mainfile(filepath=str(out / "demo.blend"))
    arm = next(ob for ob in bpy.data.objects if learn_report.REPORT_PROPERTY in ob)
    report = json.loads(arm[learn_report.REPORT_PROPERTY])
    err = learn_report.error_summary(report)
    assert f"learned rig {report['parts']} control bones" in line, line             # one per part
    assert report["parts"] == sum(not bone.name.startswith("SW-") for bone in arm.data.bones)
    assert f"mean {err['mean']:.2f}, median {err['median']:.2f}, max {err['max']:.2f}" in line, line
    tracked = json.loads(bpy.data.objects[pkg("addon.cli.demo").TRACKED_NAME]["articula_track_report"])
    assert f"tracked {TRACK} frames, median {tracked['median_mm']:.2f} mm" in line, line
    times = re.search(r"times: (.*); total ([0-9.]+) s", line)
    stages = dict(re.fullmatch(r"(.+) ([0-9.]+) s", part).groups() for part in times.group(1).split(", "))
    assert set(stages) == {"sample data", "import and build", "learning", "tracking", "rendering", "saving"}
    assert sum(map(float, stages.values())) <= float(times.group(2)) + 0.1 * len(stages)


def test_demo_frame_range_covers_every_exhibit(pkg, demo_run):
    """The scene's range covers the depth recording (6 frames) as well as the scans and rigs (4 poses)."""
    _stdout, out = demo_run
    bpy.ops.wm.open_mainfile(filepath=str(out / "demo.blend"))
    scene = bpy.context.scene
    ends = {ob.name: (ob.articula.frame_start, ob.articula.frame_start + ob.articula.frame_count - 1)
            for ob in bpy.data.objects if ob.articula.frame_count}
    assert sorted(e - s + 1 for s, e in ends.values()) == [TRACK, SCANS, DEPTH_FRAMES], ends
    assert scene.frame_start == min(s for s, _e in ends.values())
    assert scene.frame_end == max(e for _s, e in ends.values()) == DEPTH_FRAMES
    rigs = [ob for ob in bpy.data.objects if ob.type == 'ARMATURE' and ob.animation_data
            and ob.animation_data.action]
    assert len(rigs) == 3                                 # the built rig, the learned rig, the tracked rig
    for arm in rigs:
        assert max(max(keys) for keys in key_frames(pkg, arm)) <= scene.frame_end


def test_demo_picture_shows_the_heat_map(pkg, demo_run):
    """Saturated colours (the heat map's blue/cyan/green/yellow/red) in the learned rig's and the tracked
    captures' part of the picture only: the palette colours of the other exhibits are pastel."""
    _, out = demo_run
    img = bpy.data.images.load(str(out / "demo.png"))
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    rgb = px.reshape(h, w, 4)[:, :, :3]
    saturated = (rgb.max(axis=2) - rgb.min(axis=2)) > 0.45
    cols = np.nonzero(saturated.any(axis=0))[0]
    assert saturated.sum() > 0.002 * w * h, saturated.sum()
    # the learned rig and the tracked captures (error colours) are the two rightmost of the five exhibits:
    # the saturated pixels sit in the right part of the picture
    assert np.percentile(cols, 5) > 0.45 * w, (cols.min(), cols.max(), w)


def test_demo_no_learn_keeps_the_three_exhibits(pkg, tmp_path):
    res = _demo(tmp_path, "--no-learn", "--scans", "3", "--depth-frames", "2", "--resolution", "160x90")
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-3000:]
    assert not [ln for ln in res.stdout.splitlines() if ln.startswith("demo: learn")]
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "out" / "demo.blend"))
    learn_report, demo = pkg("addon.learn.report"), pkg("addon.cli.demo")
    assert not [ob for ob in bpy.data.objects if learn_report.REPORT_PROPERTY in ob]
    assert {ob.data.body for ob in bpy.data.objects if ob.type == 'FONT'} == {
        title for key, title in demo.TITLES.items() if key != "tracked"}
    assert bpy.context.scene.display.shading.color_type == 'OBJECT'     # palette colours only


def test_demo_refuses_too_few_scans_to_learn_from(tmp_path):
    res = _demo(tmp_path, "--scans", "2")
    assert res.returncode == 2
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("articula demo: error: --scans 2") and "--no-learn" in last
    assert not (tmp_path / "out" / "demo_data").exists()                 # refused before any work

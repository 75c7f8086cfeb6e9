"""Shared by ``bench_track_depth.py`` and its bad-input cases (``_depth_bad_inputs.py``): the cached synthetic
recordings, tracking one of them, and posed joint positions."""
import os
import time

import _common  # noqa: F401  (makes ``import articula`` work)
import numpy as np


def cache(name):
    """A folder for the cached recording ``name`` under ``$ARTICULA_HOME/bench_depth``."""
    root = os.path.join(os.environ.get("ARTICULA_HOME", os.path.expanduser("~/.cache/articula")), "bench_depth")
    return os.path.join(root, name)


def recording(subject, resolution, frames):
    """The cached synthetic recording of ``subject`` (``sample_scenes.depth_bench``; its description dict)."""
    from articula.sample_scenes.depth_bench import bench_recording
    w, h = resolution
    return bench_recording(cache(f"s{subject}_{w}x{h}_{frames}"), subject, (w, h), frames)


def joints_of(model, poses, bones):
    """(N, len(bones), 3) posed heads of ``bones``."""
    from articula.solver.rig.kinematics import forward_kinematics
    Rm, tm = forward_kinematics(model.skeleton, poses)
    return (np.einsum("nbij,bj->nbi", Rm, model.skeleton.heads) + tm)[:, bones]


def track(folder, model, **options):
    """Track the recording in ``folder`` with ``model`` (None: the template body); ``(result, wall seconds)``."""
    from articula.solver.track_depth.options import DepthTrackOptions
    from articula.solver.track_depth.pipeline import track_recording
    from articula.solver.track_depth.source import DepthRecording
    rec = DepthRecording.from_folder(folder)
    t0 = time.perf_counter()
    res = track_recording(rec, model, DepthTrackOptions(**options))
    return res, time.perf_counter() - t0


def world_variant(r, world):
    """The recording ``r`` (:func:`recording`) seen in another world: ``world`` is a name of
    ``_track_metrics.WORLDS`` (the generated Z-up world rotated) or "camera" (no ``cam_to_world``: the
    camera's own frame, OpenCV axes).  The depth frames are linked, ``intrinsics.json`` rewritten; returns
    ``(folder, joints (N, 14, 3) in that world)``.  The model stays as it is (its own rest axes)."""
    import _track_metrics as tm
    from articula.solver.depth import camera as cam
    c2w = r["cam_to_world"]
    if world == "camera":
        G = np.linalg.inv(c2w)
    else:
        G = np.eye(4)
        G[:3, :3] = tm.WORLDS[world]
        G[:3, 3] = (0.4, -0.7, 0.25) if world != "zup" else 0.0     # the origin moved too
    folder = r["out_dir"] + f"_world_{world}"
    os.makedirs(folder, exist_ok=True)
    for p in r["depth_paths"]:
        link = os.path.join(folder, os.path.basename(p))
        if not os.path.lexists(link):
            os.symlink(p, link)
    cam.save_intrinsics(os.path.join(folder, "intrinsics.json"), cam.load_intrinsics(r["intrinsics"]),
                        cam_to_world=None if world == "camera" else G @ c2w)
    return folder, r["joints"] @ G[:3, :3].T + G[:3, 3]

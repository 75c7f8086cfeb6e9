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

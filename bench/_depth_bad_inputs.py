"""The bad-input cases of ``./run bench track_depth --only bad``: copies of a synthetic recording with
nobody in view for a while, the person leaving through the frame edge, missing frame numbers, absurd
intrinsics, an 8-bit frame, and a long recording (the frames repeated) for bounded memory."""
import json
import os
import resource
import shutil

import numpy as np

import _common
from _track_depth_runs import joints_of, recording, track


def _copy(src, dst, frames=None):
    if os.path.isdir(dst):
        shutil.rmtree(dst)
    os.makedirs(dst)
    names = sorted(n for n in os.listdir(src) if n.startswith("depth_") and n.endswith(".png"))
    for n in names if frames is None else [names[i] for i in frames]:
        shutil.copy(os.path.join(src, n), os.path.join(dst, n))
    shutil.copy(os.path.join(src, "intrinsics.json"), os.path.join(dst, "intrinsics.json"))
    return [os.path.join(dst, n) for n in sorted(os.listdir(dst)) if n.endswith(".png")]


def _edit(paths, frames, change):
    from articula.solver.formats.png16 import read_png16, write_png16
    for k in frames:
        write_png16(paths[k], change(read_png16(paths[k])))


def _only_floor(depth):
    """A frame of the empty room: keep the pixels of the lowest 25% of the image (the floor) only."""
    out = depth.copy()
    rows = np.arange(depth.shape[0])[:, None]
    out[(rows < int(0.75 * depth.shape[0])) & (depth > 0)] = 0
    return out


def _shifted_right(depth, share):
    """The frame's content moved right by ``share`` of its width (the person walks out through the edge)."""
    out = np.zeros_like(depth)
    s = int(share * depth.shape[1])
    out[:, s:] = depth[:, :depth.shape[1] - s]
    return out


def _statuses(res, frames):
    return ", ".join(f"{k}:{res.frames[k]['status']}" for k in frames)


def _joint_error(res, r, frames):
    e = np.linalg.norm(joints_of(res.model, res.poses, r["joint_bones"]) - r["joints"][:len(res.poses)], axis=2)
    return 1000 * float(e[frames].mean())


def _refused(label, folder):
    from articula.solver.errors import ArticulaInputError
    try:
        track(folder, None)
    except ArticulaInputError as exc:
        _common.report(f"bad input {label}", "refused", note=str(exc))
        return
    _common.report(f"bad input {label}", "NOT refused")


def bad_inputs(subject, frames, long_frames, cache):
    r = recording(subject, (320, 240), frames)
    src, model = r["out_dir"], r["model"]
    # nobody in view for frames 20-29, then back
    paths = _copy(src, cache("bad_nobody"))
    _edit(paths, range(20, 30), _only_floor)
    res, _ = track(os.path.dirname(paths[0]), model)
    _common.report("bad input nobody in view (frames 20-29)", _statuses(res, [19, 20, 29, 30, 31]),
                   note=f"joint error after the person returns (frames 31-{frames - 1}): "
                        f"{_joint_error(res, r, slice(31, None)):.1f} mm")
    # the person leaves through the right edge (frames 30-39: the image content moves right by 8% more
    # each frame), then is back where it was
    paths = _copy(src, cache("bad_edge"))
    for k in range(30, 40):
        _edit(paths, [k], lambda d, k=k: _shifted_right(d, 0.08 * (k - 29)))
    res, _ = track(os.path.dirname(paths[0]), model)
    _common.report("bad input person at the frame edge (frames 30-39)", _statuses(res, [30, 35, 39, 40, 41]),
                   note=f"joint error frames 0-29 {_joint_error(res, r, slice(0, 30)):.1f} mm, "
                        f"frames 42-{frames - 1} {_joint_error(res, r, slice(42, None)):.1f} mm")
    # missing frame numbers
    keep = [k for k in range(frames) if not 10 <= k <= 12]
    paths = _copy(src, cache("bad_gaps"), keep)
    res, _ = track(os.path.dirname(paths[0]), model)
    _common.report("bad input missing frames 10-12", f"{len(res.poses)} poses for {len(paths)} files",
                   note="; ".join(n for n in res.notes if "missing" in n))
    # absurd focal length
    paths = _copy(src, cache("bad_focal"), range(4))
    ipath = os.path.join(os.path.dirname(paths[0]), "intrinsics.json")
    data = json.load(open(ipath))
    data["fx"] = data["fy"] = 5.0
    json.dump(data, open(ipath, "w"))
    _refused("focal length 5 px", os.path.dirname(paths[0]))
    # an 8-bit frame
    paths = _copy(src, cache("bad_8bit"), range(4))
    from articula.solver.formats.png16 import write_png16
    write_png16(paths[2], np.full((240, 320), 128, np.uint8))          # an 8-bit PNG
    _refused("8-bit PNG", os.path.dirname(paths[0]))
    _long(src, model, frames, long_frames, cache)


def _long(src, model, frames, n, cache):
    """``n`` frames (the recording repeated, as symbolic links): time and peak memory."""
    folder = cache(f"bad_long_{n}")
    if not os.path.isdir(folder) or len(os.listdir(folder)) != n + 1:
        if os.path.isdir(folder):
            shutil.rmtree(folder)
        os.makedirs(folder)
        names = sorted(x for x in os.listdir(src) if x.startswith("depth_") and x.endswith(".png"))
        for k in range(n):
            cycle, i = divmod(k, frames)
            i = i if cycle % 2 == 0 else frames - 1 - i          # play back and forth: continuous motion
            os.symlink(os.path.join(src, names[i]), os.path.join(folder, f"depth_{k:05d}.png"))
        shutil.copy(os.path.join(src, "intrinsics.json"), os.path.join(folder, "intrinsics.json"))
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    res, wall = track(folder, model)
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    rep = res.report()
    _common.report(f"long recording {n} frames", f"{wall:.0f} s", note=f"{n / wall:.1f} frames/s end to end, "
                   f"lost {rep['lost']}; peak RSS {rss1:.0f} MB (before: {rss0:.0f} MB)")

"""A depth recording to track, read one frame at a time (memory stays bounded for any length): the frame
files of a folder in natural order, the camera (``intrinsics.json`` or a preset; its optional
``cam_to_world`` gives the tracking frame, otherwise the camera frame, OpenCV axes), the floor and
static background fitted once from frames spread over the recording, and gaps in the frame numbering.
"""
from __future__ import annotations

import dataclasses
import os
import re

import numpy as np

from ..depth import camera as cam
from ..depth import frames as dp
from ..depth import recording as rec
from ..errors import ArticulaInputError
from .observation import ViewCamera, depth_image, observe
from .orientation import recording_up


def numbering_gaps(names) -> list:
    """``(after, before)`` name pairs between which the trailing frame numbers skip values, when the
    names are numbered frame by frame (most steps are 1; time stamps in names are not a numbering)."""
    nums = []
    for n in names:
        m = re.search(r"(\d+)(?=\.[^.]+$)", os.path.basename(n))
        nums.append(int(m.group(1)) if m else None)
    steps = [b - a for a, b in zip(nums, nums[1:]) if a is not None and b is not None]
    if not steps or np.mean(np.array(steps) == 1) < 0.5:
        return []
    return [(os.path.basename(names[i]), os.path.basename(names[i + 1])) for i in range(len(names) - 1)
            if nums[i] is not None and nums[i + 1] is not None and nums[i + 1] - nums[i] > 1]


@dataclasses.dataclass
class DepthRecording:
    """``paths`` of the depth frames (16-bit PNG, or EXR in metres read by ``read_exr``); ``camera``
    (:class:`.observation.ViewCamera`); ``world`` True when ``cam_to_world`` came from ``intrinsics.json``;
    ``options`` (:class:`solver.depth.frames.DepthOptions`); ``notes`` for the report; ``setup_paths``: the
    frames the floor and background are fitted on (all frames of the folder when ``paths`` is a range of
    them, so a chunk sees the floor a whole run sees); ``read_exr(path) -> (H, W)`` metres (Blender's)."""
    paths: list
    camera: ViewCamera
    world: bool
    options: dp.DepthOptions
    notes: list
    setup: object = None
    setup_paths: list = None
    read_exr: object = None

    @classmethod
    def from_folder(cls, folder: str, preset: str | None = None, options: dp.DepthOptions | None = None,
                    frames=None, depth_scale: float | None = None, read_exr=None) -> "DepthRecording":
        """The depth frames of ``folder`` (``frames``: an optional ``slice`` of them) with ``intrinsics.json``
        from the folder, else the camera ``preset`` (e.g. ``kinect_v1``, noted in the report).  PNG values
        are in the camera's ``depth_unit_m`` unless ``depth_scale`` (metres per unit) is given, as on import;
        EXR frames are metres, read by ``read_exr`` (:func:`solver.depth.recording.depth_frames`)."""
        opts = options or dp.DepthOptions()
        paths = all_paths = rec.list_frames(folder, rec.DEPTH_EXTENSIONS)
        if frames is not None:
            paths = all_paths[frames]
            if not paths:
                raise ArticulaInputError(f"{folder}: the frame range selects no frame")
        notes = []
        ipath = os.path.join(folder, "intrinsics.json")
        if os.path.exists(ipath):
            intr, c2w = rec.camera_file(ipath)
        elif preset:
            intr, c2w = cam.preset(preset), None
            notes.append(f"no intrinsics.json: the {intr.name} camera preset is assumed")
        else:
            raise ArticulaInputError(f"{folder}: no intrinsics.json; give a camera preset "
                                     f"({', '.join(cam.PRESETS)})")
        opts = rec.unit_options(opts, intr, depth_scale)
        opts.validate()
        rec.check_png_frames(rec.depth_frames(paths, read_exr))
        for a, b in numbering_gaps(paths):
            notes.append(f"frames missing in the numbering between {a} and {b}")
        camera = ViewCamera(intr, np.eye(4) if c2w is None else c2w)
        notes.append("poses in the world frame of intrinsics.json's cam_to_world" if c2w is not None
                     else "poses in the camera frame (OpenCV: +X right, +Y down, +Z forward)")
        return cls(paths, camera, c2w is not None, opts, notes, setup_paths=all_paths, read_exr=read_exr)

    def __len__(self) -> int:
        return len(self.paths)

    @property
    def names(self) -> list:
        return [os.path.basename(p) for p in self.paths]

    def prepare(self, progress=None) -> None:
        """Fit the floor (and background) once; rescales the intrinsics to the frames' size."""
        if self.setup is None:
            frames = rec.depth_frames(self.setup_paths or self.paths, self.read_exr)
            self.setup = rec.recording_setup(frames, self.camera.intr, self.options,
                                             progress=progress or (lambda f, t="": None))
            self.camera = ViewCamera(self.setup.intr, self.camera.cam_to_world)
            self.notes.extend(self.setup.notes)

    def up(self) -> np.ndarray:
        """The up direction in the tracking frame (:func:`.orientation.recording_up`): the floor's normal
        when a floor was found, else the camera's image up; whichever world ``cam_to_world`` names."""
        floor = self.setup.floor[0] if self.setup is not None and self.setup.floor is not None else None
        return recording_up(self.camera.R, floor)

    def observations(self, max_points: int, start: int = 0, person: str = "centre"):
        """``(k, Observation)`` for every frame from ``start``, decoded in order; the person chosen by
        ``person`` (:data:`.options.PERSON_CHOICES`) and then followed from frame to frame."""
        self.prepare()
        frames = rec.depth_frames(self.paths, self.read_exr)
        s, follow = self.setup, None
        for k, z in rec.stream_metres(frames[start:], self.options, s.shape):
            obs = observe(z, s.rays, self.camera, self.options, s.background, s.floor, max_points=max_points,
                          choose=person, follow=follow)
            follow = obs.centre
            yield start + k, obs


class PointsRecording:
    """The same interface as :class:`DepthRecording` for frames already turned into sensor-frame points
    (an imported depth object's cache, :class:`solver.formats.point_files.PointSequence`): each frame
    is rendered back into the camera's depth image (:func:`.observation.depth_image`) and observed like
    a depth frame; floor and background were removed by the import.  Without intrinsics (plain
    point-cloud files) ``default_preset`` stands in for the camera at the sensor origin."""

    def __init__(self, seq, cam_to_world=None, default_preset: str = "kinect_v1", frames=None,
                 options: dp.DepthOptions | None = None):
        self.seq, self.options = seq, options or dp.DepthOptions()
        self.index = list(range(seq.frame_count))[frames] if frames is not None else list(range(seq.frame_count))
        if not self.index:
            raise ArticulaInputError("the frame range selects no frame of the recording")
        self.notes = []
        if seq.intrinsics is not None:
            w, h, fx, fy, cx, cy = seq.intrinsics
            intr = cam.Intrinsics(int(w), int(h), float(fx), float(fy), float(cx), float(cy)).validate()
        else:
            intr = cam.preset(default_preset)
            self.notes.append(f"point clouds without intrinsics: seen through a {default_preset} camera at the origin")
        self.world = cam_to_world is not None
        self.camera = ViewCamera(intr, np.eye(4) if cam_to_world is None else cam_to_world)
        self.notes.append("poses in the world frame" if self.world else "poses in the sensor frame")

    def __len__(self) -> int:
        return len(self.index)

    @property
    def names(self) -> list:
        names = self.seq.frame_names or []
        return [names[k] if k < len(names) else f"frame {k}" for k in self.index]

    def prepare(self, progress=None) -> None:
        pass

    def up(self) -> np.ndarray:
        return recording_up(self.camera.R, self.seq.floor[0] if self.seq.floor is not None else None)

    def observations(self, max_points: int, start: int = 0, person: str = "centre"):
        rays = dp.pixel_rays(self.camera.intr)
        follow = None
        for i, k in enumerate(self.index[start:], start=start):
            z = depth_image(self.seq.points[self.seq.frame(k)], self.camera.intr)
            obs = observe(z, rays, self.camera, self.options, floor=self.seq.floor, max_points=max_points,
                          floor_removed=True, choose=person, follow=follow)
            follow = obs.centre
            yield i, obs

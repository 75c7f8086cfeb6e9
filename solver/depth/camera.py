"""Pinhole depth cameras: intrinsics, presets, ``intrinsics.json``, projection and back-projection.

Conventions (the same for every depth tool in Articula)
------------------------------------------------------
* **Camera frame** (OpenCV / depth-sensor convention): +X right, +Y down, +Z forward (the viewing
  direction).  A Blender camera looks down its local -Z with +Y up, so
  ``blender_cam_matrix_world = cam_to_world @ diag(1, -1, -1, 1)`` (see :func:`blender_from_cv`);
  :func:`blender_camera_settings` gives the lens, sensor, shift and resolution of the same camera.
* **Pixels**: column ``u`` (0..W-1, to the right), row ``v`` (0..H-1, downwards); the centre of pixel
  (u, v) is at image coordinates (u, v).  So the image centre is ((W-1)/2, (H-1)/2).
* **Depth** is the Z coordinate in the camera frame (distance along the optical axis, *not* along
  the ray), in metres in memory and ``depth_unit_m`` (default millimetres) in 16-bit PNGs; 0 = none.
* Projection: ``u = fx X/Z + cx``, ``v = fy Y/Z + cy``; back-projection ``X = (u - cx) Z / fx``,
  ``Y = (v - cy) Z / fy``.  No lens distortion (depth streams are usually delivered undistorted).
* **Extrinsics**: ``cam_to_world`` (4, 4) maps camera-frame points to world (metres, world Z up).

``intrinsics.json`` ("articula-intrinsics/1")::

    {"format": "articula-intrinsics/1", "name": "kinect_v1", "width": 640, "height": 480,
     "fx": 580.0, "fy": 580.0, "cx": 319.5, "cy": 239.5, "depth_unit_m": 0.001,
     "cam_to_world": [[1, 0, 0, 0], [0, 0, 1, -2.8], [0, -1, 0, 1.0], [0, 0, 0, 1]]}

``cam_to_world`` is optional: the pose of a static camera, a rigid 4x4 matrix as a list of rows (metres),
read by :func:`load_camera_pose` (None when absent).

:func:`load_intrinsics` also accepts Open3D's ``PinholeCameraIntrinsic`` JSON (``width``,
``height``, column-major ``intrinsic_matrix``).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, replace

import numpy as np

from ..errors import ArticulaInputError

FORMAT = "articula-intrinsics/1"
#: Plausible field of view of a pinhole depth camera, degrees, edge to edge of the image (horizontal and
#: vertical).  Real sensors are well inside: Kinect v1 57 x 43, Kinect v2 70.6 x 60, Azure Kinect 75 x 65
#: (NFOV) and 120 x 120 (WFOV), RealSense D435 87 x 58.  Below 1 deg (fx = fy = 1e12 px) every point
#: collapses onto the optical axis; a pinhole model near 180 deg (fx = fy = 1e-6 px) puts points
#: kilometres away.  Focal lengths outside these bounds are refused.
MIN_FOV_DEG, MAX_FOV_DEG = 1.0, 170.0
#: Largest ratio of fx to fy (either way): real depth sensors have square pixels (ratio ~1).
MAX_PIXEL_ASPECT = 4.0


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of a depth image (pixels), see the module docstring for conventions."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    depth_unit_m: float = 0.001  # metres per PNG depth unit
    name: str = "custom"

    @property
    def K(self) -> np.ndarray:
        """(3, 3) calibration matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def shape(self) -> tuple:
        """Image array shape (H, W)."""
        return (self.height, self.width)

    def fov_deg(self) -> tuple:
        """Horizontal and vertical field of view in degrees (edge to edge of the image)."""
        return (2 * math.degrees(math.atan(self.width / (2 * self.fx))),
                2 * math.degrees(math.atan(self.height / (2 * self.fy))))

    def with_resolution(self, width: int, height: int) -> "Intrinsics":
        """The same camera delivering a (uniformly) rescaled image, e.g. 640x480 -> 320x240.

        Pixel centres map as ``u' = (u + 0.5) s - 0.5``, so cx, cy stay at the same field point."""
        sx, sy = width / self.width, height / self.height
        return replace(self, width=int(width), height=int(height), fx=self.fx * sx, fy=self.fy * sy,
                       cx=(self.cx + 0.5) * sx - 0.5, cy=(self.cy + 0.5) * sy - 0.5)

    def validate(self, where: str = "intrinsics") -> "Intrinsics":
        """Raise :class:`ArticulaInputError` (mentioning ``where``) unless the values are usable: finite,
        a field of view within :data:`MIN_FOV_DEG`..:data:`MAX_FOV_DEG`, fx/fy within
        :data:`MAX_PIXEL_ASPECT`, the principal point inside the image."""
        for key in ("width", "height"):
            val = getattr(self, key)
            if not isinstance(val, (int, np.integer)) or isinstance(val, bool) or not 0 < val <= 100000:
                raise ArticulaInputError(f"{where}: {key} must be a positive integer, got {val!r}")
        for key in ("fx", "fy", "cx", "cy", "depth_unit_m"):
            val = getattr(self, key)
            if isinstance(val, bool) or not isinstance(val, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(val):
                raise ArticulaInputError(f"{where}: {key} must be a finite number, got {val!r}")
        for key in ("fx", "fy", "depth_unit_m"):
            if getattr(self, key) <= 0:
                raise ArticulaInputError(f"{where}: {key} must be positive, got {getattr(self, key)!r}")
        for key, size, axis in (("fx", self.width, "horizontal"), ("fy", self.height, "vertical")):
            focal = float(getattr(self, key))
            fov = 2 * math.degrees(math.atan(size / (2 * focal)))
            if not MIN_FOV_DEG <= fov <= MAX_FOV_DEG:
                lo, hi = (size / 2 / math.tan(math.radians(d) / 2) for d in (MAX_FOV_DEG, MIN_FOV_DEG))
                raise ArticulaInputError(
                    f"{where}: {key} = {focal:g} px gives a {axis} field of view of {fov:.3g} deg over {size} "
                    f"pixels; a depth camera's is between {MIN_FOV_DEG:g} and {MAX_FOV_DEG:g} deg (Kinect v1: 57), "
                    f"so {key} must be between {lo:.3g} and {hi:.3g} px")
        if max(self.fx / self.fy, self.fy / self.fx) > MAX_PIXEL_ASPECT:
            raise ArticulaInputError(f"{where}: fx = {self.fx:g} and fy = {self.fy:g} px differ by more than "
                                     f"{MAX_PIXEL_ASPECT:g} times (depth sensors have square pixels)")
        if not (-0.5 <= self.cx <= self.width - 0.5 and -0.5 <= self.cy <= self.height - 0.5):
            raise ArticulaInputError(f"{where}: principal point (cx, cy) = ({self.cx:g}, {self.cy:g}) is outside "
                                     f"the {self.width}x{self.height} image (pixel centres 0..{self.width - 1}, "
                                     f"0..{self.height - 1})")
        return self


def _from_fov(name, width, height, hfov_deg, vfov_deg):
    fx = (width / 2) / math.tan(math.radians(hfov_deg) / 2)
    fy = (height / 2) / math.tan(math.radians(vfov_deg) / 2)
    return Intrinsics(width, height, round(fx, 2), round(fy, 2), (width - 1) / 2, (height - 1) / 2,
                      name=name)


@dataclass(frozen=True)
class CameraPreset:
    """A nominal depth camera: ``name`` (its one spelling in the panel, the commands, files and messages),
    ``label`` and ``description`` (the panel), ``intrinsics``, and ``aliases``: older spellings still
    accepted (scripts, scenes and farm jobs may hold them)."""
    name: str
    label: str
    description: str
    intrinsics: Intrinsics
    aliases: tuple = ()


#: The camera presets, the one table every place reads.  Nominal models: real devices differ by a few
#: percent (per-unit factory calibration); load the device's own values with :func:`load_intrinsics`.
CAMERA_PRESETS = (
    # Kinect v1 (PrimeSense), 640x480 depth: focal length of the IR camera ~580 px (Konolige &
    # Mihelich, "Technical description of Kinect calibration", ROS wiki kinect_calibration/technical;
    # consistent with the nominal 57 deg horizontal FOV), principal point at the image centre.
    CameraPreset("kinect_v1", "Kinect v1", "Nominal Kinect v1 / PrimeSense: 640x480, fx = fy = 580 px",
                 Intrinsics(640, 480, 580.0, 580.0, 319.5, 239.5, name="kinect_v1")),
    # Kinect v2 (Kinect for Windows v2 / Xbox One), 512x424 ToF depth, nominal FOV 70.6 x 60 deg.
    CameraPreset("kinect_v2", "Kinect v2", "Nominal Kinect v2: 512x424, 70.6 x 60 degrees",
                 _from_fov("kinect_v2", 512, 424, 70.6, 60.0)),
    # Azure Kinect DK, NFOV unbinned depth mode: 640x576, nominal FOV 75 x 65 deg (Azure Kinect DK
    # hardware specification).  Pinhole equivalent of the nominal FOV (the real lens is distorted).
    CameraPreset("azure_kinect_nfov", "Azure Kinect (NFOV)",
                 "Nominal Azure Kinect DK narrow field of view: 640x576, 75 x 65 degrees",
                 _from_fov("azure_kinect_nfov", 640, 576, 75.0, 65.0), aliases=("azure_kinect",)),
    # Intel RealSense D435, 848x480 depth (the recommended resolution), nominal depth FOV
    # 87 x 58 deg (Intel RealSense D400 series datasheet).
    CameraPreset("realsense_d435", "RealSense D435", "Nominal Intel RealSense D435: 848x480, 87 x 58 degrees",
                 _from_fov("realsense_d435", 848, 480, 87.0, 58.0)),
)
#: name -> intrinsics of :data:`CAMERA_PRESETS`.
PRESETS = {p.name: p.intrinsics for p in CAMERA_PRESETS}
_SPELLINGS = {spelling.lower(): p.name for p in CAMERA_PRESETS for spelling in (p.name, p.label, *p.aliases)}


def preset_key(spelling: str) -> str:
    """The preset's name for ``spelling`` in any case, its label or an older spelling (``AZURE_KINECT``,
    ``azure_kinect`` -> ``azure_kinect_nfov``); an unknown spelling comes back lower-cased (for
    argparse's ``choices`` to refuse it with the list of names)."""
    key = str(spelling).strip().lower()
    return _SPELLINGS.get(key, key)


def preset(name: str, resolution=None) -> Intrinsics:
    """A copy of the preset ``name`` (any spelling :func:`preset_key` accepts), optionally rescaled to
    ``resolution = (width, height)``."""
    key = preset_key(name)
    if key not in PRESETS:
        raise ArticulaInputError(f"unknown camera preset {name!r}; available: {', '.join(PRESETS)}")
    intr = PRESETS[key]
    return intr if resolution is None else intr.with_resolution(*resolution)


# ------------------------------------------------------------------------------------------ files

def save_intrinsics(path, intr: Intrinsics, cam_to_world=None) -> None:
    """Write ``intr`` as ``intrinsics.json`` ("articula-intrinsics/1"), atomically; with ``cam_to_world``
    (4, 4) rigid camera-to-world (metres), also the static camera's pose (validated as on reading)."""
    path = os.fspath(path)
    intr.validate(path)
    data = {"format": FORMAT, **asdict(intr)}
    data["width"], data["height"] = int(intr.width), int(intr.height)
    if cam_to_world is not None:
        data["cam_to_world"] = check_camera_pose(cam_to_world, path).tolist()
    tmp = f"{path}.part{os.getpid()}"
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=1)
        f.write("\n")
    os.replace(tmp, path)


def _read_json(path) -> dict:
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except OSError as exc:
        raise ArticulaInputError(f"{path}: cannot read intrinsics ({exc.strerror or exc})") from exc
    except ValueError as exc:
        raise ArticulaInputError(f"{path}: not valid JSON ({exc})") from exc
    if not isinstance(data, dict):
        raise ArticulaInputError(f"{path}: expected a JSON object with width, height, fx, fy, cx, cy")
    return data


def load_intrinsics(path) -> Intrinsics:
    """Read and validate ``intrinsics.json`` (Articula's format or Open3D's pinhole JSON)."""
    path = os.fspath(path)
    data = _read_json(path)
    if data.get("format", FORMAT) != FORMAT:
        raise ArticulaInputError(f"{path}: unknown intrinsics format {data['format']!r} (expected {FORMAT!r})")
    if "fx" not in data and "intrinsic_matrix" in data:
        data = _from_open3d(data, path)
    missing = [k for k in ("width", "height", "fx", "fy", "cx", "cy") if k not in data]
    if missing:
        raise ArticulaInputError(f"{path}: intrinsics lack {', '.join(missing)}")
    intr = Intrinsics(width=data["width"], height=data["height"], fx=data["fx"], fy=data["fy"],
                      cx=data["cx"], cy=data["cy"], depth_unit_m=data.get("depth_unit_m", 0.001),
                      name=str(data.get("name", os.path.basename(os.path.dirname(os.path.abspath(path))))))
    return intr.validate(path)


def load_camera_pose(path) -> np.ndarray | None:
    """The optional ``cam_to_world`` of ``intrinsics.json``: (4, 4) float64 camera (OpenCV axes) to world,
    metres, validated by :func:`check_camera_pose`; None when the file has no such key."""
    path = os.fspath(path)
    data = _read_json(path)
    if data.get("cam_to_world") is None:
        return None
    return check_camera_pose(data["cam_to_world"], path)


#: Largest deviation of R^T R from the identity accepted in a camera pose.
POSE_TOLERANCE = 1e-4


def check_camera_pose(matrix, where: str = "cam_to_world") -> np.ndarray:
    """``matrix`` as a (4, 4) float64 rigid transform, else :class:`ArticulaInputError` naming ``where`` and
    the key: finite, last row (0, 0, 0, 1), rotation orthonormal within :data:`POSE_TOLERANCE`, det +1."""
    def bad(problem):
        return ArticulaInputError(f"{where}: cam_to_world {problem}")
    try:
        m = np.asarray(matrix, dtype=float)
    except (TypeError, ValueError):
        raise bad("must be a 4x4 matrix of numbers (a list of 4 rows)") from None
    if m.shape != (4, 4):
        raise bad(f"must be a 4x4 matrix (a list of 4 rows of 4 numbers), got shape {m.shape}")
    if not np.isfinite(m).all():
        raise bad("holds NaN or infinite values")
    if np.abs(m[3] - (0, 0, 0, 1)).max() > 0:
        raise bad(f"must end with the row [0, 0, 0, 1], got {m[3].tolist()}")
    r = m[:3, :3]
    err = np.abs(r.T @ r - np.eye(3)).max()
    if err > POSE_TOLERANCE:
        raise bad(f"is not rigid: its rotation is not orthonormal (|R^T R - I| = {err:.3g} > {POSE_TOLERANCE:g}; "
                  "no scale or shear allowed, translation in metres)")
    if np.linalg.det(r) < 0:
        raise bad("is a reflection (rotation determinant -1); a camera pose needs determinant +1")
    return m


def _from_open3d(data, path):
    mat = data["intrinsic_matrix"]
    if not (isinstance(mat, list) and len(mat) == 9):
        raise ArticulaInputError(f"{path}: intrinsic_matrix must hold 9 numbers (column-major 3x3)")
    try:
        k = np.asarray(mat, dtype=float).reshape(3, 3).T
    except (TypeError, ValueError):
        raise ArticulaInputError(f"{path}: intrinsic_matrix must hold 9 numbers (column-major 3x3)") from None
    return dict(data, fx=float(k[0, 0]), fy=float(k[1, 1]), cx=float(k[0, 2]), cy=float(k[1, 2]))


# ------------------------------------------------------------------------------------ projection

def pixel_grid(intr: Intrinsics):
    """(H, W) float arrays u (column) and v (row) of pixel-centre coordinates."""
    return np.meshgrid(np.arange(intr.width, dtype=float), np.arange(intr.height, dtype=float))


def project(points_cam: np.ndarray, intr: Intrinsics):
    """Project (N, 3) camera-frame points: returns (N, 2) image coordinates (u, v) and (N,) depth Z.

    Points with Z <= 0 get NaN coordinates."""
    p = np.asarray(points_cam, dtype=float)
    z = p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(z > 0, 1.0 / z, np.nan)
    uv = np.stack([intr.fx * p[:, 0] * inv + intr.cx, intr.fy * p[:, 1] * inv + intr.cy], axis=1)
    return uv, z


def backproject(uv: np.ndarray, depth_m: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """(N, 2) image coordinates (u, v) and (N,) depths (m) -> (N, 3) camera-frame points."""
    uv = np.asarray(uv, dtype=float)
    z = np.asarray(depth_m, dtype=float)
    return np.stack([(uv[:, 0] - intr.cx) * z / intr.fx, (uv[:, 1] - intr.cy) * z / intr.fy, z], axis=1)


def depth_to_points(depth_m: np.ndarray, intr: Intrinsics):
    """Back-project a depth image.

    ``depth_m``: (H, W) depth in metres (0 or non-finite = missing) matching ``intr``.
    Returns ``points`` (K, 3) float64 in the camera frame (metres) for the K valid pixels in
    row-major order, and their flat pixel indices (K,) int64 (``rows, cols = divmod(idx, W)``).
    """
    depth_m = np.asarray(depth_m)
    if depth_m.shape != intr.shape:
        raise ArticulaInputError(f"depth image of shape {depth_m.shape} does not match the "
                                 f"{intr.width}x{intr.height} intrinsics {intr.name!r}")
    flat = depth_m.reshape(-1).astype(float, copy=False)
    idx = np.flatnonzero(np.isfinite(flat) & (flat > 0))
    rows, cols = np.divmod(idx, intr.width)
    z = flat[idx]
    pts = np.empty((idx.size, 3))
    pts[:, 0] = (cols - intr.cx) * (z / intr.fx)
    pts[:, 1] = (rows - intr.cy) * (z / intr.fy)
    pts[:, 2] = z
    return pts, idx


# ------------------------------------------------------------------------------------ extrinsics

def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """``cam_to_world`` (4, 4) of a camera at ``eye`` looking at ``target`` with world ``up`` shown
    upwards in the image (camera +Z towards the target, +Y = image down)."""
    eye, target, up = (np.asarray(x, dtype=float) for x in (eye, target, up))
    z = target - eye
    if np.linalg.norm(z) < 1e-12:
        raise ArticulaInputError("camera eye and target coincide")
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise ArticulaInputError("camera viewing direction is parallel to the up vector")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, eye
    return m


def world_to_camera(points: np.ndarray, cam_to_world: np.ndarray) -> np.ndarray:
    """(N, 3) world points -> camera frame, for a rigid ``cam_to_world`` (4, 4)."""
    r, t = cam_to_world[:3, :3], cam_to_world[:3, 3]
    return (np.asarray(points, dtype=float) - t) @ r


def camera_to_world(points: np.ndarray, cam_to_world: np.ndarray) -> np.ndarray:
    """(N, 3) camera-frame points -> world."""
    return np.asarray(points, dtype=float) @ cam_to_world[:3, :3].T + cam_to_world[:3, 3]


_CV_TO_BLENDER = np.diag([1.0, -1.0, -1.0, 1.0])


def blender_from_cv(cam_to_world: np.ndarray) -> np.ndarray:
    """Blender camera ``matrix_world`` (looks down -Z, +Y up) for an OpenCV-style ``cam_to_world``.
    The matrix is its own inverse, so the same call converts back."""
    return np.asarray(cam_to_world, dtype=float) @ _CV_TO_BLENDER



def blender_camera_settings(intr: Intrinsics, sensor_width_mm: float = 36.0) -> dict:
    """Blender camera/render settings that reproduce ``intr`` (checked against Blender's own
    projection in ``tests/blender/sequences/test_depth_camera.py``, to 1e-3 px).  Pixel centres are at
    integer (u, v), so normalised view coordinates are ``x = (u + 0.5) / W``, ``y = 1 - (v + 0.5) / H``:

    * ``sensor_fit = 'HORIZONTAL'``, ``sensor_width`` (mm), ``lens = fx * sensor_width / W`` (mm);
    * non-square pixels (fx != fy): pixel aspect ``ax / ay = fy / fx``, the larger one 1;
    * principal point: ``shift_x = ((W - 1) / 2 - cx) / W``, ``shift_y = (cy - (H - 1) / 2) ay / (W ax)``
      (fractions of the sensor width; a principal point below the centre shifts the view up);
    * render resolution W x H (at 100 %).

    Use with ``matrix_world = blender_from_cv(cam_to_world)``."""
    w, h = intr.width, intr.height
    ax, ay = (intr.fy / intr.fx, 1.0) if intr.fy >= intr.fx else (1.0, intr.fx / intr.fy)
    return {"lens": intr.fx * sensor_width_mm / w, "sensor_width": sensor_width_mm, "sensor_fit": "HORIZONTAL",
            "shift_x": ((w - 1) / 2 - intr.cx) / w, "shift_y": (intr.cy - (h - 1) / 2) * ay / (w * ax),
            "resolution_x": int(w), "resolution_y": int(h), "pixel_aspect_x": ax, "pixel_aspect_y": ay}

"""Every setting of depth-camera tracking, once (read by the solver, the operator and ``./run track``).
Lengths in metres, angles in degrees.  Values from the depth-camera tracking dissertation where it gives
them (ch. 5 Table 5.1, ch. 6 Table 6.2); the others are marked as ours in docs/track_depth.md."""
from __future__ import annotations

import dataclasses

from ..errors import ArticulaInputError

TRACKERS = ("icp", "gmm")
PERSON_CHOICES = ("centre", "nearest", "largest", "left", "right")   # observation.connected_person's choices


@dataclasses.dataclass
class DepthTrackOptions:
    tracker: str = "gmm"              # "gmm" (ch. 6; the better on ./run bench track_depth) or "icp" (ch. 5)
    model_points: int = 1000          # model vertices used for correspondences (fixed subset)
    data_points: int = 2500           # observed points per frame, sampled on the image grid
    max_iterations: int = 12          # per frame
    converged_m: float = 0.003        # stop when no visible model point moves more than this (ch. 5: 3 mm)
    max_distance: float = 0.2         # correspondence distance limit (Table 5.1: 200 mm)
    max_normal_angle: float = 60.0    # surface pairs (Table 5.1)
    edge_normal_angle: float = 90.0   # edge pairs, 2D contour normals (Table 5.1)
    edge_candidates: int = 6          # k_s: 2D neighbours among which the 3D-closest edge point is taken
    point_weight: float = 1.0         # point-to-point rows (ch. 5, Eq. 5.1)
    data_weight: float = 0.0          # observed-point-to-model rows (ours)
    plane_weight: float = 0.0         # point-to-plane rows along the model normal (ours)
    edge_weight: float = 1.0          # edge rows (metric: pixel error x depth / focal length) vs point rows
    floor_weight: float = 1.0         # model points below the floor plane (ours)
    visibility_tolerance: float = 0.03  # model points up to this behind the rendered model depth count as visible
    damping: float = 0.05             # lambda_r of the small-update regulariser (metres^2 per radian^2)
    gmm_sigma: float = 0.02           # initial sigma of the GMM tracker (Table 6.2: 0.02 m), reset every frame
    gmm_outliers: float = 0.01        # u, uniform outlier weight (ch. 6)
    gmm_neighbours: int = 5           # model components evaluated per observed point (truncated E-step, ours)
    gmm_points: int = 1000            # observed points per frame for the GMM (a stride of the grid sample; ch. 6 ~1000)
    gmm_iterations: int = 5           # EM iterations per step of Algorithm 3 (ch. 6: < 15 per frame)
    gmm_converged_m: float = 0.001    # EM stops when no model point moves more than this (ch. 6: 1 mm)
    gmm_lambda_r: float = 1000.0      # lambda_r, small-update term (Table 6.2)
    gmm_lambda_p: float = 100.0       # lambda_p, pull of the joint rotations to the prediction (Table 6.2: 500; ours)
    smooth: bool = True               # centred 3-frame smoothing of the tracked poses at the end (ours)
    limb_share: float = 0.96          # below this share the limbs are searched again (a limb was lost, ours)
    lost_share: float = 0.35          # a frame is lost when fewer observed points than this lie near the model
    near_m: float = 0.05              # "near the model" for the lost test and the report
    adapt_size: bool = True           # template only: limb lengths on the first frames (Algorithm 4)
    size_frames: int = 5              # F of Algorithm 4
    adapt_surface: bool = True        # template only: normal displacements (ch. 5 §4.5 / ch. 6 §5.5)
    surface_every: int = 5            # L: frames between surface updates (ch. 6)
    person: str = "centre"            # with several people in view, whom to track from the start: the one
                                      # nearest the image's centre, "nearest" the camera, "largest", "left", "right"

    def validate(self) -> "DepthTrackOptions":
        if self.tracker not in TRACKERS:
            raise ArticulaInputError(f"tracker: {self.tracker!r} is not one of {', '.join(TRACKERS)}")
        if self.person not in PERSON_CHOICES:
            raise ArticulaInputError(f"person: {self.person!r} is not one of {', '.join(PERSON_CHOICES)}")
        checks = (("model_points", self.model_points, 50, 20000), ("data_points", self.data_points, 100, 100000),
                  ("max_iterations", self.max_iterations, 1, 200), ("converged_m", self.converged_m, 1e-6, 0.1),
                  ("max_distance", self.max_distance, 0.01, 2.0), ("max_normal_angle", self.max_normal_angle, 1, 180),
                  ("edge_normal_angle", self.edge_normal_angle, 1, 180), ("edge_candidates", self.edge_candidates, 1, 64),
                  ("edge_weight", self.edge_weight, 0, 100),
                  ("floor_weight", self.floor_weight, 0, 1e4), ("visibility_tolerance", self.visibility_tolerance, 0, 1),
                  ("damping", self.damping, 0, 1e6),
                  ("gmm_sigma", self.gmm_sigma, 1e-3, 1.0), ("gmm_outliers", self.gmm_outliers, 0, 0.99),
                  ("gmm_neighbours", self.gmm_neighbours, 1, 64), ("gmm_points", self.gmm_points, 50, 100000),
                  ("gmm_iterations", self.gmm_iterations, 1, 200), ("gmm_converged_m", self.gmm_converged_m, 1e-6, 0.1),
                  ("gmm_lambda_r", self.gmm_lambda_r, 0, 1e9), ("gmm_lambda_p", self.gmm_lambda_p, 0, 1e9),
                  ("lost_share", self.lost_share, 0, 1), ("limb_share", self.limb_share, 0, 1),
                  ("near_m", self.near_m, 1e-3, 1.0), ("size_frames", self.size_frames, 1, 1000),
                  ("surface_every", self.surface_every, 1, 1000))
        for name, value, lo, hi in checks:
            if not (lo <= value <= hi):
                raise ArticulaInputError(f"{name}: {value!r} is outside {lo:g}..{hi:g}")
        return self

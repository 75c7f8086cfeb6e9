"""Registered mesh sequences of a MakeHuman subject, with exact ground truth.

In memory (for other generators, e.g. depth rendering and unregistered scans)::

    vertices, faces, gt = posed_sequence(rig="cmu_mb", shape="female,heavy", n_poses=30,
                                         motion="rom", skin="lbs", seed=0)

* ``vertices`` (N, V, 3) float64: posed body vertices, metres, world Z up, the subject facing -Y and
  standing on z = 0 at rest (V = 13,380; the same vertex order in every frame);
* ``faces`` (F, 3) int32: triangles (each MakeHuman quad split along its a-c diagonal);
* ``gt``: a dict of numpy arrays, exactly the content of ``ground_truth.npz`` (below).

On disk: :func:`generate_registered` writes ``pose_0000.obj`` ... (or ``.ply``; zero-padded so the
names sort in frame order) with the same vertex order and faces in all files (quads by default,
``faces="triangles"`` for triangles), ``ground_truth.npz``, and for ``skin="hybrid"`` the model bundle
``ground_truth_model.npz`` ("articula-model/1", via ``solver.formats.bundle.save_bundle``, with the poses).
The files are in their format's axis convention, as Blender's exporter writes them (OBJ: Y up, a world
point (x, y, z) written as (x, z, -y); PLY: world Z up as is), so Blender's importers and
``articula.import_scans`` stand them up; the ground truth and the bundle are in world coordinates (Z up).

``ground_truth.npz`` keys (B bones, N poses):

=======================  =====================================================================
rest_vertices (V,3)       subject at rest;  faces (F,3) int32 triangles;  quads (Q,4) int32
bone_names (B,)           ``.L``/``.R`` names; source_bone_names: MPFB2 names; parents (B,) int32
heads, tails (B,3)        rest joints; frames (B,3,3) rest axes as columns (Y = twist axis)
pose_rotations (N,B,4)    (w,x,y,z) relative to rest, bone-local axes; pose_translations (N,3) metres
pose_scales (N,)          all 1
bone_matrices (N,B,4,4)   rest-to-posed world map of each bone (x -> R x + t, homogeneous)
posed_heads, posed_tails  (N,B,3) posed joint positions
major_joint_labels (14,)  shoulder.L ... head (``bone_roles.major_joints``); major_joint_bones (14,) int32:
                          the bone whose head is each (``posed_heads[:, major_joint_bones]``)
lbs_weights (V,B) f32     the rig's weights (rows sum 1) — the skin for ``lbs``/``dqs``
anchor (V,) int32,        hybrid skin (only for ``skin="hybrid"``): anchor part and twist/swing
twist_weights, swing_weights (V,B) f32   weights on the anchor's children (solver.rig.model.Model)
posed_vertices (N,V,3)    the posed meshes (float64; files hold them rounded)
skin, motion, rig         strings; seed, subject_seed (-1 = none) int; macros: JSON of the shape
file_faces, file_axes     "quads"/"triangles"; (forward, up) of the files, e.g. ("NEGATIVE_Z", "Y")
=======================  =====================================================================
Skins: ``lbs`` = linear blend skinning, ``dqs`` = dual quaternions as Blender's Preserve Volume,
``hybrid`` = Articula's swing/twist skin (``solver.rig.skinning``).
"""
from __future__ import annotations

import json
import os

import numpy as np

from ..solver.rig import skinning
from ..solver.formats.bundle import save_bundle
from ..solver.errors import ArticulaInputError
from ..solver.formats.axes import format_axes
from ..solver.rig.kinematics import forward_kinematics
from ..solver.rig.model import Model, Poses, Skeleton
from .bone_roles import major_joints
from .mesh_files import FORMATS, SequenceWriter
from .poses import rom_poses
from .subjects import make_subject

SKINS = ("lbs", "dqs", "hybrid")
MOTIONS = ("rom", "walk", "turn")


def make_poses(subject, motion: str, n_poses: int, seed: int, **options):
    """Poses of ``motion`` for a subject ("rom": :func:`.poses.rom_poses`, "walk": :func:`.walk.walk_poses`,
    "turn": :func:`.turn.turn_poses`)."""
    if motion == "rom":
        return rom_poses(subject.skeleton, n_poses, seed=seed, **options)
    if motion == "walk":
        from .walk import walk_poses
        return walk_poses(subject, n_poses, seed=seed, **options)
    if motion == "turn":
        from .turn import turn_poses
        return turn_poses(subject, n_poses, seed=seed, **options)
    raise ArticulaInputError(f"motion: unknown motion {motion!r} (choose from {', '.join(MOTIONS)})")


def _skin(subject, skin, poses, Rm, tm):
    """Posed vertices (N, V, 3) and the hybrid model (or None)."""
    if skin == "lbs":
        return skinning.lbs(subject.vertices, subject.lbs_weights, Rm, tm), None
    if skin == "dqs":
        return skinning.dqs(subject.vertices, subject.lbs_weights, Rm, tm), None
    if skin == "hybrid":
        model = subject.hybrid_model()
        return skinning.hybrid_skin(model, poses), model
    raise ArticulaInputError(f"skin: unknown skin {skin!r} (choose from {', '.join(SKINS)})")


def _homogeneous(Rm, tm):
    M = np.zeros(Rm.shape[:-2] + (4, 4))
    M[..., :3, :3], M[..., :3, 3], M[..., 3, 3] = Rm, tm, 1.0
    return M


def _ground_truth(subject, poses, Rm, tm, posed, model, meta):
    sk = subject.skeleton
    gt = dict(
        rest_vertices=subject.vertices, faces=subject.triangles, quads=subject.quads,
        bone_names=np.array(sk.names), source_bone_names=np.array(subject.source_names),
        parents=sk.parents, heads=sk.heads, tails=sk.tails, frames=sk.frames,
        pose_rotations=poses.rotations, pose_translations=poses.translations, pose_scales=poses.scales,
        bone_matrices=_homogeneous(Rm, tm),
        posed_heads=np.einsum("nbij,bj->nbi", Rm, sk.heads) + tm,
        posed_tails=np.einsum("nbij,bj->nbi", Rm, sk.tails) + tm,
        lbs_weights=subject.lbs_weights.astype(np.float32), posed_vertices=posed,
        macros=np.array(json.dumps(subject.macros, sort_keys=True)))
    major = major_joints(sk)
    gt.update(major_joint_labels=np.array(list(major)), major_joint_bones=np.array(list(major.values()), np.int32))
    if model is not None:
        gt.update(anchor=model.anchor, twist_weights=model.twist_weights, swing_weights=model.swing_weights)
    gt.update({k: np.array(v) for k, v in meta.items()})
    return gt


def posed_sequence(rig: str = "cmu_mb", shape=None, n_poses: int = 30, motion: str = "rom",
                   skin: str = "lbs", seed: int = 0, subject_seed: int | None = None, **motion_options):
    """``(vertices (N, V, 3), faces (F, 3) int32, gt dict)`` — see the module docstring.

    shape: macro dict or preset string (``subjects.parse_shape``); subject_seed: draws the macros not
    given in ``shape`` (None = MakeHuman defaults); seed: the motion's random seed;
    motion_options: passed to the pose generator (e.g. ``root_yaw``, ``key_every``, ``amplitude``).
    """
    if skin not in SKINS:
        raise ArticulaInputError(f"skin: unknown skin {skin!r} (choose from {', '.join(SKINS)})")
    subject = make_subject(rig, shape, subject_seed)
    poses = make_poses(subject, motion, n_poses, seed, **motion_options)
    Rm, tm = forward_kinematics(subject.skeleton, poses)
    posed, model = _skin(subject, skin, poses, Rm, tm)
    meta = dict(skin=skin, motion=motion, rig=rig, seed=int(seed),
                subject_seed=-1 if subject_seed is None else int(subject_seed))
    return posed, subject.triangles, _ground_truth(subject, poses, Rm, tm, posed, model, meta)


def frame_names(n: int, fmt: str) -> list:
    """``pose_0000.<fmt>`` ... zero-padded to at least 4 digits so names sort in frame order."""
    width = max(4, len(str(n - 1)))
    return [f"pose_{i:0{width}d}.{fmt}" for i in range(n)]


def generate_registered(out_dir, rig: str = "cmu_mb", shape=None, n_poses: int = 30, motion: str = "rom",
                        skin: str = "lbs", fmt: str = "obj", seed: int = 0, subject_seed: int | None = None,
                        faces: str = "quads", **motion_options) -> dict:
    """Write a registered sequence to ``out_dir`` (module docstring); returns the ground-truth dict."""
    if fmt not in FORMATS:
        raise ArticulaInputError(f"format: unknown mesh format {fmt!r} (choose from {', '.join(FORMATS)})")
    if faces not in ("quads", "triangles"):
        raise ArticulaInputError(f"faces: must be 'quads' or 'triangles', got {faces!r}")
    posed, _, gt = posed_sequence(rig, shape, n_poses, motion, skin, seed, subject_seed, **motion_options)
    os.makedirs(out_dir, exist_ok=True)
    writer = SequenceWriter(gt["quads"] if faces == "quads" else gt["faces"], fmt, from_world=True)
    for name, verts in zip(frame_names(len(posed), fmt), posed):
        writer.write(os.path.join(out_dir, name), verts)
    gt["file_faces"] = np.array(faces)
    gt["file_axes"] = np.array(format_axes("." + fmt))
    _save_npz(os.path.join(out_dir, "ground_truth.npz"), gt)
    if skin == "hybrid":
        _save_model_bundle(os.path.join(out_dir, "ground_truth_model.npz"), gt)
    return gt


def _save_npz(path, arrays: dict) -> None:
    tmp = path + ".tmp.npz"
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def _save_model_bundle(path, gt) -> None:
    sk = Skeleton(list(gt["bone_names"]), gt["parents"], gt["heads"], gt["tails"], gt["frames"])
    model = Model(gt["rest_vertices"], gt["faces"], sk, gt["anchor"], gt["twist_weights"], gt["swing_weights"])
    poses = Poses(gt["pose_rotations"], gt["pose_translations"], gt["pose_scales"])
    provenance = {"generator": "articula.sample_scenes.registered", "rig": str(gt["rig"]),
                  "skin": "hybrid", "motion": str(gt["motion"]), "seed": int(gt["seed"]),
                  "macros": json.loads(str(gt["macros"]))}
    save_bundle(path, model, poses, provenance)

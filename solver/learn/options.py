"""The settings of a rig-learning run, each default written once.

:class:`LearnOptions` is what :func:`solver.learn.pipeline.learn_rig` takes; the ``articula.learn_rig``
operator (property defaults and bounds: :func:`property_range`), the Blender half (``addon/learn``) and
the ``learn-rig`` batch command (argparse defaults) read their defaults from it.  A field's metadata
holds its bounds ``min`` / ``max`` (:meth:`LearnOptions.validate` refuses values outside them, in
the operator and the batch command alike: the operator's properties get them as soft limits only) and,
for the operator's slider only, ``soft_max``; :meth:`LearnOptions.validate_for` adds the limits that
depend on the input (parts per vertex count).  The method is that of dissertation (model-adaptive
mocap) chapter 3; docs/learn_rig_solver.md describes the steps the settings steer.
"""
import math
import numbers
import re
from dataclasses import dataclass, field, fields

from ..errors import ArticulaInputError

MIN_SCANS = 3           # the fewest registered scans a rig is learned from
MIN_VERTICES_PER_PART = 20  # a part (bone) needs this many mesh vertices: parts <= vertices / this


def _setting(default, **bounds):
    """A dataclass field with ``default`` and its bounds (``min``, ``max``, ``soft_max``) as metadata."""
    return field(default=default, metadata=bounds)


@dataclass(frozen=True)
class LearnOptions:
    """Every setting of :func:`solver.learn.pipeline.learn_rig`.  ``parts``, ``key_scans`` and
    ``workers`` given as None are stored as 0 (automatic / every scan / one thread per core); the
    sequences ``bcd_steps`` and ``warm_start`` are stored as tuples."""
    # number of parts k (= bones); 0: chosen from the motion, up to k_max
    parts: int = _setting(0, min=0, max=64)
    # weight of the Laplacian (local shape) term against the position term, dimensionless
    # (solver.learn.objective): 100 makes a 1 mm local-shape error cost as much as a 10 mm offset
    alpha: float = _setting(100.0, min=0.0, soft_max=1000.0)
    # cut mirror-image parts alike, pair left/right bones and equalise their lengths (weight lam)
    symmetry: bool = True
    # at most this many outer rounds of (a) joints + poses, (b) weights, (c) rest vertices after the warm
    # start (the convergence test, tol, usually stops first); 0: initialisation only (no warm start either)
    max_iterations: int = _setting(8, min=0, max=1000)
    # chooses the rest scan (unless rest_scan is given) and seeds the segmentation
    seed: int = _setting(0, min=0)
    # a solver.rig.model.Skeleton in the rest scan's coordinates to start from instead of segmenting
    initial_skeleton: object = field(default=None, compare=False)
    # λ: weight of the mirror pairs' squared bone-length differences (m⁻²)
    lam: float = _setting(1e10, min=0.0)
    # step (a): at most this many Levenberg-Marquardt iterations per round ...
    gn_iterations: int = _setting(3, min=0)
    # ... ending early when the next one is expected to gain less than this fraction of E
    gn_gain_tol: float = _setting(1e-4, min=0.0)
    # step (b): at most this many block-coordinate-descent sweeps over the weights ...
    bcd_sweeps: int = _setting(3, min=0)
    # ... trying these weight steps δ (fractions of a unit weight, each > 0), largest first
    bcd_steps: tuple = (0.2, 0.1, 0.05, 0.02)
    # stop when a round lowers E by at most this fraction of the largest decrease of a round so far
    # (the objective has flattened); 0: only a round that gains nothing stops early
    tol: float = _setting(0.25, min=0.0, max=1.0)
    # the most parts the automatic choice of k considers
    k_max: int = _setting(32, min=2)
    # rounds (warm start included) whose step (a) moves the poses only, the joints held at their
    # rotation-centre estimates
    joint_warmup_rounds: int = _setting(1, min=0)
    # index of the scan giving the initial rest mesh; None: drawn from the seed
    rest_scan: int = _setting(None, min=0)
    # rounds before the main alternation, one per value, with α times that value (each > 0); kept only
    # if they lower E at α
    warm_start: tuple = (0.01, 0.1)
    # ρ of the joint-centre prior, relative to each joint's data curvature; 0: no prior
    joint_prior: float = _setting(0.01, min=0.0, soft_max=1.0)
    # learn from at most this many scans (the most different poses), then fit the others' poses;
    # 0: learn from every scan
    key_scans: int = _setting(40, min=0, max=100000)
    # ... and, on large meshes, at most this many vertex-scans (key scans x vertices: the work of every
    # step grows with it), but never fewer than TIME_KEY_SCANS; 0: no such limit
    key_scan_budget: int = _setting(300000, min=0)
    # pose fit of each other scan (with key scans): at most this many LM iterations ...
    other_scan_iterations: int = _setting(3, min=0)
    # ... stopping at this relative decrease
    other_scan_tol: float = _setting(1e-6, min=0.0)
    # step (a) (joints + poses) on about this many well-spread vertices, weighted so that their objective
    # estimates the full one, on meshes of more than 4 x that (solver.learn.coarse); weights and rest shape
    # use all; 0: all vertices
    joint_vertices: int = _setting(4000, min=0)
    # ... with the full gradient at the start of each step (the coarse-grid correction, solver.learn.coarse;
    # off: on the 53k-vertex MakeHuman it made the warm start worse, docs/learn_rig_solver.md)
    joint_correction: bool = False
    # memory budget of a run in GB; 0: 80 % of the memory available when it starts (solver.learn.memory).
    # A run whose key scans do not fit learns from fewer of them; refused only if 3 do not fit
    memory_limit_gb: float = _setting(0.0, min=0.0)
    # name the bones of a skeleton recognised as a humanoid by human roles (hips, thigh.L, ...;
    # solver.learn.role_names) instead of root / part_NN; not with initial_skeleton
    name_roles: bool = True
    # solver threads; 0: one per CPU core, 1: serial (the result depends on it only to rounding)
    workers: int = _setting(0, min=0)

    def __post_init__(self):
        for name in ("parts", "key_scans", "workers"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, 0)
        for name in ("bcd_steps", "warm_start"):
            object.__setattr__(self, name, tuple(getattr(self, name)))

    def validate(self):
        """Raise :class:`ArticulaInputError` naming the first setting that is not a number, is out of its
        bounds, or (key_scans) too small to learn from."""
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None and ("min" in f.metadata or "max" in f.metadata):
                _check_number(f.name, value, f.metadata, f.type is int)
        if 0 < self.key_scans < MIN_SCANS:
            raise ArticulaInputError(f"key_scans: {self.key_scans} given; learning a rig needs at least "
                                     f"{MIN_SCANS} scans (0 or None: learn from every scan)")
        if not self.bcd_steps:
            raise ArticulaInputError("bcd_steps: none given; the weight step needs at least one step size")
        for name in ("bcd_steps", "warm_start"):
            for value in getattr(self, name):
                if not _is_finite(value) or value <= 0:
                    raise ArticulaInputError(f"{name}: {value!r} given; every value must be a positive number")

    def validate_for(self, num_scans, num_vertices):
        """:meth:`validate`, then refuse settings this input cannot serve, before any heavy work: more
        parts than ``num_vertices / MIN_VERTICES_PER_PART`` (the segmentation needs that many vertices per
        rigid part) and fewer than MIN_SCANS scans."""
        self.validate()
        if num_scans < MIN_SCANS:
            raise ArticulaInputError(f"{num_scans} scan{'s' if num_scans != 1 else ''}; learning a rig needs at "
                                     f"least {MIN_SCANS} registered scans in different poses")
        most = max_parts(num_vertices)
        if self.parts > most:
            raise ArticulaInputError(
                f"parts: {self.parts} given for a mesh of {num_vertices} vertices; each part needs at least "
                f"{MIN_VERTICES_PER_PART} vertices, so at most {most} parts (or 0: chosen from the motion)")


def max_parts(num_vertices) -> int:
    """The most parts a mesh of ``num_vertices`` vertices is cut into: the ``parts`` bound and
    ``num_vertices / MIN_VERTICES_PER_PART``."""
    return int(min(fields_by_name()["parts"].metadata["max"], num_vertices // MIN_VERTICES_PER_PART))


def name_setting(message: str, names: dict) -> str:
    """``message`` (from :meth:`LearnOptions.validate` / ``validate_for``, which start with the field,
    possibly after a source's ``"...: "``) with the field replaced by ``names[field]``: how the CLI (its
    flag) or the operator (its property's name) calls that setting."""
    if not names:
        return message
    pattern = r"(^|: )(" + "|".join(map(re.escape, names)) + r")(?=: )"
    return re.sub(pattern, lambda m: m.group(1) + names[m.group(2)], message, count=1)


def fields_by_name() -> dict:
    """The :class:`LearnOptions` dataclass fields by name."""
    return {f.name: f for f in fields(LearnOptions)}


def _is_finite(value):
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)


def _check_number(name, value, bounds, integer):
    """Raise :class:`ArticulaInputError` unless ``value`` is a finite number (a whole one if ``integer``)
    within ``bounds["min"]`` .. ``bounds["max"]``."""
    if not _is_finite(value) or (integer and value != int(value)):
        raise ArticulaInputError(f"{name}: {value!r} given; expected {'an integer' if integer else 'a finite number'}")
    lo, hi = bounds.get("min"), bounds.get("max")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        allowed = f"at least {lo}" if hi is None else f"from {lo} to {hi}"
        raise ArticulaInputError(f"{name}: {value!r} given; it must be {allowed}")


def property_range(name) -> dict:
    """Keyword arguments of a Blender property for setting ``name``: its default and the bounds as soft
    limits (the slider's range).  No hard limits: Blender would clamp an out-of-range value silently,
    whereas :meth:`LearnOptions.validate` refuses it with the message the batch command gives."""
    f = fields_by_name()[name]
    bounds = {"min": "soft_min", "max": "soft_max", "soft_max": "soft_max"}
    return dict(default=f.default, **{bounds[key]: value for key, value in f.metadata.items()})

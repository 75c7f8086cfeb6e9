"""Working memory of rig learning: an upper bound of a run's peak, the budget it is held to, and the
number of key scans that fit it.

:func:`working_memory_bytes` bounds the peak resident memory that :func:`solver.learn.pipeline.learn_rig`
adds to its process, from the sizes alone (so it can be checked before the scans are read, from the first
file's vertex count): a fixed part (imports, thread pools), per vertex, per vertex and learned scan (posed copies,
residuals, Jacobian blocks, the weight step's candidates), per vertex and part (the weight arrays and the
skin's per-bone blocks), the joint/pose step's Gram blocks, and every scan as float64 (the input and the
fitted poses of the scans that are not key scans).  The coefficients are the measured peaks of
docs/learn_rig_solver.md ("Memory") with a margin of MARGIN.

The budget (:func:`memory_budget_bytes`) is ``LearnOptions.memory_limit_gb`` when given, else
MEMORY_FRACTION of the memory the machine has available now (``MemAvailable`` of /proc/meminfo, else
``os.sysconf``).  :func:`plan_memory` learns from fewer key scans when the requested ones do not fit
(:class:`MemoryPlan` says so) and refuses only when even MIN_SCANS key scans do not.
"""
import os
from dataclasses import dataclass

from ..errors import ArticulaInputError
from .joints_poses import sizes
from .options import MIN_SCANS

BASE_BYTES = 0.30e9                 # imports, thread pools, BLAS buffers: measured 0.2-0.25 GB
BYTES_PER_VERTEX = 30000            # per vertex, any scan count: the report's surface distances (53k v: 29.5 kB
                                    # at 5 parts, 18 kB at 19) and the rounds' part that does not grow with M
BYTES_PER_VERTEX_SCAN = 400         # learned scans x vertices (posed copies, residuals, candidates): 53k v, 5 -> 30
                                    # scans: +280 B per vertex and scan in the rounds
BYTES_PER_VERTEX_PART = 200         # vertices x parts (weight arrays, per-bone skin blocks; not measured apart)
BYTES_PER_VERTEX_ALL_SCANS = 24     # every scan, float64 (x, y, z)
MARGIN = 1.25                       # the bound over the largest measured peak of its kind
MEMORY_FRACTION = 0.8               # of the available memory that a run may use (no limit given)


def working_memory_bytes(num_scans, num_vertices, num_parts, all_scans=0):
    """Upper bound (bytes) of the peak memory of learning from ``num_scans`` (key) scans of
    ``num_vertices`` vertices with ``num_parts`` parts, holding ``all_scans`` scans in all (0: only the
    learned ones)."""
    n_s, n_o = sizes(max(int(num_parts), 1))
    M, V, k = int(num_scans), int(num_vertices), int(num_parts)
    per_vertex = (BYTES_PER_VERTEX + BYTES_PER_VERTEX_SCAN * M + BYTES_PER_VERTEX_PART * k
                  + BYTES_PER_VERTEX_ALL_SCANS * max(all_scans, M))
    return int(MARGIN * (BASE_BYTES + per_vertex * V + 8 * M * (n_s + n_o + 1) ** 2))


def available_memory_bytes():
    """Memory (bytes) the machine can give a new process now: ``MemAvailable`` of /proc/meminfo (Linux),
    else the total physical memory (``os.sysconf``: free-page counts elsewhere, e.g. macOS, leave out the
    reclaimable file cache and would refuse runs that fit); None if neither is known (Windows: no check)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def memory_budget_bytes(limit_gb=0.0, available=None):
    """``(budget bytes or None, what it is, in words)``: ``limit_gb`` × 1e9 when > 0, else MEMORY_FRACTION of
    ``available`` bytes (None: :func:`available_memory_bytes`; unknown: no budget)."""
    if limit_gb and limit_gb > 0:
        return float(limit_gb) * 1e9, f"the memory limit of {limit_gb:g} GB"
    available = available_memory_bytes() if available is None else available
    if available is None:
        return None, "no memory budget (available memory unknown)"
    return MEMORY_FRACTION * available, (f"the memory budget of {MEMORY_FRACTION * available / 1e9:.1f} GB "
                                         f"({MEMORY_FRACTION:.0%} of the {available / 1e9:.1f} GB available)")


@dataclass
class MemoryPlan:
    """How many scans a run learns from: ``learned`` of the ``requested`` key scans (fewer when those do not
    fit the budget), the bound ``estimate`` (bytes) for ``learned``, ``budget`` (bytes or None) and ``why``
    (the budget in words)."""
    learned: int
    requested: int
    estimate: int
    budget: float
    why: str

    @property
    def reduced(self):
        return self.learned < self.requested

    def note(self):
        """The reduction in words ("" if none), for the progress line and the summary."""
        if not self.reduced:
            return ""
        return (f"learning from {self.learned} instead of {self.requested} key scans to fit {self.why}; "
                f"the other scans' poses are fitted afterwards")

    def report(self):
        """JSON-able summary for the run's report."""
        return dict(estimate_gb=self.estimate / 1e9, budget_gb=None if self.budget is None else self.budget / 1e9,
                    key_scans_requested=self.requested, key_scans_learned=self.learned, note=self.note())


def plan_memory(num_scans, num_vertices, num_parts, requested, budget, why="the memory budget", source="scans"):
    """:class:`MemoryPlan` for learning ``requested`` of ``num_scans`` scans of ``num_vertices`` vertices with
    ``num_parts`` parts (0: pass the most the automatic choice considers) within ``budget`` bytes (None: no
    limit): the most key scans ≤ ``requested`` whose :func:`working_memory_bytes` fits.  Raises
    :class:`ArticulaInputError` (naming ``source``) when not even MIN_SCANS of them fit."""
    need = working_memory_bytes(requested, num_vertices, num_parts, num_scans)
    if budget is None or need <= budget:
        return MemoryPlan(requested, requested, need, budget, why)
    fits = [k for k in range(min(requested, num_scans), MIN_SCANS - 1, -1)
            if working_memory_bytes(k, num_vertices, num_parts, num_scans) <= budget]
    if not fits:
        least = working_memory_bytes(MIN_SCANS, num_vertices, num_parts, num_scans)
        raise ArticulaInputError(
            f"{source}: {num_scans} scans x {num_vertices} vertices with {num_parts} parts need up to "
            f"{least / 1e9:.2f} GB of memory even when learning from only {MIN_SCANS} key scans, over {why}: "
            f"use fewer parts, decimate the meshes, free memory or raise the memory limit")
    k = fits[0]
    return MemoryPlan(k, requested, working_memory_bytes(k, num_vertices, num_parts, num_scans), budget, why)


def check_sizes(options, num_scans, num_vertices, source="scans", available=None):
    """The checks that need only the input's sizes, before anything is read or converted:
    ``options.validate_for`` (:class:`solver.learn.options.LearnOptions`) and :func:`plan_memory` for the
    scans learned from (at most ``options.key_scans``) of all ``num_scans``, within the budget of
    ``options.memory_limit_gb`` (:func:`memory_budget_bytes`, ``available`` bytes for tests); ``source``
    names the input in the messages.  Returns the :class:`MemoryPlan`."""
    options.validate_for(num_scans, num_vertices)
    learned = min(num_scans, options.key_scans) if options.key_scans else num_scans
    budget, why = memory_budget_bytes(options.memory_limit_gb, available)
    return plan_memory(num_scans, num_vertices, options.parts or options.k_max, learned, budget, why, source)

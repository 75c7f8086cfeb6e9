"""Working memory of rig learning: an upper bound of a run's peak, and the limit it is held to.

:func:`working_memory_bytes` bounds the peak resident memory that :func:`solver.learn.pipeline.learn_rig`
adds to its process, from the sizes alone (so it can be checked before the scans are read, from the first
file's vertex count): a fixed part (imports, thread pools), per vertex, per vertex and learned scan (posed copies,
residuals, Jacobian blocks, the weight step's candidates), per vertex and part (the weight arrays and the
skin's per-bone blocks), the joint/pose step's Gram blocks, and every scan as float64 (the input and the
fitted poses of the scans that are not key scans).  The coefficients are the measured peaks of
docs/learn_rig_solver.md ("Memory") with a margin of MARGIN.

:func:`check_memory` refuses a run whose bound exceeds MEMORY_FRACTION of the memory the machine has
available now (``MemAvailable`` of /proc/meminfo, else ``os.sysconf``), naming the estimate, what is
available and what to do.
"""
import os

from ..errors import ArticulaInputError
from .joints_poses import sizes

BASE_BYTES = 0.30e9                 # imports, thread pools, BLAS buffers: measured 0.2-0.25 GB
BYTES_PER_VERTEX = 20000            # per vertex, any scan count (grows with the mesh: 13k v ~6 kB, 54k-214k v ~20 kB)
BYTES_PER_VERTEX_SCAN = 1000        # learned scans x vertices (posed copies, residuals, candidates)
BYTES_PER_VERTEX_PART = 200         # vertices x parts (weight arrays, per-bone skin blocks; not measured apart)
BYTES_PER_VERTEX_ALL_SCANS = 24     # every scan, float64 (x, y, z)
MARGIN = 1.25                       # the bound over the largest measured peak of its kind
MEMORY_FRACTION = 0.8               # of the available memory that a run may use


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


def check_memory(num_scans, num_vertices, num_parts, all_scans=0, available=None, source="scans"):
    """Raise :class:`ArticulaInputError` if :func:`working_memory_bytes` exceeds MEMORY_FRACTION of
    ``available`` bytes (None: :func:`available_memory_bytes`; unknown: no check).  ``num_parts`` 0 is
    taken as the most the automatic choice considers (the caller passes ``k_max``).  Returns the estimate."""
    need = working_memory_bytes(num_scans, num_vertices, num_parts, all_scans)
    available = available_memory_bytes() if available is None else available
    if available is not None and need > MEMORY_FRACTION * available:
        keys = f" ({num_scans} of them learned from)" if all_scans > num_scans else ""
        raise ArticulaInputError(
            f"{source}: {max(all_scans, num_scans)} scans{keys} x {num_vertices} vertices with {num_parts} parts "
            f"need up to {need / 1e9:.1f} GB of memory; {available / 1e9:.1f} GB is available (a run may use "
            f"{MEMORY_FRACTION:.0%} of it): learn from fewer key scans, use fewer parts, decimate the meshes, "
            f"or free memory")
    return need


def check_sizes(options, num_scans, num_vertices, source="scans"):
    """The checks that need only the input's sizes, before anything is read or converted:
    ``options.validate_for`` (:class:`solver.learn.options.LearnOptions`) and :func:`check_memory` for the
    scans learned from (at most ``options.key_scans``) and all ``num_scans``; ``source`` names the input
    in the memory message.  Returns the memory estimate (bytes)."""
    options.validate_for(num_scans, num_vertices)
    learned = min(num_scans, options.key_scans) if options.key_scans else num_scans
    return check_memory(learned, num_vertices, options.parts or options.k_max, num_scans, source=source)

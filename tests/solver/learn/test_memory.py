"""The memory bound of rig learning (solver.learn.memory) against the peaks measured in
docs/learn_rig_solver.md ("Memory"), and the limit relative to the machine's available memory."""
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.learn.memory import (MEMORY_FRACTION, available_memory_bytes, check_memory, check_sizes,
                                          working_memory_bytes)
from articula.solver.learn.options import LearnOptions

# (learned scans, vertices, parts, all scans, measured peak resident memory of the process in bytes)
MEASURED = [
    (30, 13380, 19, 30, 0.417e9),        # MakeHuman, bench learn_memory makehuman:30:19
    (40, 754, 10, 400, 0.302e9),         # Dem Bones' Bone_Anim, bone:40:10
    (5, 53514, 5, 5, 1.484e9),           # MakeHuman subdivided once, subdiv1:5:5
    (5, 214050, 10, 5, 5.36e9),          # issue 16: 214,050 vertices x 5 scans (estimated 2.81 GB before)
]


@pytest.mark.parametrize("scans, vertices, parts, all_scans, peak", MEASURED)
def test_estimate_bounds_every_measured_peak(scans, vertices, parts, all_scans, peak):
    assert working_memory_bytes(scans, vertices, parts, all_scans) >= 1.1 * peak


def test_limit_is_relative_to_the_available_memory():
    need = working_memory_bytes(5, 214050, 10, 5)
    assert check_memory(5, 214050, 10, 5, available=24e9) == need        # fits a 24 GB machine
    with pytest.raises(ArticulaInputError, match=r"folder: 5 scans x 214050 vertices with 10 parts need up to "
                                                 r"\d+\.\d GB of memory; 4\.0 GB is available .*80%.*fewer key scans, "
                                                 r"use fewer parts, decimate the meshes"):
        check_memory(5, 214050, 10, 5, available=4e9, source="folder")
    with pytest.raises(ArticulaInputError, match=r"\(40 of them learned from\)"):
        check_memory(40, 214050, 10, 400, available=4e9)
    assert MEMORY_FRACTION == 0.8 and available_memory_bytes() > 0


def test_size_checks_include_the_part_count_per_vertex():
    with pytest.raises(ArticulaInputError, match=r"parts: 30 given for a mesh of 509 vertices; each part needs at "
                                                 r"least 20 vertices, so at most 25 parts"):
        check_sizes(LearnOptions(parts=30), 8, 509)
    check_sizes(LearnOptions(parts=25), 8, 509)
    with pytest.raises(ArticulaInputError, match="parts: 65 given; it must be from 0 to 64"):
        check_sizes(LearnOptions(parts=65), 8, 100000)

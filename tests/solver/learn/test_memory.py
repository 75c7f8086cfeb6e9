"""The memory bound of rig learning (solver.learn.memory) against the peaks measured in
docs/learn_rig_solver.md ("Memory"), the budget (a given limit or a share of the available memory) and
the fewer key scans a run learns from when the requested ones do not fit."""
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.learn.memory import (MEMORY_FRACTION, available_memory_bytes, check_sizes, memory_budget_bytes,
                                          plan_memory, working_memory_bytes)
from articula.solver.learn.options import LearnOptions

# (learned scans, vertices, parts, all scans, measured peak resident memory of the process in bytes)
MEASURED = [
    (30, 13380, 19, 30, 0.423e9),        # MakeHuman, bench learn_memory makehuman:30:19
    (40, 754, 10, 400, 0.302e9),         # Dem Bones' Bone_Anim, bone:40:10
    (5, 53514, 5, 5, 1.602e9),           # MakeHuman subdivided once, subdiv1:5:5 (the report's distances)
    (30, 53514, 19, 30, 1.297e9),        # subdiv1:30:19
    (5, 214050, 10, 5, 5.36e9),          # issue 16: 214,050 vertices x 5 scans (estimated 2.81 GB before)
]


@pytest.mark.parametrize("scans, vertices, parts, all_scans, peak", MEASURED)
def test_estimate_bounds_every_measured_peak(scans, vertices, parts, all_scans, peak):
    assert working_memory_bytes(scans, vertices, parts, all_scans) >= 1.1 * peak


def test_budget_is_the_limit_given_or_a_share_of_the_available_memory():
    assert memory_budget_bytes(2.5, available=1e12) == (2.5e9, "the memory limit of 2.5 GB")
    budget, why = memory_budget_bytes(0, available=10e9)
    assert budget == MEMORY_FRACTION * 10e9 and why == "the memory budget of 8.0 GB (80% of the 10.0 GB available)"
    assert MEMORY_FRACTION == 0.8 and available_memory_bytes() > 0
    assert memory_budget_bytes(0)[0] == pytest.approx(MEMORY_FRACTION * available_memory_bytes(), rel=0.2)


def test_plan_learns_from_the_most_key_scans_that_fit():
    need = [working_memory_bytes(k, 214050, 10, 400) for k in range(41)]
    plan = plan_memory(400, 214050, 10, 40, 24e9)
    assert (plan.learned, plan.reduced, plan.estimate, plan.note()) == (40, False, need[40], "")
    budget = 0.5 * (need[17] + need[18])
    plan = plan_memory(400, 214050, 10, 40, budget, "the memory limit of 9 GB")
    assert plan.learned == 17 and plan.reduced and plan.estimate == need[17] <= budget < need[18]
    assert plan.note() == ("learning from 17 instead of 40 key scans to fit the memory limit of 9 GB; the other "
                           "scans' poses are fitted afterwards")
    assert plan.report()["key_scans_learned"] == 17 and plan.report()["budget_gb"] == budget / 1e9
    assert plan_memory(400, 214050, 10, 40, None).learned == 40                 # no budget known: no limit


def test_refused_only_when_three_key_scans_do_not_fit():
    three = working_memory_bytes(3, 214050, 10, 5)
    assert plan_memory(5, 214050, 10, 5, three).learned == 3
    with pytest.raises(ArticulaInputError, match=r"folder: 5 scans x 214050 vertices with 10 parts need up to "
                                                 r"\d+\.\d\d GB of memory even when learning from only 3 key scans, "
                                                 r"over the memory limit of 1 GB: use fewer parts, decimate"):
        plan_memory(5, 214050, 10, 5, three - 1, "the memory limit of 1 GB", source="folder")
    plan = check_sizes(LearnOptions(parts=10, memory_limit_gb=three / 1e9), 5, 214050)
    assert plan.learned == 3 and plan.requested == 5
    with pytest.raises(ArticulaInputError, match="the memory budget of 0.8 GB"):
        check_sizes(LearnOptions(parts=10), 5, 214050, available=1e9)


def test_size_checks_include_the_part_count_per_vertex():
    with pytest.raises(ArticulaInputError, match=r"parts: 30 given for a mesh of 509 vertices; each part needs at "
                                                 r"least 20 vertices, so at most 25 parts"):
        check_sizes(LearnOptions(parts=30), 8, 509)
    check_sizes(LearnOptions(parts=25), 8, 509)
    with pytest.raises(ArticulaInputError, match="parts: 65 given; it must be from 0 to 64"):
        check_sizes(LearnOptions(parts=65), 8, 100000)


def test_learn_rig_learns_from_fewer_key_scans_within_a_small_memory_limit():
    from articula.solver.learn.pipeline import learn_rig
    from articula.sample_scenes.tube_scans import hybrid_truth
    model, _, scans = hybrid_truth(8, seed=1)
    V = model.num_vertices
    limit = 0.5 * (working_memory_bytes(4, V, 8, 8) + working_memory_bytes(5, V, 8, 8)) / 1e9
    stages = []
    res = learn_rig(scans, model.faces, parts=8, max_iterations=0, memory_limit_gb=limit,
                    progress=lambda f, stage, obj: stages.append(stage))
    assert len(res.report["key_scans"]) == 4 and len(res.poses) == 8
    assert res.report["memory"]["key_scans_requested"] == 8 and res.report["memory"]["key_scans_learned"] == 4
    assert stages[0].startswith(f"learning from 4 scans x {V} vertices (learning from 4 instead of 8 key scans "
                                f"to fit the memory limit of {limit:g} GB")

"""Finding roles (solver.retarget.humanoid / mapping; the names of each rig family: tests/solver/roles): the
topology/geometry inference on rigs with meaningless names in T- and A-pose, any facing, with twist
bones and girdles, on MakeHuman's four rigs (against their presets), and the JSON mapping round trip."""
import json

import numpy as np
import pytest

from articula.sample_scenes import mpfb_armature
from articula.solver.errors import ArticulaInputError
from articula.solver.retarget import humanoid
from articula.solver.retarget.armature import ArmatureRest
from articula.solver.retarget.mapping import Mapping, auto_roles
from articula.sample_scenes.mpfb_rig import roll_frames

from .humanoids import humanoid as make_humanoid

@pytest.mark.parametrize("arm_angle,yaw,twist,clavicle,girdle", [
    (0.0, 0.0, False, True, False), (45.0, 0.0, True, True, True), (30.0, 180.0, False, False, True),
    (60.0, 90.0, True, False, False)])
def test_inference_recovers_the_roles_of_a_rig_with_meaningless_names(arm_angle, yaw, twist, clavicle, girdle):
    rng = np.random.default_rng(int(arm_angle + yaw))
    order = rng.permutation(200)
    names = {}
    arm, truth = make_humanoid(1.7, arm_angle, twist, clavicle, girdle, rng=rng, yaw_deg=yaw,
                               names=lambda r: names.setdefault(r, f"b{order[len(names)]:03d}"))
    found = humanoid.infer_roles(arm)
    wanted = {r: b for r, b in truth.items() if r not in ("toe.L", "toe.R")}
    assert {r: found.get(r) for r in wanted} == wanted


def test_non_humanoids_get_no_roles():
    """A chain and a quadruped-like star have no humanoid roles."""
    J = 12
    heads = np.array([[0, 0, 0.1 * i] for i in range(J)], float)
    tails = heads + [0, 0, 0.1]
    rest = np.tile(np.eye(4), (J, 1, 1))
    rest[:, :3, :3] = roll_frames(heads, tails, np.zeros(J))
    rest[:, :3, 3] = heads
    chain = ArmatureRest("chain", [f"c{i}" for i in range(J)], np.arange(J) - 1, rest, tails, np.ones(J, bool),
                         np.eye(4))
    assert humanoid.infer_roles(chain) == {}


@pytest.mark.parametrize("rig", ["default", "game_engine", "cmu_mb", "mixamo"])
def test_makehuman_rigs_match_their_presets(rig):
    """Each MakeHuman rig (A-pose, MakeHuman's rolls) gets its preset, and the shape-only inference agrees
    with the preset on the limbs (the default rig's helper bones aside)."""
    d = mpfb_armature.rig_bones(rig)
    rest = np.tile(np.eye(4), (len(d["names"]), 1, 1))
    rest[:, :3, :3] = roll_frames(d["heads"], d["tails"], d["rolls"])
    rest[:, :3, 3] = d["heads"]
    arm = ArmatureRest(rig, d["names"], d["parents"], rest, d["tails"], np.zeros(len(rest), bool), np.eye(4))
    finding = auto_roles(arm)
    assert finding.preset and all(r in finding.roles for r in ("hips", "head", "hand.L", "foot.R", "thigh.L"))
    inferred = humanoid.infer_roles(arm)
    limbs = [f"{r}.{s}" for r in ("forearm", "shin", "foot") for s in "LR"] + ["head", "neck", "chest"]
    assert {r: inferred.get(r) for r in limbs} == {r: finding.roles.get(r) for r in limbs}


def test_mapping_json_round_trip_and_errors(tmp_path):
    m = Mapping.from_roles({"hips": "Hips", "head": "Head"}, {"hips": "pelvis", "neck": "neck_01"})
    again = Mapping.from_json(m.to_json())
    assert again.rows == m.rows and again.pairs() == {"hips": ("Hips", "pelvis")}
    assert "head" in again.missing()
    with pytest.raises(ArticulaInputError, match="not JSON"):
        Mapping.from_json("{", "m.json")
    with pytest.raises(ArticulaInputError, match="retarget mapping"):
        Mapping.from_json(json.dumps({"rows": []}), "m.json")
    with pytest.raises(ArticulaInputError, match="row 1"):
        Mapping.from_json(json.dumps({"format": "articula-retarget-mapping", "rows": [{"role": "tail"}]}))
    with pytest.raises(ArticulaInputError, match="more than one role"):
        Mapping([("hips", "a", "x"), ("head", "a", "y")]).check(["a"], ["x", "y"])


"""MakeHuman base mesh and macro targets (sample_scenes.makehuman)."""
import json

import numpy as np
import pytest
import trimesh

from articula.sample_scenes import makehuman as mh
from articula.sample_scenes.assets import ensure_assets
from articula.solver.errors import ArticulaInputError


@pytest.fixture(scope="module")
def base():
    return mh.load_base_mesh()


def test_body_counts(base):
    assert mh.BODY_VERTEX_COUNT == 13380
    assert base.vertices.shape == (19158, 3)
    assert base.body_quads.shape == (13378, 4)
    assert base.body_quads.min() == 0 and base.body_quads.max() == 13379
    assert len(np.unique(base.body_quads)) == 13380
    tri = base.body_triangles
    assert tri.shape == (2 * 13378, 3) and tri.dtype == np.int32
    # each quad's two triangles cover its four corners
    assert set(tri[0]) | set(tri[1]) == set(base.body_quads[0])


def test_axes_and_units_from_the_obj_text(base):
    """The first vertex line of base.obj, converted by hand: (x, y, z) dm Y-up -> 0.1 (x, -z, y) m Z-up."""
    path = ensure_assets(verbose=False) / "3dobjs" / "base.obj"
    first = next(line for line in path.read_text().splitlines() if line.startswith("v "))
    x, y, z = map(float, first.split()[1:])
    assert np.allclose(base.vertices[0], [0.1 * x, -0.1 * z, 0.1 * y])


@pytest.mark.parametrize("rig", ["cmu_mb", "game_engine", "default"])
def test_default_body_joint_cubes_match_mpfb_default_positions(base, rig):
    """MPFB stores each joint's position on the default human (Blender, metres, Z up): our default
    macros + axis/unit conversion reproduce it (an independent reference for all three)."""
    bones = json.loads((ensure_assets(verbose=False) / "rigs" / "standard" / f"rig.{rig}.json").read_text())
    bones = bones.get("bones", bones)
    centres = base.joint_centres(mh.shaped_vertices())
    specs = [s for b in bones.values() for s in (b["head"], b["tail"]) if s["strategy"] == "CUBE"]
    err = [np.linalg.norm(centres[s["cube_name"]] - s["default_position"]) for s in specs]
    assert len(err) > 20 and max(err) < 1e-5
    # the raw base mesh (no macros) is a different body: the check can fail
    raw = base.joint_centres()
    assert max(np.linalg.norm(raw[s["cube_name"]] - s["default_position"]) for s in specs) > 0.01


def test_macro_parts_agree_with_macro_json():
    data = json.loads((mh.targets_dir() / "macro.json").read_text())["macrotargets"]
    for macro, parts in mh.MACRO_PARTS.items():
        ref = data[macro]["parts"]
        assert [(p["low"], p["high"]) for p in ref] == [(lo, hi) for _, _, lo, hi in parts]
        assert np.allclose([(p["lowest"], p["highest"]) for p in ref], [(a, b) for a, b, _, _ in parts], atol=0.02)


@pytest.mark.parametrize("macro", ["gender", "age", "muscle", "weight"])
def test_category_weights_partition_unity(macro):
    for value in np.linspace(0, 1, 17):
        w = mh.category_weights(macro, value)
        assert abs(sum(w.values()) - 1) < 1e-12 and all(x > 0 for x in w.values())


def test_category_weights_examples():
    assert mh.category_weights("age", 0.5) == {"young": 1.0}
    assert mh.category_weights("weight", 0.75) == {"averageweight": 0.5, "maxweight": 0.5}
    assert mh.category_weights("height", 0.5) == {}
    assert mh.category_weights("height", 0.25) == {"minheight": 0.5}
    w = mh.category_weights("age", 0.34375)                 # halfway between child and young
    assert w == pytest.approx({"child": 0.5, "young": 0.5})


def test_target_weights_default_and_female():
    w = mh.macro_target_weights()
    universal = sum(v for k, v in w.items() if k.startswith("universal-"))
    race = sum(v for k, v in w.items() if k.split("-")[0] in mh.RACES)
    assert universal == pytest.approx(1) and race == pytest.approx(1)
    assert not any(k.startswith(("height/", "proportions/")) for k in w)     # 0.5 = no target
    f = mh.macro_target_weights({"gender": 0.0, "height": 1.0})
    assert all("-male-" not in k and not k.startswith("male") for k in f)
    assert sum(v for k, v in f.items() if k.startswith("height/")) == pytest.approx(1)


def _volume(full):
    base = mh.load_base_mesh()
    return trimesh.Trimesh(full[:mh.BODY_VERTEX_COUNT], base.body_triangles, process=False).volume


def test_shapes_change_the_body_as_named():
    heavy, thin = mh.shaped_vertices({"weight": 1.0}), mh.shaped_vertices({"weight": 0.0})
    assert _volume(heavy) > 1.15 * _volume(thin)
    tall, short = mh.shaped_vertices({"height": 0.8}), mh.shaped_vertices({"height": 0.2})
    h = [np.ptp(v[:mh.BODY_VERTEX_COUNT, 2]) for v in (tall, short)]
    assert h[0] - h[1] > 0.3
    default = np.ptp(mh.shaped_vertices()[:mh.BODY_VERTEX_COUNT, 2])
    assert 1.5 < default < 1.8                              # metres: units are right


def test_parse_target_merges_repeated_indices():
    idx, off = mh.parse_target("3 1 0 0\n5 0 1 0\n3 1 0 0\n")
    assert idx.tolist() == [3, 5]
    assert np.allclose(off, [[0.2, 0, 0], [0, 0, 0.1]])       # (x, -z, y) * 0.1


@pytest.mark.parametrize("shape, word", [({"weigth": 0.5}, "unknown macro"), ({"age": 1.5}, "outside"),
                                         ({"african": 0, "asian": 0, "caucasian": 0}, "race")])
def test_bad_macros(shape, word):
    with pytest.raises(ArticulaInputError, match=word):
        mh.macro_target_weights(shape)

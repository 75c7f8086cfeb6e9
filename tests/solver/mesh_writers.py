"""Independent little writers for test fixtures (plain ``struct``/string formatting, written from the
format descriptions, sharing no code with the readers under test)."""
import struct

import numpy as np

# A cube with 5 quads and 2 triangles (one quad split) and 8 vertices: mixed polygon sizes.
CUBE_VERTS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                       [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float) * [1.5, 0.25, -2.0] + [0.125, 3, 0.5]
CUBE_FACES = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4], [3, 4, 7]]


def write_obj(path, verts, faces, style="plain"):
    """style: plain | slashes (v/vt/vn) | negative (relative indices) | vonly (v//vn)."""
    lines = ["# test", "o thing", "mtllib none.mtl"]
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(verts, float).tolist()]
    lines += ["vt 0.5 0.5", "vn 0 0 1", "g group1", "s off"]
    for f in faces:
        if style == "plain":
            corners = [str(i + 1) for i in f]
        elif style == "slashes":
            corners = [f"{i + 1}/1/1" for i in f]
        elif style == "vonly":
            corners = [f"{i + 1}//1" for i in f]
        else:
            corners = [f"{i - len(verts)}/1" for i in f]
        lines.append("f " + " ".join(corners))
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def write_ply(path, verts, faces, fmt="ascii", extra=True):
    """fmt: ascii | binary_little_endian | binary_big_endian.  extra: add a colour property per vertex
    and a flags property after each face's list, to check that unknown properties are skipped."""
    head = ["ply", f"format {fmt} 1.0", "comment test", f"element vertex {len(verts)}",
            "property float x", "property float y", "property float z"]
    if extra:
        head.append("property uchar red")
    head += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    if extra:
        head.append("property int flags")
    head.append("end_header")
    text = ("\n".join(head) + "\n").encode()
    if fmt == "ascii":
        rows = [" ".join(repr(float(np.float32(c))) for c in v) + (" 7" if extra else "") for v in verts]
        rows += [f"{len(f)} " + " ".join(map(str, f)) + (" 9" if extra else "") for f in faces]
        body = ("\n".join(rows) + "\n").encode()
    else:
        o = "<" if fmt.endswith("little_endian") else ">"
        body = b"".join(struct.pack(o + "3f" + ("B" if extra else ""), *v, *((7,) if extra else ()))
                        for v in verts)
        body += b"".join(struct.pack(f"{o}B{len(f)}i" + ("i" if extra else ""), len(f), *f,
                                     *((9,) if extra else ())) for f in faces)
    with open(path, "wb") as fh:
        fh.write(text + body)


def triangles(faces):
    return [[f[0], f[k], f[k + 1]] for f in faces for k in range(1, len(f) - 1)]


def write_stl(path, verts, faces, binary=True):
    tris = triangles(faces)
    if binary:
        out = b"solid-looking binary header".ljust(80, b" ") + struct.pack("<I", len(tris))
        for t in tris:
            out += struct.pack("<12fH", 0, 0, 0, *[c for i in t for c in verts[i]], 0)
        with open(path, "wb") as fh:
            fh.write(out)
        return
    rows = ["solid test"]
    for t in tris:
        rows += ["  facet normal 0 0 0", "    outer loop"]
        rows += [f"      vertex {x!r} {y!r} {z!r}" for x, y, z in (np.asarray(verts, float)[i].tolist() for i in t)]
        rows += ["    endloop", "  endfacet"]
    rows.append("endsolid test")
    with open(path, "w") as fh:
        fh.write("\n".join(rows) + "\n")


def write_off(path, verts, faces):
    rows = ["OFF", "# comment", f"{len(verts)} {len(faces)} 0"]
    rows += [f"{x!r} {y!r} {z!r}" for x, y, z in np.asarray(verts, float).tolist()]
    rows += [f"{len(f)} " + " ".join(map(str, f)) for f in faces]
    with open(path, "w") as fh:
        fh.write("\n".join(rows) + "\n")


def write_mdd(path, frames, rest_frame=False):
    n, v, _ = frames.shape
    out = struct.pack(">2i", n, v) + struct.pack(f">{n}f", *[k / 24 for k in range(n)])
    if rest_frame:
        out += struct.pack(f">{v * 3}f", *frames[0].ravel())
    for f in frames:
        out += struct.pack(f">{v * 3}f", *f.ravel())
    with open(path, "wb") as fh:
        fh.write(out)


def write_pc2(path, frames, start=1.0, rate=1.0):
    n, v, _ = frames.shape
    out = b"POINTCACHE2\0" + struct.pack("<iiffi", 1, v, start, rate, n)
    for f in frames:
        out += struct.pack(f"<{v * 3}f", *f.ravel())
    with open(path, "wb") as fh:
        fh.write(out)

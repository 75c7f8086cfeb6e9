"""Mesh-file readers against fixture files written with known content by independent writers."""
import struct

import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.formats.mesh_files import read_mesh
from articula.solver.formats.obj import read_obj
from articula.solver.formats.ply import read_ply
from articula.solver.formats.polymesh import PolyMesh
from articula.solver.formats.stl import read_stl

from ..mesh_writers import CUBE_FACES, CUBE_VERTS, triangles, write_obj, write_off, write_ply, write_stl


def faces_of(mesh: PolyMesh):
    out, s = [], 0
    for n in mesh.face_sizes:
        out.append(mesh.corner_verts[s:s + n].tolist())
        s += n
    return out


@pytest.mark.parametrize("style", ["plain", "slashes", "negative", "vonly"])
def test_obj(tmp_path, style):
    path = str(tmp_path / "cube.obj")
    write_obj(path, CUBE_VERTS, CUBE_FACES, style)
    mesh = read_mesh(path)
    assert np.array_equal(mesh.vertices, CUBE_VERTS)
    assert faces_of(mesh) == CUBE_FACES
    assert mesh.face_sizes.tolist() == [4, 4, 4, 4, 4, 3, 3]


def test_obj_negative_indices_are_relative_to_the_face_line(tmp_path):
    path = tmp_path / "rel.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 5 5 5\nf -4 -3 -1\nv 1 2 3 1.0\n")
    mesh = read_obj(str(path))
    assert faces_of(mesh) == [[0, 1, 2], [0, 1, 3]]
    assert mesh.vertices[4].tolist() == [1, 2, 3]   # the optional w is ignored


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("extra", [True, False])
def test_ply(tmp_path, fmt, extra):
    path = str(tmp_path / "cube.ply")
    write_ply(path, CUBE_VERTS, CUBE_FACES, fmt, extra)
    mesh = read_mesh(path)
    assert np.array_equal(mesh.vertices, CUBE_VERTS.astype(np.float32))
    assert faces_of(mesh) == CUBE_FACES


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_all_triangles_uses_uniform_path(tmp_path, fmt):
    tris = triangles(CUBE_FACES)
    path = str(tmp_path / "tri.ply")
    write_ply(path, CUBE_VERTS, tris, fmt)
    assert faces_of(read_ply(path)) == tris


@pytest.mark.parametrize("binary", [True, False])
def test_stl_welds_in_order_of_first_appearance(tmp_path, binary):
    path = str(tmp_path / "cube.stl")
    write_stl(path, CUBE_VERTS, CUBE_FACES, binary)
    mesh = read_stl(path)
    tris = triangles(CUBE_FACES)
    # expected numbering: vertices in order of first use by the triangle list
    order = list(dict.fromkeys(i for t in tris for i in t))
    assert len(mesh.vertices) == 8
    assert np.allclose(mesh.vertices, CUBE_VERTS[order], atol=1e-6 if binary else 0)
    renum = {old: new for new, old in enumerate(order)}
    assert faces_of(mesh) == [[renum[i] for i in t] for t in tris]


def test_off(tmp_path):
    path = str(tmp_path / "cube.off")
    write_off(path, CUBE_VERTS, CUBE_FACES)
    mesh = read_mesh(path)
    assert np.array_equal(mesh.vertices, CUBE_VERTS)
    assert faces_of(mesh) == CUBE_FACES


def test_off_counts_on_header_line_and_colours(tmp_path):
    path = tmp_path / "c.off"
    path.write_text("COFF 3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n0 1 0 0 0 255 255\n3 0 1 2 1 1 1\n")
    mesh = read_mesh(str(path))
    assert mesh.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0]] and faces_of(mesh) == [[0, 1, 2]]


def test_triangles_fan():
    mesh = PolyMesh(CUBE_VERTS, np.array([len(f) for f in CUBE_FACES], np.int32),
                    np.array(sum(CUBE_FACES, []), np.int32))
    assert mesh.triangles().tolist() == triangles(CUBE_FACES)


def test_topology_difference_names_the_face():
    a = PolyMesh(CUBE_VERTS, np.array([4, 3]), np.array([0, 1, 2, 3, 4, 5, 6]))
    b = PolyMesh(CUBE_VERTS, np.array([4, 3]), np.array([0, 1, 2, 3, 4, 6, 5]))
    assert a.topology_difference(a) is None
    assert "face 2 differs (vertices [5, 7, 6] vs [5, 6, 7]" in a.topology_difference(b)
    assert "vertex count 7 vs 8" in a.topology_difference(PolyMesh(CUBE_VERTS[:7], a.face_sizes, a.corner_verts))


# -- bad input ---------------------------------------------------------------------------------------
def test_nan_named_with_vertex(tmp_path):
    path = tmp_path / "nan.obj"
    path.write_text("v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(ArticulaInputError, match=r"nan\.obj: vertex 2 has a non-finite"):
        read_obj(str(path))


def test_inf_in_binary_ply(tmp_path):
    v = CUBE_VERTS.copy()
    v[5, 2] = np.inf
    path = str(tmp_path / "inf.ply")
    write_ply(path, v, CUBE_FACES, "binary_little_endian")
    with pytest.raises(ArticulaInputError, match="vertex 6 has a non-finite"):
        read_ply(path)


@pytest.mark.parametrize("name, content, message", [
    ("g.obj", b"v 0 0 0\nv 1 0 0\nv zero 1 0\nf 1 2 3\n", "bad vertex coordinate"),
    ("r.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", r"face 1 uses vertex index 4, but the file has 3 vertices \(indices 1..3\)"),
    ("z.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1/1 0/1 2/1\n", "line 5: face 2 uses vertex index 0"),
    ("b.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", "bad face index 'x'"),
    ("e.obj", b"# nothing\n", "no vertices"),
    ("bin.obj", b"\0\1\2garbage", "not an OBJ"),
    ("g.ply", b"garbage", "not a PLY"),
    ("t.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
              b"property float z\nend_header\n\0\0\0\0", "truncated"),
    ("g.stl", b"\x01" * 300, "not an STL"),
    ("g.off", b"hello\n", "not an OFF"),
    ("s.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n", "ends early"),
    ("x.xyz", b"1 2 3", "unsupported mesh format"),
])
def test_bad_files_name_the_file_and_problem(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ArticulaInputError, match=message) as info:
        read_mesh(str(path))
    assert name in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(ArticulaInputError, match="nope.obj: file not found"):
        read_mesh(str(tmp_path / "nope.obj"))


def test_degenerate_faces_dropped(tmp_path):
    path = tmp_path / "d.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 1 2\nf 3 2 1\n")
    assert faces_of(read_obj(str(path))) == [[0, 1, 2], [2, 1, 0]]


def test_degenerate_faces_dropped_mixed_sizes(tmp_path):
    path = tmp_path / "m.off"
    path.write_text("OFF\n4 3 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n4 0 1 1 2\n3 2 3 0\n")
    mesh = read_mesh(str(path))
    assert faces_of(mesh) == [[0, 1, 2, 3], [2, 3, 0]]


def test_off_triangles_fast_path_and_colours_on_faces(tmp_path):
    path = tmp_path / "t.off"
    path.write_text("OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3 255 0 0\n")
    assert faces_of(read_mesh(str(path))) == [[0, 1, 2], [0, 2, 3]]
    path.write_text("OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n")
    assert faces_of(read_mesh(str(path))) == [[0, 1, 2], [0, 2, 3]]


def test_obj_indented_lines_crlf_and_colours(tmp_path):
    path = tmp_path / "i.obj"
    path.write_bytes(b"  v 0 0 0 1 0 0\r\n\tv 1 0 0 0 1 0\r\n v 0 1 0 0 0 1\r\n  f 1/1 2/2 3/3\r\n\tf 3 2 1\r\n")
    mesh = read_obj(str(path))
    assert mesh.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    assert faces_of(mesh) == [[0, 1, 2], [2, 1, 0]]


def _two_list_ply(fmt, faces, cut=0):
    """A PLY whose faces carry a second list (``corner_ids``, 2 ints per corner) beside their indices,
    so the reader takes the record-by-record path; ``cut`` drops that many bytes off the end."""
    head = ["ply", f"format {fmt} 1.0", f"element vertex {len(CUBE_VERTS)}", "property float x",
            "property float y", "property float z", f"element face {len(faces)}",
            "property list uchar int vertex_indices", "property uchar tag", "property list uchar int corner_ids",
            "end_header"]
    if fmt == "ascii":
        rows = [" ".join(repr(float(c)) for c in v) for v in CUBE_VERTS]
        rows += [f"{len(f)} {' '.join(map(str, f))} 5 {2 * len(f)} " + " ".join(["8"] * 2 * len(f)) for f in faces]
        body = ("\n".join(rows) + "\n").encode()
    else:
        o = "<" if fmt.endswith("little_endian") else ">"
        body = b"".join(struct.pack(o + "3f", *v) for v in CUBE_VERTS)
        body += b"".join(struct.pack(f"{o}B{len(f)}iBB{2 * len(f)}i", len(f), *f, 5, 2 * len(f), *[8] * 2 * len(f))
                         for f in faces)
    data = ("\n".join(head) + "\n").encode() + body
    return data[:len(data) - cut]


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("faces", [CUBE_FACES, triangles(CUBE_FACES)[:5] + [[0, 1, 2, 3, 4]]])
def test_ply_record_by_record_with_two_lists(tmp_path, fmt, faces):
    path = tmp_path / "two.ply"
    path.write_bytes(_two_list_ply(fmt, faces))
    mesh = read_ply(str(path))
    assert np.array_equal(mesh.vertices, CUBE_VERTS.astype(np.float32)) and faces_of(mesh) == faces


@pytest.mark.parametrize("fmt, message", [("ascii", r"ends inside element 'face'; truncated"),
                                          ("binary_little_endian", r"ends inside element 'face' \(record 7\)")])
def test_ply_truncated_inside_a_record(tmp_path, fmt, message):
    path = tmp_path / "cut.ply"
    path.write_bytes(_two_list_ply(fmt, CUBE_FACES, cut=6))
    with pytest.raises(ArticulaInputError, match=message):
        read_ply(str(path))


def test_ply_bad_list_length_names_the_record(tmp_path):
    data = _two_list_ply("ascii", CUBE_FACES).replace(b"\n4 4 5 6 7 5", b"\nx 4 5 6 7 5")
    path = tmp_path / "bad.ply"
    path.write_bytes(data)
    with pytest.raises(ArticulaInputError, match=r"bad list length in PLY element 'face' record \d"):
        read_ply(str(path))

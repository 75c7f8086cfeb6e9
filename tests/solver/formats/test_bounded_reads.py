"""Huge or wrong files are refused from their first bytes and their size, fast and without filling the
memory (issue 16 item 4).  The files are sparse (``truncate`` to 2 GB after a valid or invalid header: no
disk space); each read runs in a child process that measures its wall time and peak-RSS growth
(``VmHWM``, reset through ``/proc/self/clear_refs`` before each read)."""
import json
import re
import struct
import subprocess
import sys
import zlib

import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.formats import bounded
from articula.solver.formats.mesh_files import check_mesh
from articula.solver.formats.scan_files import read_scan_files

from ...conftest import PKGROOT
from ..mesh_writers import CUBE_FACES, CUBE_VERTS, write_obj

GB2 = 2 * 1024 ** 3


def _text(first, line, size=2 * bounded.HEAD_BYTES):
    """Valid text beyond the checked first bytes: ``first`` then ``line`` repeated to ``size`` bytes."""
    return first + line * (size // len(line))


def _png_head(width=640, height=480, depth=16):
    ihdr = struct.pack(">IIBBBBB", width, height, depth, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + ihdr + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))


def _npy_head(rows):
    head = "{'descr': '<f8', 'fortran_order': False, 'shape': (%d, 3), }" % rows
    head += " " * (117 - len(head)) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(head)) + head.encode()


# name, first bytes, reader (module:function), expected message
CASES = [
    ("valid.obj", _text(b"# scan\n", b"v 0 0 0\n"), "obj:read_obj",
     r"valid.obj: 2.1 GB is larger than the 1.0 GB limit for a single scan; decimate"),
    ("garbage.obj", b"PK\x03\x04 this is a zip file\n" + b"x" * 5000, "obj:read_obj",
     r"garbage.obj, line 1: not an OBJ file \(the line starts with 'PK"),
    ("zeros.obj", b"", "obj:read_obj", r"zeros.obj: not an OBJ text file \(binary data\)"),
    ("valid.png", _png_head(), "png16:read_png16",
     r"valid.png: 2.1 GB is far larger than a 640x480 PNG image can take"),
    ("huge.png", _png_head(100000, 100000), "png16:read_png16",
     r"huge.png: the PNG header declares a 100000x100000 image \(20 GB uncompressed\), larger than the 537 MB limit for a single frame"),
    ("garbage.png", b"GIF89a", "png16:read_png16", r"garbage.png: not a PNG file \(bad signature\)"),
    ("valid.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                  b"property float z\nend_header\n", "ply:read_ply", r"valid.ply: 2.1 GB is larger than the 1.0 GB"),
    ("counts.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\n"
                   b"property float y\nproperty float z\nend_header\n", "ply:read_ply",
     r"counts.ply: the PLY header declares 1000000000 'vertex' records, which need at least 12 GB, but the "
     r"file has 2.1 GB after the header; truncated\?"),
    ("garbage.ply", b"plyx", "ply:read_ply", r"garbage.ply: not a PLY file"),
    ("binary.stl", b"\0" * 80 + struct.pack("<I", (GB2 - 84) // 50 + 3), "stl:read_stl",
     r"binary.stl: not an STL file .*header says 42949674 triangles \(2.1 GB\) but the file has 2.1 GB"),
    ("ascii.stl", _text(b"solid x\n", b" facet normal 0 0 1\n  outer loop\n"), "stl:read_stl",
     r"ascii.stl: 2.1 GB is larger than the 1.0 GB limit"),
    ("valid.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "off:read_off", r"valid.off: 2.1 GB is larger"),
    ("counts.off", b"OFF\n900000000 1 0\n", "off:read_off",
     r"counts.off: the OFF header declares 900000000 vertices and 1 faces, which need at least 5.4 GB"),
    ("big.mdd", struct.pack(">2i", 2, 10 ** 8), "pointcache:read_mdd",
     r"big.mdd: MDD header says 2 frames of 100000000 points \(2400000016 bytes\) but the file has 2147483648"),
    ("huge.mdd", struct.pack(">2i", 10, 40_000_000), "pointcache:read_mdd",
     r"huge.mdd: 4.8 GB is larger than the 4.0 GB limit for a point cache; export fewer frames", 48 + 4_800_000_000),
    ("big.pc2", b"POINTCACHE2\0" + struct.pack("<iiffi", 1, 10 ** 8, 0.0, 1.0, 10), "pointcache:read_pc2",
     r"big.pc2: PC2 header says 10 samples of 100000000 points \(12 GB\) but the file has 2.1 GB"),
    ("valid.npy", _npy_head((GB2 - 128) // 24), "point_files:read_point_file",
     r"valid.npy: 2.1 GB is larger than the 1.0 GB limit for a single point-cloud frame"),
    ("garbage.npy", b"\x80\x04random", "point_files:read_point_file", r"garbage.npy: not a NumPy .npy file"),
    ("valid.xyz", _text(b"# x y z\n", b"0 0 1\n"), "point_files:read_point_file", r"valid.xyz: 2.1 GB is larger than the 1.0 GB"),
    ("garbage.xyz", b"hello world\n", "point_files:read_point_file", r"garbage.xyz, line 1: not a point-cloud text"),
    ("valid.dmat", b"3 4\n", "articula.bench._libigl:read_dmat", r"valid.dmat: 2.1 GB is larger than the 1.0 GB limit for a single rig file"),
    ("counts.dmat", b"30 100000000000\n", "articula.bench._libigl:read_dmat", r"counts.dmat: header says 100000000000 x 30 values"),
    ("valid.tgf", b"1 0 0 0\n", "articula.bench._libigl:read_tgf", r"valid.tgf: 2.1 GB is larger"),
    ("garbage.Tmat", b"not numbers\n", "articula.bench._libigl:read_tmat", r"garbage.Tmat, line 1: expected 3 numbers"),
    ("depth.png", _png_head(), "depth.recording:read_depth_png", r"depth.png: 2.1 GB is far larger"),
]

CHILD = r"""
import importlib, json, resource, sys, time
sys.path.insert(0, sys.argv[1])
from articula.solver.errors import ArticulaInputError

def hwm_kb():
    with open("/proc/self/status") as f:
        return next(int(l.split()[1]) for l in f if l.startswith("VmHWM"))

out = []
for path, reader in json.loads(sys.argv[2]):
    mod, fn = reader.split(":")
    name = mod if mod.startswith("articula.") else "articula.solver." + ("formats." if "." not in mod else "") + mod
    func = getattr(importlib.import_module(name), fn)
    with open("/proc/self/clear_refs", "w") as f:   # reset the peak RSS to the current RSS
        f.write("5")
    before = hwm_kb()
    t = time.perf_counter()
    try:
        func(path)
        msg = None
    except ArticulaInputError as exc:
        msg = str(exc)
    out.append({"seconds": time.perf_counter() - t, "extra_mb": (hwm_kb() - before) / 1024, "message": msg})
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def refusals(tmp_path_factory):
    """{name: {"seconds", "extra_mb", "message"}} of reading every case's 2 GB sparse file in a child."""
    folder = tmp_path_factory.mktemp("sparse")
    jobs = []
    for name, head, reader, _, *size in CASES:
        path = folder / name
        with open(path, "wb") as f:
            f.write(head)
            f.truncate(size[0] if size else GB2)
        jobs.append((str(path), reader))
    run = subprocess.run([sys.executable, "-c", CHILD, PKGROOT, json.dumps(jobs)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    results = dict(zip([c[0] for c in CASES], json.loads(run.stdout)))
    for name, r in results.items():     # shown with -s: the numbers quoted in docs/scans.md
        print(f"{name:14s} {r['seconds'] * 1000:8.2f} ms {r['extra_mb']:7.2f} MB  {r['message']}")
    return results


@pytest.mark.parametrize("name, message", [(c[0], c[3]) for c in CASES])
def test_a_2gb_file_is_refused_fast_and_without_reading_it(refusals, name, message):
    got = refusals[name]
    assert got["message"] is not None, f"{name} was accepted"
    assert re.search(message, got["message"]), got["message"]
    assert got["seconds"] < 0.5, got
    assert got["extra_mb"] < 50, got


def test_scan_lists_are_checked_before_the_first_file_is_read(tmp_path):
    """A bad last scan is refused before the (slow) reading of the others: the first file is not even
    readable as a mesh, so reaching it would give another message."""
    write_obj(str(tmp_path / "a.obj"), CUBE_VERTS, CUBE_FACES)
    (tmp_path / "b.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")
    with open(tmp_path / "c.obj", "wb") as f:
        f.write(_text(b"", b"v 0 0 0\n"))
        f.truncate(GB2)
    with pytest.raises(ArticulaInputError, match=r"c.obj: 2.1 GB is larger than the 1.0 GB limit for a single scan"):
        read_scan_files([str(tmp_path / n) for n in ("b.obj", "a.obj", "c.obj")])
    with pytest.raises(ArticulaInputError, match=r"b.obj: face 1 uses vertex index 9, but the file has 3 vertices "
                                                 r"\(indices 1..3\)"):
        read_scan_files([str(tmp_path / n) for n in ("b.obj", "a.obj")])


def test_the_limit_is_a_module_constant(tmp_path, monkeypatch):
    path = tmp_path / "small.obj"
    write_obj(str(path), CUBE_VERTS, CUBE_FACES)
    check_mesh(str(path))
    monkeypatch.setattr(bounded, "MAX_SCAN_BYTES", 100)
    monkeypatch.setattr(bounded.check_size, "__defaults__", (100, "a single scan", "decimate the mesh or split the file"))
    with pytest.raises(ArticulaInputError, match=r"small.obj: \d+ bytes is larger than the 100 bytes limit for a single scan"):
        check_mesh(str(path))


@pytest.mark.parametrize("name, content, message", [
    ("kd.obj", b"# material file saved as obj\nnewmtl skin\nKd 1 1 1\n", r"kd.obj, line 2: not an OBJ file"),
    ("bom.obj", b"\xef\xbb\xbfv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", None),
    ("cont.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 \\\n 3\n", None),
    ("html.stl", b"solid\n<html>\n", r"html.stl: not an STL file"),
    ("junk.off", b"OFF\nthree one zero\n", r"junk.off: OFF header has no vertex and face counts"),
    ("neg.ply", b"ply\nformat ascii 1.0\nelement vertex -3\nend_header\n", r"neg.ply: bad PLY header line 3"),
])
def test_first_bytes_decide(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    if message is None:
        from articula.solver.formats.mesh_files import read_mesh
        assert read_mesh(str(path)).face_sizes.tolist() == [3]
    else:
        with pytest.raises(ArticulaInputError, match=message):
            check_mesh(str(path))


def test_png_image_data_beyond_its_declared_size_is_not_inflated(tmp_path):
    """A small PNG whose IDAT inflates to far more than its 4x4 image (a "zip bomb") is refused."""
    from articula.solver.formats.png16 import read_png16
    ihdr = struct.pack(">IIBBBBB", 4, 4, 16, 0, 0, 0, 0)
    idat = zlib.compress(b"\0" * 50_000_000, 9)

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    (tmp_path / "bomb.png").write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat)
                                        + chunk(b"IEND", b""))
    with pytest.raises(ArticulaInputError, match=r"bomb.png: PNG image data is larger than its declared size"):
        read_png16(str(tmp_path / "bomb.png"))

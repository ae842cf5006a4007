"""Playground mesh files (issue 16): the .obj reader's results, and .stl/.ply/.off through
trimesh with non-UTF-8 text and broken files answered in words naming the file. The faults
of .obj files are fuzzed in test_fuzz; the ROS path in test_faults."""
import struct

import numpy as np
import pytest
import trimesh

from vplayground_ros.mesh_files import read_obj
from vplayground_ros.resources import find_shared
from vplayground_ros.scene import SceneError, load_world, read_mesh

SQUARE = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]


def test_the_shipped_playground_reads_as_trimesh_reads_it():
    path = find_shared("meshes/playground.obj")
    vertices, faces = read_obj(path.read_bytes())
    theirs = trimesh.load(path, force="mesh", process=False)
    np.testing.assert_array_equal(vertices[faces], theirs.vertices[theirs.faces])


def test_obj_forms_polygons_and_references():
    data = (b"# a square, its corners in every form\r\n"
            b"mtllib square.mtl\r\no square\r\ng top\r\ns 1\r\nusemtl steel\r\n"
            b"f 1/1/1 2//1 3/3 4\r\n"  # before its vertices: positive numbers may look ahead
            b"v 0 0 0\r\nv 1 0 0 1.0\r\nv 1 1 0 0.5 0.5 0.5\r\nv 0 1 0 # the last corner\r\n"
            b"vt 0 0\r\nvt 1 0\r\nvt 1 1\r\nvn 0 0 1\r\nvp 0.5\r\nl 1 2\r\np 3\r\n"
            b"f -4 -3 -1\r\n")  # counted back from the last vertex
    vertices, faces = read_obj(data)
    np.testing.assert_array_equal(vertices, SQUARE)
    np.testing.assert_array_equal(faces, [[0, 1, 2], [0, 2, 3], [0, 1, 3]])  # fanned from corner 1
    assert faces.dtype == np.int64 and vertices.dtype == np.float64


@pytest.mark.parametrize("encode", [
    lambda text: text.encode("utf-16"),                  # Windows "Unicode", with its mark
    lambda text: b"\xef\xbb\xbf" + text.encode("utf-8"),  # UTF-8 with a mark
    lambda text: text.encode("cp1252"),                   # names in a legacy code page
    lambda text: text.replace("\n", "\r").encode("latin-1"),  # classic Mac OS line ends
])
def test_obj_encodings_do_not_change_the_geometry(encode):
    text = "o Büro\n" + "".join(f"v {x} {y} {z}\n" for x, y, z in SQUARE) + "# naïve\nf 1 2 3 4\n"
    vertices, faces = read_obj(encode(text))
    np.testing.assert_array_equal(vertices, SQUARE)
    np.testing.assert_array_equal(faces, [[0, 1, 2], [0, 2, 3]])


TRIANGLE_STL = "solid {name}\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n" \
               "endloop\nendfacet\nendsolid {name}\n"
TRIANGLE_OFF = "OFF\n# {name}\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
TRIANGLE_PLY = "ply\nformat {format} 1.0\ncomment {name}\nelement vertex 3\nproperty float x\nproperty float y\n" \
               "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"


def binary_ply(name):
    body = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<B3i", 3, 0, 1, 2)
    return TRIANGLE_PLY.format(format="binary_little_endian", name=name).encode("latin-1") + body


@pytest.mark.parametrize("suffix, data", [
    (".stl", TRIANGLE_STL.format(name="Büro").encode("latin-1")),
    (".off", TRIANGLE_OFF.format(name="Büro").encode("latin-1")),
    (".ply", (TRIANGLE_PLY.format(format="ascii", name="Büro") + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").encode("latin-1")),
    (".ply", binary_ply("Büro")),
    # Binary STL: an 80-byte header of any bytes, one triangle (normal, corners, attribute).
    (".stl", b"\xe9\xff" * 40 + struct.pack("<I12fH", 1, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0)),
])
def test_trimesh_formats_with_non_utf8_text_load(tmp_path, suffix, data):
    path = tmp_path / f"mesh{suffix}"
    path.write_bytes(data)
    vertices, faces = read_mesh(path)
    np.testing.assert_array_equal(vertices[faces], [[(0, 0, 0), (1, 0, 0), (0, 1, 0)]])


@pytest.mark.parametrize("suffix, data, problem", [
    (".off", b"OFF\n3 1 0\n0 0\n1 0\n0 1\n3 0 1 2\n", "not a readable OFF file"),
    (".ply", TRIANGLE_PLY.format(format="ascii", name="x").encode() + b"0 0 0\n1 0\n", "not a readable PLY file"),
    (".stl", TRIANGLE_STL.format(name="x").replace("vertex 1 0 0", "vertex 1 0").encode(), "not a readable STL file"),
    (".off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "not a readable OFF file"),
    (".stl", b"\x00" * 83, "has no triangles"),
])
def test_broken_trimesh_formats_are_refused_naming_the_file(tmp_path, suffix, data, problem):
    path = tmp_path / f"broken{suffix}"
    path.write_bytes(data)
    with pytest.raises(SceneError) as error:
        load_world({"version": 1, "playground": {"mesh": str(path)}})
    assert str(error.value).startswith(f"<scene>: playground.mesh: mesh {path}") and problem in str(error.value)


@pytest.mark.parametrize("index", [1 << 63, 1 << 100])
def test_a_vertex_number_beyond_any_file_is_refused_in_words(tmp_path, index):
    """A face corner of 2^63 or more overflowed the reader's 64-bit corner array (OverflowError
    out of a spawn or a scene load) instead of being refused as the missing vertex it names."""
    path = tmp_path / "far.obj"
    path.write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 " + str(index).encode() + b"\n")
    with pytest.raises(SceneError, match=f"far.obj: line 4: the face refers to vertex {index}, more than any file"):
        load_world({"version": 1, "playground": {"mesh": str(path)}})

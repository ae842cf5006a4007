"""Playground mesh files (bytes) -> vertices (V, 3) and triangles (T, 3).

Wavefront .obj is read by the project's own reader: it states what is wrong and on which line,
where trimesh answers with a numpy error or a traceback, and it needs no text-encoding
detection. .stl, .ply and .off go through trimesh, their text parts made UTF-8 first.
Every problem is a MeshError whose message a user can act on.
"""
import codecs
import io
import math
from array import array

import numpy as np

from .physics.specs import quote

# .obj statements that carry nothing a rigid playground uses: texture and normal coordinates,
# parameter-space vertices, object and group names, smoothing, materials, lines and points.
OBJ_SKIPPED = frozenset({b"vt", b"vn", b"vp", b"o", b"g", b"s", b"usemtl", b"mtllib", b"l", b"p"})
OBJ_VERTEX_NUMBERS = (3, 4, 6)  # x y z; x y z w; x y z r g b (a colour, as MeshLab writes)
# Vertex numbers beyond this are in no file (a vertex a line), nor fit the corners' 64-bit integers.
MAX_VERTEX_NUMBER = 1 << 62


class MeshError(ValueError):
    """A mesh file that cannot be used: the message says what is wrong and, for text, where."""


def shown(token):
    """A token of the file as a user would see it in an editor, for error messages."""
    return quote(token.decode("utf-8", "backslashreplace"))


def obj_text(data):
    """The bytes of an .obj as lines of ASCII statements. Statements are ASCII whatever the
    file's encoding, so bytes of any other encoding can only be in comments and names, which
    are skipped: only a UTF-8 byte-order mark is removed and UTF-16 (with its mark, as Windows
    tools write it) decoded. NUL bytes mean binary data."""
    if data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8):]
    elif data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        try:
            data = data.decode("utf-16").encode("utf-8")
        except UnicodeDecodeError as error:
            raise MeshError(f"starts as UTF-16 text but byte {error.start} is not UTF-16") from None
    nul = data.find(b"\0")
    if nul >= 0:
        line = data.count(b"\n", 0, nul) + 1
        raise MeshError(f"line {line}: a NUL byte: binary data (or UTF-16 text without a byte-order "
                        "mark), not .obj text")
    if b"\n" not in data:  # classic Mac OS line ends
        data = data.replace(b"\r", b"\n")
    return io.BytesIO(data)


def read_obj(data):
    """(vertices, triangles) of Wavefront .obj bytes. Reads `v` (x y z, then an optional w or
    r g b, both ignored) and `f` (corners `v`, `v/vt`, `v//vn` or `v/vt/vn`; 1-based, or
    negative: counted back from the last vertex so far; polygons fanned around their first
    corner); skips comments and the OBJ_SKIPPED statements."""
    coordinates = array("d")
    corners = array("q")  # three per triangle, 1-based
    vertex_count = 0
    highest = highest_line = 0  # the largest vertex number used, and where: it may come before the vertex
    # The loop body is the reader's whole cost (a 500,000-triangle mesh is 750,000 lines), so
    # the common forms are handled inline and everything else in the functions it calls.
    for number, line in enumerate(obj_text(data), 1):
        if b"#" in line:
            line = line[:line.index(b"#")]
        fields = line.split()
        if not fields:
            continue
        keyword = fields[0]
        if keyword == b"v":
            if len(fields) != 4:
                check_extra_vertex_numbers(fields, number)
            try:
                x, y, z = float(fields[1]), float(fields[2]), float(fields[3])
            except ValueError:
                raise unparsable_coordinate(fields, number) from None
            if x - x or y - y or z - z:  # 0.0 but for inf and nan
                raise unparsable_coordinate(fields, number)
            coordinates.extend((x, y, z))
            vertex_count += 1
        elif keyword == b"f":
            try:
                face = ([int(corner.partition(b"/")[0]) for corner in fields[1:]] if b"/" in line
                        else list(map(int, fields[1:])))
            except ValueError:
                raise unparsable_corner(fields, number) from None
            if len(face) < 3 or min(face) <= 0:
                face = checked_face(face, fields, number, vertex_count)
            top = max(face)
            if top > highest:
                if top > MAX_VERTEX_NUMBER:  # (nor could the array of corners hold it)
                    raise MeshError(f"line {number}: the face refers to vertex {top}, more than any file holds")
                highest, highest_line = top, number
            if len(face) == 3:
                corners.extend(face)
            else:
                for k in range(1, len(face) - 1):
                    corners.extend((face[0], face[k], face[k + 1]))
        elif keyword not in OBJ_SKIPPED:
            raise MeshError(f"line {number}: unknown statement {shown(keyword)} (this reader takes "
                            f"v and f, and skips {' '.join(sorted(k.decode() for k in OBJ_SKIPPED))})")
    if highest > vertex_count:
        raise MeshError(f"line {highest_line}: the face refers to vertex {highest}, but the file "
                        f"has only {vertex_count} vertices")
    return (np.frombuffer(coordinates, dtype=np.float64).reshape(-1, 3),
            np.frombuffer(corners, dtype=np.int64).reshape(-1, 3) - 1)


def check_extra_vertex_numbers(fields, line):
    """A `v` statement of other than three numbers: w, or an r g b colour, which must be
    numbers too, else a MeshError."""
    if len(fields) - 1 not in OBJ_VERTEX_NUMBERS:
        raise MeshError(f"line {line}: a vertex has {len(fields) - 1} numbers; expected x y z "
                        "(optionally followed by w, or by r g b)")
    if first_unparsable(fields[4:], float) is not None:
        raise unparsable_coordinate(fields, line)


def unparsable_coordinate(fields, line):
    """The MeshError for a `v` statement with a number that does not parse or is not finite."""
    token = first_unparsable(fields[1:], float)
    if token is not None:
        hint = " (the decimal separator is '.')" if b"," in token else ""
        return MeshError(f"line {line}: {shown(token)} is not a number{hint}")
    token = next(t for t in fields[1:] if not math.isfinite(float(t)))
    return MeshError(f"line {line}: {shown(token)} is not a finite number")


def first_unparsable(tokens, convert):
    """The first of the tokens `convert` refuses (reported instead of a whole line)."""
    for token in tokens:
        try:
            convert(token)
        except ValueError:
            return token
    return None


def unparsable_corner(fields, line):
    """The MeshError for an `f` statement with a corner that is not `v`, `v/vt`, `v//vn` or
    `v/vt/vn`."""
    corner = first_unparsable(fields[1:], lambda corner: int(corner.partition(b"/")[0]))
    return MeshError(f"line {line}: face corner {shown(corner)} does not start with a vertex number")


def checked_face(face, fields, line, defined):
    """A face of fewer than three corners, or with numbers below 1: with the negative ones
    (counted back from the last of the `defined` vertices before it) made 1-based, else a
    MeshError."""
    if len(face) < 3:
        raise MeshError(f"line {line}: a face needs at least 3 corners, this one has {len(face)}")
    for k, index in enumerate(face):
        if index == 0:
            raise MeshError(f"line {line}: face corner {shown(fields[k + 1])}: vertex numbers start "
                            "at 1 (or count back from -1)")
        if index < 0:
            if -index > defined:
                raise MeshError(f"line {line}: the face refers to vertex {index}, but only "
                                f"{defined} vertices come before it")
            face[k] = defined + 1 + index
    return face


def utf8_text_parts(data, file_type):
    """The file with its text parts in UTF-8, for trimesh, which decodes any other encoding with
    charset_normalizer (not installed). Those parts are ASCII but for comments and names, so
    reading them as Latin-1 (every byte a character) and writing UTF-8 changes no number.
    Binary STL and a binary PLY's body are left as they are."""
    def utf8(text):
        try:
            text.decode("utf-8")
            return text
        except UnicodeDecodeError:
            return text.decode("latin-1").encode("utf-8")
    if file_type == "stl" and len(data) == 84 + 50 * int.from_bytes(data[80:84], "little"):
        return data  # binary: the 80-byte header is decoded only where trimesh can
    if file_type == "ply":
        header, end, body = data.partition(b"end_header")
        return utf8(header) + end + body
    return utf8(data)


def read_with_trimesh(data, file_type):
    """(vertices, triangles) of an .stl, .ply or .off file's bytes."""
    import trimesh  # only scenes with such a playground need it

    try:
        # From memory, not the path: trimesh opens no other file.
        mesh = trimesh.load(io.BytesIO(utf8_text_parts(data, file_type)), file_type=file_type,
                            force="mesh", process=False)
    except Exception as error:  # trimesh raises many kinds for broken files
        detail = f"{type(error).__name__}: {str(error).strip()[:200]}".rstrip(": ")
        raise MeshError(f"not a readable {file_type.upper()} file (trimesh: {detail})") from None
    # Their loaders make x y z triples (where an .obj's 2-D vertices stayed 2-D).
    return (np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64),
            np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64))

"""Tests of subtrace.io.obj: OpenSubdiv oracle shapes, real models, syntax, errors, fuzzing."""

from __future__ import annotations

import json
import re
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from shared_data import MODELS, ORACLE

from fuzzing import mutations
from subtrace.errors import ObjError, SubtraceWarning
from subtrace.io.obj import (DEFAULT_DIFFUSE, DEFAULT_SHININESS, DEFAULT_SPECULAR, Material,
                             ObjData, ObjReader, read_obj)

ORACLE_SHAPES = sorted((ORACLE / "shapes").glob("*.obj"))
MODEL_FILES = sorted(MODELS.glob("*.obj"))


@pytest.fixture(autouse=True)
def _scanner_for_every_size(monkeypatch):
    """The tests here read small files through the byte scanner too (with the statement
    reader behind it), as larger files are read; the default for small files is the
    statement reader alone (test_a_small_file_is_read_without_compiling_the_scanner)."""
    from subtrace.io import obj_scan

    monkeypatch.setattr(obj_scan, "STATEMENT_READER_BYTES", 0)


def read_quiet(path) -> ObjData:
    """read_obj with its SubtraceWarnings silenced (they stay in data.warnings)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SubtraceWarning)
        return read_obj(path)


def write(tmp_path: Path, text: str, name: str = "mesh.obj") -> Path:
    path = tmp_path / name
    path.write_bytes(text.encode("utf-8"))
    return path


def expect_error(path: Path, line: int | None, *words: str) -> ObjError:
    """read_obj(path) must raise ObjError naming the file, `line` and every word."""
    with pytest.raises(ObjError) as info:
        read_quiet(path)
    err = info.value
    message = str(err)
    assert path.name in message
    assert err.line == line, message
    if line is not None:
        assert f"{path.name}:{line}:" in message
    for word in words:
        assert word.lower() in message.lower(), message
    return err


def check_layout(data: ObjData):
    """Dtypes, shapes and C-contiguity promised by ObjData."""
    expected = {
        "points": (np.float64, 2), "face_sizes": (np.int32, 1), "face_verts": (np.int32, 1),
        "uvs": (np.float64, 2), "face_uvs": (np.int32, 1), "normals": (np.float64, 2),
        "face_normals": (np.int32, 1), "face_material": (np.int32, 1),
        "face_group": (np.int32, 1), "face_object": (np.int32, 1),
        "crease_edges": (np.int32, 2), "crease_sharpness": (np.float32, 1),
        "corner_verts": (np.int32, 1), "corner_sharpness": (np.float32, 1),
        "hole_faces": (np.int32, 1),
    }
    for name, (dtype, ndim) in expected.items():
        array = getattr(data, name)
        assert array.dtype == dtype and array.ndim == ndim, name
        assert array.flags.c_contiguous, name
    num_faces, num_corners = len(data.face_sizes), int(data.face_sizes.sum())
    assert data.points.shape[1] == 3 and data.uvs.shape[1] == 2 and data.normals.shape[1] == 3
    assert len(data.face_verts) == len(data.face_uvs) == len(data.face_normals) == num_corners
    assert len(data.face_material) == len(data.face_group) == len(data.face_object) == num_faces
    assert data.crease_edges.shape == (len(data.crease_sharpness), 2)
    assert len(data.corner_verts) == len(data.corner_sharpness)
    assert (data.face_sizes >= 3).all()
    assert ((data.face_verts >= 0) & (data.face_verts < len(data.points))).all()
    assert ((data.face_uvs >= -1) & (data.face_uvs < len(data.uvs))).all()
    assert ((data.face_normals >= -1) & (data.face_normals < len(data.normals))).all()
    assert ((data.face_group >= 0) & (data.face_group < len(data.groups))).all()
    assert ((data.face_object >= 0) & (data.face_object < len(data.objects))).all()
    assert ((data.face_material >= -1) & (data.face_material < len(data.materials))).all()


# -- OpenSubdiv oracle shapes ------------------------------------------------------------

_BOUNDARY = {None: "VTX_BOUNDARY_EDGE_ONLY", 0: "VTX_BOUNDARY_NONE",
             1: "VTX_BOUNDARY_EDGE_AND_CORNER", 2: "VTX_BOUNDARY_EDGE_ONLY"}
_CREASING = {None: "CREASE_UNIFORM", "uniform": "CREASE_UNIFORM", "chaikin": "CREASE_CHAIKIN"}
_TRI_SUB = {None: "TRI_SUB_CATMARK", "catmark": "TRI_SUB_CATMARK", "smooth": "TRI_SUB_SMOOTH"}


@pytest.mark.parametrize("obj_path", ORACLE_SHAPES, ids=lambda p: p.stem)
def test_oracle_shape_matches_opensubdiv(obj_path):
    data = read_quiet(obj_path)
    oracle = np.load(ORACLE / f"{obj_path.stem}.npz")
    meta = json.loads(str(oracle["meta"]))
    check_layout(data)

    # Both sides parse the same decimal text with a correctly rounded strtod: exact.
    np.testing.assert_array_equal(data.points, oracle["control_points"])
    np.testing.assert_array_equal(data.face_sizes, oracle["face_sizes"])
    np.testing.assert_array_equal(data.face_verts, oracle["face_verts"])

    # With interpolateboundary 0 OpenSubdiv adds holes of its own: tagged ones are a subset.
    oracle_holes = set(np.flatnonzero(oracle["face_is_hole"]).tolist())
    tagged_holes = set(data.hole_faces.tolist())
    if data.boundary == 0:
        assert tagged_holes <= oracle_holes
    else:
        assert tagged_holes == oracle_holes

    options = meta["sdc_options"]
    assert options["VtxBoundaryInterpolation"] == _BOUNDARY[data.boundary]
    assert options["CreasingMethod"] == _CREASING[data.crease_method]
    # OpenSubdiv applies smoothtriangles to Catmark meshes only.
    tri_sub = data.smooth_triangles if meta["scheme"] == "catmark" else None
    assert options["TriangleSubdivision"] == _TRI_SUB[tri_sub]

    # Tagged sharpness reaches OpenSubdiv unchanged (float32, last tag wins); boundary and
    # non-manifold sharpening only touches untagged edges and vertices in these shapes.
    edge_ids = {tuple(sorted(e)): k for k, e in enumerate(oracle["edges"].tolist())}
    tagged_edges = dict(zip(map(tuple, np.sort(data.crease_edges, axis=1).tolist()),
                            data.crease_sharpness))
    for edge, sharpness in tagged_edges.items():
        assert oracle["edge_sharpness"][edge_ids[edge]] == sharpness, edge
    for vert, sharpness in dict(zip(data.corner_verts.tolist(), data.corner_sharpness)).items():
        assert oracle["vertex_sharpness"][vert] == sharpness, vert


def test_oracle_tags_read_as_documented():
    shapes = ORACLE / "shapes"
    edgenone = read_quiet(shapes / "catmark_edgenone.obj")
    assert edgenone.boundary == 0 and len(edgenone.crease_edges) == 18
    assert edgenone.corner_verts.tolist() == [48] and edgenone.corner_sharpness[0] == 10.0
    assert read_quiet(shapes / "catmark_chaikin1.obj").crease_method == "chaikin"
    assert read_quiet(shapes / "catmark_chaikin0.obj").crease_method == "uniform"
    assert read_quiet(shapes / "catmark_smoothtris1.obj").smooth_triangles == "smooth"
    assert read_quiet(shapes / "catmark_hole_test3.obj").hole_faces.tolist() == [
        15, 2, 7, 8, 9, 5, 13, 14]
    cube = read_quiet(shapes / "catmark_cube.obj")
    assert cube.boundary is None and cube.crease_method is None
    assert cube.smooth_triangles is None and cube.warnings == ()
    # The face-varying tag is read, without a warning (the shape has no vt to use it on);
    # 1 is corners only (the oracle's sdc_options say so too).
    semisharp = read_quiet(shapes / "catmark_cubes_semisharp.obj")
    assert semisharp.fvar_interpolation == 1 and semisharp.warnings == ()
    assert cube.fvar_interpolation is None


def test_oracle_shape_with_missing_mtl_warns():
    path = ORACLE / "shapes" / "catmark_gregory_test2.obj"
    with pytest.warns(SubtraceWarning) as record:
        data = read_obj(path)
    assert any("crazy_plane2.mtl" in str(w.message) for w in record)
    assert data.materials == (Material("initialShadingGroup", DEFAULT_DIFFUSE),)
    assert data.groups == ("pPlane1",)
    assert (data.face_material == 0).all()


# -- real models ---------------------------------------------------------------------------

# Face counts by size, from models/README.md.
MODEL_FACES = {
    "spot_control_mesh": {4: 160, 5: 16, 3: 4},
    "blub_control_mesh": {4: 100, 5: 4, 3: 8},
    "chamfer_cube": {4: 18, 3: 8},
    "hole_capsule": {4: 76},
    "sword_quad_dominant": {4: 22117, 3: 348},
    "csaszar_torus": {3: 14},
    "spot_low_resolution": {3: 1654},
    "torus": {3: 4608},
}


@pytest.mark.parametrize("obj_path", MODEL_FILES, ids=lambda p: p.stem)
def test_model_face_counts(obj_path):
    data = read_quiet(obj_path)
    check_layout(data)
    sizes, counts = np.unique(data.face_sizes, return_counts=True)
    assert dict(zip(sizes.tolist(), counts.tolist())) == MODEL_FACES[obj_path.stem]
    if obj_path.stem == "csaszar_torus":
        assert len(data.points) == 7


def test_large_model_parses_fast():
    path = MODELS / "sword_quad_dominant.obj"
    read_quiet(path)  # warm caches
    best = min(_timed(read_quiet, path) for _ in range(3))
    assert best < 0.5, f"{path.name} took {best:.3f} s"


def _timed(function, *args) -> float:
    start = time.perf_counter()
    function(*args)
    return time.perf_counter() - start


# -- syntax --------------------------------------------------------------------------------

SQUARE = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"


def test_index_forms_and_alignment(tmp_path):
    text = (SQUARE + "vt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\nvn 0 0 -1\n"
            "f 1 2 3\nf 1/1 2/2 3/3\nf 1//2 2//2 3//1\nf 1/3/1 2/2/2 3/1/1 4/1/2\n"
            "f 1/1 2 3//2\n")
    data = read_quiet(write(tmp_path, text))
    check_layout(data)
    assert data.face_sizes.tolist() == [3, 3, 3, 4, 3]
    assert data.face_verts.tolist() == [0, 1, 2] * 3 + [0, 1, 2, 3] + [0, 1, 2]
    assert data.face_uvs.tolist() == [-1] * 3 + [0, 1, 2] + [-1] * 3 + [2, 1, 0, 0] + [0, -1, -1]
    assert data.face_normals.tolist() == [-1] * 6 + [1, 1, 0] + [0, 1, 0, 1] + [-1, -1, 1]
    np.testing.assert_array_equal(data.uvs, [[0, 0], [1, 0], [1, 1]])
    np.testing.assert_array_equal(data.normals, [[0, 0, 1], [0, 0, -1]])
    assert data.warnings == ()


def test_negative_indices_count_back_from_elements_read_so_far(tmp_path):
    text = ("v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nf -3/-3 -2/-2 -1/-1\n"
            "v 5 5 5\nvn 0 0 1\nf -4 -3//-1 -1\n")
    data = read_quiet(write(tmp_path, text))
    assert data.face_verts.tolist() == [0, 1, 2, 0, 1, 3]
    assert data.face_uvs.tolist() == [0, 1, 2, -1, -1, -1]
    assert data.face_normals.tolist() == [-1, -1, -1, -1, 0, -1]


def test_positive_index_may_point_to_a_later_vertex(tmp_path):
    data = read_quiet(write(tmp_path, "v 0 0 0\nv 1 0 0\nf 1 2 3\nv 1 1 0\n"))
    assert data.face_verts.tolist() == [0, 1, 2]


def test_faces_are_kept_as_written(tmp_path):
    text = SQUARE + "v 2 0 0\nv 2 1 0\nf 4 3 2 1\nf 2 5 6 3 3\nf 1 2 3\n"
    data = read_quiet(write(tmp_path, text))
    assert data.face_sizes.tolist() == [4, 5, 3]
    assert data.face_verts.tolist() == [3, 2, 1, 0, 1, 4, 5, 2, 2, 0, 1, 2]


def test_continuation_lines_crlf_tabs_comments(tmp_path):
    text = ("# a comment\r\n\r\n"
            "v\t0 0 0   \r\n"
            "v 1 \\\r\n  0 0 # trailing comment\r\n"
            "v 1 1 0\r\n"
            "  \t\r\n"
            "v 0 1 0 # another\r\n"
            "f 1 2 \\\n3 \\\n 4\r\n"
            "f 1 2 x\\\n3\n")  # `x\` joins with `3`: "x 3" would be bad, proving the join
    path = write(tmp_path, text)
    err = expect_error(path, 12, "vertex", "not an integer")  # first line of that statement
    assert "'x'" in str(err)
    data = read_quiet(write(tmp_path, text.rsplit("f 1 2 x", 1)[0]))
    np.testing.assert_array_equal(data.points, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    assert data.face_verts.tolist() == [0, 1, 2, 3]


def test_continued_statement_errors_name_its_first_line(tmp_path):
    path = write(tmp_path, SQUARE + "f 1 2 \\\n 3 \\\n 9\n")
    expect_error(path, 5, "out of range")


def test_v_with_w_or_colour_and_vt_with_w(tmp_path):
    text = ("v 0 0 0 1\nv 1 0 0 0.5 0.25 0.125\nv 1 1 0\n"
            "vt 0.5\nvt 0.25 0.75 0\nf 1/1 2/2 3/2\n")
    data = read_quiet(write(tmp_path, text))
    np.testing.assert_array_equal(data.points, [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    np.testing.assert_array_equal(data.uvs, [[0.5, 0.0], [0.25, 0.75]])


def test_exponents_and_signs(tmp_path):
    data = read_quiet(write(tmp_path, "v -1e-3 +2.5E2 .5\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"))
    assert data.points[0].tolist() == [-1e-3, 250.0, 0.5]


def test_groups_objects_and_materials(tmp_path):
    (tmp_path / "a.mtl").write_text(
        "# library a\nnewmtl red\nKa 0 0 0\nKd 1 0 0\nillum 2\n\nnewmtl grey\nKd 0.5\n")
    (tmp_path / "b.mtl").write_text("newmtl blue\r\nKd 0 0 1\r\nmap_Kd blue.png\r\n")
    text = ("mtllib a.mtl b.mtl\n" + SQUARE +
            "f 1 2 3\n"
            "o body\ng left\nusemtl blue\nf 1 2 3\n"
            "g right\nusemtl red\ns 1\nf 1 3 4\n"
            "usemtl ghost\nf 2 3 4\n"
            "o lid\ng\nusemtl\nf 1 2 4\n"
            "g left\nusemtl red\nf 1 2 3 4\n")
    with pytest.warns(SubtraceWarning, match="ghost"):
        data = read_obj(write(tmp_path, text))
    check_layout(data)
    assert data.materials == (
        Material("red", (1.0, 0.0, 0.0)), Material("grey", (0.5, 0.5, 0.5)),
        Material("blue", (0.0, 0.0, 1.0)), Material("ghost", DEFAULT_DIFFUSE))
    assert data.face_material.tolist() == [-1, 2, 0, 3, -1, 0]
    assert data.groups == ("default", "left", "right")
    assert data.face_group.tolist() == [0, 1, 2, 2, 0, 1]
    assert data.objects == ("default", "body", "lid")
    assert data.face_object.tolist() == [0, 1, 1, 1, 2, 2]
    # the ghost material, and b.mtl's map_Kd whose file is missing (named, the colour kept)
    assert len(data.warnings) == 2 and f"{data.path}:15:" in data.warnings[1]
    assert "b.mtl:3: map_Kd texture 'blue.png' not found" in data.warnings[0]
    assert "material 'blue' keeps its constant colours" in data.warnings[0]


@pytest.mark.parametrize("statement", ["map_d spot.png", "map_Ka spot.png", "disp spot.png",
                                       "MAP_PR -bm 2 spot.png"])
def test_a_texture_map_not_applied_is_one_warning_naming_its_file(tmp_path, statement):
    """A texture map subtrace does not apply is one warning naming the MTL line and the
    file (there, but not applied), and the material keeps its colours; a map naming no file
    is a warning too."""
    (tmp_path / "spot.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    (tmp_path / "t.mtl").write_text(
        f"newmtl skin\nKd 0.2 0.3 0.4\n{statement}\n{statement.split()[0]}\n")
    data = read_quiet(write(tmp_path, "mtllib t.mtl\nusemtl skin\n" + SQUARE + "f 1 2 3 4\n"))
    assert data.materials == (Material("skin", (0.2, 0.3, 0.4)),)
    assert len(data.warnings) == 2, data.warnings
    key = statement.split()[0]
    assert f"t.mtl:3: {key} texture 'spot.png' not applied" in data.warnings[0]
    assert "material 'skin' keeps its constant colours" in data.warnings[0]
    assert f"t.mtl:4: {key} names no file" in data.warnings[1]


@pytest.mark.parametrize("statement, slot, fields", [
    ("map_Kd spot.png", "diffuse", {}),
    ("MAP_KD spot.png", "diffuse", {}),
    ("map_Ks -s 2 3 1 -o 0.5 spot.png", "specular", {"scale": (2.0, 3.0),
                                                     "offset": (0.5, 0.0)}),
    ("map_Bump -bm 0.25 -imfchan g spot.png", "bump", {"bump_scale": 0.25, "channel": 1}),
    ("bump -clamp on spot.png", "bump", {"clamp": True}),
    ("norm -blendu off spot.png", "normal", {})])
def test_an_applied_texture_map_is_read_with_its_options(tmp_path, statement, slot, fields):
    """map_Kd, map_Ks, map_Bump / bump and norm become the material's maps (the file
    relative to the MTL, the MTL line kept for messages; -bm, -s, -o, -clamp, -imfchan
    read, the other options skipped), without a warning; a missing file is one warning
    naming it and the MTL line, and no map."""
    (tmp_path / "spot.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    (tmp_path / "t.mtl").write_text(
        f"newmtl skin\nKd 0.2 0.3 0.4\n{statement}\n{statement.replace('spot.png', 'no.png')}\n")
    data = read_quiet(write(tmp_path, "mtllib t.mtl\nusemtl skin\n" + SQUARE + "f 1 2 3 4\n"))
    (mat,) = data.materials
    assert mat.diffuse == (0.2, 0.3, 0.4)
    (tmap,) = mat.maps
    assert tmap.slot == slot and tmap.path == str((tmp_path / "spot.png").resolve())
    assert tmap.where.endswith("t.mtl:3")
    for name, value in fields.items():
        assert getattr(tmap, name) == value
    assert len(data.warnings) == 1, data.warnings
    assert "t.mtl:4:" in data.warnings[0] and "'no.png' not found" in data.warnings[0]


@pytest.mark.parametrize("statement, problem", [
    ("map_Kd -bm x spot.png", "option -bm needs a number"),
    ("map_Kd -frob 1 spot.png", "unknown option '-frob'"),
    ("bump -clamp maybe spot.png", "-clamp takes on or off")])
def test_a_bad_texture_map_option_is_an_error_naming_the_mtl_line(tmp_path, statement,
                                                                  problem):
    (tmp_path / "spot.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    (tmp_path / "t.mtl").write_text(f"newmtl skin\n{statement}\n")
    with pytest.raises(ObjError, match=problem) as err:
        read_obj(write(tmp_path, "mtllib t.mtl\nusemtl skin\n" + SQUARE + "f 1 2 3 4\n"))
    assert "t.mtl:2" in str(err.value)


def test_missing_mtl_is_a_warning(tmp_path):
    path = write(tmp_path, "mtllib nowhere.mtl\nusemtl skin\n" + SQUARE + "f 1 2 3 4\n")
    with pytest.warns(SubtraceWarning) as record:
        data = read_obj(path)
    assert data.materials == (Material("skin", DEFAULT_DIFFUSE),)
    assert data.face_material.tolist() == [0]
    assert any("nowhere.mtl" in str(w.message) and f"{path}:1:" in str(w.message)
               for w in record)
    assert [str(w.message) for w in record] == list(data.warnings)


def test_malformed_mtl_is_an_error(tmp_path):
    (tmp_path / "bad.mtl").write_text("newmtl m\nKd 1 zero 0\n")
    with pytest.raises(ObjError) as info:
        read_quiet(write(tmp_path, "mtllib bad.mtl\n" + SQUARE + "f 1 2 3\n"))
    assert "bad.mtl:2:" in str(info.value) and "Kd" in str(info.value)


def test_mtl_specular_and_shininess(tmp_path):
    """Ks and Ns are read per material (Ns defaults where Ks comes alone, Ks to none)."""
    (tmp_path / "s.mtl").write_text(
        "newmtl shiny\nKd 0.5 0.4 0.3\nKs 0.2\nNs 64\nnewmtl half\nKs 0.1 0.2 0.3\n"
        "newmtl matte\nKd 1 1 1\n")
    data = read_quiet(write(tmp_path, "mtllib s.mtl\nusemtl shiny\n" + SQUARE + "f 1 2 3\n"))
    assert data.materials == (
        Material("shiny", (0.5, 0.4, 0.3), (0.2, 0.2, 0.2), 64.0),
        Material("half", DEFAULT_DIFFUSE, (0.1, 0.2, 0.3), DEFAULT_SHININESS),
        Material("matte", (1.0, 1.0, 1.0), DEFAULT_SPECULAR, DEFAULT_SHININESS))


@pytest.mark.parametrize("line,key", [("Ks 1 2", "Ks"), ("Ns -3", "Ns"), ("Ns shiny", "Ns"),
                                      ("Ns 1 2", "Ns")])
def test_malformed_specular_is_an_error(tmp_path, line, key):
    (tmp_path / "bad.mtl").write_text(f"newmtl m\n{line}\n")
    with pytest.raises(ObjError) as info:
        read_quiet(write(tmp_path, "mtllib bad.mtl\n" + SQUARE + "f 1 2 3\n"))
    assert "bad.mtl:2:" in str(info.value) and key in str(info.value)


def test_unknown_and_freeform_statements_warn_once(tmp_path):
    text = SQUARE + "l 1 2\nl 2 3\np 1\ncstype bspline\nvp 0.5\nf 1 2 3\n"
    with pytest.warns(SubtraceWarning) as record:
        data = read_obj(write(tmp_path, text))
    messages = list(data.warnings)
    assert [str(w.message) for w in record] == messages
    assert len(messages) == 4
    assert ":5:" in messages[0] and "'l'" in messages[0] and "2 lines" in messages[0]
    assert any("free-form" in m and "cstype" in m for m in messages)


def test_opensubdiv_tags(tmp_path):
    text = (SQUARE + "v 2 0 0\nv 2 1 0\nf 1 2 3 4\nf 2 5 6 3\n"
            "t crease 2/1/0 1 2 2.5\n"
            "t crease 4/2/0 0 1 4 5 1 10\n"
            "t crease 4/1/0 2 3 3 0 0.5\n"
            "t corner 2/1/0 0 3 4\n"
            "t corner 2/2/0 4 5 1.5 0\n"
            "t hole 1/0/0 1\n"
            "t interpolateboundary 1/0/0 1\n"
            "t creasemethod 0/0/1 chaikin\n"
            "t smoothtriangles 0/0/1 smooth\n"
            "t facevaryingpropagatecorners 1/0/0 1\n"
            "t faceVaryingInterpolateBoundary 1/0/0 1\n"
            "t mystery 0/0/0\n")
    with pytest.warns(SubtraceWarning):
        data = read_obj(write(tmp_path, text))
    check_layout(data)
    assert data.crease_edges.tolist() == [[1, 2], [0, 1], [4, 5], [2, 3], [3, 0]]
    assert data.crease_sharpness.tolist() == [2.5, 1.0, 10.0, 0.5, 0.5]
    assert data.corner_verts.tolist() == [0, 3, 4, 5]
    assert data.corner_sharpness.tolist() == [4.0, 4.0, 1.5, 0.0]
    assert data.hole_faces.tolist() == [1]
    assert (data.boundary, data.crease_method, data.smooth_triangles) == (1, "chaikin", "smooth")
    assert len(data.warnings) == 3
    assert "facevaryingpropagatecorners" in data.warnings[0]
    assert "mystery" in data.warnings[2]


def test_tag_values_last_one_wins_and_normal_means_uniform(tmp_path):
    text = (SQUARE + "f 1 2 3 4\nt interpolateboundary 1/0/0 0\nt interpolateboundary 1/0/0 2\n"
            "t creasemethod 0/0/1 chaikin\nt creasemethod 0/0/1 normal\n"
            "t smoothtriangles 0/0/1 catmark\n")
    data = read_quiet(write(tmp_path, text))
    assert (data.boundary, data.crease_method, data.smooth_triangles) == (2, "uniform", "catmark")


def test_utf8_names_and_bom(tmp_path):
    path = tmp_path / "mesh.obj"
    path.write_bytes(b"\xef\xbb\xbfo caf\xc3\xa9\n" + SQUARE.encode() + b"f 1 2 3\n")
    assert read_quiet(path).objects == ("café",)


def test_accepts_pathlike_and_str(tmp_path):
    path = write(tmp_path, SQUARE + "f 1 2 3\n")
    assert read_quiet(str(path)).path == str(path)
    assert read_quiet(path).face_sizes.tolist() == [3]


# -- errors --------------------------------------------------------------------------------


def test_error_empty_file(tmp_path):
    expect_error(write(tmp_path, ""), None, "empty", "no faces")


def test_error_no_faces(tmp_path):
    expect_error(write(tmp_path, "# only points\n" + SQUARE), None, "no faces")


def test_error_missing_file(tmp_path):
    expect_error(tmp_path / "absent.obj", None, "no such file")


def test_error_directory(tmp_path):
    folder = tmp_path / "folder.obj"
    folder.mkdir()
    expect_error(folder, None, "directory")


def test_error_not_utf8(tmp_path):
    path = tmp_path / "mesh.obj"
    path.write_bytes(SQUARE.encode() + b"g caf\xe9\nf 1 2 3\n")
    expect_error(path, 5, "UTF-8")


def test_error_bad_number(tmp_path):
    err = expect_error(write(tmp_path, "v 0 0 0\nv 1 x 3\nv 0 1 0\nf 1 2 3\n"), 2,
                       "not a number")
    assert "'x'" in str(err)


def test_error_too_few_coordinates(tmp_path):
    expect_error(write(tmp_path, "v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n"), 2, "3 coordinates")


def test_error_too_few_normal_coordinates(tmp_path):
    expect_error(write(tmp_path, SQUARE + "vn 0 1\nf 1 2 3\n"), 5, "vn", "3 coordinates")


@pytest.mark.parametrize("value", ["nan", "inf", "-Infinity", "1e400"])
def test_error_non_finite_coordinates(tmp_path, value):
    expect_error(write(tmp_path, f"v 0 0 0\nv 1 0 0\nv 0 {value} 0\nf 1 2 3\n"), 3,
                 "finite")


def test_error_non_finite_uv(tmp_path):
    expect_error(write(tmp_path, SQUARE + "vt 0 nan\nf 1/1 2/1 3/1\n"), 5, "vt", "finite")


def test_error_index_zero(tmp_path):
    expect_error(write(tmp_path, SQUARE + "f 1 2 3\nf 0 1 2\n"), 6, "index 0", "start at 1")


def test_error_index_out_of_range_positive(tmp_path):
    err = expect_error(write(tmp_path, SQUARE + "f 1 2 3\nf 1 2 5\n"), 6, "out of range")
    assert "5" in str(err) and "4" in str(err)


def test_error_index_out_of_range_negative(tmp_path):
    # Only 4 vertices are read before the face; the one after it does not count.
    expect_error(write(tmp_path, SQUARE + "f -1 -2 -5\nv 9 9 9\n"), 5, "relative", "out of range")


def test_error_non_integer_index(tmp_path):
    expect_error(write(tmp_path, SQUARE + "f 1 2.0 3\n"), 5, "not an integer")


def test_error_empty_vertex_index(tmp_path):
    expect_error(write(tmp_path, SQUARE + "vt 0 0\nf 1 /1 3\n"), 6, "without a vertex index")


def test_error_too_many_slashes(tmp_path):
    expect_error(write(tmp_path, SQUARE + "f 1/1/1/1 2 3\n"), 5, "too many '/'")


def test_error_face_with_two_vertices(tmp_path):
    expect_error(write(tmp_path, SQUARE + "f 1 2 3\nf 1 2\n"), 6, "at least 3")


def test_error_uv_index_out_of_range(tmp_path):
    expect_error(write(tmp_path, SQUARE + "vt 0 0\nf 1/1 2/2 3/1\n"), 6, "texture", "out of range")


def test_error_normal_index_out_of_range(tmp_path):
    expect_error(write(tmp_path, SQUARE + "vn 0 0 1\nf 1//1 2//-2 3//1\n"), 6, "normal",
                 "out of range")


def test_error_earliest_line_wins(tmp_path):
    # A bad number (found by the bulk conversion) before a malformed face (found while
    # scanning) is the one reported.
    expect_error(write(tmp_path, "v 0 0 0\nv 1 q 0\nv 0 1 0\nf 1 2\n"), 2, "not a number")
    expect_error(write(tmp_path, SQUARE + "f 1 2 9\nf 1 2 x\n"), 5, "out of range")


TAG_ERRORS = [
    ("t crease 2/1 0 1 1.0", "count header"),
    ("t crease two/1/0 0 1 1.0", "count header"),
    ("t crease", "count header"),
    ("t crease 2/1/0 0 1", "announces 3 values but the line has 2"),
    ("t crease 2/1/0 0 1 1.0 7", "announces 3 values but the line has 4"),
    ("t crease 2/1/0 0 one 1.0", "not an integer"),
    ("t crease 2/1/0 0 1 sharp", "not a number"),
    ("t crease 2/1/0 0 1 nan", "not a number"),
    ("t crease 2/1/0 0 1 -1", "negative sharpness"),
    ("t corner 1/1/0 0 -0.5", "negative sharpness"),
    ("t crease 3/1/0 0 1 2 1.0", "pairs"),
    ("t crease 4/3/0 0 1 1 2 1 2 3", "one per edge"),
    ("t crease 2/0/0 0 1", "1 sharpness"),
    ("t crease 2/1/0 2 2 1.0", "itself"),
    ("t corner 2/3/0 0 1 1 2 3", "one per vertex"),
    ("t hole 1/1/0 0 1.0", "face indices only"),
    ("t interpolateboundary 1/0/0 3", "unknown value 3"),
    ("t interpolateboundary 0/0/1 edgeonly", "expects 1/0/0"),
    ("t creasemethod 0/0/1 smooth", "unknown 'smooth'"),
    ("t creasemethod 1/0/0 1", "expects 0/0/1"),
    ("t smoothtriangles 0/0/1 loop", "unknown 'loop'"),
    ("t", "tag name"),
]


@pytest.mark.parametrize("tag, words", TAG_ERRORS, ids=[t for t, _ in TAG_ERRORS])
def test_error_malformed_tag(tmp_path, tag, words):
    expect_error(write(tmp_path, SQUARE + "f 1 2 3 4\n" + tag + "\nf 1 2 3\n"), 6, words)


@pytest.mark.parametrize("tag, words", [
    ("t crease 2/1/0 0 4 1.0", "vertex index 4 out of range"),
    ("t crease 2/1/0 -1 0 1.0", "vertex index -1 out of range"),
    ("t corner 1/1/0 7 1.0", "vertex index 7 out of range"),
    ("t hole 2/0/0 0 2", "face index 2 out of range"),
])
def test_error_tag_index_out_of_range_checked_after_reading(tmp_path, tag, words):
    # The tag comes before the elements it may name, so the check waits for the end of the
    # file; the error still names the tag's line.
    text = tag + "\n" + SQUARE + "f 1 2 3 4\nf 1 2 3\n"
    expect_error(write(tmp_path, text), 1, words, "0-based")


# -- property tests ------------------------------------------------------------------------

_coordinate = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, width=64)


@st.composite
def obj_texts(draw):
    """A valid OBJ text and the arrays it must parse to.

    Faces reference points already written with negative indices or any point with
    positive ones; each corner picks its own index form.
    """
    points, uvs, normals = [], [], []
    lines, sizes, verts, face_uvs, face_normals = [], [], [], [], []
    for _ in range(draw(st.integers(1, 4))):
        for _ in range(draw(st.integers(3, 6))):
            point = draw(st.tuples(_coordinate, _coordinate, _coordinate))
            points.append(point)
            lines.append("v " + " ".join(repr(c) for c in point))
        for _ in range(draw(st.integers(0, 2))):
            uvs.append(draw(st.tuples(_coordinate, _coordinate)))
            lines.append("vt " + " ".join(repr(c) for c in uvs[-1]))
        for _ in range(draw(st.integers(0, 2))):
            normals.append(draw(st.tuples(_coordinate, _coordinate, _coordinate)))
            lines.append("vn " + " ".join(repr(c) for c in normals[-1]))
        for _ in range(draw(st.integers(1, 3))):
            size = draw(st.integers(3, min(6, len(points))))
            face = draw(st.lists(st.integers(0, len(points) - 1), min_size=size,
                                 max_size=size, unique=True))
            corners = []
            for vert in face:
                def ref(index, count):
                    return str(index - count if draw(st.booleans()) else index + 1)

                uv = draw(st.integers(-1, len(uvs) - 1))
                normal = draw(st.integers(-1, len(normals) - 1))
                text = ref(vert, len(points))
                if uv >= 0 and normal >= 0:
                    text += f"/{ref(uv, len(uvs))}/{ref(normal, len(normals))}"
                elif uv >= 0:
                    text += f"/{ref(uv, len(uvs))}"
                elif normal >= 0:
                    text += f"//{ref(normal, len(normals))}"
                corners.append(text)
                verts.append(vert)
                face_uvs.append(uv)
                face_normals.append(normal)
            sizes.append(size)
            separator = draw(st.sampled_from([" ", "  ", "\t"]))
            lines.append("f" + separator + separator.join(corners))
    newline = draw(st.sampled_from(["\n", "\r\n"]))
    expected = dict(points=points, face_sizes=sizes, face_verts=verts, uvs=uvs,
                    face_uvs=face_uvs, normals=normals, face_normals=face_normals)
    return newline.join(lines) + newline, expected


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=obj_texts())
def test_random_valid_obj_round_trips(tmp_path, case):
    text, expected = case
    data = read_quiet(write(tmp_path, text))
    check_layout(data)
    assert data.points.tolist() == [list(p) for p in expected["points"]]
    assert data.uvs.reshape(-1, 2).tolist() == [list(p) for p in expected["uvs"]]
    assert data.normals.reshape(-1, 3).tolist() == [list(p) for p in expected["normals"]]
    for name in ("face_sizes", "face_verts", "face_uvs", "face_normals"):
        assert getattr(data, name).tolist() == expected[name], name
    assert data.warnings == ()


_VALID = (SQUARE + "vt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1 4/1/1\nf -1 -2 -3\n"
          "t crease 2/1/0 0 1 2.0\nt corner 1/1/0 2 10\ng side\nusemtl m\nf 1//1 3//1 4//1\n")


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(garbage=mutations(_VALID, " \t\r\n\\#/-+.0123456789eEfvtngosl", 120, 8))
def test_garbage_parses_or_raises_obj_error(tmp_path, garbage):
    path = tmp_path / "fuzz.obj"
    path.write_bytes(garbage)
    try:
        data = read_quiet(path)
    except ObjError as err:
        assert str(err).startswith(str(path))
        return
    check_layout(data)


def test_errors_carry_path_and_line(tmp_path):
    path = write(tmp_path, SQUARE + "f 1 2 0\n")
    with pytest.raises(ObjError) as info:
        read_quiet(path)
    assert (info.value.path, info.value.line) == (str(path), 5)
    assert re.match(rf"{re.escape(str(path))}:5: ", str(info.value))


# -- the byte scanner against the statement reader -----------------------------------------


def _both_readers(path: Path):
    """(read_fast result or None, read result or the ObjError it raised) for one file."""
    from subtrace.io.obj import ObjReader, decode_obj

    raw = path.read_bytes()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SubtraceWarning)
        source = [raw]
        fast = ObjReader(str(path)).read_fast(source)
        # (what it read, it let the bytes go before cutting the arrays to size)
        assert (source == []) if fast is not None else True
        try:
            slow = ObjReader(str(path)).read(decode_obj(str(path), raw))
        except ObjError as err:
            slow = err
    return fast, slow


def assert_same_data(fast: ObjData, slow: ObjData):
    """Every field equal, arrays bit for bit (signed zeros included) with the same layout."""
    for name in ObjData.__dataclass_fields__:
        a, b = getattr(fast, name), getattr(slow, name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and a.shape == b.shape and a.flags.c_contiguous, name
            assert a.tobytes() == b.tobytes(), name
        else:
            assert a == b, name


@pytest.mark.parametrize("obj_path", MODEL_FILES + ORACLE_SHAPES, ids=lambda p: p.stem)
def test_byte_scanner_reads_every_model_as_the_statement_reader(obj_path):
    fast, slow = _both_readers(obj_path)
    assert fast is not None, "the byte scanner handed a valid model to the statement reader"
    assert_same_data(fast, slow)


def test_byte_scanner_hands_over_what_it_cannot_read(tmp_path):
    # Each is valid and read by the statement reader alone: a continuation line, a space
    # str.split() knows and the scanner does not, digits float() accepts but the scanner
    # does not; the last two are numbers the scanner leaves to float() (no hand-over).
    for text, handed_over in [(SQUARE + "f 1 2 \\\n 3\n", True),
                              (SQUARE + "f 1\u00a02 3\n", True),
                              ("v 1_0 0 0\n" + SQUARE + "f 1 2 3\n", True),
                              ("v 0.1234567890123456789 1e-30 0\n" + SQUARE + "f 1 2 3\n", False),
                              ("v 1e300 2e-300 0\n" + SQUARE + "f 1 2 3\n", False)]:
        fast, slow = _both_readers(write(tmp_path, text))
        assert (fast is None) == handed_over, text
        if fast is not None:
            assert_same_data(fast, slow)
    fast, _ = _both_readers(write(tmp_path, "v 1e300 2e-300 0\n" + SQUARE + "f 1 2 3\n"))
    assert fast.points[0].tolist() == [1e300, 2e-300, 0.0]


_number = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.builds(lambda x, places: f"{x:.{places}f}", st.floats(-1e3, 1e3), st.integers(0, 25)),
    st.builds(lambda m, e, s: f"{m}{s}{e}", st.integers(-10**20, 10**20),
              st.integers(0, 40), st.sampled_from(["e", "E", "e+", "e-", "E-0"])),
    st.sampled_from(["-0", "+.5", "5.", "0.000727", "-1.5E-3"]),
)
_bad_number = st.sampled_from([".", "1e", "nan", "inf", "1e400", "-", "0x1", "1_0"])


@st.composite
def obj_statements(draw):
    """Mostly valid OBJ text mixing every statement kind, with now and then a bad token."""
    lines, counts = SQUARE.split("\n")[:4], {"v": 4, "vt": 0, "vn": 0}
    for _ in range(draw(st.integers(0, 14))):
        kind = draw(st.sampled_from(["v", "v", "vt", "vn", "f", "f", "f", "other"]))
        sep = draw(st.sampled_from([" "] * 12 + ["\t", "  ", "\x0b", "\x1c", "\u00a0"]))
        if kind in counts:
            width = draw(st.sampled_from([3] * 12 + [4, 6, 2] if kind != "vt" else [1, 2, 3]))
            numbers = [draw(draw(st.sampled_from([_number] * 40 + [_bad_number])))
                       for _ in range(width)]
            lines.append(sep.join([kind] + numbers))
            counts[kind] += 1
        elif kind == "f" and counts["v"]:
            corners = []
            for _ in range(draw(st.sampled_from([3, 4, 4, 5] * 5 + [2]))):
                fields = []
                for key in ("v", "vt", "vn"):
                    n = counts[key]
                    use = key == "v" or (n and draw(st.booleans()))
                    fields.append(str(draw(st.one_of(st.integers(1, n), st.integers(-n, -1))))
                                  if use and n else "")
                corner = "/".join(fields).rstrip("/")
                if fields[1] == "" and fields[2]:
                    corner = f"{fields[0]}//{fields[2]}"
                corners.append(draw(st.sampled_from([corner] * 80 + ["0", "x", "1/2/3/4"])))
            lines.append(sep.join(["f"] + corners))
        else:
            lines.append(draw(st.sampled_from([
                "# comment", "", "g a b", "o thing", "usemtl red", "usemtl", "s 1", "curv 1 2",
                "t crease 2/1/0 0 1 2.0", "t corner 1/1/0 0 5", "t hole 1/0/0 0", "g h\u00e9",
                "t interpolateboundary 1/0/0 1", "vp 1", "v 1 2 3 # c", "f 1 2 3#x",
                "\u00a0v 1 2 3", "\x00v 1 2 3", "t bogus 0/0/0", "mtllib none.mtl"])))
    lines.append(draw(st.sampled_from(["f 1 2 3", "f 4 3 2 1", ""])))
    newline = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    text = newline.join(lines) + draw(st.sampled_from(["", newline]))
    return (draw(st.sampled_from(["", "\ufeff"])) + text).encode("utf-8")


@settings(max_examples=400, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=obj_statements())
def test_byte_scanner_agrees_with_the_statement_reader(tmp_path, data):
    path = tmp_path / "scan.obj"
    path.write_bytes(data)
    fast, slow = _both_readers(path)
    if fast is not None:
        assert isinstance(slow, ObjData), f"the scanner read what is an error: {slow}"
        assert_same_data(fast, slow)


def test_slow_numbers_round_as_float_does():
    """The numbers the scanner leaves over (more digits than it keeps, large exponents) are
    converted in chunks of byte strings: bit for bit float()'s, across a chunk's end, with
    widths that differ within a chunk; None for a token that is not a number."""
    from subtrace.io import obj as obj_module

    rng = np.random.default_rng(7)
    bits = rng.integers(0, 2**63 - 1, 40000, dtype=np.int64)
    doubles = bits.view(np.float64)
    doubles = doubles[np.isfinite(doubles)]
    tokens = [repr(x) for x in doubles.tolist()] + [f"{x:.25e}" for x in doubles[:5000]]
    tokens += ["0." + "9" * 40, "-" + "1" * 30 + "e-330", "4.9406564584124654e-324",
               "2.4703282292062328e-324", "2.4703282292062327e-324", "1.7976931348623157e308",
               "+1.5", ".5", "5.", "-.5e3", "1E5", "0.00072475878906250006",
               "0." + "3" * 500 + "e2", "1" * 400]  # (tokens longer than a chunk's width)
    data = " ".join(tokens).encode()
    ends = np.cumsum([len(t) + 1 for t in tokens]) - 1
    spans = np.stack([ends - [len(t) for t in tokens], ends], axis=1).astype(np.int64)
    assert len(tokens) > obj_module._SLOW_CHUNK
    got = obj_module.slow_numbers(data, spans)
    want = np.array([float(t) for t in tokens])
    assert got.view(np.int64).tolist() == want.view(np.int64).tolist()
    assert obj_module.slow_numbers(b"1.5 x", np.array([[0, 3], [4, 5]])) is None


_COLD_READ = """
import json, sys
from subtrace.io import obj_scan
from subtrace.io.obj import read_obj
first = read_obj(sys.argv[1])
compiled = [len(obj_scan.scan_bytes.signatures)]
obj_scan.STATEMENT_READER_BYTES = 0
second = read_obj(sys.argv[1])
compiled.append(len(obj_scan.scan_bytes.signatures))
print(json.dumps({"compiled": compiled, "same": [first.points.tobytes() == second.points.tobytes(),
                  first.face_verts.tolist() == second.face_verts.tolist(),
                  first.face_sizes.tolist() == second.face_sizes.tolist()]}))
"""


def test_a_small_file_is_read_without_compiling_the_scanner(tmp_path):
    """A small OBJ goes to the statement reader (as fast as loading the scanner, and on an
    empty kernel cache far faster than compiling it): nothing compiles; with the limit at 0
    (as `subtrace warmup` sets it) the scanner compiles and reads the same cage."""
    import json
    import os
    import subprocess
    import sys

    from subtrace.data import sample_cage_path

    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(SUBTRACE_CACHE_DIR=str(tmp_path / "cache"), PYTHONDONTWRITEBYTECODE="1")
    proc = subprocess.run([sys.executable, "-c", _COLD_READ, str(sample_cage_path())],
                          capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["compiled"] == [0, 1] and all(out["same"])


def test_a_file_with_a_late_error_is_read_again_for_it(tmp_path):
    """A file the byte scanner reads (every file here: the fixture above) whose error shows
    only once the scanner let its bytes go (a tag's vertex index out of range, checked
    last): the file is read again and the statement reader names the tag's line."""
    n = 400
    grid = "".join(f"v {i % 97} {i // 97} 0.123456789012345678\n" for i in range(n))
    faces = "".join(f"f {i + 1} {i + 2} {i + 98} {i + 97}\n" for i in range(n - 98))
    path = write(tmp_path, grid + faces + f"t crease 2/1/0 0 {n + 5} 1.0\n")
    source = [path.read_bytes()]
    assert ObjReader(str(path)).read_fast(source) is None and source == []
    expect_error(path, n + (n - 98) + 1, "out of range")

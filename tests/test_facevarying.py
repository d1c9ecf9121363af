"""Face-varying UVs against OpenSubdiv 3.5 (``tests/oracle/fvar``, its README documents the
data), in all six linear-interpolation modes, on OpenSubdiv's fvar shapes and six more of its
regression shapes, subtrace's own seam / crease shapes and Spot:

* the UV of every face corner of refined levels 1 and 2 (``Cage.refine_uv``): 1e-12 (they
  agree to ~4e-16; only the order of the sums differs);
* limit UVs at ptex samples (``Cage.evaluate_uv``): 1e-9 (the issue's bound; they agree to
  ~1e-15) where OpenSubdiv's value is exact (its face-varying patch is a regular one, or
  the value does not move between isolation levels 8 and 10); elsewhere (a ptex corner on
  an end cap whose limit mask OpenSubdiv only approximates: a dart of the cage) within
  that movement plus 1e-9, since OpenSubdiv's own value is still converging there;

and the ways a mode is chosen (the OBJ tag, USD's ``faceVaryingLinearInterpolation``, the
primvar's interpolation), bad input, and cages whose UVs change nothing else.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from shared_data import MODELS, ORACLE

import subtrace
from subtrace.cli import main
from subtrace.errors import SubtraceError, TopologyError
from subtrace.mesh.cage import make_cage

FVAR = ORACLE / "fvar"
SHAPES = {
    "catmark_fvar_bound0": ORACLE / "shapes",
    "catmark_fvar_bound3": ORACLE / "shapes",
    "loop_fvar_bound0": ORACLE / "shapes",
    "catmark_fvar_seams": FVAR / "shapes",
    "catmark_fvar_chaikin": FVAR / "shapes",
    "loop_fvar_seams": FVAR / "shapes",
    "spot_control_mesh": MODELS,
    # more of OpenSubdiv's shapes (with vt): n-gons and valence 2, non-manifold edges, the
    # smooth triangle rule, holes, boundary "none", semi-sharp Loop
    "catmark_val2_interior": ORACLE / "shapes",
    "catmark_nonman_edges": ORACLE / "shapes",
    "catmark_smoothtris1": ORACLE / "shapes",
    "catmark_hole_test3": ORACLE / "shapes",
    "catmark_edgenone": ORACLE / "shapes",
    "loop_cubes_semisharp": ORACLE / "shapes",
}
MODES = range(6)
UV_TOL = 1e-9
REFINED_TOL = 1e-12


def _oracle(name):
    z = np.load(FVAR / f"{name}.npz")
    return z, json.loads(str(z["meta"]))


@pytest.fixture(scope="module")
def cages():
    cache = {}

    def get(name, mode):
        if name not in cache:
            _, meta = _oracle(name)
            cache[name] = subtrace.load_cage(SHAPES[name] / f"{name}.obj", scheme=meta["scheme"])
        cage = cache[name]
        return replace(cage, uv=replace(cage.uv, mode=mode))

    return get


def test_the_data_is_here():
    assert sorted(p.stem for p in FVAR.glob("*.npz")) == sorted(SHAPES)
    for name in SHAPES:
        assert (SHAPES[name] / f"{name}.obj").is_file()
        z, meta = _oracle(name)
        assert meta["modes"][5] == "all" and meta["opensubdiv"].startswith("3.")


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", sorted(SHAPES))
def test_refined_uvs(cages, name, mode):
    z, meta = _oracle(name)
    cage = cages(name, mode)
    for level in range(1, meta["levels"] + 1):
        values, face_values = cage.refine_uv(level)
        assert len(face_values) == len(cage.refine(level).face_verts)
        np.testing.assert_allclose(values[face_values], z[f"refined{level}_m{mode}"], rtol=0,
                                   atol=REFINED_TOL)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", sorted(SHAPES))
def test_limit_uvs(cages, name, mode):
    z, _ = _oracle(name)
    cage = cages(name, mode)
    got = cage.evaluate_uv(z["sample_ptex_face"], z["sample_uv"])
    err = np.abs(got - z[f"uv_m{mode}"]).max(axis=1)
    iso = z[f"isodiff_m{mode}"]
    exact = (z[f"regular_m{mode}"] == 1) | (iso <= 1e-14)
    assert exact.mean() > 0.97
    assert err[exact].max() <= UV_TOL, np.nonzero(exact & (err > UV_TOL))[0]
    assert (err[~exact] <= iso[~exact] + UV_TOL).all()


def test_modes_differ_where_they_should():
    """The six modes give six different surfaces on the shapes with seams, junctions,
    darts and creases (so each test above tests its own mode there)."""
    for name in ("catmark_fvar_seams", "loop_fvar_seams", "spot_control_mesh"):
        z, _ = _oracle(name)
        uvs = [z[f"uv_m{m}"] for m in MODES]
        for a in MODES:
            for b in range(a + 1, 6):
                assert np.abs(uvs[a] - uvs[b]).max() > 1e-3, (name, a, b)


def _obj_with_tag(tmp_path, name, tag):
    text = (SHAPES[name] / f"{name}.obj").read_text()
    path = tmp_path / f"{name}.obj"
    path.write_text(text + ("" if tag is None else
                            f"t facevaryinginterpolateboundary 1/0/0 {tag}\n"))
    return path


@pytest.mark.parametrize("mode", MODES)
def test_obj_tag_selects_the_mode(tmp_path, mode):
    z, _ = _oracle("catmark_fvar_bound0")
    cage = subtrace.load_cage(_obj_with_tag(tmp_path, "catmark_fvar_bound0", mode))
    assert cage.uv.mode == mode
    got = cage.evaluate_uv(z["sample_ptex_face"], z["sample_uv"])
    np.testing.assert_allclose(got, z[f"uv_m{mode}"], rtol=0, atol=UV_TOL)


def test_without_the_tag_the_mode_is_opensubdivs_default(tmp_path):
    """Sdc::Options' default, which OpenSubdiv's OBJ loaders (regression/common/far_utils.h)
    keep: linear everywhere."""
    cage = subtrace.load_cage(_obj_with_tag(tmp_path, "catmark_fvar_bound0", None))
    assert cage.uv.mode == 5 and cage.uv.mode_name == "all"


def _bad(capsys, path, words):
    code = main(["info", str(path)])
    _, err = capsys.readouterr()
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"subtrace: error: {path}:") and words in lines[0], err


@pytest.mark.parametrize("tag, words", [
    ("6", "unknown value 6, expected 0 (none), 1 (corners only)"),
    ("-1", "unknown value -1"),
])
def test_bad_obj_tag_is_one_error_line(tmp_path, capsys, tag, words):
    _bad(capsys, _obj_with_tag(tmp_path, "catmark_fvar_bound0", tag), words)
    path = tmp_path / "float.obj"
    path.write_text((SHAPES["catmark_fvar_bound0"] / "catmark_fvar_bound0.obj").read_text()
                    + "t facevaryinginterpolateboundary 0/1/0 2.0\n")
    _bad(capsys, path, "expects 1/0/0 and one integer")


def test_bad_vt_index_is_one_error_line(tmp_path, capsys):
    text = (SHAPES["catmark_fvar_bound0"] / "catmark_fvar_bound0.obj").read_text()
    path = tmp_path / "vt.obj"
    path.write_text(text.replace("f  6/6  7/7  12/12 11/11", "f  6/6  7/99  12/12 11/11"))
    _bad(capsys, path, "texture coordinate index 99 out of range: the file has 31 vt lines")


def test_api_checks_the_uvs():
    pts = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    with pytest.raises(TopologyError, match="UV index 4 is out of range: there are 4 UVs"):
        make_cage(pts, [4], [0, 1, 2, 3], uvs=np.eye(4, 2), face_uvs=[0, 1, 2, 4])
    with pytest.raises(TopologyError, match="3 UV indices for 4 face corners"):
        make_cage(pts, [4], [0, 1, 2, 3], uvs=np.eye(4, 2), face_uvs=[0, 1, 2])
    with pytest.raises(TopologyError, match="unknown face-varying interpolation 6"):
        make_cage(pts, [4], [0, 1, 2, 3], uvs=np.eye(4, 2), face_uvs=[0, 1, 2, 3], uv_mode=6)


def test_cages_without_uvs():
    cage = subtrace.load_cage(ORACLE / "shapes" / "catmark_pole8.obj")  # (no vt)
    assert cage.uv is None
    with pytest.raises(ValueError, match="the cage has no UVs"):
        cage.evaluate_uv([0], [[0.5, 0.5]])
    with pytest.raises(ValueError, match="the cage has no UVs"):
        cage.refine_uv(1)


def test_mixed_vt_gives_no_uvs(tmp_path):
    text = (SHAPES["catmark_fvar_bound0"] / "catmark_fvar_bound0.obj").read_text()
    path = tmp_path / "mixed.obj"
    path.write_text(text.replace("f  6/6  7/7  12/12 11/11", "f  6  7  12 11"))
    assert subtrace.load_cage(path).uv is None


def test_uvs_change_nothing_else():
    """Spot with and without its UVs: the same refined points and limit surface, bit for
    bit (the renderer's images are tests/test_golden.py's)."""
    with_uv = subtrace.load_cage(MODELS / "spot_control_mesh.obj")
    without = replace(with_uv, uv=None, _cache={})
    assert with_uv.uv is not None
    for level in (1, 2):
        assert np.array_equal(with_uv.refine(level).points, without.refine(level).points)
    rng = np.random.default_rng(3)
    ptex = rng.integers(0, 252, 64)
    uv = rng.random((64, 2))
    for a, b in zip(with_uv.evaluate(ptex, uv), without.evaluate(ptex, uv)):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("name", ["catmark_chaikin1", "catmark_cubes_semisharp",
                                  "catmark_val2_interior", "catmark_nonquads",
                                  "catmark_smoothtris1", "catmark_edgenone",
                                  "loop_icos_semisharp", "loop_triangle_edgeonly"])
def test_uvs_of_the_vertices_follow_the_points(name):
    """UVs with the cage's own topology (a value per vertex: its x, y) in mode none are
    vertex data: their limit is the limit position's x, y (``Cage.evaluate``, checked
    against OpenSubdiv in test_oracle.py), on cages with semi-sharp and Chaikin creases,
    darts, valence 2, n-gons, triangles, boundary "none" and Loop (seeded samples)."""
    cage = subtrace.load_cage(ORACLE / "shapes" / f"{name}.obj", scheme=name.split("_")[0])
    cage = replace(cage, uv=None, _cache={})
    uvs = make_cage(cage.points, cage.face_sizes, cage.face_verts, cage.scheme,
                    boundary=cage.options.boundary, chaikin=cage.options.chaikin,
                    smooth_triangles=cage.options.smooth_triangles,
                    crease_edges=cage.tags.crease_edges, crease_sharpness=cage.tags.crease_sharpness,
                    corner_verts=cage.tags.corner_verts, corner_sharpness=cage.tags.corner_sharpness,
                    hole_faces=cage.tags.hole_faces, uvs=cage.points[:, :2],
                    face_uvs=cage.face_verts, uv_mode=0)
    from subtrace.patches.evaluate import ptex_layout

    n_ptex = len(ptex_layout(cage)[0])
    rng = np.random.default_rng(7)
    ptex = rng.integers(0, n_ptex, 300)
    uv = rng.random((300, 2))
    if cage.scheme == "loop":
        uv = np.where(uv.sum(axis=1, keepdims=True) > 1, 1 - uv, uv)
    corners = [[0, 0], [1, 0], [0, 1]] if cage.scheme == "loop" else [[0, 0], [1, 0], [1, 1],
                                                                      [0, 1]]
    uv[:20] = np.resize(np.array(corners, float), (20, 2))  # ptex corners
    P, _, _ = cage.evaluate(ptex, uv)
    got = uvs.evaluate_uv(ptex, uv)
    live = ~np.isnan(P[:, 0])
    np.testing.assert_array_equal(np.isnan(got[:, 0]), ~live)
    scale = np.abs(cage.points).max()
    # (positions at depth-24 cells are interpolated from exact corners: 1e-12 of the size)
    np.testing.assert_allclose(got[live], P[live, :2], rtol=0, atol=1e-11 * scale)


def test_restricted_cage_keeps_its_uvs(cages):
    z, _ = _oracle("catmark_fvar_seams")
    cage = cages("catmark_fvar_seams", 2)
    whole = cage.restricted(np.ones(cage.n_faces, bool))
    np.testing.assert_array_equal(whole.uv.face_values, cage.uv.face_values)
    got = whole.evaluate_uv(z["sample_ptex_face"], z["sample_uv"])
    np.testing.assert_allclose(got, cage.evaluate_uv(z["sample_ptex_face"], z["sample_uv"]),
                               rtol=0, atol=1e-15)


def test_holes_and_argument_checks(cages):
    cage = cages("catmark_fvar_seams", 2)
    hole = int(cage.tags.hole_faces[0])
    from subtrace.patches.evaluate import ptex_starts

    ptex = int(ptex_starts(cage)[hole])
    assert np.isnan(cage.evaluate_uv([ptex], [[0.5, 0.5]])).all()
    with pytest.raises(ValueError, match="evaluate_uv: u and v must lie in"):
        cage.evaluate_uv([0], [[1.5, 0.5]])


# --------------------------------------------------------------------------------------
# USD: primvars:st


def _usd_stage(tmp_path, name, *, token=None, interpolation="faceVarying", indexed=True):
    """The shape as a USD mesh with its vt as primvars:st (``faceVarying``; or its points'
    x, y as ``vertex`` / ``varying`` st), in a folder of its own."""
    pytest.importorskip("pxr")
    from pxr import Sdf, Usd, UsdGeom, Vt

    from subtrace.io.obj import read_obj

    data = read_obj(SHAPES[name] / f"{name}.obj")
    tmp_path.mkdir(parents=True, exist_ok=True)
    path = tmp_path / f"{name}_{interpolation}_{token}_{indexed}.usda"
    stage = Usd.Stage.CreateNew(str(path))
    mesh = UsdGeom.Mesh.Define(stage, "/M")
    mesh.CreatePointsAttr([tuple(p) for p in data.points.tolist()])
    mesh.CreateFaceVertexCountsAttr(data.face_sizes.tolist())
    mesh.CreateFaceVertexIndicesAttr(data.face_verts.tolist())
    mesh.CreateInterpolateBoundaryAttr("edgeOnly")
    if token is not None:
        mesh.CreateFaceVaryingLinearInterpolationAttr(token)
    pv = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, interpolation)
    if interpolation == "faceVarying" and indexed:
        pv.Set(Vt.Vec2fArray([tuple(t) for t in data.uvs.tolist()]))
        pv.SetIndices(Vt.IntArray(data.face_uvs.tolist()))
    elif interpolation == "faceVarying":
        pv.Set(Vt.Vec2fArray([tuple(t) for t in data.uvs[data.face_uvs].tolist()]))
    else:  # one UV per point: the points' own x, y
        pv.Set(Vt.Vec2fArray([(p[0], p[1]) for p in data.points.tolist()]))
    stage.Save()
    return path, data


USD_TOKENS = ["none", "cornersOnly", "cornersPlus1", "cornersPlus2", "boundaries", "all"]


@pytest.mark.parametrize("mode", MODES)
def test_usd_attribute_selects_the_mode(tmp_path, mode):
    z, _ = _oracle("catmark_fvar_bound0")
    path, _ = _usd_stage(tmp_path, "catmark_fvar_bound0", token=USD_TOKENS[mode])
    cage = subtrace.load_cage(path)
    assert cage.uv.mode == mode
    got = cage.evaluate_uv(z["sample_ptex_face"], z["sample_uv"])
    # (the stage holds the UVs as floats: they are OpenSubdiv's data rounded to float32)
    np.testing.assert_allclose(got, z[f"uv_m{mode}"], rtol=0, atol=1e-7)


def test_usd_default_is_corners_plus1_and_unindexed_corners_are_apart(tmp_path):
    z, _ = _oracle("catmark_fvar_bound0")
    path, _ = _usd_stage(tmp_path, "catmark_fvar_bound0")
    cage = subtrace.load_cage(path)
    assert cage.uv.mode == 2  # USD's fallback for faceVaryingLinearInterpolation
    # unindexed, each corner is a value of its own: every face a UV island of its own,
    # its corners pinned (corners plus1), so bilinear: OpenSubdiv's linear mode
    path, _ = _usd_stage(tmp_path, "catmark_fvar_bound0", indexed=False)
    cage = subtrace.load_cage(path)
    got = cage.evaluate_uv(z["sample_ptex_face"], z["sample_uv"])
    np.testing.assert_allclose(got, z["uv_m5"], rtol=0, atol=1e-7)


def test_usd_vertex_uvs_follow_the_points(tmp_path):
    """``vertex`` st is interpolated as the points are: here st is the points' (x, y), so
    the limit UV is the limit position's (x, y) (Cage.evaluate, checked against
    OpenSubdiv in test_oracle.py); ``varying`` st is linear over each face."""
    z, _ = _oracle("catmark_fvar_bound0")
    ptex, uv = z["sample_ptex_face"], z["sample_uv"]
    path, data = _usd_stage(tmp_path, "catmark_fvar_bound0", interpolation="vertex")
    cage = subtrace.load_cage(path)
    P, _, _ = cage.evaluate(ptex, uv)
    np.testing.assert_allclose(cage.evaluate_uv(ptex, uv), P[:, :2], rtol=0, atol=1e-7)
    path, data = _usd_stage(tmp_path, "catmark_fvar_bound0", interpolation="varying")
    cage = subtrace.load_cage(path)
    fo = cage.face_offsets
    c = data.points[data.face_verts[fo[ptex][:, None] + np.arange(4)], :2]
    u, v = uv[:, :1], uv[:, 1:]
    bilinear = (1 - u) * (1 - v) * c[:, 0] + u * (1 - v) * c[:, 1] + u * v * c[:, 2] \
        + (1 - u) * v * c[:, 3]
    np.testing.assert_allclose(cage.evaluate_uv(ptex, uv), bilinear, rtol=0, atol=1e-7)


def test_usd_bad_token_and_counts(tmp_path):
    path, _ = _usd_stage(tmp_path, "catmark_fvar_bound0", token="sometimes")
    with pytest.raises(SubtraceError, match="faceVaryingLinearInterpolation 'sometimes'"):
        subtrace.load_cage(path)
    from pxr import Usd, UsdGeom, Vt

    path, _ = _usd_stage(tmp_path / "counts", "catmark_fvar_bound0")
    stage = Usd.Stage.Open(str(path))
    pv = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/M")).GetPrimvar("st")
    pv.SetIndices(Vt.IntArray([0, 1, 2]))
    stage.Save()
    with pytest.raises(SubtraceError, match=r"primvars:st \(faceVarying\) has 3 indices for "
                                            "64 face corners"):
        subtrace.load_cage(path)

"""Tests of the OBJ reader's free-form geometry (subtrace.io.freeform, made into surfaces by
subtrace.nurbs.freeform): trimmed rational
B-spline and Bezier surfaces as CAD exporters write them, beside polygons, and one clear
error (file, line, problem) for each kind of bad free-form input."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import naive
from subtrace.errors import ObjError, SubtraceWarning
from subtrace.io.obj import read_obj
from subtrace.nurbs.bezier import evaluate
from subtrace.nurbs.freeform import freeform_of
from subtrace.nurbs.model import build_model
from subtrace.nurbs.trim import signed_area

W45 = math.sqrt(0.5)

SQUARE = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"

# a rational quadratic circle of radius 0.3 around (0.5, 0.5) as 9 vp (u v w)
CIRCLE_VP = "".join(
    f"vp {0.5 + 0.3 * x!r} {0.5 + 0.3 * y!r} {w!r}\n"
    for (x, y), w in (((1, 0), 1.0), ((1, 1), W45), ((0, 1), 1.0), ((-1, 1), W45),
                      ((-1, 0), 1.0), ((-1, -1), W45), ((0, -1), 1.0), ((1, -1), W45),
                      ((1, 0), 1.0)))
CIRCLE_CURV2 = ("cstype rat bspline\ndeg 2\ncurv2 1 2 3 4 5 6 7 8 9\n"
                "parm u 0 0 0 1 1 2 2 3 3 4 4 4\nend\n")
PLATE = ("cstype bspline\ndeg 1 1\nsurf 0 1 0 1 1 2 4 3\nparm u 0 0 1 1\nparm v 0 0 1 1\n")


def write(tmp_path, text, name="model.obj"):
    path = tmp_path / name
    path.write_text(text)
    return path


def read_quiet(path):
    """read_obj, with ``freeform`` its records made into surfaces (freeform_of)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SubtraceWarning)
        data = read_obj(path)
    return dataclasses.replace(data, freeform=freeform_of(data))


def expect_error(path, line, *words):
    with pytest.raises(ObjError) as info:
        read_quiet(path)
    err = info.value
    assert err.path == str(path) and err.line == line, str(err)
    assert str(err).startswith(f"{path}:{line}: " if line is not None else f"{path}: ")
    for w in words:
        assert w in str(err), str(err)
    return err


# -- valid files -------------------------------------------------------------------------


def test_plate_with_a_circular_hole(tmp_path):
    text = SQUARE + CIRCLE_VP + CIRCLE_CURV2 + PLATE + "hole 0 4 1\nend\n"
    data = read_quiet(write(tmp_path, text))
    assert len(data.face_sizes) == 0  # free-form only: read, not "no faces"
    ff = data.freeform
    assert len(ff.surfaces) == 1 and len(ff.curves) == 1 and ff.param_points.shape == (9, 3)
    s = ff.surfaces[0]
    assert s.degree == (1, 1) and s.domain == (0.0, 1.0, 0.0, 1.0) and not s.rational
    assert len(s.loops) == 1 and s.loops[0].hole and signed_area(s.loops[0]) < 0
    assert ff.surface_lines == (21,)
    model = build_model(ff.surfaces)
    uv = np.array([[0.5, 0.5], [0.5, 0.79], [0.5, 0.81], [0.05, 0.05]])
    assert model.inside([0, 0, 0, 0], uv).tolist() == [False, False, True, True]


def rational_cylinder_obj(height=2.0):
    """A quarter cylinder as `cstype rat bspline`, the weight as the v line's w."""
    lines = []
    for z in (0.0, height):
        for (x, y), w in (((1, 0), 1.0), ((1, 1), W45), ((0, 1), 1.0)):
            lines.append(f"v {x} {y} {z} {w!r}")
    lines += ["cstype rat bspline", "deg 2 1", "surf 0 1 0 1 1 2 3 4 5 6",
              "parm u 0 0 0 1 1 1", "parm v 0 0 1 1", "end"]
    return "\n".join(lines) + "\n"


def test_rational_surface_takes_the_weights_of_v_lines(tmp_path):
    data = read_quiet(write(tmp_path, rational_cylinder_obj()))
    s = data.freeform.surfaces[0]
    assert s.rational and s.control[0, 1, 3] == W45
    model = build_model(data.freeform.surfaces)
    uv = np.random.default_rng(1).random((200, 2))
    P, _, _ = evaluate(model.nets, model.patch_degree, model.patch_rect,
                       np.zeros(200, np.int64), uv)
    assert np.abs(np.hypot(P[:, 0], P[:, 1]) - 1.0).max() <= 8 * np.finfo(float).eps
    # non-rational: the same numbers with w ignored give a different (polynomial) surface
    data = read_quiet(write(tmp_path, rational_cylinder_obj().replace("rat ", "")))
    assert not data.freeform.surfaces[0].rational
    assert data.freeform.surfaces[0].control[0, 1, 3] == 1.0


def test_bezier_surface_and_curves_with_segment_joins(tmp_path):
    # a bicubic Bezier surface of 2 x 1 segments (7 x 4 control points) over [0,2] x [0,1],
    # trimmed by a two-segment linear Bezier loop... made of two curves
    pts = [f"v {i} {j} {(i * j) % 3}" for j in range(4) for i in range(7)]
    text = "\n".join(pts) + "\n" + (
        "vp 0.2 0.2\nvp 1.8 0.2\nvp 1.8 0.8\nvp 0.2 0.8\n"
        "cstype bezier\ndeg 1\n"
        "curv2 1 2 3\nparm u 0 1 2\nend\n"
        "curv2 3 4 1\nparm u 0 1 2\nend\n"
        "deg 3 3\nsurf 0 2 0 1 " + " ".join(str(k + 1) for k in range(28)) + "\n"
        "parm u 0 1 2\nparm v 0 1\ntrim 0 2 1 0 2 2\nend\n")
    data = read_quiet(write(tmp_path, text))
    s = data.freeform.surfaces[0]
    assert s.degree == (3, 3) and s.knots_u.tolist() == [0, 0, 0, 0, 1, 1, 1, 2, 2, 2, 2]
    model = build_model(data.freeform.surfaces)
    assert model.n_patches == 2 and model.patch_rect[:, :2].tolist() == [[0, 1], [1, 2]]
    assert signed_area(s.loops[0]) > 0
    # the Bezier patches interpolate the corner control points
    P, _, _ = evaluate(model.nets, model.patch_degree, model.patch_rect, [0, 1, 1],
                       [[0, 0], [2, 1], [1, 0]])
    assert P.tolist() == [[0, 0, 0], [6, 3, 0], [3, 0, 0]]
    inside = model.inside([0, 0, 0], [[1.0, 0.5], [0.1, 0.5], [1.9, 0.9]])
    assert inside.tolist() == [True, False, False]


def test_polygons_beside_surfaces_read_as_without_them(tmp_path):
    polygons = SQUARE + "v 2 0 0\nusemtl red\nf 1 2 3 4\nf 2 5 3\n"
    plain = read_quiet(write(tmp_path, polygons, "plain.obj"))
    text = (polygons + CIRCLE_VP + CIRCLE_CURV2 + "usemtl blue\n" + PLATE
            + "trim 0 4 1\nscrv 0 4 1\nsp 1\nend\ncon 1 0 1 1 1 0 1 1\nf 1 3 4\n")
    with pytest.warns(SubtraceWarning) as record:
        mixed = read_obj(write(tmp_path, text, "mixed.obj"))
    n = len(plain.face_sizes)
    assert mixed.face_sizes[:n].tolist() == plain.face_sizes.tolist()
    assert mixed.face_verts[: plain.face_verts.size].tolist() == plain.face_verts.tolist()
    assert np.array_equal(mixed.points, plain.points)
    assert [m.name for m in mixed.materials] == ["red", "blue"]
    assert mixed.face_material.tolist() == [0, 0, 1]
    assert freeform_of(mixed).surfaces[0].material == 1
    messages = [str(w.message) for w in record]
    assert messages == list(mixed.warnings)
    messages = [m for m in messages if "free-form" in m]
    # scrv, sp and con: read and ignored with one warning each, naming their lines
    assert [m.split(": ", 1)[1] for m in messages] == [
        "free-form geometry statement 'scrv' ignored",
        "free-form geometry statement 'sp' ignored",
        "free-form geometry statement 'con' ignored"]
    assert f"mixed.obj:{text.count(chr(10), 0, text.index('scrv')) + 1}:" in messages[0]


def test_indices_count_back_and_forward(tmp_path):
    # negative control point / curve indices count back; positive ones may come later
    text = ("cstype bspline\ndeg 1 1\nsurf 0 1 0 1 1 2 4 3\nparm u 0 0 1 1\n"
            "parm v 0 0 1 1\nhole 0 4 -1\nend\n")  # no curv2 before it: -1 is out of range
    expect_error(write(tmp_path, SQUARE + text), 10, "curv2 index -1 out of range")
    text = SQUARE + PLATE + "hole 0 4 1\nend\n" + CIRCLE_VP + CIRCLE_CURV2
    data = read_quiet(write(tmp_path, text))  # a forward reference to the curv2
    assert data.freeform.surfaces[0].loops[0].hole
    text = SQUARE + CIRCLE_VP + CIRCLE_CURV2.replace(
        "curv2 1 2 3 4 5 6 7 8 9", "curv2 -9 -8 -7 -6 -5 -4 -3 -2 -1") + (
        "cstype bspline\ndeg 1 1\nsurf 0 1 0 1 -4 -3 -1 -2\nparm u 0 0 1 1\n"
        "parm v 0 0 1 1\nhole 0 4 -1\nend\n")
    data = read_quiet(write(tmp_path, text))
    assert data.freeform.surfaces[0].control[1, 1, :3].tolist() == [1, 1, 0]


def test_stray_free_form_attributes_only_warn(tmp_path):
    data = read_quiet(write(tmp_path, SQUARE + "cstype bspline\ndeg 3\nvp 0.5\nf 1 2 3\n"))
    assert data.freeform is None and len(data.warnings) == 3


def test_curves_without_surfaces_are_no_faces(tmp_path):
    expect_error(write(tmp_path, CIRCLE_VP + CIRCLE_CURV2), None, "no faces")


# -- bad input: one error naming file, line and problem ------------------------------------

BAD = [
    # (text, line, words)
    (SQUARE + "cstype taylor\n", 5, "cstype 'taylor' is not supported"),
    (SQUARE + "cstype rat nurbs\n", 5, "cstype 'nurbs' is unknown"),
    (SQUARE + "cstype bspline\ndeg 0 1\n", 6, "degrees 1 to"),
    (SQUARE + "deg 1 1\nsurf 0 1 0 1 1 2 4 3\n", 6, "surf before any cstype"),
    (SQUARE + "cstype bspline\nsurf 0 1 0 1 1 2 4 3\n", 6, "surf before any deg"),
    (SQUARE + "cstype bspline\ndeg 1\nsurf 0 1 0 1 1 2 4 3\n", 7, "surf needs two degrees"),
    (SQUARE + PLATE, 7, "surf has no `end`"),
    (SQUARE + PLATE.replace("parm v 0 0 1 1\n", "") + "end\n", 7, "no `parm v`"),
    (SQUARE + PLATE.replace("parm u 0 0 1 1", "parm u 0 0.5 0.4 1") + "end\n", 8,
     "knot 3 (0.4) is below knot 2 (0.5); knots must not decrease"),
    (SQUARE + PLATE.replace("parm u 0 0 1 1", "parm u 0 0 0.5 1 1") + "end\n", 7,
     "surf has 4 control points, but parm u (5 knots, degree 1: 3 columns)"),
    (SQUARE + PLATE.replace("1 2 4 3", "1 2 4") + "end\n", 7,
     "surf has 3 control points; a degree 1 x 1 surface needs at least 4"),
    (SQUARE.replace("v 1 1 0", "v 1 1 0 0") + PLATE.replace("bspline", "rat bspline")
     + "end\n", 7, "control point 4 (the v of line 3) has weight 0; weights of a rational "
     "surface must be positive"),
    (SQUARE.replace("v 1 1 0", "v 1 1 0 -2") + PLATE.replace("bspline", "rat bspline")
     + "end\n", 7, "weight -2"),
    (SQUARE + PLATE.replace("1 2 4 3", "1 2 4 9") + "end\n", 7,
     "vertex index 9 out of range: the file has 4 v lines"),
    (SQUARE + PLATE.replace("surf 0 1", "surf 0 2") + "end\n", 7,
     "outside the knot domain"),
    (SQUARE + CIRCLE_VP + CIRCLE_CURV2.replace("4 4 4", "4 4") + PLATE + "end\n", 17,
     "parm u has 11 knots; a degree-2 B-spline with 9 control points needs 12"),
    (SQUARE + CIRCLE_VP + CIRCLE_CURV2.replace("curv2 1 2", "curv2 1 12") + PLATE + "end\n",
     16, "parameter vertex index 12 out of range: the file has 9 vp lines"),
    (SQUARE + CIRCLE_VP.replace("0.7071067811865476", "0.0", 1) + CIRCLE_CURV2 + PLATE
     + "end\n", 16, "control point 2 (the vp of line 6) has weight 0; weights of a rational "
     "curve must be positive"),
    (SQUARE + CIRCLE_VP + CIRCLE_CURV2 + PLATE + "trim 0 4 2\nend\n", 24,
     "trim: curv2 index 2 out of range: the file has 1 curv2 statements"),
    (SQUARE + CIRCLE_VP + CIRCLE_CURV2 + PLATE + "trim 0 3 1\nend\n", 24,
     "trim: trim loop is not closed"),
    (SQUARE + CIRCLE_VP + CIRCLE_CURV2 + PLATE.replace("surf 0 1 0 1", "surf 0 1 0 0.7")
     + "hole 0 4 1\nend\n", 24, "outside the surface's domain"),
    (SQUARE + CIRCLE_VP + CIRCLE_CURV2 + PLATE + "trim 0 5 1\nend\n", 24,
     "leaves the curve's domain"),
    (SQUARE + CIRCLE_VP + CIRCLE_CURV2 + PLATE + "trim 0 4\nend\n", 24,
     "trim needs triples u0 u1 curv2"),
    (SQUARE + "parm u 0 1\n", 5, "parm outside a curv2 or surf"),
    (SQUARE + "hole 0 1 1\n", 5, "hole outside a surf"),
    (SQUARE + "end\n", 5, "end without a curv2 or surf"),
    (SQUARE + PLATE + PLATE, 12, "surf inside the surf of line 7"),
    (SQUARE + PLATE.replace("surf 0 1", "surf 0 one") + "end\n", 7,
     "surf: 'one' is not a finite number"),
    (SQUARE + "vp 1 2 3 4\n", 5, "vp needs 1 to 3 numbers"),
]


@pytest.mark.parametrize("text, line, words", BAD, ids=[b[2][:40] for b in BAD])
def test_bad_free_form_input(tmp_path, text, line, words):
    expect_error(write(tmp_path, text), line, words)


# -- round trip of random surfaces ---------------------------------------------------------


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rational=st.booleans())
def test_random_surfaces_read_back_and_evaluate(tmp_path_factory, seed, rational):
    rng = np.random.default_rng(seed)
    du, dv = (int(x) for x in rng.integers(1, 4, size=2))
    nu, nv = du + 1 + int(rng.integers(0, 3)), dv + 1 + int(rng.integers(0, 3))
    ku = np.concatenate([np.zeros(du + 1), np.sort(rng.random(nu - du - 1)), np.ones(du + 1)])
    kv = np.concatenate([np.zeros(dv + 1), np.sort(rng.random(nv - dv - 1)), np.ones(dv + 1)])
    points = rng.normal(size=(nu * nv, 3))
    weights = rng.uniform(0.3, 3.0, nu * nv)
    lines = [f"v {x!r} {y!r} {z!r} {w!r}" for (x, y, z), w in zip(points.tolist(),
                                                                  weights.tolist())]
    lines += [f"cstype {'rat ' if rational else ''}bspline", f"deg {du} {dv}",
              "surf 0 1 0 1 " + " ".join(str(k + 1) for k in range(nu * nv)),
              "parm u " + " ".join(repr(float(k)) for k in ku),
              "parm v " + " ".join(repr(float(k)) for k in kv), "end"]
    path = tmp_path_factory.mktemp("ff") / "random.obj"
    path.write_text("\n".join(lines) + "\n")
    data = read_quiet(path)
    s = data.freeform.surfaces[0]
    w = weights if rational else np.ones(nu * nv)
    assert np.array_equal(s.control.reshape(-1, 4)[:, 3], w)
    model = build_model(data.freeform.surfaces)
    uv = rng.random((20, 2))
    ids = np.array([np.nonzero((model.patch_rect[:, 0] <= u) & (u <= model.patch_rect[:, 1])
                               & (model.patch_rect[:, 2] <= v) & (v <= model.patch_rect[:, 3])
                               )[0][0] for u, v in uv])
    P, _, _ = evaluate(model.nets, model.patch_degree, model.patch_rect, ids, uv)
    control = np.column_stack([points * w[:, None], w]).reshape(nv, nu, 4)
    for k in range(len(uv)):
        want, _, _ = naive.nurbs_surface_eval(ku.tolist(), kv.tolist(), du, dv,
                                              control.tolist(), *uv[k])
        assert np.allclose(P[k], want, rtol=0, atol=1e-10 * np.abs(points).max())


# -- the command line ------------------------------------------------------------------------

MODELS = __import__("pathlib").Path(__file__).resolve().parents[1] / "models" / "nurbs"


@pytest.mark.parametrize("name, rows", [
    ("plate_holes.obj", {"free-form surfaces": "1 (0 rational, 1 polynomial)",
                         "surface degrees": "3x3: 1",
                         "Bezier patches": "9 (knot insertion; 9..9 per surface)",
                         "trim loops": "1 outer, 2 holes (1 of 1 surfaces trimmed)",
                         "trim curves": "4 curv2, 14 Bezier segments in loops, 16 monotone "
                                        "curve units"}),
    ("cylinder_window.obj", {"surface degrees": "2x1: 1", "Bezier patches": "4 (knot "
                             "insertion; 4..4 per surface)",
                             "trim loops": "0 outer, 1 holes (1 of 1 surfaces trimmed)"}),
    ("torus_patches.obj", {"free-form surfaces": "16 (16 rational, 0 polynomial)",
                           "Bezier patches": "16 (knot insertion; 1..1 per surface)"}),
])
def test_info_reports_free_form_content(capsys, name, rows):
    from subtrace.cli import main

    assert main(["info", str(MODELS / name)]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    got = dict(line.split(":", 1) for line in out.splitlines())
    assert got["faces"].strip() == "0 (free-form surfaces only)"
    for key, value in rows.items():
        assert got[key].strip() == value, key


def test_sample_models_are_what_the_generator_writes(tmp_path):
    import shutil
    import subprocess
    import sys

    for f in ("make_models.py",):
        shutil.copy(MODELS / f, tmp_path / f)
    # the generator writes beside itself; it finds subtrace through the repository's src/
    script = (tmp_path / "make_models.py").read_text().replace(
        'HERE.parents[1] / "src"', repr(str(MODELS.parents[1] / "src")))
    (tmp_path / "make_models.py").write_text(script)
    subprocess.run([sys.executable, str(tmp_path / "make_models.py")], check=True,
                   capture_output=True)
    for name in ("plate_holes.obj", "cylinder_window.obj", "torus_patches.obj"):
        assert (tmp_path / name).read_text() == (MODELS / name).read_text(), name


def test_torus_patches_close_up():
    # the 16 Bezier patches share their edge control points (one v line each), and every
    # point lies on the torus (radii 1 and 0.35) to rounding
    data = read_quiet(MODELS / "torus_patches.obj")
    assert len(data.points) == 64  # 8 x 8 distinct control points of a closed net
    model = build_model(data.freeform.surfaces)
    rng = np.random.default_rng(2)
    ids = np.repeat(np.arange(16), 50)
    P, _, _ = evaluate(model.nets, model.patch_degree, model.patch_rect, ids,
                       rng.random((len(ids), 2)))
    ring = np.hypot(P[:, 0], P[:, 1]) - 1.0
    assert np.abs(np.hypot(ring, P[:, 2]) - 0.35).max() <= 1e-14

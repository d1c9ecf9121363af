"""PLY, STL, OFF and glTF meshes as cages (io/meshes.py, through trimesh): the same cage as
the OBJ of the same triangles, STL corners merged, polygons triangulated with a warning,
glTF node transforms applied; every command reads them."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh", reason="trimesh (subtrace[meshes]) is not installed")

import subtrace  # noqa: E402
from subtrace.cli import main  # noqa: E402
from subtrace.errors import SubtraceWarning  # noqa: E402
from subtrace.shapes import torus_cage  # noqa: E402


def _triangles():
    """A closed all-triangle cage (a torus's quads cut in two) as (points, faces (f,3)); the
    points rounded to single precision, which PLY, STL and glTF files store exactly."""
    t = torus_cage()
    q = t.face_verts.reshape(-1, 4)
    points = np.asarray(t.points).astype(np.float32).astype(np.float64)
    return points, np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])


def _obj(path, points, faces):
    path.write_text("".join(f"v {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in points)
                    + "".join("f " + " ".join(str(i + 1) for i in f) + "\n" for f in faces))


@pytest.mark.parametrize("ext", ["ply", "off", "stl", "glb"])
def test_formats_give_the_cage_of_the_obj(tmp_path, ext):
    """The same triangles written by trimesh in each format load to a Loop cage whose limit
    surface is the OBJ's, bit for bit (STL: vertices merged back by position; the order of
    vertices may differ there, so the comparison is by the limit points' set)."""
    points, faces = _triangles()
    obj = tmp_path / "t.obj"
    _obj(obj, points, faces)
    other = tmp_path / f"t.{ext}"
    trimesh.Trimesh(points, faces, process=False).export(other)
    a = subtrace.load_cage(obj)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SubtraceWarning)  # all triangles: nothing to say
        b = subtrace.load_cage(other)
    assert a.scheme == b.scheme == "loop"
    assert len(b.points) == len(a.points) and len(b.face_sizes) == len(a.face_sizes)
    pa, pb = a.limit(1)[0], b.limit(1)[0]
    if ext == "stl":  # the vertices come back sorted: compare the sets of limit points
        pa, pb = np.unique(np.round(pa, 12), axis=0), np.unique(np.round(pb, 12), axis=0)
    else:
        np.testing.assert_array_equal(a.face_verts, b.face_verts)
    # (trimesh writes OFF's coordinates as decimals of 12 significant digits)
    np.testing.assert_allclose(pa, pb, rtol=0, atol=1e-10 if ext == "off" else 0.0)


def test_polygons_are_triangulated_with_a_warning(tmp_path):
    ply = tmp_path / "quad.ply"
    ply.write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                   "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                   "end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
    with pytest.warns(SubtraceWarning, match="trimesh triangulated"):
        cage = subtrace.load_cage(ply)
    assert cage.scheme == "loop" and len(cage.face_sizes) == 2


def test_gltf_scene_transforms_and_commands(tmp_path, capsys):
    """Two meshes of a glTF scene, one moved by its node, join into one cage in world space;
    render, info and intersect all read the file."""
    scene = trimesh.Scene()
    box = trimesh.creation.box()
    scene.add_geometry(box, node_name="a")
    scene.add_geometry(box.copy(), node_name="b",
                       transform=trimesh.transformations.translation_matrix([5.0, 0, 0]))
    glb = tmp_path / "two.glb"
    scene.export(glb)
    cage = subtrace.load_cage(glb)
    assert len(cage.face_sizes) == 24
    assert cage.points[:, 0].max() == pytest.approx(5.5)
    assert main(["render", str(glb), "-o", str(tmp_path / "x.exr"), "--width", "32",
                 "--height", "24", "--quiet"]) == 0
    assert main(["info", str(glb)]) == 0
    assert "loop" in capsys.readouterr().out
    lines = tmp_path / "l.csv"
    lines.write_text("ox,oy,oz,dx,dy,dz\n5,0,-5,0,0,1\n")
    out = tmp_path / "h.csv"
    assert main(["intersect", str(glb), "--lines", str(lines), "--precision", "1e-4",
                 "-o", str(out)]) == 0
    assert len(out.read_text().strip().splitlines()) == 3  # header, entry and exit

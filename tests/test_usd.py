"""USD stages as input (io/usd.py): UsdGeomMesh subdivision attributes, transforms, cameras,
lights; the OpenSubdiv oracle shapes round-trip through USD with the same limit surface, and
a stage renders the same image as the equivalent OBJ with the same flags."""

from __future__ import annotations

import numpy as np
import pytest

from shared_data import ORACLE, SHAPES

pxr = pytest.importorskip("pxr", reason="usd-core (subtrace[usd]) is not installed")
from pxr import Gf, Usd, UsdGeom, UsdLux  # noqa: E402

import subtrace  # noqa: E402
from subtrace.cli import main  # noqa: E402
from subtrace.io.exr import read_exr  # noqa: E402
from subtrace.io.obj import BOUNDARY_EDGE_AND_CORNER, BOUNDARY_EDGE_ONLY, read_obj  # noqa: E402

BOUNDARY_TOKEN = {0: "none", BOUNDARY_EDGE_AND_CORNER: "edgeAndCorner",
                  BOUNDARY_EDGE_ONLY: "edgeOnly"}
CUBE_PTS = [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1), (-1, -1, 1), (1, -1, 1),
            (1, 1, 1), (-1, 1, 1)]
CUBE_FACES = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [2, 3, 7, 6], [1, 2, 6, 5], [0, 4, 7, 3]]


def write_usd_from_obj(obj_path, usd_path, scheme, leaf="/Shape"):
    """The OBJ cage (with its OpenSubdiv tags) as a UsdGeomMesh: creases as chains of one
    edge each, with a sharpness per chain (or per edge), corners, holes, the boundary mode
    (the OBJ default edge-only written out: USD's own default is edge-and-corner)."""
    d = read_obj(obj_path)
    stage = Usd.Stage.CreateNew(str(usd_path))
    mesh = UsdGeom.Mesh.Define(stage, leaf)
    mesh.CreatePointsAttr([Gf.Vec3f(*map(float, p)) for p in d.points])
    mesh.CreateFaceVertexCountsAttr([int(n) for n in d.face_sizes])
    mesh.CreateFaceVertexIndicesAttr([int(i) for i in d.face_verts])
    mesh.CreateSubdivisionSchemeAttr("loop" if scheme == "loop" else "catmullClark")
    boundary = BOUNDARY_EDGE_ONLY if d.boundary is None else d.boundary
    mesh.CreateInterpolateBoundaryAttr(BOUNDARY_TOKEN[boundary])
    if d.smooth_triangles == "smooth":
        mesh.CreateTriangleSubdivisionRuleAttr("smooth")
    if len(d.crease_edges):
        mesh.CreateCreaseIndicesAttr([int(i) for i in np.ravel(d.crease_edges)])
        mesh.CreateCreaseLengthsAttr([2] * len(d.crease_edges))
        mesh.CreateCreaseSharpnessesAttr([float(s) for s in d.crease_sharpness])
    if len(d.corner_verts):
        mesh.CreateCornerIndicesAttr([int(i) for i in d.corner_verts])
        mesh.CreateCornerSharpnessesAttr([float(s) for s in d.corner_sharpness])
    if len(d.hole_faces):
        mesh.CreateHoleIndicesAttr([int(i) for i in d.hole_faces])
    stage.Save()
    return d


def _shapes():
    names = sorted(p.stem for p in ORACLE.glob("*.npz"))
    return [n for n in names if not n.startswith("catmark_fvar") and "chaikin" not in n]


@pytest.mark.parametrize("name", _shapes())
def test_oracle_shapes_round_trip_through_usd(tmp_path, name):
    """Each OpenSubdiv shape written as a USD mesh loads to the same cage (options and
    limit surface, bit for bit) as its OBJ, and so matches OpenSubdiv's samples."""
    obj = SHAPES / f"{name}.obj"
    usd = tmp_path / f"{name}.usda"
    scheme = name.split("_")[0]
    d = write_usd_from_obj(obj, usd, scheme)
    # USD's points are single precision (point3f[]): the OBJ's cage with its points rounded so
    a = subtrace.make_cage(
        d.points.astype(np.float32).astype(np.float64), d.face_sizes, d.face_verts, scheme,
        boundary=d.boundary, chaikin=d.crease_method == "chaikin",
        smooth_triangles=d.smooth_triangles == "smooth", crease_edges=d.crease_edges,
        crease_sharpness=d.crease_sharpness, corner_verts=d.corner_verts,
        corner_sharpness=d.corner_sharpness, hole_faces=d.hole_faces)
    b = subtrace.load_cage(usd)
    assert a.scheme == b.scheme and a.options == b.options
    z = np.load(ORACLE / f"{name}.npz")
    Pa, da, _ = a.evaluate(z["sample_ptex_face"], z["sample_uv"])
    Pb, db, _ = b.evaluate(z["sample_ptex_face"], z["sample_uv"])
    np.testing.assert_array_equal(Pa, Pb)
    np.testing.assert_array_equal(da, db)
    exact = z["sample_exact_P"].astype(bool)
    diag = float(np.linalg.norm(np.ptp(z["control_points"], axis=0)))
    # (plus what rounding the points to single precision moves the surface: the limit is
    # an affine combination of the points)
    rounding = 2 * np.finfo(np.float32).eps * float(np.abs(z["control_points"]).max())
    err = np.linalg.norm(Pb - z["sample_P"], axis=1)[exact].max(initial=0)
    assert err < 1e-7 * diag + rounding


def _cube_mesh(stage, prim, **attrs):
    """A cube UsdGeomMesh at ``prim`` with the attributes ``attrs`` (``CreaseIndices=...``)."""
    mesh = UsdGeom.Mesh.Define(stage, prim)
    mesh.CreatePointsAttr(CUBE_PTS)
    mesh.CreateFaceVertexCountsAttr([4] * 6)
    mesh.CreateFaceVertexIndicesAttr(sum(CUBE_FACES, []))
    for key, value in attrs.items():
        getattr(mesh, f"Create{key}Attr")(value)
    return mesh


def _cube_stage(path, **attrs):
    stage = Usd.Stage.CreateNew(str(path))
    world = UsdGeom.Xform.Define(stage, "/World")
    return stage, world, _cube_mesh(stage, "/World/Cube", **attrs)


def test_stage_renders_as_the_equivalent_obj(tmp_path, capsys):
    """A stage (a cube with a semi-sharp crease chain, a corner, a camera) renders the same
    pixels as the OBJ with the same tags, rendered through the same camera."""
    usd = tmp_path / "cube.usda"
    stage, world, mesh = _cube_stage(usd, CreaseIndices=[0, 1, 2, 6], CreaseLengths=[4],
                                     CreaseSharpnesses=[2.0], CornerIndices=[7],
                                     CornerSharpnesses=[3.0])
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    cam.AddRotateXYZOp().Set((-25.0, 35.0, 0.0))  # (the first op is the outermost: an
    cam.AddTranslateOp().Set((0.0, 0.0, 7.0))     # orbit about the origin)
    stage.Save()
    obj = tmp_path / "cube.obj"
    obj.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in CUBE_PTS)
                   + "".join("f " + " ".join(str(i + 1) for i in f) + "\n" for f in CUBE_FACES)
                   + "t crease 2/1/0 0 1 2.0\nt crease 2/1/0 1 2 2.0\nt crease 2/1/0 2 6 2.0\n"
                   + "t corner 1/1/0 7 3.0\nt interpolateboundary 1/0/0 1\n")
    from subtrace.io.usd import read_stage

    _renders_as(tmp_path, usd, obj, read_stage(usd).cameras[0],
                ("A", "Z", "N.X", "N.Y", "N.Z", "u", "v", "patch_id"))


def _renders_as(tmp_path, usd, obj, c, channels):
    """Render the stage ``usd`` and the OBJ ``obj`` through the stage's camera ``c`` at
    96x72: the stage's channels ``channels`` the same as the OBJ's bit for bit; returns the
    stage's image."""
    size = ["--width", "96", "--height", "72", "--quiet"]
    assert main(["render", str(usd), "-o", str(tmp_path / "u.exr"), *size]) == 0
    assert main(["render", str(obj), "-o", str(tmp_path / "o.exr"), *size,
                 "--eye", *map(str, c.eye), "--target", *map(str, c.target),
                 "--up", *map(str, c.up), "--fov", repr(c.fov_deg)]) == 0
    u, _ = read_exr(tmp_path / "u.exr")
    o, _ = read_exr(tmp_path / "o.exr")
    assert np.count_nonzero(u["A"]) > 500
    for name in channels:
        np.testing.assert_array_equal(u[name], o[name], err_msg=name)
    return u


def test_transform_orientation_visibility_and_purpose(tmp_path):
    """World transforms move the points; a left-handed mesh's faces are turned to the
    right-handed order; invisible and guide meshes are left out; displayColor is the
    object's colour; per-edge and per-chain crease sharpnesses read alike."""
    from subtrace.io.usd import read_stage

    usd = tmp_path / "t.usda"
    stage, world, mesh = _cube_stage(usd, CreaseIndices=[0, 1, 2], CreaseLengths=[3],
                                     CreaseSharpnesses=[1.5, 2.5],
                                     DisplayColor=[(0.1, 0.2, 0.3)])
    world.AddTranslateOp().Set((10.0, 0.0, 0.0))
    _cube_mesh(stage, "/World/Left", Orientation="leftHanded")
    _cube_mesh(stage, "/World/Hidden", Visibility="invisible")
    _cube_mesh(stage, "/World/Guide", Purpose="guide")
    light = UsdLux.DistantLight.Define(stage, "/World/Sun")
    light.AddRotateXOp().Set(-90.0)  # pointing down: its -Z axis becomes -Y
    stage.Save()
    content = read_stage(usd)
    assert [m.prim for m in content.meshes] == ["/World/Cube", "/World/Left"]
    cube, lefty = content.meshes
    np.testing.assert_allclose(cube.points, np.asarray(CUBE_PTS) + [10.0, 0.0, 0.0])
    np.testing.assert_allclose(cube.crease_sharpness, [1.5, 2.5])
    assert cube.color == pytest.approx((0.1, 0.2, 0.3))
    first = lefty.face_verts[:4]
    assert list(first) == CUBE_FACES[0][::-1]
    (direction, _, intensity, angle), = content.lights
    assert angle is None  # (not authored: a hard light)
    np.testing.assert_allclose(direction, (0.0, -1.0, 0.0), atol=1e-12)
    assert intensity == pytest.approx(1.0)


@pytest.mark.parametrize("attrs, words", [
    ({"CreaseIndices": [0, 1, 2], "CreaseLengths": [2], "CreaseSharpnesses": [1.0]},
     "creaseLengths"),
    ({"CreaseIndices": [0, 1], "CreaseLengths": [2], "CreaseSharpnesses": [1.0, 2.0, 3.0]},
     "creaseSharpnesses"),
    ({"CornerIndices": [0, 1], "CornerSharpnesses": [1.0]}, "cornerSharpnesses"),
    ({"HoleIndices": [9]}, "hole index"),
    ({"SubdivisionScheme": "sqrt3"}, "subdivisionScheme"),
    ({"FaceVertexCounts": [4] * 5}, "faceVertexCounts"),
])
def test_bad_stages_are_one_line(tmp_path, capsys, attrs, words):
    usd = tmp_path / "bad.usda"
    stage, _, _ = _cube_stage(usd, **attrs)
    stage.Save()
    for command in (["render", str(usd), "-o", str(tmp_path / "x.exr")], ["info", str(usd)]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and words in err and "bad.usda" in err and \
            "/World/Cube" in err, err
    assert not (tmp_path / "x.exr").exists()


def test_text_stage_with_a_byte_that_is_not_utf8_is_one_line(tmp_path, capsys):
    """A .usda whose text holds a byte that is not UTF-8 (where USD's own error message
    cannot even be turned into a string) is one line naming the file and the line."""
    usd = tmp_path / "bad.usda"
    stage, _, _ = _cube_stage(usd)
    stage.Save()
    lines = usd.read_bytes().split(b"\n")
    lines[3] = lines[3] + b' "\xe3\x28"'
    usd.write_bytes(b"\n".join(lines))
    for command in (["render", str(usd), "-o", str(tmp_path / "x.exr")], ["info", str(usd)]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "bad.usda:4:" in err and "UTF-8" in err, err
    assert not (tmp_path / "x.exr").exists()


def test_stage_without_meshes_and_missing_camera(tmp_path, capsys):
    empty = tmp_path / "empty.usda"
    Usd.Stage.CreateNew(str(empty)).Save()
    assert main(["render", str(empty), "-o", str(tmp_path / "x.exr")]) == 2
    assert "no visible UsdGeomMesh" in capsys.readouterr().err
    usd = tmp_path / "c.usda"
    stage, _, _ = _cube_stage(usd)
    stage.Save()
    assert main(["render", str(usd), "-o", str(tmp_path / "x.exr"), "--camera", "/Cam"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no camera prim /Cam" in err


def test_bilinear_scheme_is_flat(tmp_path):
    """subdivisionScheme none: each face is itself (a point at a face's centre is on it)."""
    usd = tmp_path / "flat.usda"
    stage, _, _ = _cube_stage(usd, SubdivisionScheme="none")
    stage.Save()
    cage = subtrace.load_cage(usd)
    P, _, _ = cage.evaluate(np.arange(6), np.full((6, 2), 0.5))
    # the face centres of the cube: one coordinate is +-1, the others 0
    np.testing.assert_allclose(np.sort(np.abs(P), axis=1), [[0, 0, 1]] * 6, atol=1e-12)


def _animated_stage(path, *, points=True, camera=True, light=True, time_range=(1, 3)):
    """A cube whose top corners rise over frames 1..3 (``points``), a camera that orbits
    (``camera``: its rotation sampled, else still), a distant light that turns (``light``),
    and the stage's time range (None: none authored)."""
    stage, world, mesh = _cube_stage(path)
    if points:
        attr = mesh.GetPointsAttr()
        attr.Clear()
        for t in (1, 2, 3):
            attr.Set([Gf.Vec3f(x, y + (0.4 * t if y > 0 else 0.0), z) for x, y, z in CUBE_PTS],
                     Usd.TimeCode(t))
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    rot = cam.AddRotateXYZOp()
    if camera:
        for t in (1, 2, 3):
            rot.Set((-20.0, 25.0 * t, 0.0), Usd.TimeCode(t))
    else:
        rot.Set((-20.0, 25.0, 0.0))
    cam.AddTranslateOp().Set((0.0, 0.0, 8.0))
    if light:
        sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
        turn = sun.AddRotateXYZOp()
        for t in (1, 3):
            turn.Set((-60.0, 60.0 * t, 0.0), Usd.TimeCode(t))
    if time_range is not None:
        stage.SetStartTimeCode(time_range[0])
        stage.SetEndTimeCode(time_range[1])
    stage.Save()
    return stage


def _still_of(animated, still_path, t):
    """The animated stage at time ``t`` written again with every value a default (no time
    samples): a stage that an independent reader must render as frame ``t``."""
    src = Usd.Stage.Open(str(animated))
    out = Usd.Stage.CreateNew(str(still_path))
    for prim in src.Traverse():
        dst = out.DefinePrim(prim.GetPath(), prim.GetTypeName())
        for attr in prim.GetAttributes():
            value = attr.Get(Usd.TimeCode(t)) if attr.HasAuthoredValue() else None
            if value is not None:  # (fallbacks stay fallbacks)
                dst.CreateAttribute(attr.GetName(), attr.GetTypeName(),
                                    custom=attr.IsCustom()).Set(value)
    out.Save()


def test_stage_frames_are_its_time_samples(tmp_path, capsys):
    """``--frames`` without --turntable renders the stage's time codes to numbered files:
    frame t is, bit for bit, the render of the stage rewritten with its values at t as
    still defaults (moving points, an orbiting camera, a turning light), and a render
    without --frames is the first frame of the stage's authored range."""
    usd = tmp_path / "anim.usda"
    _animated_stage(usd)
    size = ["--width", "64", "--height", "48", "--quiet"]
    assert main(["render", str(usd), "-o", str(tmp_path / "f.#.exr"), "--frames", ":",
                 *size]) == 0
    assert sorted(p.name for p in tmp_path.glob("f.*.exr")) == ["f.1.exr", "f.2.exr",
                                                                  "f.3.exr"]
    frames = {t: read_exr(tmp_path / f"f.{t}.exr")[0] for t in (1, 2, 3)}
    for t in (1, 2, 3):
        _still_of(usd, tmp_path / f"still{t}.usda", t)
        assert main(["render", str(tmp_path / f"still{t}.usda"), "-o",
                     str(tmp_path / f"s{t}.exr"), *size]) == 0
        still, _ = read_exr(tmp_path / f"s{t}.exr")
        assert np.count_nonzero(still["A"]) > 300
        for name in ("R", "G", "B", "A", "Z", "N.X", "u", "v", "patch_id"):
            np.testing.assert_array_equal(frames[t][name], still[name], err_msg=f"{t} {name}")
    assert not np.array_equal(frames[1]["Z"], frames[3]["Z"])  # it moves
    assert main(["render", str(usd), "-o", str(tmp_path / "first.exr"), *size]) == 0
    np.testing.assert_array_equal(read_exr(tmp_path / "first.exr")[0]["Z"], frames[1]["Z"])
    capsys.readouterr()
    assert main(["render", str(usd), "-o", str(tmp_path / "g.#.exr"), "--frames", "2:9",
                 *size]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--frames" in err and "1..3" in err


def test_stage_frames_without_a_range_and_cage_reuse(tmp_path):
    """Without an authored time range the frames are the span of the time samples; a stage
    whose meshes do not move (only its camera does) reads its cages once for every frame,
    one whose points move reads them per frame."""
    from subtrace.frames import frame_scenes
    from subtrace.io.scene import scene_for_meshes
    from subtrace.io.usd import is_animated, time_range

    moving, still = tmp_path / "moving.usda", tmp_path / "still.usda"
    _animated_stage(moving, time_range=None)
    _animated_stage(still, points=False, light=False, time_range=None)
    assert time_range(moving) == (1, 3) and time_range(still) == (1, 3)
    assert is_animated(moving) and not is_animated(still)
    jobs, cages = frame_scenes(scene_for_meshes([str(moving)]), frames="1:3")
    assert [k for k, *_ in jobs] == [1, 2] and cages is None
    jobs, cages = frame_scenes(scene_for_meshes([str(still)]), frames=":")
    assert [k for k, *_ in jobs] == [1, 2, 3] and cages is not None
    assert len({s.camera.eye for _, s, _, _ in jobs}) == 3  # the camera orbits


def test_frames_of_a_stage_without_time_samples_is_one_line(tmp_path, capsys):
    usd = tmp_path / "cube.usda"
    stage, _, _ = _cube_stage(usd)
    stage.Save()
    assert main(["render", str(usd), "-o", str(tmp_path / "x.#.exr"), "--frames", "1:3"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no time samples" in err and "cube.usda" in err
    assert not list(tmp_path.glob("x*"))


def test_a_stage_without_lights_gets_the_picture_defaults(tmp_path):
    """A stage with no lights (nor camera) gets the same picture on the command line and
    named by a bare TOML scene: the picture defaults of io/scene.py (1280x720, the
    gradient, key and fill lights, shadows and the ground), as an OBJ cage does; a stage
    with a distant light keeps its light in both."""
    from pxr import UsdLux

    from subtrace.io.scene import DEFAULT_LIGHTS, load_scene, scene_for_meshes

    usd = tmp_path / "cube.usda"
    stage, _, _ = _cube_stage(usd)
    stage.Save()
    toml = tmp_path / "scene.toml"
    toml.write_text('[[object]]\nmesh = "cube.usda"\n')
    cli, bare = scene_for_meshes([str(usd)]), load_scene(toml)
    for scene in (cli, bare):
        assert (scene.camera.width, scene.camera.height) == (1280, 720)
        assert scene.lights == DEFAULT_LIGHTS and scene.ground is not None
        assert scene.render.background_bottom is not None and scene.render.shadows
    assert (cli.camera, cli.render, cli.ground) == (bare.camera, bare.render, bare.ground)
    lit = tmp_path / "lit.usda"
    stage, _, _ = _cube_stage(lit)
    UsdLux.DistantLight.Define(stage, "/World/Sun")
    UsdLux.DistantLight.Define(stage, "/World/SoftSun").CreateAngleAttr(4.5)
    stage.Save()
    lights = scene_for_meshes([str(lit)]).lights
    # (an authored angle: a soft sun of that angular diameter; none: a hard light)
    assert len(lights) == 2 and sorted(l.angle or 0.0 for l in lights) == [0.0, 4.5]


# ------------------------------------------------------------------------------------------
# UsdPreviewSurface materials
# ------------------------------------------------------------------------------------------


def _checker_png(path, n=64, k=8):
    import OpenImageIO as oiio

    y, x = np.mgrid[0:n, 0:n]
    c = ((x // (n // k) + y // (n // k)) % 2).astype(np.float32)
    img = np.stack([0.1 + 0.8 * c, 0.3 + 0.4 * c, 0.7 - 0.5 * c], axis=2)
    assert oiio.ImageBuf(np.ascontiguousarray(img)).write(str(path), "uint8")
    return path


def _cube_uvs():
    """One UV square per face (its corners in face order): (24, 2)."""
    return [(a, b) for _ in CUBE_FACES for a, b in ((0, 0), (1, 0), (1, 1), (0, 1))]


def _preview_material(stage, mesh, **inputs):
    """A UsdPreviewSurface material bound to ``mesh`` with the authored ``inputs``
    (name -> (Sdf type, value)); a value that is a path connects a UsdUVTexture of that
    file, read at ``st``."""
    from pxr import Sdf, UsdShade

    material = UsdShade.Material.Define(stage, "/World/Looks/Mat")
    surface = UsdShade.Shader.Define(stage, "/World/Looks/Mat/Surface")
    surface.CreateIdAttr("UsdPreviewSurface")
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    reader = UsdShade.Shader.Define(stage, "/World/Looks/Mat/St")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("st")
    for name, (kind, value) in inputs.items():
        put = surface.CreateInput(name, kind)
        if isinstance(value, str):
            tex = UsdShade.Shader.Define(stage, f"/World/Looks/Mat/{name}Texture")
            tex.CreateIdAttr("UsdUVTexture")
            tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(value)
            tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
                reader.ConnectableAPI(), "result")
            put.ConnectToSource(tex.ConnectableAPI(), "rgb")
        else:
            put.Set(value)
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)


def test_a_preview_surface_texture_renders_as_the_obj_with_its_map(tmp_path):
    """A stage whose cube has face-varying ``st`` and a bound UsdPreviewSurface whose
    diffuseColor is a UsdUVTexture renders the same colours as the OBJ with the same UVs
    and an MTL ``map_Kd`` of the image (``Kd 1 1 1``), through the same camera; the
    texture is there (the two checker colours)."""
    from pxr import Sdf, UsdShade  # noqa: F401

    png = _checker_png(tmp_path / "checker.png")
    usd = tmp_path / "cube.usda"
    stage, world, mesh = _cube_stage(usd, FaceVaryingLinearInterpolation="all")
    UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying).Set(_cube_uvs())
    _preview_material(stage, mesh, diffuseColor=(Sdf.ValueTypeNames.Color3f, "checker.png"))
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    cam.AddRotateXYZOp().Set((-25.0, 35.0, 0.0))
    cam.AddTranslateOp().Set((0.0, 0.0, 7.0))
    stage.Save()
    (tmp_path / "cube.mtl").write_text(f"newmtl skin\nKd 1 1 1\nmap_Kd {png.name}\n")
    vt = "".join(f"vt {a} {b}\n" for a, b in ((0, 0), (1, 0), (1, 1), (0, 1)))
    obj = tmp_path / "cube.obj"
    obj.write_text("mtllib cube.mtl\nusemtl skin\n" + vt
                   + "".join(f"v {x} {y} {z}\n" for x, y, z in CUBE_PTS)
                   + "".join("f " + " ".join(f"{i + 1}/{k + 1}" for k, i in enumerate(f)) + "\n"
                             for f in CUBE_FACES)
                   + "t interpolateboundary 1/0/0 1\n")
    from subtrace.io.usd import read_stage

    content = read_stage(usd)
    material = content.meshes[0].material
    assert [m.slot for m in material.maps] == ["diffuse"] and material.metallic is None
    assert material.maps[0].path == str(png)
    u = _renders_as(tmp_path, usd, obj, content.cameras[0], ("A", "R", "G", "B"))
    lit = u["A"] > 0
    blue = u["B"][lit] / np.maximum(u["R"][lit], 1e-6)  # (0.7 / 0.1 and 0.2 / 0.9)
    assert (blue > 3).sum() > 50 and (blue < 0.5).sum() > 50


def test_a_preview_surfaces_authored_inputs_only(tmp_path):
    """Authored metallic / roughness turn reflections on (the other 0), authored colours
    are taken (specularColor with useSpecularWorkflow 1 only); a surface that authors none
    keeps the fallback grey and no reflection; a cube without a material has none."""
    from pxr import Sdf

    from subtrace.io.usd import SURFACE_DIFFUSE, read_stage

    cases = [
        ({"metallic": (Sdf.ValueTypeNames.Float, 1.0),
          "diffuseColor": (Sdf.ValueTypeNames.Color3f, (0.9, 0.5, 0.1))},
         ((0.9, 0.5, 0.1), (0.0, 0.0, 0.0), 1.0, 0.0)),
        ({"roughness": (Sdf.ValueTypeNames.Float, 0.25),
          "specularColor": (Sdf.ValueTypeNames.Color3f, (0.3, 0.3, 0.3))},
         (SURFACE_DIFFUSE, (0.0, 0.0, 0.0), 0.0, 0.25)),
        ({"useSpecularWorkflow": (Sdf.ValueTypeNames.Int, 1),
          "specularColor": (Sdf.ValueTypeNames.Color3f, (0.3, 0.2, 0.1))},
         (SURFACE_DIFFUSE, (0.3, 0.2, 0.1), None, None)),
        ({}, (SURFACE_DIFFUSE, (0.0, 0.0, 0.0), None, None)),
    ]
    for k, (inputs, (diffuse, specular, metallic, roughness)) in enumerate(cases):
        usd = tmp_path / f"m{k}.usda"
        stage, _, mesh = _cube_stage(usd)
        _preview_material(stage, mesh, **inputs)
        stage.Save()
        m = read_stage(usd).meshes[0].material
        np.testing.assert_allclose(m.diffuse, diffuse, rtol=1e-6)
        np.testing.assert_allclose(m.specular, specular, rtol=1e-6)
        assert (m.metallic, m.roughness) == (metallic, roughness) and m.maps == ()
    usd = tmp_path / "bare.usda"
    stage, _, _ = _cube_stage(usd)
    stage.Save()
    assert read_stage(usd).meshes[0].material is None


def test_a_preview_surface_input_out_of_range_is_one_line(tmp_path, capsys):
    from pxr import Sdf

    usd = tmp_path / "bad.usda"
    stage, _, mesh = _cube_stage(usd)
    _preview_material(stage, mesh, roughness=(Sdf.ValueTypeNames.Float, 1.5))
    stage.Save()
    assert main(["render", str(usd), "-o", str(tmp_path / "x.exr")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.usda" in err and "/World/Looks/Mat" in err and \
        "roughness" in err and "1.5" in err, err
    assert not (tmp_path / "x.exr").exists()


def test_a_metallic_preview_surface_reflects_as_the_mtls_pbr_material(tmp_path):
    """metallic 1, roughness 0.2 on a stage's cube: the same colours bit for bit as the OBJ
    whose MTL says ``Kd 0.9 0.6 0.2``, ``Pm 1``, ``Pr 0.2``, through the same camera, and
    not those of the cube without them (it reflects)."""
    from pxr import Sdf

    usd = tmp_path / "cube.usda"
    stage, world, mesh = _cube_stage(usd)
    _preview_material(stage, mesh, metallic=(Sdf.ValueTypeNames.Float, 1.0),
                      roughness=(Sdf.ValueTypeNames.Float, 0.2),
                      diffuseColor=(Sdf.ValueTypeNames.Color3f, (0.9, 0.6, 0.2)))
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    cam.AddRotateXYZOp().Set((-25.0, 35.0, 0.0))
    cam.AddTranslateOp().Set((0.0, 0.0, 7.0))
    stage.Save()
    from subtrace.io.usd import read_stage

    c = read_stage(usd).cameras[0]
    view = ["--width", "64", "--height", "48", "--quiet", "--eye", *map(str, c.eye),
            "--target", *map(str, c.target), "--up", *map(str, c.up), "--fov", repr(c.fov_deg)]
    images = {}
    for name, mtl in (("pbr", "Kd 0.9 0.6 0.2\nPm 1\nPr 0.2\n"), ("plain", "Kd 0.9 0.6 0.2\n")):
        (tmp_path / f"{name}.mtl").write_text(f"newmtl m\n{mtl}")
        obj = tmp_path / f"{name}.obj"
        obj.write_text(f"mtllib {name}.mtl\nusemtl m\n"
                       + "".join(f"v {x} {y} {z}\n" for x, y, z in CUBE_PTS)
                       + "".join("f " + " ".join(str(i + 1) for i in f) + "\n"
                                 for f in CUBE_FACES) + "t interpolateboundary 1/0/0 1\n")
        assert main(["render", str(obj), "-o", str(tmp_path / f"{name}.exr"), *view]) == 0
        images[name] = read_exr(tmp_path / f"{name}.exr")[0]
    assert main(["render", str(usd), "-o", str(tmp_path / "u.exr"), *view[:5]]) == 0
    u = read_exr(tmp_path / "u.exr")[0]
    assert np.count_nonzero(u["A"]) > 300
    for name in ("A", "R", "G", "B"):
        np.testing.assert_array_equal(u[name], images["pbr"][name], err_msg=name)
    assert not np.array_equal(u["R"], images["plain"]["R"])

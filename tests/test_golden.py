"""Golden images: every scene of ``scenes/`` rendered small and compared with
``golden_images/<scene>.exr``; the goldens themselves checked against an independent reference
(a fine uniform refinement pushed to the limit, ray cast in plain numpy); and proof that the
thresholds catch a one-level refinement change and a crease change.

The comparison is subtrace's pytest plugin's (:mod:`subtrace.testing.plugin`, the ``golden``
fixture; its settings are pyproject.toml's ``[tool.subtrace.compare]``: the goldens in
golden_images/, failures in test_output/golden/). Regenerate the goldens (after a change that
is meant to alter the images) with::

    python -m pytest tests/test_golden.py --update-goldens

A failing comparison writes the render, the reference and their difference (EXR and PNG) to
``test_output/golden/<scene>/`` (git-ignored) and prints the paths; every run's comparisons
are on one page, ``test_output/golden/report.html``. (The goldens' headers record the command
with ``--update-golden``, the plugin's other spelling of the option.)
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import naive
import numpy as np
import pytest
from naive import ray_triangles

import subtrace
from subtrace.compare import DEFAULT_THRESHOLDS, FAIL, GROUPS, OPTIONAL_GROUPS, compare_images
from subtrace.io.exr import read_exr
from subtrace.io.scene import apply_overrides, load_scene
from subtrace.nurbs.scene import has_faces, has_surfaces

ROOT = Path(__file__).resolve().parents[1]
SCENES_DIR = ROOT / "scenes"
GOLDEN_DIR = ROOT / "golden_images"  # pyproject.toml [tool.subtrace.compare] goldens
MODELS = ROOT / "models"  # the scenes' meshes, in the repository (models/README.md)
# the scenes' goldens, and the built-in default scene's (``default``: Spot textured)
DEFAULT_SCENE = ROOT / "src" / "subtrace" / "data" / "default_scene.toml"
SCENES = sorted(p.stem for p in SCENES_DIR.glob("*.toml")) + ["default"]


def scene_file(scene: str) -> Path:
    """The TOML file of a golden's scene (``default``: the built-in default scene)."""
    return DEFAULT_SCENE if scene == "default" else SCENES_DIR / f"{scene}.toml"

# Small renders: each golden stays well under 100 KB and all eight render in about a second
# once the kernels are compiled. The scenes' own tolerance (1 px) is kept, so the goldens
# exercise the adaptive depth choice at this resolution.
GOLDEN_WIDTH, GOLDEN_HEIGHT = 160, 120
# Only the channels that `subtrace compare` judges are stored (u, v would double the size),
# less the optional position group (P is eye + Z d: the camera and Z give it).
GOLDEN_CHANNELS = tuple(c for g, names in GROUPS.items() if g not in OPTIONAL_GROUPS
                        for c in names)
# The comparison uses subtrace compare's defaults: the renderer is deterministic, so an
# unchanged renderer gives 0 everywhere; the percents absorb silhouette, crease and patch
# border pixels that harmless arithmetic changes flip, while a one-level refinement change
# (the `level` id over whole patches) and a crease sharpness change (depth, normals) fail
# (test_thresholds_catch_*). pyproject.toml's [tool.subtrace.compare] sets no threshold, so
# the plugin judges by these.
GOLDEN_THRESHOLDS = DEFAULT_THRESHOLDS


def update_command(scene: str) -> str:
    """The exact command that (re)writes one scene's golden image, as the goldens' headers
    record it (``--update-golden``: the plugin's other spelling of ``--update-goldens``)."""
    return f'python -m pytest "tests/test_golden.py::test_golden[{scene}]" --update-golden'


def golden_path(scene: str) -> Path:
    return GOLDEN_DIR / f"{scene}.exr"


def golden_scene(scene: str, **overrides):
    """The scene file at the golden resolution (plus any other apply_overrides values)."""
    loaded = load_scene(scene_file(scene))
    return apply_overrides(loaded, width=GOLDEN_WIDTH, height=GOLDEN_HEIGHT, **overrides)


def render_channels(scene) -> tuple[dict, object]:
    """Render ``scene``: (the GOLDEN_CHANNELS, the RenderResult)."""
    from subtrace.render import render_scene

    result = render_scene(scene)
    return {c: result.channels[c] for c in GOLDEN_CHANNELS}, result


def golden_attributes(result, scene, name: str) -> dict:
    """Header of a golden image: camera, scheme, tolerance (subtrace:version is added by
    write_exr), the scene, the command that regenerates it and the thresholds it is held to.
    Timings and counts are left out so that regenerating an unchanged golden gives the same
    file."""
    from subtrace.render import result_attributes

    keep = ("subtrace:camera", "subtrace:camera_fov_deg", "worldToCamera",
            "subtrace:tolerance_rad", "subtrace:tolerance_px", "subtrace:scheme",
            "subtrace:accel")
    attrs = {k: v for k, v in result_attributes(result, scene).items() if k in keep}
    attrs["subtrace:scene"] = scene_file(name).relative_to(ROOT).as_posix()
    attrs["subtrace:meshes"] = ";".join(Path(o.mesh).name for o in scene.objects)
    attrs["subtrace:golden_command"] = update_command(name)
    attrs["subtrace:golden_thresholds"] = json.dumps(
        {g: dataclasses.asdict(t) for g, t in GOLDEN_THRESHOLDS.items()}
    )
    return attrs


@pytest.mark.parametrize("name", SCENES)
def test_golden(name, golden):
    """Each scene renders to its golden image within GOLDEN_THRESHOLDS (the plugin's
    comparison; with --update-goldens the render is written as the golden, header and all)."""
    scene = golden_scene(name)
    channels, result = render_channels(scene)
    golden(channels, name, attributes=golden_attributes(result, scene, name))


def test_every_scene_has_a_golden():
    """Every scene of scenes/ has its golden image, and every golden image its scene."""
    goldens = sorted(p.stem for p in GOLDEN_DIR.glob("*.exr") if p.stem != "default") + [
        "default"] * (GOLDEN_DIR / "default.exr").is_file()
    missing = [update_command(s) for s in SCENES if s not in goldens]
    assert not missing, "missing golden images; create them with: " + "; ".join(missing)
    assert goldens == SCENES, f"golden images without a scene: {set(goldens) - set(SCENES)}"


@pytest.mark.parametrize("name", SCENES)
def test_golden_header_and_size(name):
    """Goldens record scheme, tolerance, version and the regenerating command, hold exactly
    the compared channels at the golden resolution, and stay small for the repository."""
    path = golden_path(name)
    assert path.stat().st_size < 150_000
    channels, attrs = read_exr(path)
    assert tuple(channels) == GOLDEN_CHANNELS
    assert channels["R"].shape == (GOLDEN_HEIGHT, GOLDEN_WIDTH)
    assert attrs["subtrace:version"] == subtrace.__version__
    assert set(attrs["subtrace:scheme"].split(",")) <= {"catmark", "loop", "nurbs"}
    assert attrs["subtrace:tolerance_px"] == pytest.approx(1.0, rel=1e-6)
    assert attrs["subtrace:golden_command"] == update_command(name)
    assert attrs["subtrace:scene"] == scene_file(name).relative_to(ROOT).as_posix()


# --------------------------------------------------------------------------------------
# the goldens against an independent reference
# --------------------------------------------------------------------------------------

REF_EDGE_PX = 2.0  # reference triangles: every edge projects to at most this many pixels
REF_MAX_LEVEL = 7
DEPTH_JUMP = 0.05  # relative depth step between neighbour pixels that marks an occlusion edge
NORMAL_SLACK_DEG = 0.5  # the renderer's own normal error beyond the reference's (see below)


def reference_mesh(cage, camera, uvs=False):
    """(points (n,3) float64, triangles (T,3) int64): the exact limit points of a uniform
    refinement of ``cage`` at the first level where every edge projects to at most
    REF_EDGE_PX pixels, Catmark quads split along one diagonal, hole faces left out. With
    ``uvs``, also the UVs of the triangles' corners (T,3,2): the refined face-varying
    values (``Cage.refine_uv``, OpenSubdiv's InterpolateFaceVarying)."""
    eye = np.asarray(camera.eye)
    first = 1 if cage.scheme == "catmark" else 0  # Catmark level 0 may have n-gons
    for level in range(first, REF_MAX_LEVEL + 1):
        mesh = cage.refine(level)
        k = int(mesh.face_sizes.max())
        faces = mesh.face_verts.reshape(-1, k)[~mesh.face_hole].astype(np.int64)
        P, _, _ = cage.limit(level)
        corners = P[faces]
        edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=-1).max(axis=1)
        dist = np.linalg.norm(corners - eye, axis=-1).min(axis=1)
        if (edges / dist).max() <= REF_EDGE_PX * camera.pixel_angle():
            break
    corner_uv = None
    if uvs:
        values, fvals = cage.refine_uv(level)
        corner_uv = values[fvals.reshape(-1, k)[~mesh.face_hole]]
    if k == 4:
        faces = np.concatenate([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]])
        if uvs:
            corner_uv = np.concatenate([corner_uv[:, [0, 1, 2]], corner_uv[:, [0, 2, 3]]])
    return (P, faces, corner_uv) if uvs else (P, faces)


REF_NURBS_EDGE_PX = 2.0  # as REF_EDGE_PX; a triangle kept or dropped whole moves a trim edge by
# less than its size, which the coverage check's band of one pixel around the reference's
# silhouettes absorbs (the test passes at 1 px too, five times slower)
REF_NURBS_MAX_N = 512


def reference_nurbs_mesh(path, camera) -> tuple[np.ndarray, np.ndarray]:
    """(points, triangles) of the free-form surfaces of the OBJ file ``path``: each surface
    at a uniform grid of its parameter rectangle fine enough that every edge projects to at
    most REF_NURBS_EDGE_PX pixels (points by plain de Boor, naive.nurbs_grid), cells split
    into two triangles, a triangle dropped where its centroid's (u, v) is trimmed away by the
    brute-force even-odd rule over the loops sampled densely (naive.polygon_parity):
    kept inside the outer loops (all of the rectangle without them) and outside the holes."""
    from subtrace.io.obj import read_obj
    from subtrace.nurbs.freeform import freeform_of

    eye = np.asarray(camera.eye)
    points, faces = [], []
    for surface in freeform_of(read_obj(path)).surfaces:
        n = 8
        while True:
            P, uv = naive.nurbs_grid(surface, n)
            along = np.concatenate([np.linalg.norm(np.diff(P, axis=a), axis=-1).ravel()
                                    for a in (0, 1)])
            dist = np.linalg.norm(P - eye, axis=-1).min()
            need = along.max() / dist / (REF_NURBS_EDGE_PX * camera.pixel_angle())
            if need <= 1.0 or n >= REF_NURBS_MAX_N:
                break
            n = min(REF_NURBS_MAX_N, int(np.ceil(n * need * 1.1)))
        idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
        a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
        tri = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                              np.stack([a, c, d], -1).reshape(-1, 3)])
        centre = uv.reshape(-1, 2)[tri].mean(axis=1)
        outer = [naive.loop_polygon(lp.segments) for lp in surface.loops if not lp.hole]
        holes = [naive.loop_polygon(lp.segments) for lp in surface.loops if lp.hole]
        keep = naive.polygon_parity(outer, centre) if outer else np.ones(len(tri), bool)
        keep &= ~naive.polygon_parity(holes, centre)
        faces.append(tri[keep] + sum(len(p) for p in points))
        points.append(P.reshape(-1, 3))
    return np.concatenate(points), np.concatenate(faces)


def ray_cast(triangles: np.ndarray, camera) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit of every pixel's ray with ``triangles``: (t (H,W), triangle (H,W)), t the
    distance from the eye (inf, -1 on a miss). Plain numpy: each triangle is tested against
    the pixels of its projected bounding box (one pixel wider on each side), Moller-Trumbore
    in float64 with barycentrics allowed 1e-9 outside (a pixel centre on a shared edge hits
    both triangles rather than neither). Triangles reaching behind the eye are skipped (the
    scenes' cameras are outside their objects)."""
    W, H = camera.width, camera.height
    eye = np.asarray(camera.eye, dtype=np.float64)
    right, up, forward = camera.basis()
    s = camera.pixel_size()
    dirs = camera.ray_directions().reshape(-1, 3)
    rel = triangles - eye
    z = rel @ forward
    keep = (z > 1e-9).all(axis=1)
    tri_index = np.nonzero(keep)[0]
    rel, z = rel[keep], z[keep]
    col = (rel @ right) / (z * s) - 0.5 + 0.5 * W
    row = -(rel @ up) / (z * s) - 0.5 + 0.5 * H
    c0 = np.clip(np.floor(col.min(axis=1)) - 1, 0, W - 1).astype(np.int64)
    c1 = np.clip(np.ceil(col.max(axis=1)) + 1, 0, W - 1).astype(np.int64)
    r0 = np.clip(np.floor(row.min(axis=1)) - 1, 0, H - 1).astype(np.int64)
    r1 = np.clip(np.ceil(row.max(axis=1)) + 1, 0, H - 1).astype(np.int64)
    inside = (col.max(axis=1) >= -1) & (col.min(axis=1) <= W) & (row.max(axis=1) >= -1) & (
        row.min(axis=1) <= H)
    nc, nr = np.where(inside, c1 - c0 + 1, 0), np.where(inside, r1 - r0 + 1, 0)
    best_t = np.full(W * H, np.inf)
    best_tri = np.full(W * H, -1, dtype=np.int64)
    chunk = 200_000
    for a in range(0, len(rel), chunk):
        sl = slice(a, a + chunk)
        counts = nc[sl] * nr[sl]
        tri = np.repeat(np.arange(a, min(a + chunk, len(rel))), counts)
        k = np.arange(len(tri)) - np.repeat(np.cumsum(counts) - counts, counts)
        pix = (r0[tri] + k // nc[tri]) * W + c0[tri] + k % nc[tri]
        # from the eye (the origin of ``rel``), one ray per (pixel, triangle) pair
        t, u, v = ray_triangles(np.zeros(3), dirs[pix], rel[tri, 0], rel[tri, 1], rel[tri, 2])
        eps = 1e-9
        with np.errstate(invalid="ignore"):
            hit = (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps) & (t > 0) & np.isfinite(t)
        pix, t, tri = pix[hit], t[hit], tri[hit]
        order = np.lexsort((t, pix))
        pix, t, tri = pix[order], t[order], tri[order]
        first = np.r_[True, pix[1:] != pix[:-1]]
        pix, t, tri = pix[first], t[first], tri[first]
        better = t < best_t[pix]
        best_t[pix[better]] = t[better]
        best_tri[pix[better]] = tri_index[tri[better]]
    return best_t.reshape(H, W), best_tri.reshape(H, W)


def normal_spread_deg(points: np.ndarray, faces: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(T,) degrees: how far the surface normal may turn within reach of each triangle.

    Each vertex gets the cone (around the mean) of the normals of its triangles; a
    triangle's spread is twice the widest cone of its corners, which bounds the angle between
    its normal and that of any triangle sharing a corner. Beside a crease it is the crease's
    dihedral angle, elsewhere about the turn of the normal over one triangle."""
    from subtrace.compare import normal_angle_deg

    mean = np.zeros_like(points)
    for k in range(3):
        np.add.at(mean, faces[:, k], normals)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean /= np.linalg.norm(mean, axis=1)[:, None]
    cone = np.zeros(len(points))
    for k in range(3):
        np.maximum.at(cone, faces[:, k], normal_angle_deg(normals, mean[faces[:, k]]))
    return 2.0 * cone[faces].max(axis=1)


def reference_check(channels: dict, scene, tol_rad: float) -> dict:
    """Check rendered ``channels`` against the independent reference of ``scene``.

    The reference: for every object, the triangles of :func:`reference_mesh` (exact limit
    points of a fine uniform refinement, each edge at most REF_EDGE_PX pixels), ray cast in
    numpy (:func:`ray_cast`) through the same pixel centres. Edge pixels are those within
    one pixel of a reference silhouette or of an occlusion step (neighbour depths differing by
    more than DEPTH_JUMP); elsewhere both images see the same smooth piece of surface.
    Returns lists of offending pixels (row, col) per check, empty when the render is right:

    * coverage: a pixel covered in one and not the other that is not an edge pixel (a
      tolerance of one pixel moves a silhouette by less than a pixel);
    * (free-form surfaces: :func:`reference_nurbs_mesh`, plain de Boor points and the
      even-odd rule over densely sampled trim loops);
    * depth: |Z - Z_ref| cos(theta) > tol_rad * Z_ref off the edges (theta: between the ray
      and the reference normal): the two surfaces further apart, along the normal, than the
      tolerance angle at that distance. Both lie much closer to the limit surface than that
      (cells and reference triangles subtend at most a pixel or two, and a flat piece of
      that size deviates from the surface by a fraction of its size proportional to its
      normal's turn), so this is what the tolerance allows, with room;
    * normals: the rendered normal (an exact limit normal, or a blend of exact ones across
      a cell) further than the triangle's normal_spread_deg + NORMAL_SLACK_DEG from the
      hit triangle's normal, off the edges. The limit normal anywhere on the triangle lies
      within its spread of its normal; the slack covers the renderer's blend across a cell
      of at most a pixel.
    """
    camera = scene.make_camera()
    points, faces = [], []
    for o in scene.objects:
        meshes = []
        if has_surfaces(o.mesh):  # free-form surfaces
            meshes.append(reference_nurbs_mesh(o.mesh, camera))
        if not has_surfaces(o.mesh) or has_faces(o.mesh):  # a subdivision cage
            cage = subtrace.load_cage(o.mesh, scheme=o.scheme, boundary=o.boundary_code)
            meshes.append(reference_mesh(cage, camera))
        for P, F in meshes:
            faces.append(F + sum(len(p) for p in points))
            points.append(P)
    points, faces = np.concatenate(points), np.concatenate(faces)
    tris = points[faces]
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    area = np.linalg.norm(normals, axis=1)
    normals /= np.where(area > 0, area, 1.0)[:, None]
    t_ref, tri = ray_cast(np.where((area > 0)[:, None, None], tris, np.nan), camera)
    spread = normal_spread_deg(points, faces, normals)

    H, W = t_ref.shape
    covered_ref = np.isfinite(t_ref)
    covered = np.isfinite(channels["Z"])  # the centre ray's hit (alpha is anti-aliased)
    padded = np.pad(t_ref, 1, constant_values=np.inf)
    edge = np.zeros((H, W), dtype=bool)
    with np.errstate(invalid="ignore"):
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                q = padded[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
                edge |= np.isfinite(q) != covered_ref
                edge |= np.abs(q - t_ref) > DEPTH_JUMP * np.minimum(q, t_ref)
    inner = covered & covered_ref & ~edge
    n_ref = normals[tri[inner]]
    cos = np.abs(np.einsum("ij,ij->i", camera.ray_directions()[inner], n_ref))
    z, z_ref = channels["Z"][inner].astype(np.float64), t_ref[inner]
    n = np.stack([channels[c][inner] for c in ("N.X", "N.Y", "N.Z")], axis=-1)
    from subtrace.compare import normal_angle_deg

    angle = normal_angle_deg(n.astype(np.float64), n_ref)
    rows, cols = np.nonzero(inner)
    pixels = lambda bad: list(zip(rows[bad].tolist(), cols[bad].tolist()))  # noqa: E731
    return {
        "coverage": list(zip(*[a.tolist() for a in np.nonzero((covered != covered_ref) & ~edge)])),
        "depth": pixels(np.abs(z - z_ref) * cos > tol_rad * z_ref),
        "normals": pixels(angle > spread[tri[inner]] + NORMAL_SLACK_DEG),
        "inner_pixels": int(inner.sum()),
        "covered_pixels": int(covered.sum()),
    }


@pytest.mark.parametrize("name", SCENES)
def test_golden_matches_independent_reference(name):
    """Each golden image is right, not only what the code produced: coverage, depth and
    normals agree with a fine uniform refinement ray cast in numpy (see reference_check)."""
    path = golden_path(name)
    channels, attrs = read_exr(path)
    scene = golden_scene(name)
    assert attrs["subtrace:camera"] == scene.make_camera().header_attributes()["subtrace:camera"]
    bad = reference_check(channels, scene, attrs["subtrace:tolerance_rad"])
    # most covered pixels are judged: the edge band is a small part of each image
    assert bad["inner_pixels"] > 0.5 * bad["covered_pixels"]
    for check in ("coverage", "depth", "normals"):
        assert not bad[check], f"{name}: {check} differs from the reference at {bad[check][:10]}"


# --------------------------------------------------------------------------------------
# the thresholds catch real changes
# --------------------------------------------------------------------------------------

CREASES_OBJ = MODELS / "opensubdiv" / "catmark_cubes_semisharp.obj"
CREASE_LINE = "t crease 2/1/0  8  9  2.0"  # one semi-sharp crease of the creases scene


def perturbed_creases_scene(tmp_path, sharpness: float):
    """The creases scene with one crease's sharpness changed from 2.0 to ``sharpness``."""
    text = CREASES_OBJ.read_text()
    assert text.count(CREASE_LINE) == 1
    obj = tmp_path / "perturbed.obj"
    obj.write_text(text.replace(CREASE_LINE, f"t crease 2/1/0  8  9  {sharpness}"))
    scene = golden_scene("creases")
    return dataclasses.replace(
        scene, objects=(dataclasses.replace(scene.objects[0], mesh=str(obj)),)
    )


@pytest.mark.parametrize("sharpness", [1.0, 2.5])
def test_thresholds_catch_crease_change(tmp_path, sharpness):
    """Changing one crease's sharpness (2 -> 1 or 2.5) fails the golden comparison through
    the geometry (depth and normals), not only through the ids."""
    rendered, _ = render_channels(perturbed_creases_scene(tmp_path, sharpness))
    comparison = compare_images(rendered, golden_path("creases"), GOLDEN_THRESHOLDS)
    assert comparison.verdict == FAIL
    assert comparison.groups["depth"].verdict == FAIL
    assert comparison.groups["normals"].verdict == FAIL


def test_reference_check_rejects_a_wrong_crease(tmp_path):
    """The reference check has teeth: a render whose crease is wrong (sharpness 1 instead of
    2) departs from the reference of the unchanged scene. (Sharpness 2.5 moves the surface
    less than the tolerance-sized bounds of the check; the golden comparison catches it.)"""
    rendered, result = render_channels(perturbed_creases_scene(tmp_path, 1.0))
    bad = reference_check(rendered, golden_scene("creases"), result.tolerance_rad)
    assert len(bad["depth"]) + len(bad["normals"]) > 10


@pytest.mark.parametrize("tolerance", [0.5, 2.0])
def test_thresholds_catch_one_level_change(tolerance):
    """Halving or doubling the tolerance refines (nearly) every patch one level deeper or
    shallower: the comparison fails on the ids group (level)."""
    rendered, _ = render_channels(golden_scene("spot", tolerance=tolerance))
    comparison = compare_images(rendered, golden_path("spot"), GOLDEN_THRESHOLDS)
    assert comparison.verdict == FAIL
    assert comparison.groups["ids"].verdict == FAIL


# --------------------------------------------------------------------------------------
# the textured default scene's colour against an independent reference
# --------------------------------------------------------------------------------------


def _lab(rgb: np.ndarray) -> np.ndarray:
    """CIE L*a*b* (D65) of linear sRGB / Rec.709 colours (n,3)."""
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722],
                  [0.0193, 0.1192, 0.9505]])
    xyz = rgb @ m.T / m.sum(axis=1)
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.stack([116 * f[:, 1] - 16, 500 * (f[:, 0] - f[:, 1]), 200 * (f[:, 1] - f[:, 2])],
                    axis=1)


def reference_albedo(scene, camera, tmp_path) -> np.ndarray:
    """(H,W,3) the diffuse texture's colour each pixel's ray sees (NaN on a miss), made
    without subtrace's texturing: the refined mesh of :func:`reference_mesh` with its
    corners' face-varying UVs, ray cast in numpy, each hit's UV its triangle's barycentric
    blend, the image decoded from sRGB in numpy, written as a float EXR and looked up by
    OpenImageIO's TextureSystem (its own MIP levels) over the pixel's footprint as the UV
    differences to its neighbours give it (GPU-style screen derivatives; not subtrace's
    ray cones)."""
    import OpenImageIO as oiio

    obj = scene.objects[0]
    (tmap,) = [m for m in obj.textures if m.slot == "diffuse"]
    cage = subtrace.load_cage(obj.mesh)
    P, faces, corner_uv = reference_mesh(cage, camera, uvs=True)
    tris = P[faces]
    t_ref, tri = ray_cast(tris, camera)
    H, W = t_ref.shape
    hit = tri >= 0
    d = camera.ray_directions().reshape(H, W, 3)[hit]
    k = tri[hit]
    eye = np.asarray(camera.eye, np.float64)
    _, u, v = ray_triangles(eye, d, tris[k, 0], tris[k, 1], tris[k, 2])
    uv = np.full((H, W, 2), np.nan)
    uv[hit] = ((1 - u - v)[:, None] * corner_uv[k, 0] + u[:, None] * corner_uv[k, 1]
               + v[:, None] * corner_uv[k, 2])
    # screen derivatives: the smaller of the forward and backward differences (one side
    # may cross a silhouette or a UV seam)
    def deriv(axis):
        fwd = np.roll(uv, -1, axis) - uv
        bwd = uv - np.roll(uv, 1, axis)
        nf, nb = np.linalg.norm(fwd, axis=-1), np.linalg.norm(bwd, axis=-1)
        pick = np.where(np.isnan(nf) | (nb < nf), 1, 0)[..., None]
        out = np.where(pick == 1, bwd, fwd)
        return np.nan_to_num(out)

    ddx, ddy = deriv(1), deriv(0)
    src = oiio.ImageBuf(tmap.path).get_pixels(oiio.FLOAT)[:, :, :3]
    lin = np.where(src <= 0.04045, src / 12.92, ((src + 0.055) / 1.055) ** 2.4)
    spec = oiio.ImageSpec(lin.shape[1], lin.shape[0], 3, oiio.FLOAT)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(lin, np.float32))
    exr = str(tmp_path / "linear_texture.exr")
    assert buf.write(exr)
    ts = oiio.TextureSystem(shared=False)
    ts.attribute("automip", 1)
    opt = oiio.TextureOpt()
    opt.swrap = opt.twrap = oiio.Wrap.Periodic
    out = np.full((H, W, 3), np.nan)
    for r, c in zip(*np.nonzero(hit)):
        s, t = uv[r, c]
        out[r, c] = ts.texture(exr, opt, float(s), float(1 - t), float(ddx[r, c, 0]),
                               float(-ddx[r, c, 1]), float(ddy[r, c, 0]),
                               float(-ddy[r, c, 1]), 3)
    return out


def test_textured_default_golden_matches_reference_colour(tmp_path):
    """The default scene's golden (Spot with its texture) has the reference's texture
    colours (:func:`reference_albedo`): the golden's diffuse colour at each pixel is
    ``(golden - S) / (L - S)``, L and S the same scene rendered white and black (the
    lighting, shadows and specular lobe are linear in the diffuse colour; one ray a pixel:
    anti-aliasing mixes the textured golden's rays at edges alone). Off the silhouettes
    and occlusion steps (the reference check's edge band), the colour difference is a mean
    CIE76 Delta E below 1.5 (1.09 measured; 1 is about the least visible difference) and
    its 95th percentile below 8 (6.3): at 160x120 Spot's texture is about 16 texels a
    pixel, and the spots' and eyes' edges fall a fraction of a pixel apart in the two (the
    reference's triangles are 2 px and its UVs linear across them, the renderer's cells
    1 px) and are filtered over different footprints (screen differences against ray
    cones); the texture turned upside down gives a mean of 27."""
    scene = golden_scene("default")
    channels, _ = read_exr(golden_path("default"))
    plain = [dataclasses.replace(scene.objects[0], textures=(), color=c)
             for c in ((1.0, 1.0, 1.0), (0.0, 0.0, 0.0))]
    flat = apply_overrides(scene, samples=1)
    lit, spec = (render_channels(dataclasses.replace(flat, objects=(o,)))[0] for o in plain)
    rgb = lambda ch: np.stack([ch[c] for c in "RGB"], -1).astype(np.float64)  # noqa: E731
    camera = scene.make_camera()
    ref = reference_albedo(scene, camera, tmp_path)
    light = rgb(lit) - rgb(spec)
    albedo = (rgb(channels) - rgb(spec)) / np.where(light > 0, light, np.nan)
    t = channels["Z"]
    padded = np.pad(t, 1, constant_values=np.inf)
    H, W = t.shape
    edge = np.zeros((H, W), bool)
    with np.errstate(invalid="ignore"):
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                q = padded[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
                edge |= np.isfinite(q) != np.isfinite(t)
                edge |= np.abs(q - t) > DEPTH_JUMP * np.minimum(q, t)
    judged = (~edge & np.isfinite(t) & np.isfinite(ref).all(-1)
              & (light > 0.03).all(-1) & np.isfinite(albedo).all(-1))
    assert judged.sum() > 0.5 * np.isfinite(t).sum()
    de = np.linalg.norm(_lab(np.clip(albedo[judged], 0, 1)) - _lab(ref[judged]), axis=1)
    print(f"default golden vs reference: mean Delta E {de.mean():.3f}, 95th percentile "
          f"{np.quantile(de, 0.95):.3f}, max {de.max():.2f} over {judged.sum()} pixels")
    assert de.mean() < 1.5 and np.quantile(de, 0.95) < 8.0

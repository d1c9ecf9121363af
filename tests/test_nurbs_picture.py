"""Free-form (trimmed NURBS) surfaces in the picture (picture.py with nurbs/scene.py): lit by
``shade.light`` like the cages, they cast and receive shadows (against the cages and
themselves), occlude ambient occlusion rays and get anti-aliasing rays; a convex surface
never shadows itself; secondary rays refine NURBS patches by their ray cones, never finer
than without them; and the image does not depend on the thread count."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace.io.scene import apply_overrides, load_scene, scene_from_dict
from subtrace.render import render_scene

ROOT = Path(__file__).resolve().parents[1]
SPHERE = str(ROOT / "models" / "nurbs" / "sphere.obj")  # the unit sphere, one surface
SLAB = ("v -4 -4 -1.5\nv 4 -4 -1.5\nv 4 4 -1.5\nv -4 4 -1.5\nv -4 -4 -1.2\nv 4 -4 -1.2\n"
        "v 4 4 -1.2\nv -4 4 -1.2\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\n"
        "f 4 1 5 8\n" + "".join(f"t crease 2/1/0 {a} {b} 10\n" for a, b in (
            (0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5),
            (2, 6), (3, 7))))


def _scene(tmp_path, meshes, shadows=True, samples=1, ao=0, size=(96, 72)):
    return scene_from_dict({
        "object": [{"mesh": m} for m in meshes],
        "camera": {"eye": [2.0, -6.0, 5.0], "target": [0.0, 0.0, -0.5], "up": [0, 0, 1],
                   "width": size[0], "height": size[1]},
        "render": {"headlight": True, "headlight_intensity": 0.3, "shadows": shadows,
                   "samples": samples, "ao": ao, "background": [0.2, 0.2, 0.2]},
        "light": [{"direction": [0.0, 0.0, -1.0]}],  # straight down
        "ground": False,
    }, base_dir=tmp_path)


def test_a_nurbs_sphere_does_not_shadow_or_occlude_itself(tmp_path):
    """The sphere is convex: with shadows and ambient occlusion every pixel's colour is
    bit for bit that without them (the secondary rays leave it by the hit's error bound),
    while the light leaves half of it dark."""
    plain = render_scene(_scene(tmp_path, [SPHERE], shadows=False)).channels
    both = render_scene(_scene(tmp_path, [SPHERE], shadows=True, ao=8)).channels
    hit = plain["A"] > 0
    assert hit.sum() > 500
    for c in "RGB":
        assert np.array_equal(plain[c], both[c]), c


def test_nurbs_surfaces_take_the_materials_specular_lobe(tmp_path):
    """A sphere given ``specular`` and ``shininess`` in the scene: its colour is the plain
    (diffuse) render's plus Ks times Blinn-Phong's (N.H)^Ns for the light and for the
    headlight (whose half vector is the view direction), computed here from the image's
    own normals and positions; a surface read from an MTL material with Ks gets it too."""
    eye = np.array([2.0, -6.0, 5.0])  # (_scene's camera)
    ks, ns = 0.5, 30.0

    def render(**material):
        data = _scene(tmp_path, [SPHERE], shadows=False)
        return render_scene(replace(data, objects=[replace(data.objects[0], **material)]))

    plain = render().channels
    shiny = render(specular=(ks, ks, ks), shininess=ns).channels
    hit = plain["A"] > 0
    n = np.stack([shiny[c] for c in ("N.X", "N.Y", "N.Z")], axis=-1)[hit].astype(np.float64)
    p = np.stack([shiny[c] for c in ("P.X", "P.Y", "P.Z")], axis=-1)[hit].astype(np.float64)
    v = eye - p
    v /= np.linalg.norm(v, axis=1)[:, None]
    h = v + np.array([0.0, 0.0, 1.0])  # towards the eye plus towards the light
    h /= np.linalg.norm(h, axis=1)[:, None]
    lobe = ks * (np.maximum((n * h).sum(axis=1), 0.0) ** ns
                 + 0.3 * np.maximum((n * v).sum(axis=1), 0.0) ** ns)
    extra = shiny["R"][hit].astype(np.float64) - plain["R"][hit]
    assert lobe.max() > 0.4  # the highlight is in view
    np.testing.assert_allclose(extra, lobe, atol=2e-3)

    mtl = tmp_path / "shiny.mtl"
    mtl.write_text(f"newmtl shiny\nKd 0.8 0.8 0.8\nKs {ks} {ks} {ks}\nNs {ns}\n")
    obj = tmp_path / "sphere.obj"
    obj.write_text("mtllib shiny.mtl\nusemtl shiny\n" + Path(SPHERE).read_text())
    from_mtl = render_scene(_scene(tmp_path, [str(obj)], shadows=False)).channels
    np.testing.assert_allclose(from_mtl["R"], shiny["R"], atol=1e-6)


def test_nurbs_and_cages_shadow_each_other(tmp_path):
    """Light straight down: the sphere (NURBS) shadows the slab (a cage) exactly over the
    disc of its radius below it (within a pixel of its outline, at the slab's footprint
    there), and the slab pixels outside it stay lit."""
    slab = tmp_path / "slab.obj"
    slab.write_text(SLAB)
    result = render_scene(_scene(tmp_path, [SPHERE, str(slab)], size=(160, 120)))
    ch = result.channels
    p = np.stack([ch[c] for c in ("P.X", "P.Y", "P.Z")], axis=-1).astype(np.float64)
    on_slab = (ch["object_id"] == 1) & (np.abs(p[..., 2] + 1.2) < 1e-3)  # its top face
    r = np.hypot(p[..., 0], p[..., 1])
    lit = ch["R"][on_slab & (r > 1.3)].min()
    dark = ch["R"][on_slab & (r < 0.9)]
    assert dark.size > 200 and (on_slab & (r > 1.3)).sum() > 1000
    assert dark.max() < 0.5 * lit  # in shadow: only the headlight
    shadowed = on_slab & (ch["R"] < 0.5 * lit)
    assert r[shadowed].max() < 1.0 + 0.05  # (a pixel of the slab is about 0.04 wide)


def test_nurbs_silhouettes_are_antialiased(tmp_path):
    """With more rays per edge pixel the sphere's silhouette gets intermediate alpha, and
    where the centre ray hit, its channels stay those of one ray per pixel (where it
    missed, a covered pixel has its nearest extra ray's: test_picture.py)."""
    one = render_scene(_scene(tmp_path, [SPHERE], samples=1)).channels
    many = render_scene(_scene(tmp_path, [SPHERE], samples=8)).channels
    assert set(np.unique(one["A"])) == {0.0, 1.0}
    partial = (many["A"] > 0) & (many["A"] < 1)
    assert partial.sum() > 20
    centre = np.isfinite(one["Z"])
    for c in ("Z", "N.X", "object_id", "P.X"):
        assert one[c][centre].tobytes() == many[c][centre].tobytes(), c
    assert np.all(np.isfinite(many["Z"][many["A"] > 0]))


def test_nurbs_picture_does_not_depend_on_the_threads():
    scene = apply_overrides(load_scene(ROOT / "scenes" / "nurbs_mixed.toml"), width=96,
                            height=54, samples=4, ao=4)
    one = render_scene(scene, threads=1).channels
    two = render_scene(scene, threads=2).channels
    for c in one:
        assert one[c].tobytes() == two[c].tobytes(), c


def test_ray_cones_refine_shadow_rays_no_finer():
    """Shadow rays leaving the torus of nurbs_torus (points on it seen from the eye) towards
    the light: traced with their ray cones (width t * tol at the origin) they find their
    occluders at leaf levels no deeper than traced without (the angular criterion measured
    from the origin alone), strictly shallower on the whole, and they find the same
    occluders (the hits are exact roots either way)."""
    from subtrace.camera import camera_frame
    from subtrace.nurbs.scene import load_nurbs
    from subtrace.nurbs.trace import hit_geometry, trace_nurbs, trace_rays

    scene = apply_overrides(load_scene(ROOT / "scenes" / "nurbs_torus.toml"), width=128,
                            height=72)
    nurbs = load_nurbs(scene)
    camera = scene.make_camera()
    frame = camera_frame(camera)
    tol = scene.render.tolerance_rad(camera)
    hits = trace_nurbs(nurbs.model, nurbs.bvh, frame, 128, 72, tol)
    pix = np.nonzero(hits.patch >= 0)[0]
    points, normals, _ = hit_geometry(nurbs.model, hits.patch[pix], hits.st[pix])
    light = -np.array(scene.lights[0].direction) / np.linalg.norm(scene.lights[0].direction)
    normals *= np.where((normals @ light) < 0, -1.0, 1.0)[:, None]  # towards the light
    t = hits.t[pix]
    err = t * tol + 2.0 ** -40 * np.abs(points).max(axis=1)
    origins = points + err[:, None] * normals
    dirs = np.repeat(light[None], len(pix), axis=0)
    plain = trace_rays(nurbs.model, nurbs.bvh, origins, dirs, tol)
    cone = trace_rays(nurbs.model, nurbs.bvh, origins, dirs, tol, cone=t * tol)
    both = (plain.patch >= 0) & (cone.patch >= 0)
    assert both.sum() > 50  # the sphere and the torus shadow parts of the torus
    assert np.array_equal(plain.patch >= 0, cone.patch >= 0)
    assert np.all(cone.level[both] <= plain.level[both])
    assert cone.level[both].mean() < plain.level[both].mean() - 1
    np.testing.assert_allclose(cone.t[both], plain.t[both], rtol=1e-6)


@given(st.lists(st.sampled_from([b"surf", b"f", b" ", b"\t", b"\n", b"\r\n", b"x", b"#",
                                 b"v 1 2 3", b"s"]), max_size=24))
@settings(max_examples=400, deadline=None)
def test_the_statement_scan_finds_what_a_line_anchored_pattern_does(parts):
    """nurbs.scene._has_statement (``find`` and a check in place) answers as the regular
    expression ``^[ \\t]*KEYWORD[ \\t]`` (multi-line) does, for ``surf`` and ``f``."""
    import re

    from subtrace.nurbs.scene import _has_statement

    raw = b"".join(parts)
    for keyword in (b"surf", b"f"):
        pattern = re.compile(rb"^[ \t]*" + keyword + rb"[ \t]", re.MULTILINE)
        assert _has_statement(raw, keyword) == (pattern.search(raw) is not None), raw

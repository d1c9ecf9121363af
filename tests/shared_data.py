"""Where the tests find their data (the real meshes of ``models/``, the OpenSubdiv shapes and
reference results of ``tests/oracle/``, both in the repository), and small scene builders
shared by the renderer's tests."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import subtrace
from subtrace.io.scene import scene_from_dict

REPO = Path(__file__).resolve().parents[1]
MODELS = REPO / "models"
ORACLE = REPO / "tests" / "oracle"
SHAPES = ORACLE / "shapes"


def load_shape(name):
    """An OpenSubdiv regression shape's cage."""
    return subtrace.load_cage(SHAPES / f"{name}.obj")


def small_scene(meshes, eye, target, width=64, height=48, fov=60.0, tolerance=1.0,
                colors=None):
    """A scene of ``meshes`` seen from ``eye`` towards ``target``, lit by the headlight
    alone on black, without a ground (the geometry's tests need no more)."""
    objects = [{"mesh": str(m)} for m in meshes]
    for o, c in zip(objects, colors or []):
        o["color"] = c
    return scene_from_dict(
        {
            "object": objects,
            "camera": {"eye": list(eye), "target": list(target), "fov": fov, "width": width,
                       "height": height},
            "render": {"tolerance": tolerance, "background": [0.0, 0.0, 0.0],
                       "headlight_intensity": 1.0},
            "light": [],
            "ground": False,
        }
    )


def lathe_cage(path, n=8):
    """A closed lathe cage modelled as hard surfaces are: ``n`` segments around, triangle
    fans at the poles (extraordinary vertices of valence ``n``), three rings of semi-sharp
    creases of sharpness 7.2, 6.9 (fractional) and 8 (the first beside the top pole's
    triangles), and a crease of sharpness 6 down one meridian from the first ring to the
    third, crossing the second (a junction of four sharp edges) and ending on both (where
    sharpness changes along a line). Returns the path."""
    import numpy as np

    profile = [(0.0, 2.0), (0.6, 1.9), (0.8, 1.4), (0.55, 1.0), (0.7, 0.4), (0.75, 0.0)]
    rings = profile[1:]  # (radius, height) of the rings; the poles on the axis
    lines = ["v 0 2.05 0"]
    for r, y in rings:
        for k in range(n):
            a = 2.0 * np.pi * k / n
            lines.append(f"v {r * np.cos(a):.6f} {y:.6f} {r * np.sin(a):.6f}")
    lines.append("v 0 -0.05 0")
    top, bottom = 1, 2 + len(rings) * n

    def at(ring, k):
        return 2 + ring * n + k % n

    for k in range(n):
        lines.append(f"f {top} {at(0, k + 1)} {at(0, k)}")
        for ring in range(len(rings) - 1):
            lines.append(f"f {at(ring, k)} {at(ring, k + 1)} {at(ring + 1, k + 1)} "
                         f"{at(ring + 1, k)}")
        last = len(rings) - 1
        lines.append(f"f {bottom} {at(last, k)} {at(last, k + 1)}")
    for ring, s in ((0, 7.2), (2, 6.9), (3, 8.0)):
        for k in range(n):
            lines.append(f"t crease 2/1/0 {at(ring, k) - 1} {at(ring, k + 1) - 1} {s}")
    for ring in range(3):
        lines.append(f"t crease 2/1/0 {at(ring, 0) - 1} {at(ring + 1, 0) - 1} 6.0")
    path.write_text("\n".join(lines) + "\n")
    return path


# The start of a program for :func:`run_fresh`: from then on the list ``compiled`` receives
# the name (``module.qualname``) of every function Numba compiles (not what it loads)
COMPILE_LISTENER = """
from numba.core import event
compiled = []


class _Compiles(event.Listener):
    def on_start(self, ev):
        func = getattr(ev.data.get("dispatcher"), "py_func", None)
        compiled.append(getattr(func, "__module__", "") + "." + getattr(func, "__qualname__", "?"))

    def on_end(self, ev):
        pass


event.register("numba:compile", _Compiles())
"""


def run_fresh(code, *args, cache):
    """Run the Python program ``code`` with ``args`` in a fresh process whose kernel cache is
    the folder ``cache``; its standard output (the test fails with its errors if it fails)."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(SUBTRACE_CACHE_DIR=str(cache), PYTHONDONTWRITEBYTECODE="1")
    proc = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def error_without_root_powers(code):
    """The standard output of the Python program ``code`` (which prints the error it
    expects) run in a fresh process as this root user without the capabilities that let
    root read and write any file (setpriv, util-linux); the test is skipped where setpriv
    is not installed."""
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("running as root without setpriv (util-linux): root reads and writes "
                    "any file")
    caps = "-dac_override,-dac_read_search"
    proc = subprocess.run([setpriv, f"--inh-caps={caps}", f"--bounding-set={caps}",
                           sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


# the renderer's shared checks (tests of several rooms use them)


def check_watertight(mesh, eye, tolerance, monkeypatch):
    """Renders from ``eye`` inside ``mesh`` (None: a point found inside) both ways at 48x36,
    120 degrees: every pixel covered."""
    import numpy as np

    from subtrace.render import render_scene

    cage = subtrace.load_cage(mesh)
    if eye is None:
        # a point inside: the middle of the limit surface along a ray through the centre
        eye = inside_point(cage)
    scene = small_scene([mesh], eye, np.asarray(eye) + [0.3, 0.1, 1.0], fov=120.0, width=48,
                   height=36, tolerance=tolerance)
    res = render_scene(scene, cages=[cage])
    A = res.channels["A"]
    assert np.count_nonzero(A == 0) == 0
    # and looking the other way
    scene = small_scene([mesh], eye, np.asarray(eye) - [0.3, 0.1, 1.0], fov=120.0, width=48,
                   height=36, tolerance=tolerance)
    assert np.count_nonzero(render_scene(scene, cages=[cage]).channels["A"] == 0) == 0


def first_hit(cage, eye, direction):
    """The first hit of the ray from ``eye`` along ``direction`` (a 1-pixel render)."""
    import numpy as np

    from subtrace.render import render_scene

    eye = np.asarray(eye, dtype=np.float64)
    scene = small_scene([cage.path], eye, eye + direction, width=1, height=1, fov=1.0)
    t = float(render_scene(scene, cages=[cage]).channels["Z"][0, 0])
    assert np.isfinite(t)
    return eye + t * direction / np.linalg.norm(direction)


def inside_point(cage):
    """Midpoint between where a ray from outside enters the limit surface and where it
    leaves it again (found by a second ray starting just past the entry)."""
    import numpy as np

    lo, hi = cage.bounds()
    size = float(np.linalg.norm(hi - lo))
    # aim at a point on the surface: the centre of the bounds may lie in a hole (torus)
    d = np.array([0.0, 0.0, -1.0])
    P, _, _ = cage.limit(1)
    start = P[np.argmax(P[:, 2])] + np.array([0.0, 0.0, 2.0 * size])
    start = start + 1e-3 * size * np.array([1.0, 1.0, 0.0])
    p1 = first_hit(cage, start, d)
    p2 = first_hit(cage, p1 + 1e-6 * size * d, d)
    return tuple(0.5 * (p1 + p2))


def write_plane(path, z, half):
    """A 4x4-quad square in the plane z, normal +z, as an OBJ."""
    import numpy as np

    n = 5
    xs = np.linspace(-half, half, n)
    lines = [f"v {x} {y} {z}" for y in xs for x in xs]
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i + 1
            lines.append(f"f {a} {a + 1} {a + n + 1} {a + n}")
    path.write_text("\n".join(lines) + "\n")


def _sorted_rows(arrays, keys):
    import numpy as np

    order = np.lexsort(tuple(arrays[k] for k in reversed(keys)))
    return [a[order] for a in arrays]


def assert_same_isolation(ref, got, scale, atol=1e-13, normal_atol=1e-9, ring_rtol=None):
    """Two isolations of the same faces, ``(depths, boxes, (subs, cells))`` each (the
    fixed maps' against local topology, ``patches/isolate.py``): the same depths, the same
    pieces at the same places with the same own depths, the boxes of the pieces their
    nets' exactly, and the boxes, nets, cell corners (``atol`` of ``scale``), unit normals
    (``normal_atol``) and cells' one-ring diagonals (``atol`` of ``scale``, or relative
    ``ring_rtol``) to rounding. Returns the numbers of pieces and cells."""
    import numpy as np

    from subtrace.patches.basis import net_bounds

    (d0, b0, (s0, c0)), (d1, b1, (s1, c1)) = ref, got
    np.testing.assert_array_equal(d0, d1)
    for a, b in zip(b0, b1):
        np.testing.assert_allclose(a, b, rtol=0, atol=atol * scale)
    s0, s1 = _sorted_rows(list(s0), (0, 1, 2, 3)), _sorted_rows(list(s1), (0, 1, 2, 3))
    for k in (0, 1, 2, 3, 5):  # the same pieces at the same places, the same own depths
        np.testing.assert_array_equal(s0[k], s1[k])
    for s in (s0, s1):  # the boxes that travel with the pieces: their nets', exactly
        lo, hi, _ = net_bounds(s[4])
        np.testing.assert_array_equal(s[6], lo)
        np.testing.assert_array_equal(s[7], hi)
    np.testing.assert_allclose(s0[4], s1[4], rtol=0, atol=atol * scale)
    c0, c1 = _sorted_rows(list(c0), (0, 1, 2)), _sorted_rows(list(c1), (0, 1, 2))
    for k in (0, 1, 2, 6):
        np.testing.assert_array_equal(c0[k], c1[k])
    np.testing.assert_allclose(c0[3], c1[3], rtol=0, atol=atol * scale)
    np.testing.assert_allclose(c0[4], c1[4], rtol=0, atol=normal_atol)
    if ring_rtol is None:
        np.testing.assert_allclose(c0[5], c1[5], rtol=0, atol=atol * scale)
    else:
        np.testing.assert_allclose(c0[5], c1[5], rtol=ring_rtol)
    return len(s0[0]), len(c0[0])

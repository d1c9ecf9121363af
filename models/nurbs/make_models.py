"""Write the trimmed NURBS sample models of this folder (subtrace's own work, MIT like the
rest of subtrace):

    python models/nurbs/make_models.py          # rewrites the five .obj files here

* ``plate_holes.obj``: a gently curved bicubic B-spline plate (6 x 6 control points, two
  inner knots each way: 9 Bezier patches) trimmed by a rounded rectangle (one rational
  quadratic B-spline ``curv2``: straight sides and quarter-circle corners), with a
  circular hole made of two half-circle curves and a teardrop hole (one closed cubic
  Bezier ``curv2``).
* ``cylinder_window.obj``: a whole rational quadratic cylinder (radius 1, height 2: a
  9-point circle, 2 rows) with a rounded window cut out of it (a hole loop in parameter
  space, one rational quadratic B-spline).
* ``torus_patches.obj``: a closed torus (radii 1 and 0.35) as 16 rational biquadratic
  Bezier surfaces (``cstype rat bezier``), sharing their control vertices along common
  edges: the Bezier extraction of the 9 x 9 tensor product of two rational circles.

* ``sphere.obj``: the unit sphere as one rational biquadratic NURBS surface (a 9-point
  circle swept along a 5-point half circle: 8 Bezier patches), with its poles where a side of
  the patches shrinks to a point (the normal there is the limit normal).
* ``blob_bezier.obj``: a closed wobbly torus as 96 bicubic Bezier surfaces (``cstype
  bezier``, deg 3 3), the Bezier extraction of a uniform cubic B-spline periodic in both
  directions; neighbouring surfaces share their boundary control vertices.

Every rational control point is written as ``v x y z w`` (Euclidean x y z, weight w), trim
curve points as ``vp u v w``. ``subtrace info <file>`` reports them and ``subtrace render``
draws them (scenes/nurbs_*.toml).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1] / "src"))  # the checkout's subtrace

W45 = math.sqrt(0.5)  # weight of a quarter circle's middle control point


def fmt(x: float) -> str:
    return repr(float(x))


def rounded_rect(u0, u1, v0, v1, r):
    """Control points (u, v, w) of a closed rational quadratic B-spline: a rounded
    rectangle, counter-clockwise from the middle of the bottom side; and its knots."""
    corners = [(u1, v0, 1), (u1, v1, 1), (u0, v1, 1), (u0, v0, 1)]
    pts = [((u0 + u1) / 2, v0, 1.0)]
    for (cu, cv, _), (du_in, dv_in), (du_out, dv_out) in zip(
            corners, [(1, 0), (0, 1), (-1, 0), (0, -1)], [(0, 1), (-1, 0), (0, -1), (1, 0)]):
        a = (cu - r * du_in, cv - r * dv_in)  # end of the straight side
        b = (cu + r * du_out, cv + r * dv_out)  # start of the next side
        pts += [((pts[-1][0] + a[0]) / 2, (pts[-1][1] + a[1]) / 2, 1.0), (*a, 1.0),
                (cu, cv, W45), (*b, 1.0)]
    pts += [((pts[-1][0] + pts[0][0]) / 2, (pts[-1][1] + pts[0][1]) / 2, 1.0), pts[0]]
    spans = (len(pts) - 1) // 2
    knots = [0, 0, 0] + [k for k in range(1, spans) for _ in (0, 1)] + [spans] * 3
    return pts, knots


def half_circle(cu, cv, r, start_angle):
    """5 control points (u, v, w) of a rational quadratic half circle, counter-clockwise."""
    pts = []
    for k in range(5):
        a = start_angle + k * math.pi / 4
        d = 1.0 if k % 2 == 0 else 1.0 / W45
        pts.append((cu + r * d * math.cos(a), cv + r * d * math.sin(a), 1.0 if k % 2 == 0
                    else W45))
    return pts


class Obj:
    """Accumulates OBJ lines with 1-based v / vp counters."""

    def __init__(self, title):
        self.lines = [f"# {title}", "# written by models/nurbs/make_models.py (subtrace)"]
        self.nv = self.nvp = self.ncurv = 0

    def v(self, x, y, z, w=None):
        self.lines.append(f"v {fmt(x)} {fmt(y)} {fmt(z)}" + ("" if w is None else f" {fmt(w)}"))
        self.nv += 1
        return self.nv

    def curv2(self, cstype, degree, pts, parm):
        first = self.nvp + 1
        for u, v, w in pts:
            self.lines.append(f"vp {fmt(u)} {fmt(v)} {fmt(w)}")
            self.nvp += 1
        self.lines += [f"cstype {cstype}", f"deg {degree}",
                       "curv2 " + " ".join(str(first + k) for k in range(len(pts))),
                       "parm u " + " ".join(fmt(k) for k in parm), "end"]
        self.ncurv += 1
        return self.ncurv

    def write(self, name):
        (HERE / name).write_text("\n".join(self.lines) + "\n")
        print(f"wrote {HERE / name} ({len(self.lines)} lines)")


def plate():
    obj = Obj("plate_holes: a bicubic B-spline plate, rounded outline, two holes")
    n = 6
    ids = []
    for j in range(n):  # rows along v, u fastest
        for i in range(n):
            x, y = i / (n - 1), j / (n - 1)
            ids.append(obj.v(2 * x - 1, 2 * y - 1, 0.3 * (x - 0.5) * (y - 0.5) * 4
                             + 0.1 * math.sin(3 * x)))
    outline, knots = rounded_rect(0.04, 0.96, 0.04, 0.96, 0.15)
    c_out = obj.curv2("rat bspline", 2, outline, knots)
    h1 = obj.curv2("rat bspline", 2, half_circle(0.42, 0.42, 0.16, 0.0), [0, 0, 0, 1, 1, 2, 2, 2])
    h2 = obj.curv2("rat bspline", 2, half_circle(0.42, 0.42, 0.16, math.pi),
                   [0, 0, 0, 1, 1, 2, 2, 2])
    tear = [(0.72, 0.70, 1), (0.90, 0.72, 1), (0.74, 0.88, 1), (0.72, 0.70, 1)]
    h3 = obj.curv2("bezier", 3, tear, [0, 1])
    obj.lines += ["cstype bspline", "deg 3 3",
                  "surf 0 1 0 1 " + " ".join(map(str, ids)),
                  "parm u 0 0 0 0 0.333 0.667 1 1 1 1",
                  "parm v 0 0 0 0 0.333 0.667 1 1 1 1",
                  f"trim 0 {knots[-1]} {c_out}",
                  f"hole 0 2 {h1} 0 2 {h2}",
                  f"hole 0 1 {h3}", "end"]
    obj.write("plate_holes.obj")


def cylinder():
    obj = Obj("cylinder_window: a rational quadratic cylinder with a rounded window")
    circle = [(1, 0, 1), (1, 1, W45), (0, 1, 1), (-1, 1, W45), (-1, 0, 1), (-1, -1, W45),
              (0, -1, 1), (1, -1, W45), (1, 0, 1)]
    ids = [obj.v(x, y, z, w) for z in (0.0, 2.0) for x, y, w in circle]
    window, knots = rounded_rect(0.4, 1.6, 0.25, 0.75, 0.12)
    c = obj.curv2("rat bspline", 2, window, knots)
    obj.lines += ["cstype rat bspline", "deg 2 1",
                  "surf 0 4 0 1 " + " ".join(map(str, ids)),
                  "parm u 0 0 0 1 1 2 2 3 3 4 4 4", "parm v 0 0 1 1",
                  f"hole 0 {knots[-1]} {c}", "end"]
    obj.write("cylinder_window.obj")


def torus():
    from subtrace.nurbs.surface import bezier_patches, make_surface

    obj = Obj("torus_patches: a closed torus as 16 rational biquadratic Bezier patches")
    circle = [(1, 0, 1), (1, 1, W45), (0, 1, 1), (-1, 1, W45), (-1, 0, 1), (-1, -1, W45),
              (0, -1, 1), (1, -1, W45), (1, 0, 1)]
    big, small = 1.0, 0.35
    points, weights = [], []
    for (a, b, wa) in circle:  # v: around the tube
        for (x, y, wb) in circle:  # u: around the axis
            r = big + small * a
            points.append((r * x, r * y, small * b))
            weights.append(wa * wb)
    knots = [0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 4]
    surface = make_surface((2, 2), knots, knots, points, weights)
    nets, _ = bezier_patches(surface)
    index = {}
    obj.lines.append("cstype rat bezier")
    obj.lines.append("deg 2 2")
    body = []
    for net in nets:
        refs = []
        for j in range(3):  # u fastest within each row of v
            for i in range(3):
                h = net[i, j]
                key = tuple(np.round(h, 12))
                if key not in index:
                    index[key] = obj.v(*(h[:3] / h[3]), h[3])
                refs.append(index[key])
        body += ["surf 0 1 0 1 " + " ".join(map(str, refs)), "parm u 0 1", "parm v 0 1",
                 "end"]
    obj.lines += body
    obj.write("torus_patches.obj")


def sphere():
    obj = Obj("sphere: the unit sphere as one rational biquadratic NURBS surface "
              "(poles at z = +-1)")
    circle = [(1, 0, 1), (1, 1, W45), (0, 1, 1), (-1, 1, W45), (-1, 0, 1), (-1, -1, W45),
              (0, -1, 1), (1, -1, W45), (1, 0, 1)]
    meridian = [(0, -1, 1), (1, -1, W45), (1, 0, 1), (1, 1, W45), (0, 1, 1)]  # (r, z, w)
    ids = [obj.v(r * x, r * y, z, wa * wb) for (r, z, wa) in meridian for (x, y, wb) in circle]
    obj.lines += ["cstype rat bspline", "deg 2 2",
                  "surf 0 4 0 2 " + " ".join(map(str, ids)),
                  "parm u 0 0 0 1 1 2 2 3 3 4 4 4", "parm v 0 0 0 1 1 2 2 2", "end"]
    obj.write("sphere.obj")


def blob_point(i, j, nu, nv):
    """Control point (i, j) of the closed cubic B-spline blob: a torus whose tube radius and
    centre circle wobble."""
    a = 2 * math.pi * i / nu  # around the axis
    b = 2 * math.pi * j / nv  # around the tube
    big = 1.0 + 0.18 * math.sin(3 * a)
    small = 0.42 + 0.12 * math.cos(2 * a) * math.cos(b)
    r = big + small * math.cos(b)
    return r * math.cos(a), r * math.sin(a), small * math.sin(b) + 0.1 * math.sin(2 * a)


def blob():
    from subtrace.nurbs.surface import bezier_patches, make_surface

    obj = Obj("blob_bezier: a closed wobbly torus as 96 bicubic Bezier patches")
    nu, nv = 12, 8
    # a uniform cubic B-spline periodic in both directions: 3 control rows and columns wrap
    points = [blob_point(i % nu, j % nv, nu, nv) for j in range(nv + 3) for i in range(nu + 3)]
    knots_u = list(range(nu + 3 + 4))
    knots_v = list(range(nv + 3 + 4))
    surface = make_surface((3, 3), knots_u, knots_v, points)
    nets, _ = bezier_patches(surface)
    index = {}
    obj.lines += ["cstype bezier", "deg 3 3"]
    for net in nets:
        refs = []
        for j in range(4):  # u fastest within each row of v
            for i in range(4):
                key = tuple(np.round(net[i, j, :3], 12))
                if key not in index:
                    index[key] = obj.v(*net[i, j, :3])
                refs.append(index[key])
        obj.lines += ["surf 0 1 0 1 " + " ".join(map(str, refs)), "parm u 0 1", "parm v 0 1",
                      "end"]
    obj.write("blob_bezier.obj")


if __name__ == "__main__":
    plate()
    cylinder()
    torus()
    sphere()
    blob()

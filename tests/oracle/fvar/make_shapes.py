"""Writes the small face-varying test shapes of ``shapes/`` (run once; the OBJ files are
committed). A 6 x 5 grid of quads whose UVs fall into three islands (A: columns 0-2, B:
columns 3-5 below row 2, C: above it), so that vertices have one, two or three UV values:

* the junction of the three islands (3 values), the seams between them (2 values), a slit
  inside island A (column edge x = 1 from y = 3 to the boundary: a dart at (1, 3));
* semi-sharp creases on a seam edge and inside one island only at a seam vertex (OpenSubdiv's
  dependent sharpening in the corners-plus modes), an infinitely sharp crease inside an
  island at a seam vertex, a semi-sharp crease elsewhere, semi-sharp corners on a seam and on
  a boundary corner, a hole;
* Catmull-Clark: a quad split into two triangles and two quads merged into a hexagon;
  ``catmark_fvar_chaikin`` is the same cage with Chaikin's crease rule; ``loop_fvar_seams``
  the grid's quads cut into triangles.
"""

from __future__ import annotations

import math
from pathlib import Path

HERE = Path(__file__).resolve().parent / "shapes"
NI, NJ = 7, 6  # vertices along x and y


def vid(i, j):
    return j * NI + i


def island(i, j):
    """The UV island of quad (i, j)."""
    if i < 3:
        return "A"
    return "B" if j < 2 else "C"


def uv_of(isl, i, j, left=False):
    u = 0.05 + 0.11 * i + 0.015 * math.sin(1.7 * j)
    v = 0.05 + 0.13 * j + 0.012 * math.cos(2.3 * i)
    du, dv = {"A": (0.0, 0.0), "B": (0.45, -0.02), "C": (0.5, 0.08)}[isl]
    if left:
        du -= 0.04
    return (u + du, v + dv)


def build(triangles: bool):
    points = [(float(i), float(j), 0.35 * math.sin(0.9 * i) * math.cos(0.8 * j))
              for j in range(NJ) for i in range(NI)]
    uvs, uv_index = [], {}

    def uv(isl, i, j, left=False):
        key = (isl, i, j, left)
        if key not in uv_index:
            uv_index[key] = len(uvs)
            uvs.append(uv_of(isl, i, j, left))
        return uv_index[key]

    faces = []
    for j in range(NJ - 1):
        for i in range(NI - 1):
            isl = island(i, j)
            ring = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]
            # the slit of island A: faces left of x = 1 above y = 3 take their own values
            # at its vertices (1, 4) and (1, 5); (1, 3) keeps one value (a dart)
            corners = [(vid(a, b), uv(isl, a, b, left=(i == 0 and a == 1 and b >= 4)))
                       for a, b in ring]
            faces.append(((i, j), corners))
    out = []
    for (i, j), corners in faces:
        if triangles:
            out += [[corners[0], corners[1], corners[2]], [corners[0], corners[2], corners[3]]]
        elif (i, j) == (1, 1):
            out += [[corners[0], corners[1], corners[2]], [corners[0], corners[2], corners[3]]]
        elif (i, j) == (3, 3):
            nxt = next(c for (a, b), c in faces if (a, b) == (4, 3))
            # quads (3, 3) and (4, 3) as one hexagon
            out.append([corners[0], nxt[0], nxt[1], nxt[2], nxt[3], corners[3]])
        elif (i, j) == (4, 3):
            continue
        else:
            out.append(corners)
    tags = [
        # a semi-sharp seam edge, and one inside island A at the seam vertex (3, 4)
        (vid(3, 3), vid(3, 4), 2.5),
        (vid(2, 4), vid(3, 4), 1.7),
        # infinitely sharp inside island C at the seam vertex (4, 2)
        (vid(4, 2), vid(4, 3), 10.0),
        # semi-sharp inside island B, ending on the B / C seam
        (vid(5, 1), vid(5, 2), 3.0),
        # along the seam between A and B
        (vid(3, 0), vid(3, 1), 1.5),
    ]
    lines = [f"# {'loop' if triangles else 'catmark'} face-varying test shape "
             "(tests/oracle/fvar/make_shapes.py)"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in points]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in uvs]
    lines += ["f " + " ".join(f"{v + 1}/{t + 1}" for v, t in face) for face in out]
    lines += [f"t crease 2/1/0 {a} {b} {s}" for a, b, s in tags]
    lines.append(f"t corner 1/1/0 {vid(3, 1)} 1.3")
    lines.append(f"t corner 1/1/0 {vid(6, 0)} 2.0")
    hole = next(k for k, face in enumerate(out) if face[0][0] == vid(5, 4))
    lines.append(f"t hole 1/0/0 {hole}")
    return "\n".join(lines) + "\n"


def main():
    HERE.mkdir(exist_ok=True)
    quads = build(triangles=False)
    (HERE / "catmark_fvar_seams.obj").write_text(quads)
    (HERE / "catmark_fvar_chaikin.obj").write_text(
        quads + "t creasemethod 0/0/1 chaikin\n")
    (HERE / "loop_fvar_seams.obj").write_text(build(triangles=True))


if __name__ == "__main__":
    main()

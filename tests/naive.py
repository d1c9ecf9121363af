"""Slow reference implementations (oracles) of subtrace's fast paths, for the tests.

Topology: the numpy / plain-Python relations of ``subtrace.subdiv.topology`` as they were
before the jitted kernels (``base_edges`` with lexsort + unique, CSR lists by stable sorts,
vertex rings ordered by a plain loop).

NURBS: de Boor evaluation of (rational) B-spline curves and surfaces with their derivatives
(Cox-de Boor basis functions), and the trim test's parity by polynomial roots over whole
Bezier segments (no monotone units, no tree).
"""

from __future__ import annotations

import math

import numpy as np


def base_edges(face_offsets, face_verts, n_verts):
    """(edge_verts (E,2) i4, face_edges (C,) i4, forward (C,) bool); see topology.base_edges."""
    sizes = np.diff(face_offsets)
    face_of = np.repeat(np.arange(len(sizes)), sizes)
    k = np.arange(face_offsets[-1]) - face_offsets[face_of]
    a = np.asarray(face_verts, dtype=np.int64)
    b = a[face_offsets[face_of] + (k + 1) % sizes[face_of]]
    keys = np.minimum(a, b) * n_verts + np.maximum(a, b)
    # a degenerate edge is never shared; a face using a pair again gets a new edge for it
    unique_use = a == b
    order = np.lexsort((np.arange(len(keys)), face_of, keys))
    same = (keys[order][1:] == keys[order][:-1]) & (face_of[order][1:] == face_of[order][:-1])
    unique_use[order[1:][same]] = True
    keys[unique_use] = n_verts * n_verts + np.nonzero(unique_use)[0]
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    face_edges = rank[inverse.ravel()].astype(np.int32)
    edge_verts = np.stack([a[first[order]], b[first[order]]], axis=1).astype(np.int32)
    forward = (edge_verts[face_edges, 0] == a) & (edge_verts[face_edges, 1] == b)
    return edge_verts, face_edges, forward


def _csr(keys, n):
    order = np.argsort(keys, kind="stable")
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(keys, minlength=n), out=offsets[1:])
    return offsets, order


def relations(n_verts, face_offsets, face_verts, edge_verts, face_edges, forward,
              edge_nonmanifold=None):
    """Dict of the Level relations build_level computes, vertex rings ordered."""
    sizes = np.diff(face_offsets)
    face_of = np.repeat(np.arange(len(sizes), dtype=np.int32), sizes)
    k = (np.arange(face_offsets[-1]) - face_offsets[face_of]).astype(np.int32)
    out = {}
    out["edge_face_offsets"], order = _csr(face_edges, len(edge_verts))
    out["edge_faces"], out["edge_face_corner"] = face_of[order], k[order]
    out["vert_face_offsets"], order = _csr(face_verts, n_verts)
    vert_faces, vert_face_corner = face_of[order], k[order]
    out["vert_edge_offsets"], order = _csr(edge_verts.ravel(), n_verts)
    vert_edges = (order // 2).astype(np.int32)
    eo = out["edge_face_offsets"]
    if edge_nonmanifold is None:
        n_uses = np.diff(eo)
        edge_nonmanifold = (n_uses > 2) | (n_uses < 1) | (edge_verts[:, 0] == edge_verts[:, 1])
        for e in np.nonzero(n_uses == 2)[0]:
            u0 = eo[e]
            f0, f1 = out["edge_faces"][u0], out["edge_faces"][u0 + 1]
            c0 = face_offsets[f0] + out["edge_face_corner"][u0]
            c1 = face_offsets[f1] + out["edge_face_corner"][u0 + 1]
            if forward[c0] == forward[c1] or f0 == f1:
                edge_nonmanifold[e] = True
    vfo, veo = out["vert_face_offsets"], out["vert_edge_offsets"]
    manifold = np.zeros(n_verts, dtype=bool)
    for v in range(n_verts):
        faces = list(zip(vert_faces[vfo[v]:vfo[v + 1]], vert_face_corner[vfo[v]:vfo[v + 1]]))
        edges = vert_edges[veo[v]:veo[v + 1]]
        nf, ne = len(faces), len(edges)
        if nf == 0 or edge_nonmanifold[edges].any() or ne not in (nf, nf + 1):
            continue
        lead = [face_edges[face_offsets[f] + c] for f, c in faces]
        trail = [face_edges[face_offsets[f] + (c - 1) % sizes[f]] for f, c in faces]
        starts = [j for j in range(nf) if eo[lead[j] + 1] - eo[lead[j]] == 1]
        boundary = ne == nf + 1
        if len(starts) != (1 if boundary else 0):
            continue
        ring = [starts[-1] if starts else 0]
        for _ in range(nf - 1):
            nxt = [j for j in range(nf) if j not in ring and lead[j] == trail[ring[-1]]]
            if not nxt:
                break
            ring.append(nxt[0])
        if len(ring) < nf or (not boundary and trail[ring[-1]] != lead[ring[0]]):
            continue
        manifold[v] = True
        vert_faces[vfo[v]:vfo[v + 1]] = [faces[j][0] for j in ring]
        vert_face_corner[vfo[v]:vfo[v + 1]] = [faces[j][1] for j in ring]
        vert_edges[veo[v]:veo[v] + nf] = [lead[j] for j in ring]
        if boundary:
            vert_edges[veo[v] + nf] = trail[ring[-1]]
    out.update(vert_faces=vert_faces, vert_face_corner=vert_face_corner, vert_edges=vert_edges,
               vert_manifold=manifold, edge_nonmanifold=edge_nonmanifold)
    return out


def ray_triangles(origin, direction, A, B, C):
    """Moller-Trumbore in float64, lines against triangles: ``(t, u, v)``, each (m,), with
    the line ``origin + t * direction`` (origin, direction (3,), or (m,3): one line per
    triangle) meeting the plane of triangle ``(A[i], B[i], C[i])`` (each (m,3)) at
    barycentrics ``(1 - u - v, u, v)``;
    NaN or inf where the line is parallel to the plane. The line hits the triangle where
    ``u >= 0, v >= 0, u + v <= 1`` (:func:`ray_triangle_hits`)."""
    A, B, C = (np.asarray(X, dtype=np.float64) for X in (A, B, C))
    o = np.asarray(origin, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    e1, e2 = B - A, C - A
    pv = np.cross(d, e2)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / (e1 * pv).sum(axis=1)
        tv = o - A
        u = (tv * pv).sum(axis=1) * inv
        qv = np.cross(tv, e1)
        v = (d * qv).sum(axis=1) * inv
        t = (e2 * qv).sum(axis=1) * inv
    return t, u, v


def ray_triangle_hits(origin, direction, A, B, C, slack=0.0):
    """``(t, index)`` of the triangles the line hits (barycentrics down to ``-slack``
    allowed: a line through a shared edge hits both), sorted by ``t``."""
    t, u, v = ray_triangles(origin, direction, A, B, C)
    with np.errstate(invalid="ignore"):
        hit = (u >= -slack) & (v >= -slack) & (u + v <= 1 + slack) & np.isfinite(t)
    idx = np.nonzero(hit)[0]
    order = np.argsort(t[idx], kind="stable")
    return t[idx][order], idx[order]


# --------------------------------------------------------------------------------------
# NURBS: plain-Python de Boor evaluation and trim parity (oracles of subtrace.nurbs)
# --------------------------------------------------------------------------------------


def bspline_span(knots, degree, n_ctrl, t):
    """The span k with knots[k] <= t < knots[k+1] (the last non-empty one at the end)."""
    k = degree
    while k < n_ctrl - 1 and not (knots[k] <= t < knots[k + 1]):
        k += 1
    return k


def bspline_basis(knots, degree, n_ctrl, t):
    """(N, dN): the n_ctrl basis functions of degree ``degree`` at t and their derivatives,
    by the Cox-de Boor recursion over the span holding t (plain Python lists)."""
    k = bspline_span(knots, degree, n_ctrl, t)
    # degree 0: 1 on the span
    N = [[0.0] * (len(knots) - 1)]
    N[0][k] = 1.0
    for p in range(1, degree + 1):
        row = [0.0] * (len(knots) - 1 - p)
        for i in range(len(row)):
            a = knots[i + p] - knots[i]
            b = knots[i + p + 1] - knots[i + 1]
            left = (t - knots[i]) / a * N[p - 1][i] if a > 0 else 0.0
            right = (knots[i + p + 1] - t) / b * N[p - 1][i + 1] if b > 0 else 0.0
            row[i] = left + right
        N.append(row)
    values = N[degree][:n_ctrl]
    if degree == 0:
        return values, [0.0] * n_ctrl
    lower = N[degree - 1]
    deriv = []
    for i in range(n_ctrl):
        a = knots[i + degree] - knots[i]
        b = knots[i + degree + 1] - knots[i + 1]
        d = (degree / a * lower[i] if a > 0 else 0.0)
        d -= (degree / b * lower[i + 1] if b > 0 else 0.0)
        deriv.append(d)
    return values, deriv


def deboor_curve(knots, degree, ctrl, t):
    """Homogeneous point (list) of the B-spline curve (knots, ctrl (n, k)) at t: de Boor's
    algorithm, plain Python."""
    ctrl = [list(map(float, row)) for row in ctrl]
    n = len(ctrl)
    k = bspline_span(knots, degree, n, t)
    d = [ctrl[j + k - degree][:] for j in range(degree + 1)]
    for r in range(1, degree + 1):
        for j in range(degree, r - 1, -1):
            i = j + k - degree
            a = (t - knots[i]) / (knots[i + degree + 1 - r] - knots[i])
            d[j] = [(1.0 - a) * x + a * y for x, y in zip(d[j - 1], d[j])]
    return d[degree]


def nurbs_surface_eval(knots_u, knots_v, du, dv, control, u, v):
    """(P, P_u, P_v) of the rational surface ``control (nv, nu, 4)`` homogeneous (row j
    along v) at (u, v): basis functions by Cox-de Boor, then the quotient rule (lists)."""
    nv, nu = len(control), len(control[0])
    Nu, dNu = bspline_basis(list(knots_u), du, nu, u)
    Nv, dNv = bspline_basis(list(knots_v), dv, nv, v)
    H, Hu, Hv = [0.0] * 4, [0.0] * 4, [0.0] * 4
    for j in range(nv):
        for i in range(nu):
            for c in range(4):
                x = float(control[j][i][c])
                H[c] += Nu[i] * Nv[j] * x
                Hu[c] += dNu[i] * Nv[j] * x
                Hv[c] += Nu[i] * dNv[j] * x
    P = [H[c] / H[3] for c in range(3)]
    Pu = [(Hu[c] - P[c] * Hu[3]) / H[3] for c in range(3)]
    Pv = [(Hv[c] - P[c] * Hv[3]) / H[3] for c in range(3)]
    return P, Pu, Pv


def bezier_curve_point(ctrl, t):
    """Projected point (u, v) of the rational Bezier curve ``ctrl (d+1, 3)`` at t."""
    pts = [list(map(float, row)) for row in ctrl]
    while len(pts) > 1:
        pts = [[(1.0 - t) * a + t * b for a, b in zip(p, q)] for p, q in zip(pts, pts[1:])]
    return pts[0][0] / pts[0][2], pts[0][1] / pts[0][2]


def trim_parity(segments, px, py):
    """Inside (odd crossings) of the point (px, py) for closed loops given as rational
    Bezier segments ``(d+1, 3)`` homogeneous, NOT split into monotone units: every real
    root t in [0, 1) of v(t) = py (the polynomial Y(t) - py W(t) in the power basis) whose
    u(t) > px is a crossing. For points in general position (random ones): a crossing at a
    segment's end, a tangency or a horizontal segment at height py has probability 0."""
    crossings = 0
    for seg in segments:
        seg = np.asarray(seg, dtype=np.float64)
        d = len(seg) - 1
        coef = np.zeros(d + 1)
        for i in range(d + 1):
            # C(d,i) t^i (1-t)^(d-i) in powers of t
            for k in range(d - i + 1):
                coef[i + k] += (math.comb(d, i) * math.comb(d - i, k) * (-1) ** k
                                * (seg[i, 1] - py * seg[i, 2]))
        poly = np.trim_zeros(coef, "b")
        if len(poly) < 2:
            continue
        for r in np.polynomial.polynomial.polyroots(poly):
            if abs(r.imag) < 1e-9 and 0.0 <= r.real < 1.0:
                x, _ = bezier_curve_point(seg, r.real)
                if x > px:
                    crossings += 1
    return crossings % 2 == 1


def loop_polygon(segments, samples=64):
    """(k, 2) points of a closed loop of rational Bezier segments ``(d+1, 3)``, each segment
    sampled at ``samples`` equal parameter steps (plain de Casteljau)."""
    pts = []
    for seg in segments:
        for k in range(samples):
            pts.append(bezier_curve_point(seg, k / samples))
    return np.array(pts)


def polygon_parity(polygons, points):
    """(n,) bool: even-odd rule of ``points (n, 2)`` against the closed ``polygons`` (each
    (k, 2)): the brute-force crossing count of a ray towards +u with every polygon edge,
    in numpy."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    inside = np.zeros(len(points), dtype=bool)
    px, py = points[:, :1], points[:, 1:]
    for poly in polygons:
        a = np.asarray(poly, dtype=np.float64)
        b = np.roll(a, -1, axis=0)
        ax, ay, bx, by = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
        for lo in range(0, len(points), 2048):
            qx, qy = px[lo:lo + 2048], py[lo:lo + 2048]
            spans = (ay <= qy) != (by <= qy)
            with np.errstate(divide="ignore", invalid="ignore"):
                x = ax + (qy - ay) * (bx - ax) / (by - ay)
            inside[lo:lo + 2048] ^= (np.count_nonzero(spans & (x > qx), axis=1) % 2) == 1
    return inside


def nurbs_grid(surface, n):
    """(points (n+1, n+1, 3), uv (n+1, n+1, 2)): the surface (a subtrace NurbsSurface) at a
    uniform (n+1) x (n+1) grid of its parameter rectangle: the Cox-de Boor basis functions
    of each grid u and v (:func:`bspline_basis`), their tensor product with the homogeneous
    control points, then the division by the weight."""
    u0, u1, v0, v1 = surface.domain
    du, dv = surface.degree
    nv, nu, _ = surface.control.shape
    ku, kv = surface.knots_u.tolist(), surface.knots_v.tolist()
    us = [u0 + (u1 - u0) * a / n for a in range(n + 1)]
    vs = [v0 + (v1 - v0) * b / n for b in range(n + 1)]
    Nu = np.array([bspline_basis(ku, du, nu, u)[0] for u in us])  # (n+1, nu)
    Nv = np.array([bspline_basis(kv, dv, nv, v)[0] for v in vs])  # (n+1, nv)
    H = np.einsum("ai,bj,jic->abc", Nu, Nv, surface.control)
    uv = np.stack(np.meshgrid(us, vs, indexing="ij"), axis=-1)
    return H[..., :3] / H[..., 3:], uv


def boundary_recipe(level, f, sharp_edge):
    """Plain-Python oracle of ``patches.boxspline._boundary_recipes`` for one triangle: the 12
    box-spline points of triangle ``f`` with corners on a boundary or an infinitely sharp
    crease, or None.

    The rules are in that function's docstring; here dictionaries of lattice points stand
    for the kernel's fixed table. Returns ``(a, b, r)`` (12,) int64 each, the point ``a``
    (b = r = -1) or the phantom ``a + b - r``; None where some point cannot be so made."""
    from subtrace.patches.basis import BOX_POINTS, LATTICE_DIRS, TRI_CORNER, TRI_LEAD

    fo, fv = level.face_offsets, level.face_verts
    ve, veo = level.vert_edges, level.vert_edge_offsets
    vf, vfo = level.vert_faces, level.vert_face_offsets
    ev = level.edge_verts
    at = {}
    for k in range(3):
        c = int(fv[fo[f] + k])
        ring = ve[veo[c]:veo[c + 1]]
        n = len(ring)
        slot = int(np.nonzero(vf[vfo[c]:vfo[c + 1]] == f)[0][0])
        cut = np.nonzero(sharp_edge[ring])[0]
        if len(cut) == 0 and n == 6:
            fan = np.roll(ring, -slot)  # a smooth regular corner: the whole ring
            lead = 0
        elif len(cut) == 2 and (n == 4 and list(cut) == [0, 3] or n == 6 and cut[1] - cut[0] == 3):
            # the triangle's side: edges from the sharp one before the face to the next
            s0 = cut[0] if cut[0] <= slot < cut[1] else cut[1]
            fan = np.roll(ring, -s0)[:4]
            lead = (slot - s0) % n
        else:
            return None
        at[tuple(TRI_CORNER[k])] = c
        for t in range(6):
            m = lead + t if lead + t < len(fan) else lead + t - 6
            if len(fan) == 4 and not 0 <= m < 4:
                continue  # beyond the crease
            e = fan[m % 6]
            far = int(ev[e, 1] if ev[e, 0] == c else ev[e, 0])
            q = tuple(TRI_CORNER[k] + LATTICE_DIRS[(TRI_LEAD[k] + t) % 6])
            if at.setdefault(q, far) != far:
                return None  # the ring does not lie on one lattice (not regular)
    out = np.full((3, len(BOX_POINTS)), -1, dtype=np.int64)
    for i, q in enumerate(BOX_POINTS.tolist()):
        if tuple(q) in at:
            out[0, i] = at[tuple(q)]
            continue
        for d in range(6):
            a = tuple(np.add(q, LATTICE_DIRS[d]))
            b = tuple(np.add(q, LATTICE_DIRS[(d + 1) % 6]))
            r = tuple(np.add(a, LATTICE_DIRS[(d + 1) % 6]))
            if a in at and b in at and r in at and _edge_flag(level, at[a], at[b], sharp_edge):
                out[:, i] = at[a], at[b], at[r]
                break
        else:
            return None
    return out[0], out[1], out[2]


def _edge_is(level, a, b, flag):
    """``flag`` of the edge joining vertices a and b (False if there is none)."""
    for e in level.vert_edges[level.vert_edge_offsets[a]:level.vert_edge_offsets[a + 1]]:
        if b in level.edge_verts[e]:
            return bool(flag[e])
    return False


def _edge_flag(level, a, b, flag):
    """``flag`` of the edge joining vertices a and b (False if there is none)."""
    for e in level.vert_edges[level.vert_edge_offsets[a]:level.vert_edge_offsets[a + 1]]:
        if b in level.edge_verts[e]:
            return bool(flag[e])
    return False


# --------------------------------------------------------------------------------------
# shading: the shadow rays of hit pixels and the anti-aliasing's edge marks, in numpy
# --------------------------------------------------------------------------------------


def shadow_rays(frame, width, t, normals, pix_patch, lights, tol_rad, point_rounding,
                dirs=None):
    """[(pixels, origins, directions, tmax)] per light (rows of ``lights.light_array``): the
    shadow rays of the hit pixels whose normal faces the light, in pixel order, as numpy
    made them before ``shade.shadow_visibility`` had kernels: the hit point from the pixel's
    unit ray (divided by its length), displaced along the normal by ``t * tol_rad`` and
    the point's rounding."""
    pix = np.nonzero(pix_patch >= 0)[0]
    th = t[pix]
    if dirs is None:
        row, col = np.divmod(pix.astype(np.int64), width)
        if len(frame) > 4:
            col, row = col + int(frame[4, 0]), row + int(frame[4, 1])
        d = frame[3] + col[:, None] * frame[1] + row[:, None] * frame[2]
        d = d / np.sqrt((d * d).sum(axis=1))[:, None]
    else:
        d = dirs[pix]
    points = frame[0] + th[:, None] * d
    f = normals[pix]
    err = th * tol_rad + point_rounding * np.abs(points).max(axis=1)
    out = []
    for light in lights:
        if light[0] == 0:  # directional: x, y, z the direction it travels
            to = np.repeat(-light[None, 1:4], len(pix), axis=0)
            dist = np.full(len(pix), np.inf)
        else:
            v = light[1:4] - points
            dist = np.sqrt((v * v).sum(axis=1))
            with np.errstate(divide="ignore", invalid="ignore"):
                to = v / dist[:, None]
        facing = (f * to).sum(axis=1) > 0.0
        out.append((pix[facing], points[facing] + err[facing, None] * f[facing], to[facing],
                    dist[facing] - err[facing]))
    return out


def edge_marks(planes, width, height, depth_step, cos_jump, contrast, channels):
    """(height, width) bool: ``shade.edge_pixels`` in numpy (``channels``: its indices
    ``(C_R, C_A, C_Z, C_N, C_OBJECT)``)."""
    c_r, c_a, c_z, c_n, c_obj = channels
    p = planes.astype(np.float64).reshape(len(planes), height, width)
    y = 0.2126 * p[c_r] + 0.7152 * p[c_r + 1] + 0.0722 * p[c_r + 2]
    with np.errstate(invalid="ignore"):
        lum = np.where(y <= 0.0031308, np.maximum(12.92 * y, 0.0),
                       np.minimum(1.055 * np.abs(y) ** (1.0 / 2.4) - 0.055, 1.0))
    hit = p[c_a] > 0.0

    def differ(a, b):  # index tuples of the two pixels of each pair (inf - inf: NaN, no step)
        with np.errstate(invalid="ignore"):
            depth = np.abs(p[c_z][a] - p[c_z][b]) > depth_step * np.minimum(p[c_z][a],
                                                                              p[c_z][b])
        dot = sum(p[c_n + k][a] * p[c_n + k][b] for k in range(3))
        both = hit[a] & hit[b] & ((p[c_obj][a] != p[c_obj][b]) | depth | (dot < cos_jump))
        return (np.abs(lum[a] - lum[b]) > contrast) | (hit[a] != hit[b]) | both

    mark = np.zeros((height, width), bool)
    right = differ((slice(None), slice(0, -1)), (slice(None), slice(1, None)))
    mark[:, :-1] |= right
    mark[:, 1:] |= right
    down = differ((slice(0, -1), slice(None)), (slice(1, None), slice(None)))
    mark[:-1] |= down
    mark[1:] |= down
    return mark

"""Exact evaluation of the limit surface at parametric points (OpenSubdiv's ptex convention).

All samples are processed together, one subdivision level at a time. At each level the
faces within two rings of the faces holding the samples are cut out and refined once
(``subdiv.limit.extract``), and each sample moves to the child face that contains it:

* a Catmull-Clark quad whose four corners are smooth, valence-4 and crease-free is a
  uniform bicubic B-spline patch of its 16 points, and a Loop triangle whose three corners
  are smooth, valence-6 and crease-free a quartic box-spline patch of its 12 points: the
  sample is evaluated there exactly, with exact derivatives (the common case, reached after
  a few levels except next to an extraordinary vertex or a crease);
* a Catmull-Clark quad along one semi-sharp crease of one sharpness (or two opposite ones),
  with smooth valence-4 corners otherwise, is a B-spline along the crease and a crease curve
  across it (:mod:`subtrace.patches.crease`): the sample is evaluated there in closed form,
  derivatives exact, instead of refining it as many levels as the sharpness;
* everything else keeps subdividing down to ``config.EVAL_MAX_DEPTH`` levels, where the face
  is 2^-depth of its ptex face: the position is interpolated from the exact limit points of
  its corners (error O(4^-depth), below double precision) and the derivatives are finite
  differences of such exact positions (``config.EVAL_FD_STEP``);
* at a ptex corner on a smooth extraordinary vertex, where the parametrization is singular,
  the derivatives come from the vertex's limit tangents instead (:func:`_corner_derivatives`),
  so that their cross product is the exact limit normal.

Non-quad Catmull-Clark faces are split into their ptex sub-faces by the first level. Points
on hole faces come back as NaN.

UVs (:func:`evaluate_uv`) take the same descent with the cage's face-varying channel
(``subdiv.facevarying``) refined in step, retiring a sample where its face of the channel
is a regular patch, boundaries, creases and corners of the channel included (phantom
points, as OpenSubdiv's regular face-varying patches), and linear mode as the bilinear
interpolation of the face's corners.
"""

from __future__ import annotations

import numpy as np

from subtrace import config
from subtrace.patches.basis import (
    B_CORNER, BOX_POINTS, LATTICE_DIRS, LEAD, TRAIL, TRI_CORNER, TRI_LEAD, box_spline_basis,
    bspline_basis, tri_bernstein,
)
from subtrace.patches.boxspline import box_nets, loop_regular
from subtrace.patches.crease import crease_derivatives
from subtrace.patches.bspline import control_points, regular_mask
from subtrace.subdiv.facevarying import FVAR_ALL, base_channel, cut_channel, refine_channel
from subtrace.subdiv.limit import SMOOTH, classify, extract, limit_points, smooth_edge_tangents
from subtrace.subdiv.refine import refine_level, refine_points
from subtrace.subdiv.topology import compact


def ptex_starts(cage):
    """(F+1,) int64: the first ptex id of each face of ``cage`` in its own numbering (a
    regular face is one ptex face, another of n sides n), and the count at the end."""
    sizes = cage.face_sizes
    counts = np.where(sizes == cage.options.regular_face_size, 1, sizes)
    first = np.zeros(len(sizes) + 1, dtype=np.int64)
    np.cumsum(counts, out=first[1:])
    return first


def ptex_layout(cage):
    """(base face of each ptex face, sub-face (-1 for regular faces), first ptex id per face)."""
    reg = cage.options.regular_face_size
    sizes = cage.face_sizes
    first = ptex_starts(cage)
    counts = np.diff(first)
    base = np.repeat(np.arange(len(sizes)), counts)
    sub = np.arange(first[-1]) - first[base]
    sub = np.where(sizes[base] == reg, -1, sub)
    return base.astype(np.int32), sub.astype(np.int32), first


def _samples(cage, ptex_face, uv, name):
    """``ptex_face`` (m,) and ``uv`` (m,2) checked (ValueError naming ``name``), ``uv``
    clipped to the domain, and the ptex layout (base face, sub-face of each ptex face)."""
    ptex_face = np.asarray(ptex_face)
    uv = np.asarray(uv, dtype=np.float64)
    if ptex_face.ndim != 1 or uv.shape != (len(ptex_face), 2):
        raise ValueError(f"{name}: ptex_face must have shape (m,) and uv shape (m, 2)")
    if len(ptex_face) and not np.issubdtype(ptex_face.dtype, np.integer):
        raise ValueError(f"{name}: ptex_face must hold integers")
    base, subface, first = ptex_layout(cage)
    n_ptex = len(base)
    if len(ptex_face) and (ptex_face.min() < 0 or ptex_face.max() >= n_ptex):
        raise ValueError(f"{name}: ptex face ids must lie in [0, {n_ptex})")
    if not np.all(np.isfinite(uv)):
        raise ValueError(f"{name}: uv must be finite")
    tol = 1e-12
    if np.any(uv < -tol) or np.any(uv > 1 + tol):
        raise ValueError(f"{name}: u and v must lie in [0, 1]")
    if cage.scheme == "loop" and np.any(uv.sum(axis=1) > 1 + tol):
        raise ValueError(f"{name}: Loop samples need u + v <= 1")
    return ptex_face, np.clip(uv, 0.0, 1.0), base, subface


def evaluate(cage, ptex_face, uv):
    ptex_face, uv, base, subface = _samples(cage, ptex_face, uv, "evaluate")
    m = len(ptex_face)
    P = np.full((m, 3), np.nan)
    dPdu = np.full((m, 3), np.nan)
    dPdv = np.full((m, 3), np.nan)
    if m == 0:
        return P, dPdu, dPdv
    faces = base[ptex_face]
    live = ~cage.base.face_hole[faces]
    idx = np.nonzero(live)[0]
    if len(idx) == 0:
        return P, dPdu, dPdv
    p, du, dv, exact_d = _descend(cage, faces[idx], subface[ptex_face[idx]], uv[idx], True)
    P[idx] = p
    dPdu[idx] = du
    dPdv[idx] = dv
    need = idx[~exact_d]
    if len(need):
        du, dv = _fd_derivatives(cage, faces[need], subface[ptex_face[need]], uv[need], P[need])
        dPdu[need], dPdv[need] = du, dv
    _corner_derivatives(cage, faces[idx], subface[ptex_face[idx]], uv[idx], idx, dPdu, dPdv)
    return P, dPdu, dPdv


# parameter-space directions of the leading edge (to the next corner) and the trailing
# edge (to the previous corner) at each corner of a ptex quad / triangle
_QUAD_UV = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
_TRI_UV = np.array([[0, 0], [1, 0], [0, 1]])


def _corner_derivatives(cage, faces, subface, uv, rows, dPdu, dPdv):
    """Derivatives at ptex corners that are smooth extraordinary vertices, from the exact
    limit tangents there (rows ``rows`` of dPdu, dPdv are replaced).

    The parametrization is singular at such a corner: OpenSubdiv's derivatives there are
    those of its end-cap patch and only their normal is meaningful (finite differences do
    not even give that for Loop: at valence 3 the tangent and curvature terms decay alike).
    Here the limit tangents along the face's two edges at the corner, T_lead and T_trail
    (the smooth tangent mask turned to each edge, scaled as a regular vertex's would be),
    are taken as the images of the two edge directions a, b in (u, v): the linear map
    [T_lead T_trail] [a b]^-1 gives dP/du and dP/dv, whose cross product is the exact limit
    normal, oriented like the faces. Corners where the vertex is regular, sharp, or still
    semi-sharp keep what the descent gave them.

    Work happens on level 1 (where every face has the scheme's regular size): corner j of a
    regular face is corner j of its child j, with the same (u, v) directions over half the
    length; a ptex sub-face of an n-gon is a level-1 face.
    """
    is_loop = cage.scheme == "loop"
    table = _TRI_UV if is_loop else _QUAD_UV
    pos = np.full(len(faces), -1)
    for j, corner in enumerate(table):
        pos[np.all(uv == corner, axis=1)] = j
    sel = np.nonzero(pos >= 0)[0]
    if len(sel) == 0:
        return
    base = cage.base
    bfo = base.face_offsets
    corners = [base.face_verts[bfo[f] : bfo[f + 1]]
               for f in compact(faces[sel], base.n_faces)[0]]
    verts = compact(np.concatenate(corners), base.n_verts)[0]
    sub, s2c, _, sub_faces = extract(base, verts, rings=2)
    ref = refine_level(sub, cage.options)
    child = ref.child
    pts = refine_points(ref, cage.points[s2c])
    cls = classify(child, cage.options)
    face_map = np.full(base.n_faces, -1, dtype=np.int64)
    face_map[sub_faces] = np.arange(len(sub_faces))
    sf = face_map[faces[sel]]
    regular = subface[sel] < 0
    j = np.where(regular, pos[sel], subface[sel])  # which child of the face
    c = 4 * sf + j if is_loop else sub.face_offsets[sf] + j  # the level-1 face
    p = pos[sel]  # the sample's corner of it
    w = child.face_verts[child.face_offsets[c] + p]
    valence = np.diff(child.vert_edge_offsets)[w]
    todo = (cls[w] == SMOOTH) & (valence != (6 if is_loop else 4))
    if not todo.any():
        return
    sel, c, p, w, regular = sel[todo], c[todo], p[todo], w[todo], regular[todo]
    # the ring slot of face c at w: its leading edge, and the next (its trailing edge)
    slot = np.empty(len(w), dtype=np.int64)
    for t in range(len(w)):
        a = child.vert_face_offsets[w[t]]
        ring = child.vert_faces[a : child.vert_face_offsets[w[t] + 1]]
        slot[t] = np.nonzero(ring == c[t])[0][0]
    nxt = (slot + 1) % valence[todo]
    scale = 1.0 / 3.0 if is_loop else 1.0 / 12.0
    t_lead = scale * smooth_edge_tangents(child, pts, cage.options, w, slot)
    t_trail = scale * smooth_edge_tangents(child, pts, cage.options, w, nxt)
    n = len(table)
    ab = np.stack([table[(p + 1) % n] - table[p], table[(p - 1) % n] - table[p]], axis=2)
    ab = ab * np.where(regular, 0.5, 1.0)[:, None, None]  # (k, 2, 2): columns a, b
    inv = np.linalg.inv(ab.astype(np.float64))
    T = np.stack([t_lead, t_trail], axis=2)  # (k, 3, 2)
    D = T @ inv  # (k, 3, 2): columns dP/du, dP/dv
    dPdu[rows[sel]] = D[:, :, 0]
    dPdv[rows[sel]] = D[:, :, 1]


def _positions(cage, faces, subface, uv):
    return _descend(cage, faces, subface, uv, False)[0]


_FD4 = np.array([-25.0, 48.0, -36.0, 16.0, -3.0]) / 12.0


def _fd_derivatives(cage, faces, subface, uv, P0):
    """Derivatives from fourth-order one-sided finite differences of exact positions.

    Differences are taken along u, v and w = (-1, 1), forward where the domain allows, else
    backward; at a corner of a Loop triangle where u or v cannot move inside the domain, its
    derivative comes from the other two (d/dw = d/dv - d/du).
    """
    h = config.EVAL_FD_STEP
    is_loop = cage.scheme == "loop"

    def inside(q):
        ok = np.all((q >= -1e-15) & (q <= 1.0 + 1e-15), axis=1)
        if is_loop:
            ok &= q.sum(axis=1) <= 1.0 + 1e-15
        return ok

    # gather every query point first, so that one batched descent serves them all
    plan = []
    queries = []
    n_q = 0
    for name, d in (("u", (1.0, 0.0)), ("v", (0.0, 1.0)), ("w", (-1.0, 1.0))):
        if not is_loop and name == "w":
            break
        d = np.array(d)
        fwd = inside(uv + 4 * h * d)
        bwd = inside(uv - 4 * h * d) & ~fwd
        for sel, sign in ((fwd, 1.0), (bwd, -1.0)):
            idx = np.nonzero(sel)[0]
            if len(idx) == 0:
                continue
            for k in range(1, 5):
                queries.append((idx, np.clip(uv[idx] + sign * k * h * d, 0.0, 1.0)))
            plan.append((name, idx, sign, n_q))
            n_q += 4 * len(idx)
        ok_name = fwd | bwd
        plan.append((name, None, ok_name, None))
    q_idx = np.concatenate([q[0] for q in queries])
    q_uv = np.concatenate([q[1] for q in queries])
    Pq = _positions(cage, faces[q_idx], subface[q_idx], q_uv)
    D = {n: np.zeros_like(P0) for n in "uvw"}
    ok = {}
    for name, idx, sign, start in plan:
        if idx is None:
            ok[name] = sign
            continue
        k = len(idx)
        acc = _FD4[0] * P0[idx]
        for j in range(4):
            acc = acc + _FD4[j + 1] * Pq[start + j * k : start + (j + 1) * k]
        D[name][idx] = sign * acc / h
    du, dv = D["u"], D["v"]
    if is_loop:
        du = np.where(ok["u"][:, None], du, D["v"] - D["w"])
        dv = np.where(ok["v"][:, None], dv, D["w"] + D["u"])
    return du, dv


# --------------------------------------------------------------------------------------


def _grids16(level, f):
    """4x4 control points (vertex ids, [u index][v index]) of the regular quads ``f`` (n,):
    (n,4,4). Around each corner, the three other faces of its valence-4 ring
    counter-clockwise give their diagonals and shared edges' far ends."""
    fo, fv = level.face_offsets, level.face_verts
    n = len(f)
    G = -np.ones((n, 4, 4), dtype=np.int64)
    k4 = np.arange(4)
    for i in range(4):
        c = fv[fo[f] + i]
        a = level.vert_face_offsets[c]
        ring = level.vert_faces[a[:, None] + k4]
        rc = level.vert_face_corner[a[:, None] + k4]
        pos = np.argmax(ring == f[:, None], axis=1)
        G[:, B_CORNER[i][0], B_CORNER[i][1]] = c
        lead, trail = LEAD[i], TRAIL[i]
        dirs = [trail, -lead, -trail, lead]
        rows = np.arange(n)
        for k in (1, 2, 3):
            j = (pos + k) % 4
            g, kk = ring[rows, j], rc[rows, j]
            q = B_CORNER[i] + dirs[k - 1] + dirs[k]
            G[:, q[0], q[1]] = fv[fo[g] + (kk + 2) % 4]
            if k >= 2:
                e = level.vert_edges[level.vert_edge_offsets[c] + j]
                a0, b0 = level.edge_verts[e, 0], level.edge_verts[e, 1]
                q = B_CORNER[i] + dirs[k - 1]
                G[:, q[0], q[1]] = np.where(a0 == c, b0, a0)
    return G


def _grid12(level, f):
    """The 12 control points (vertex ids, in BOX_POINTS order) of a regular triangle ``f``."""
    fo, fv = level.face_offsets, level.face_verts
    at = {}
    for k in range(3):
        c = fv[fo[f] + k]
        fa, ea = level.vert_face_offsets[c], level.vert_edge_offsets[c]
        slot = int(np.nonzero(level.vert_faces[fa : fa + 6] == f)[0][0])
        for t in range(6):
            a, b = level.edge_verts[level.vert_edges[ea + (slot + t) % 6]]
            far = b if a == c else a
            at[tuple(TRI_CORNER[k] + LATTICE_DIRS[(TRI_LEAD[k] + t) % 6])] = far
        at[tuple(TRI_CORNER[k])] = c
    return np.array([at[tuple(q)] for q in BOX_POINTS], dtype=np.int64)


def _descend(cage, faces, subface, uv, want_derivs):
    """Walk every sample down the subdivision hierarchy; see the module comment."""
    opts = cage.options
    is_loop = cage.scheme == "loop"
    m = len(faces)
    P = np.zeros((m, 3))
    dU = np.zeros((m, 3))
    dV = np.zeros((m, 3))
    exact_d = np.zeros(m, dtype=bool)
    # per sample: local (u,v) in the current face and the Jacobian d(local)/d(ptex)
    loc = uv.copy()
    J = np.tile(np.eye(2), (m, 1, 1))
    level, pts = cage.base, cage.points
    cur = faces.astype(np.int64).copy()  # current face of each sample, in `level`
    active = np.ones(m, dtype=bool)
    depth = 0
    max_depth = config.EVAL_MAX_DEPTH
    while active.any():
        ids = np.nonzero(active)[0]
        fo = level.face_offsets
        # cut out the faces within two rings of the active samples' faces, and refine it
        # (compact, not np.unique: that imports numpy.ma, which a render does not need)
        verts = compact(np.concatenate([level.face_verts[fo[f] : fo[f + 1]]
                                        for f in compact(cur[ids], level.n_faces)[0]]),
                        level.n_verts)[0]
        sub, s2c, c2s, sub_faces = extract(level, verts, rings=2)
        face_map = np.full(level.n_faces, -1, dtype=np.int64)
        face_map[sub_faces] = np.arange(len(sub_faces))
        sub_pts = pts[s2c]
        sf = face_map[cur[ids]]
        # regular patches (bicubic B-spline / quartic box spline): evaluate exactly, retire
        cls = classify(sub, opts)
        val = np.diff(sub.vert_edge_offsets)
        sfo = sub.face_offsets
        reg_valence = 6 if is_loop else 4
        n_side = 3 if is_loop else 4
        sized = (sfo[sf + 1] - sfo[sf]) == n_side
        cv = sub.face_verts[np.minimum(sfo[sf][:, None] + np.arange(n_side),
                                       len(sub.face_verts) - 1)]
        regular = sized & np.all((cls[cv] == SMOOTH) & (val[cv] == reg_valence), axis=1)
        done, f_done = ids[regular], sf[regular]
        if len(done):
            if is_loop:
                for i, f in zip(done, f_done):
                    X = sub_pts[_grid12(sub, f)]  # (12,3)
                    b, bu, bv = box_spline_basis(loc[i, 0], loc[i, 1])
                    P[i] = b @ X
                    lu, lv = bu @ X, bv @ X
                    dU[i] = J[i, 0, 0] * lu + J[i, 1, 0] * lv
                    dV[i] = J[i, 0, 1] * lu + J[i, 1, 1] * lv
            else:
                X = sub_pts[_grids16(sub, f_done)]  # (n,4,4,3)
                bu, du_ = bspline_basis(loc[done, 0])
                bv, dv_ = bspline_basis(loc[done, 1])
                P[done] = np.einsum("ni,nj,nijk->nk", bu, bv, X)
                lu = np.einsum("ni,nj,nijk->nk", du_, bv, X)
                lv = np.einsum("ni,nj,nijk->nk", bu, dv_, X)
                # chain rule: d/dptex = J^T d/dlocal
                Jd = J[done]
                dU[done] = Jd[:, 0, 0, None] * lu + Jd[:, 1, 0, None] * lv
                dV[done] = Jd[:, 0, 1, None] * lu + Jd[:, 1, 1, None] * lv
            exact_d[done] = True
            active[done] = False
        if not is_loop and want_derivs:
            _retire_creased(sub, sub_pts, opts, face_map, cur, loc, J, active, P, dU, dV,
                            exact_d)
        ids = np.nonzero(active)[0]
        sf = face_map[cur[ids]]
        if len(ids) == 0:
            break
        if depth >= max_depth:
            _interpolate_corners(sub, sub_pts, opts, sf, loc[ids], ids, P, is_loop)
            break
        ref = refine_level(sub, opts)
        child_pts = refine_points(ref, sub_pts)
        cur[ids], nu, nv, A = _step_down(sub, sf, loc[ids], subface[ids], depth, is_loop)
        loc[ids, 0] = nu
        loc[ids, 1] = nv
        J[ids] = A @ J[ids]
        level, pts = ref.child, child_pts
        depth += 1
    return P, dU, dV, exact_d


def _retire_creased(sub, sub_pts, opts, face_map, cur, loc, J, active, P, dU, dV, exact_d):
    """Retire the active samples on quads of ``sub`` along one semi-sharp crease of one
    sharpness (or two opposite ones): the crease maps' closed form
    (:func:`~subtrace.patches.crease.crease_derivatives`) gives their point and derivatives
    there, where the descent would refine them until the sharpness has run out (as many
    levels as the sharpness, each through local topology)."""
    ids = np.nonzero(active)[0]
    if not len(ids):
        return
    ok, pos, lu, lv = crease_derivatives(sub, sub_pts, opts, face_map[cur[ids]], loc[ids])
    done = ids[ok]
    if not len(done):
        return
    lu, lv = lu[ok], lv[ok]
    P[done] = pos[ok]
    Jd = J[done]
    dU[done] = Jd[:, 0, 0, None] * lu + Jd[:, 1, 0, None] * lv
    dV[done] = Jd[:, 0, 1, None] * lu + Jd[:, 1, 1, None] * lv
    exact_d[done] = True
    active[done] = False


def _step_down(sub, sf, loc, subface, depth, is_loop):
    """The child faces of ``sub``'s faces ``sf`` that hold the samples at local ``loc``
    (k,2) (an n-gon's ptex sub-face ``subface`` at the first level), their local (u, v)
    there and the Jacobians (k,2,2) of the step."""
    sfo = sub.face_offsets
    u = loc[:, 0]
    v = loc[:, 1]
    if is_loop:
        j, nu, nv, A = _loop_child(u, v)
    else:
        quad = (sfo[sf + 1] - sfo[sf]) == 4
        j = np.where(quad, _quadrant(u, v), subface)
        if depth > 0:
            j = np.where(quad, j, 0)
        nu = np.where(quad, 2 * u - ((j == 1) | (j == 2)), u)
        nv = np.where(quad, 2 * v - ((j == 2) | (j == 3)), v)
        A = np.where(quad[:, None, None], 2.0 * np.eye(2), np.eye(2))
    # child face j of a parent face is child number (first corner of the face) + j
    return (sfo[sf] + j if not is_loop else 4 * sf + j), nu, nv, A


def _quadrant(u, v):
    right = u >= 0.5
    top = v >= 0.5
    return np.where(top, np.where(right, 2, 3), np.where(right, 1, 0))


def _loop_child(u, v):
    """Child triangle holding (u,v) and the affine map to its local coordinates."""
    m = len(u)
    j = np.full(m, 3)
    j = np.where(u + v <= 0.5, 0, j)
    j = np.where((j == 3) & (u >= 0.5), 1, j)
    j = np.where((j == 3) & (v >= 0.5), 2, j)
    nu = np.select([j == 0, j == 1, j == 2], [2 * u, 2 * u - 1, 2 * u], 1 - 2 * u)
    nv = np.select([j == 0, j == 1, j == 2], [2 * v, 2 * v, 2 * v - 1], 1 - 2 * v)
    s = np.where(j == 3, -2.0, 2.0)
    A = s[:, None, None] * np.eye(2)
    return j, nu, nv, A


def _interpolate_corners(level, pts, opts, faces, loc, ids, P, is_loop):
    """Position inside a tiny face from the exact limit points of its corners."""
    fo, fv = level.face_offsets, level.face_verts
    corner_ids = np.concatenate([fv[fo[f] : fo[f + 1]] for f in faces])
    uniq, inv = np.unique(corner_ids, return_inverse=True)
    L, _, _ = limit_points(level, pts, opts, which=uniq)
    k = 0
    for t, f in enumerate(faces):
        n = fo[f + 1] - fo[f]
        c = L[inv[k : k + n]]
        k += n
        u, v = loc[t]
        if is_loop:
            P[ids[t]] = (1 - u - v) * c[0] + u * c[1] + v * c[2]
        else:
            P[ids[t]] = (1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + u * v * c[2] + (1 - u) * v * c[3]


# --------------------------------------------------------------------------------------
# face-varying data (UVs)
# --------------------------------------------------------------------------------------


def uv_channel(cage):
    """The base face-varying channel of ``cage``'s UVs (``subdiv.facevarying``) and its
    values' UVs (n,3) float64 (third coordinate 0: the limit and patch code is 3-D), made
    once per cage and UVs (a cage copied with other UVs, ``dataclasses.replace``, shares
    the cache)."""
    uvs = cage.uv
    got = cage._cache.get("uv_channel")
    if got is None or got[0] is not uvs:
        ch, index = base_channel(cage.base, uvs.face_values, uvs.mode, cage.options)
        pts = np.zeros((len(index), 3))
        pts[:, :2] = uvs.values[index]
        got = cage._cache["uv_channel"] = (uvs, ch, pts)
    return got[1], got[2]


def evaluate_uv(cage, ptex_face, uv):
    """The limit UVs (m,2) float64 at the parametric points ``ptex_face`` (m,), ``uv``
    (m,2) of ``cage`` (ptex convention as :func:`evaluate`; NaN on holes), with
    OpenSubdiv's face-varying rules (``subdiv.facevarying``).

    Linear mode (ALL) is the bilinear interpolation of the face's corners (the limit of
    bilinear refinement; a ptex sub-face of an n-gon between its corner, edge midpoints and
    centroid; a Loop triangle's linear one). Otherwise the samples descend as
    :func:`evaluate`'s do, the channel refined in step with the cage, and a sample is
    evaluated exactly where its face of the channel is a regular patch: a bicubic
    B-spline (Loop: a quartic box spline), with phantom points beyond a regular boundary,
    crease or corner of the channel (``patches.bspline`` / ``patches.boxspline``, as
    OpenSubdiv's regular face-varying patches); values that follow a partner's sharpness
    are not regular. What is left at ``config.EVAL_MAX_DEPTH`` is interpolated from the
    exact limit values of its corners."""
    if cage.uv is None:
        raise ValueError("evaluate_uv: the cage has no UVs (an OBJ file's vt on every face "
                         "corner, a USD mesh's primvars:st)")
    ptex_face, uv, base, subface = _samples(cage, ptex_face, uv, "evaluate_uv")
    out = np.full((len(ptex_face), 2), np.nan)
    faces = base[ptex_face]
    idx = np.nonzero(~cage.base.face_hole[faces])[0]
    if len(idx) == 0:
        return out
    sub = subface[ptex_face[idx]]
    if cage.uv.mode == FVAR_ALL:
        out[idx] = _linear_uv(cage, faces[idx], sub, uv[idx])
    else:
        out[idx] = _descend_uv(cage, faces[idx], sub, uv[idx])[:, :2]
    return out


def _linear_uv(cage, faces, subface, uv):
    """Bilinear (Loop: linear) interpolation of the faces' corner UVs (see
    :func:`evaluate_uv`)."""
    fo = cage.face_offsets
    values, fvals = cage.uv.values, cage.uv.face_values
    u, v = uv[:, 0:1], uv[:, 1:2]
    n = (fo[faces + 1] - fo[faces])[:, None]
    if cage.scheme == "loop":
        c = values[fvals[fo[faces][:, None] + np.arange(3)]]
        return (1 - u - v) * c[:, 0] + u * c[:, 1] + v * c[:, 2]
    quad = subface < 0
    k = np.where(quad, 0, subface)[:, None]
    corner = lambda i: values[fvals[fo[faces][:, None] + (k + i) % n]][:, 0]  # noqa: E731
    centroid = np.zeros((len(faces), 2))
    for f in np.unique(faces[~quad]):
        centroid[faces == f] = values[fvals[fo[f]:fo[f + 1]]].mean(axis=0)
    c0, c1, c3 = corner(0), corner(1), corner(-1)
    c2 = np.where(quad[:, None], corner(2), centroid)
    c1 = np.where(quad[:, None], c1, 0.5 * (c0 + c1))
    c3 = np.where(quad[:, None], c3, 0.5 * (c0 + c3))
    return (1 - u) * (1 - v) * c0 + u * (1 - v) * c1 + u * v * c2 + (1 - u) * v * c3


def _descend_uv(cage, faces, subface, uv):
    """Walk the samples down the cage's and the channel's levels (see :func:`evaluate_uv`):
    (m,3) UVs, third coordinate 0."""
    opts = cage.options
    is_loop = cage.scheme == "loop"
    ch, pts = uv_channel(cage)
    m = len(faces)
    out = np.zeros((m, 3))
    loc = uv.copy()
    level = cage.base
    cur = faces.astype(np.int64).copy()
    active = np.ones(m, dtype=bool)
    depth = 0
    while active.any():
        ids = np.nonzero(active)[0]
        fo = level.face_offsets
        verts = np.unique(np.concatenate([level.face_verts[fo[f]:fo[f + 1]]
                                          for f in np.unique(cur[ids])]))
        sub, _, c2s, sub_faces = extract(level, verts, rings=2)
        sch, old_v = cut_channel(ch, sub_faces, c2s)
        sub_pts = pts[old_v]
        face_map = np.full(level.n_faces, -1, dtype=np.int64)
        face_map[sub_faces] = np.arange(len(sub_faces))
        sf = face_map[cur[ids]]
        regular = _uv_regular(sch, opts, sf, is_loop)
        done = ids[regular]
        if len(done):
            out[done] = _uv_patches(sch.level, sub_pts, sf[regular], loc[done], is_loop)
            active[done] = False
        ids, sf = ids[~regular], sf[~regular]
        if len(ids) == 0:
            break
        if depth >= config.EVAL_MAX_DEPTH:
            _interpolate_corners(sch.level, sub_pts, opts, sf, loc[ids], ids, out, is_loop)
            break
        ref = refine_level(sub, opts)
        ch, pts = refine_channel(sch, ref, sub_pts)
        cur[ids], nu, nv, _ = _step_down(sub, sf, loc[ids], subface[ids], depth, is_loop)
        loc[ids, 0] = nu
        loc[ids, 1] = nv
        level = ref.child
        depth += 1
    return out


def _uv_regular(ch, opts, faces, is_loop):
    """(k,) bool: the channel's faces ``faces`` that are regular patches of it: none of
    their corners a value that follows a partner's sharpness, or one with a face of
    another size than the scheme's (on the cage's own level: ``regular_mask`` takes a
    boundary corner's faces to be quads, as they are from level 1 on)."""
    regular = loop_regular if is_loop else regular_mask
    lev = ch.level
    ok = regular(lev, opts, faces)
    odd = np.diff(lev.face_offsets) != opts.regular_face_size
    if ok.any() and ((ch.partner >= 0).any() or odd.any()):
        n = opts.regular_face_size
        fo = lev.face_offsets
        corners = lev.face_verts[np.minimum(fo[faces][:, None] + np.arange(n),
                                            len(lev.face_verts) - 1)]
        bad = ch.partner >= 0
        if odd.any():
            at = np.repeat(np.arange(lev.n_verts), np.diff(lev.vert_face_offsets))
            bad[at[odd[lev.vert_faces]]] = True
        ok &= ~bad[corners].any(axis=1)
    return ok


def _uv_patches(level, pts, faces, loc, is_loop):
    """Values (k,3) at local ``loc`` (k,2) of the regular faces ``faces`` of ``level``."""
    if is_loop:
        nets = box_nets(level, pts, faces)  # (k,15,3) triangular Bezier
        return np.einsum("nk,nkd->nd", tri_bernstein(loc), nets)
    X = control_points(level, faces, pts)  # (k,4,4,3) B-spline, phantoms beyond sides
    bu, _ = bspline_basis(loc[:, 0])
    bv, _ = bspline_basis(loc[:, 1])
    return np.einsum("ni,nj,nijd->nd", bu, bv, X)

"""Slow reference implementations (oracles) of subtrace's fast paths, for the tests.

Topology: the numpy / plain-Python relations of ``subtrace.mesh.topology`` as they were
before the jitted kernels (``base_edges`` with lexsort + unique, CSR lists by stable sorts,
vertex rings ordered by a plain loop).
"""

from __future__ import annotations

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

"""Sharpness arithmetic and vertex rules shared by Catmull-Clark and Loop (OpenSubdiv Sdc::Crease).

All sharpness values are float32 and every operation on them is done in float32, exactly as
OpenSubdiv does, so that fractional crease weights (and hence refined points) agree with it
to the last bits. Rules are bit values as in Sdc: smooth 1, dart 2, crease 4, corner 8.
"""

from __future__ import annotations

import numpy as np

from subtrace.runtime.jit import callee_njit, nb
from subtrace.subdiv.topology import INF_SHARP

RULE_SMOOTH = 1
RULE_DART = 2
RULE_CREASE = 4
RULE_CORNER = 8

F0 = np.float32(0.0)
F1 = np.float32(1.0)
F_075 = np.float32(0.75)
F_025 = np.float32(0.25)


@nb.njit(cache=True, inline="always")
def decrement(s):
    """Uniform subdivision of one sharpness value."""
    if s <= F0:
        return F0
    if s >= INF_SHARP:
        return INF_SHARP
    if s > F1:
        return s - F1
    return F0


@nb.njit(cache=True)
def child_edge_sharpness_at_vertex(s, around, chaikin):
    """Sharpness of the child of an edge of sharpness ``s`` at an end vertex whose incident
    edges have sharpness ``around`` (float32 array, ``s`` among them)."""
    n = len(around)
    if (not chaikin) or n < 2:
        return decrement(s)
    if s <= F0:
        return F0
    if s >= INF_SHARP:
        return INF_SHARP
    total = F0
    count = 0
    for i in range(n):
        a = around[i]
        if a > F0 and a < INF_SHARP:
            count += 1
            total += a
    if count > 1:
        avg = (total - s) / np.float32(count - 1)
        s = F_075 * s + F_025 * avg
    s = s - F1
    if s > F0:
        return s
    return F0


@callee_njit
def rule_of(vert_sharp, edge_sharp_around):
    """Sdc vertex rule from a vertex sharpness and its incident edges' sharpness."""
    if vert_sharp > F0:
        return RULE_CORNER
    n_sharp = 0
    for i in range(len(edge_sharp_around)):
        if edge_sharp_around[i] > F0:
            n_sharp += 1
    if n_sharp > 2:
        return RULE_CORNER
    return 1 << n_sharp


@callee_njit
def fractional_weight(p_vert, c_vert, p_edges, c_edges, chaikin):
    """Weight of the parent rule when a vertex's rule changes between levels (float32)."""
    count = 0
    total = F0
    if p_vert > F0 and c_vert <= F0:
        count = 1
        total = p_vert
    for i in range(len(p_edges)):
        p = p_edges[i]
        if not chaikin:
            if p > F0 and p <= F1:
                total += p
                count += 1
        else:
            if p > F0 and c_edges[i] <= F0:
                total += p
                count += 1
    if count == 0:
        return F0
    w = total / np.float32(count)
    if w > F1:
        return F1
    return w


@callee_njit
def vertex_rules(p_vert, c_vert, p_edges, c_edges, chaikin):
    """``(parent rule, child rule, weight of the parent's)`` of a vertex point: the rule of
    the vertex's sharpness ``p_vert`` and its edges' ``p_edges``, the child's (from
    ``c_vert``, ``c_edges``) where the parent's is a crease or a corner, and where the two
    differ the fractional weight between them (else 1)."""
    p_rule = rule_of(p_vert, p_edges)
    c_rule = p_rule
    if p_rule != RULE_SMOOTH and p_rule != RULE_DART:
        c_rule = rule_of(c_vert, c_edges)
    pw = 1.0
    if c_rule != p_rule:
        pw = np.float64(fractional_weight(p_vert, c_vert, p_edges, c_edges, chaikin))
    return p_rule, c_rule, pw

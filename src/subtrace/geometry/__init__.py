"""subtrace.geometry: the kinds of items a ray can meet (:mod:`subtrace.geometry.kinds`) and
each kind's operations, a module per kind: Bezier pieces and cells of Catmull-Clark patches
with the walk over a patch's items (:mod:`~subtrace.geometry.bezier`), Loop triangles and
cells (:mod:`~subtrace.geometry.tris`), and what they share (:mod:`~subtrace.geometry.prims`,
:mod:`~subtrace.geometry.snap`).

The room sits above ``patches`` (whose Bezier bases the intersectors split) and ``accel``
(whose slab tests they enter boxes by), below every room that stores, traces or shades
items, so each names a kind the same way: no room compares an item's kind with a bare number
(tests/test_layout.py).
"""

"""subtrace.geometry: the kinds of geometry a ray can meet (:mod:`subtrace.geometry.kinds`).

The vocabulary sits here, below every room that builds, stores, traces or shades items, so
that each names a kind the same way: no room compares an item's kind with a bare number.
"""

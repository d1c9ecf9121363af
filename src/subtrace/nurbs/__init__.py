"""Free-form surfaces: trimmed (rational) NURBS as OBJ files carry them (docs/seeds.md,
section 4), read by :mod:`subtrace.io.freeform` into plain records, made into surfaces by
:mod:`~subtrace.nurbs.freeform`, ray traced by :mod:`~subtrace.nurbs.trace`.

Modules (importing this package imports none of them, and nothing here imports Numba
until a kernel module is imported):

* :mod:`~subtrace.nurbs.knots`: knot vector checks, Boehm knot insertion, Bezier
  extraction, de Casteljau split and degree elevation (numpy, build time);
* :mod:`~subtrace.nurbs.surface`: :class:`NurbsSurface` and its rational Bezier patches;
* :mod:`~subtrace.nurbs.freeform`: an OBJ file's free-form records made into validated
  surfaces and trim loops (``freeform_of``; ObjError naming the line of a problem);
* :mod:`~subtrace.nurbs.bezier`: exact point and first derivatives of rational Bezier
  patches (homogeneous de Casteljau + quotient rule) and curves (Numba);
* :mod:`~subtrace.nurbs.trim`: trimming curves, closed oriented loops, monotone units;
* :mod:`~subtrace.nurbs.trimtree`: the trim kd-tree and its crossing-parity test (Numba);
* :mod:`~subtrace.nurbs.model`: all of a file's surfaces in the flat tables below;
* :mod:`~subtrace.nurbs.trace`: the kernels: per-ray refinement of the patches, Newton's
  root, the trim test, every root along a line (Numba);
* :mod:`~subtrace.nurbs.scene`: a scene's surfaces and the render's NURBS pass.

The interface the kernels consume (:func:`subtrace.nurbs.model.build_model` ->
:class:`~subtrace.nurbs.model.NurbsModel`; m patches, S surfaces, k trim-tree nodes, n curve
units; float64 / int32, C-contiguous):

==========================  ==================================================================
``nets`` (m, Du+1, Dv+1, 4)  homogeneous control points (x w, y w, z w, w) of each rational
                             Bezier patch, ``net[i, j]`` the coefficient of B_i(s) B_j(t),
                             s along u over the patch's [0, 1]; padded to the model's largest
                             degrees (entries past the patch's own degrees are 0)
``patch_degree`` (m, 2)      the patch's (du, dv)
``patch_rect`` (m, 4)        (u0, u1, v0, v1): the patch in its surface's parameters, so a
                             local (s, t) is u = u0 + s (u1 - u0), v = v0 + t (v1 - v0)
``patch_surface`` (m,)       its surface
``surface_domain`` (S, 4)    the surface's parameter rectangle (OBJ ``surf s0 s1 t0 t1``)
``surface_material`` (S,)    index into the OBJ file's materials (-1: none)
``surface_trim`` (S,)        root node of the surface's trim tree, -1: untrimmed
``surface_trim_invert`` (S,) the tree holds holes only: keep where it answers outside
``trim``                     one :class:`~subtrace.nurbs.trimtree.TrimTree` for all surfaces
                             (node_box (k,4), node_axis, node_split, node_child, node_count,
                             node_inside (k,), units ctrl (n, D+1, 3), degree, p0, p1);
                             node and unit indices absolute
==========================  ==================================================================

Per ray (:mod:`subtrace.nurbs.trace`) a patch is treated like the renderer's other Bezier
pieces: bounded by its projected control points (positive weights keep the patch in their
convex hull, tested), split by de Casteljau in homogeneous coordinates (a split net is
again a rational Bezier net, with the rectangle halved) while its angular size is above
the tolerance, its hit solved by Newton's method with
:func:`subtrace.nurbs.bezier.patch_eval` (point, dP/ds, dP/dt; divide by the rectangle's
sides for d/du, d/dv). A hit at local (s, t) maps to (u, v) through ``patch_rect``; it is
kept when the surface is untrimmed, or when :func:`subtrace.nurbs.trimtree.trim_inside`
answers True, XOR ``surface_trim_invert``; else the ray goes on to the next hit. Patches of
a surface share their sides exactly (they come from the same knot insertion), and a root
near a side is found from either side, so a surface is watertight; sides shared between
surfaces are only as close as the file's numbers.
"""

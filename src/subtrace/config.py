"""Every tunable of subtrace with its default, in one place (habit 7 of docs/style.md)."""

# Sharpness at or above this value is infinitely sharp (OpenSubdiv's Sdc::Crease).
SHARPNESS_INFINITE = 10.0

# Exact evaluation: deepest local subdivision before a point is taken as the limit of its
# extraordinary corner: 2^-24 of a ptex face, whose squared size is below double precision.
EVAL_MAX_DEPTH = 24

# Step (in ptex units) of the finite differences that give derivatives where no exact
# bicubic (Catmark) or box-spline (Loop) patch is reached (creases, boundaries, extraordinary).
EVAL_FD_STEP = 2.0**-16

# Renderer: face rings cut out around the patches whose grids are refined together (the
# descendants' limit points need their neighbourhood refined correctly; tests compare the
# grids with uniform refinement).
GRID_RINGS = 2

# Shells of patches near Chaikin creases of sharpness in (1, 4/3) are grown by this fraction
# of their size: there OpenSubdiv's blend weight exceeds 1 and refined points can leave the
# control points' hull (by 5 % of the cage in the worst case measured).
SHELL_CHAIKIN_MARGIN = 0.25

# Deepest grid of one patch (2^n x 2^n cells): bounds memory when the eye is inside a shell.
MAX_GRID_DEPTH = 8

# How primary rays find the patch shells they enter: "projection" (shells binned into image
# tiles, accel/projection.py; measured faster on Spot and the sword, BENCHMARKS.md) or "bvh".
PRIMARY_ACCEL = "projection"

# Patches per BVH leaf, and the traversal stack size (enough for any tree this builds).
BVH_LEAF_SIZE = 2
STACK_SIZE = 128

# Ray / micro-triangle test: edge functions down to -TRI_SLACK times their sum still count
# as inside. Shared vertices of patches refined to different depths can differ in the last
# bit (the same limit point computed at two levels); this closes those gaps (1e-12 of a
# triangle is far below anything visible) without letting rays through.
TRI_SLACK = 1e-12

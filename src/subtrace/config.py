"""Every tunable of subtrace with its default, in one place (habit 7 of docs/style.md)."""

# Sharpness at or above this value is infinitely sharp (OpenSubdiv's Sdc::Crease).
SHARPNESS_INFINITE = 10.0

# Exact evaluation: deepest local subdivision before a point is taken as the limit of its
# extraordinary corner: 2^-24 of a ptex face, whose squared size is below double precision.
EVAL_MAX_DEPTH = 24

# Step (in ptex units) of the finite differences that give derivatives where no exact
# bicubic patch is reached (Loop, creases, boundaries).
EVAL_FD_STEP = 2.0**-16

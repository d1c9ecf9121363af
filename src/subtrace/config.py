"""Every tunable of subtrace with its default, in one place (habit 7 of docs/style.md)."""

# Sharpness at or above this value is infinitely sharp (OpenSubdiv's Sdc::Crease).
SHARPNESS_INFINITE = 10.0

# Exact evaluation: deepest local subdivision before a point is taken as the limit of its
# extraordinary corner (2^-60 of a ptex face is far below double precision of any model).
EVAL_MAX_DEPTH = 60

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

# The control-edge bound of a cell at an extraordinary vertex is not a proven bound (measured
# up to 0.8 % short on Spot); irregular cells stop refining only with this much to spare
# (patches/isolate.py), and line queries guess an irregular patch's first isolation depth
# from this multiple of its bound (lines/items.py).
IRREGULAR_MARGIN = 1.25

# Isolate smooth patches of one extraordinary vertex by fixed linear maps
# (patches/stencil.py) instead of local topology; False: every patch by topology
STENCIL_ISOLATION = True

# Largest coordinate magnitude a render accepts (io/limits.py: check_coordinates): the
# renderer squares distances and multiplies up to three coordinates (1e100^3 = 1e300 is
# still below the largest double, 1.8e308); a cage at 1e100 renders (tested), one at 1e300
# overflowed to inf and never finished.
MAX_COORDINATE = 1e100

# Largest vertex valence a render accepts (a Catmull-Clark face of more vertices gives its
# centre that valence; io/limits.py: check_valences). Isolating an extraordinary vertex costs
# time growing with its valence at every level: valence 1000 renders in about 35 s on 2
# cores, a 10,000-vertex face had not finished after 60 s (in isolated_depths' refinement).
MAX_VALENCE = 1024

# Refinement depth is limited by floating point, not by a constant: a patch stops refining
# where its cells would be smaller than 2^-PRECISION_BITS of the largest coordinate
# magnitude the ray test works at (the patch's shell and the eye):
# patches/criterion.py: precision_depths. Below that the descent resolves nothing more: net
# boxes are padded by BOX_PAD = 1e-12 (about 2^-40) and cell slabs by 1e-11 of that
# magnitude (patches/basis.py, geometry/bezier.py), so a finer cell's box is mostly padding,
# while a cell of 2^-40 still spans 4096 ulps (2^-52), far above the few ulps of rounding
# in its corners and the ray / triangle test. Since a patch's extent is at most 2*sqrt(3)
# times that magnitude, no depth exceeds PRECISION_BITS + 2 = 42: dyadic parameters
# (i / 2^n) stay exact in doubles (52 bits) and shifts 1 << n fit int64. A patch whose
# tolerance asks for more is capped there, and the render says so (one warning, the EXR
# header's subtrace:depth_cap and depth_cap_reason = "precision").
PRECISION_BITS = 40

# An isolated Loop patch (an irregular triangle, patches/isolate_loop.py) keeps the exact
# samples of each side it snaps onto a coarser neighbour: 2^d + 1 of them for a neighbour at
# depth d, built with the patch. Where the eye sits inside shells the tolerance asks for the
# precision limit (about 40) on both sides of an edge, 2^40 samples; such patches are held
# at this depth, with the warning (reason "size"). Regular Loop patches and every
# Catmull-Clark patch are not.
LOOP_MAX_ISOLATED_DEPTH = 20
# A Loop patch whose shell holds the eye (a view from inside or on the edge of a shell)
# asks for no finite depth, and its rays' descent near the eye grows about 4x a level (an
# open Loop box seen from inside, 48x36 px: depth 14 0.6 s, depth 20 31 s and 33 million
# micro-triangles): such patches are held at this depth, with the warning (reason "size").
LOOP_MAX_INSIDE_DEPTH = 14

# A cell side carries at most 2^FAN_LEVELS samples (a regular patch or piece beside a finer
# one fans its cells, geometry/bezier.py): a coarser neighbour is raised to within FAN_LEVELS
# of the finer one (patches/criterion.py: edge_sampling; trace/pools.py: Pieces), which
# only adds refinement where rays descend, never a cap.
FAN_LEVELS = 8

# A side snapped onto a coarser cell-bearing neighbour's polyline (geometry/snap.py) keeps all
# 2^d + 1 samples of that polyline, d its depth: an edge whose cell-bearing patches are all
# deeper than SNAP_MAX_DEPTH is sampled at its finest patch's depth instead, its
# cell-bearing patches raised to it (patches/criterion.py: edge_sampling). At most 4,097
# samples (96 KiB) a side; reached only in close-ups and at absurd tolerances (1e-12 px
# asks for depth 42, whose polyline would be 2^42 points).
SNAP_MAX_DEPTH = 12

# A hit on a cell (of an irregular patch) takes the blend of its corners' exact normals,
# unless a corner's normal lies more than this far from that blend: then the exact limit
# normal at the hit's parameter (shade.exact_cell_normals; a crease narrower than the cell
# turns the normal within its fillet, the blend over the whole cell).
CELL_NORMAL_SPREAD_DEG = 10.0

# How primary rays find the patch shells they enter: "projection" (shells binned into image
# tiles, accel/projection.py; measured faster on Spot and the sword, BENCHMARKS.md) or "bvh".
PRIMARY_ACCEL = "projection"

# Build patches only for the cage faces whose limit surface a primary ray may reach (the box
# of each face's one-ring projected into the image, render.py): off-screen parts of a cage
# cost nothing. Rays that leave the view (shadows, reflections) need it off.
CULL_TO_VIEW = True

# A cage of at least this many faces has its topology built only around the faces in view
# (``Cage.restricted``, render.table_in_view) when they and their rings are at most
# LAZY_TOPOLOGY_SHARE of its faces: the topology of 358,048 faces is 67 MB and 0.1 s, most
# of a large cage's cost when a tenth of it is seen. Smaller cages build it whole (the same
# patches and image either way).
LAZY_TOPOLOGY_FACES = 20000
LAZY_TOPOLOGY_SHARE = 0.5

# Patches per BVH leaf, and the traversal stack size (enough for any tree this builds).
BVH_LEAF_SIZE = 2
STACK_SIZE = 128

# Parallel rays (a directional light's shadow rays, accel/parallel.py): a run of at least
# PARALLEL_MIN_RAYS rays of one direction in a trace, and PARALLEL_RAYS_PER_SHELL per
# shell, walks a grid of the shells projected along it instead of the BVH (a grid took
# 0.7 ms for Spot's 678 shells, 23 ms for the sword's 28,321, whose 30,568 shadow rays
# walk the BVH in less); about PARALLEL_CELLS cells per shell (Spot: 76 x 53; a ray's
# list then holds 3-10 shells), at most PARALLEL_MAX_SIDE along a side.
PARALLEL_MIN_RAYS = 2048
PARALLEL_RAYS_PER_SHELL = 8
PARALLEL_CELLS = 6
PARALLEL_MAX_SIDE = 1024

# Ray / micro-triangle test: edge functions down to -TRI_SLACK times their sum still count
# as inside. Shared vertices of patches refined to different depths can differ in the last
# bit (the same limit point computed at two levels); this closes those gaps (1e-12 of a
# triangle is far below anything visible) without letting rays through.
TRI_SLACK = 1e-12

# Free-form surfaces (nurbs/). Trim loops are closed when consecutive curves meet within
# TRIM_CLOSURE_TOL of the surface's parameter range (the larger side of its rectangle), and lie
# in its domain when they leave it by no more than that: CAD exporters write about 6 to 15
# significant digits, so loops closed in the modeller meet to about 1e-6 of the range in the
# file; the reader then closes the gap exactly (moves the next curve's first point).
TRIM_CLOSURE_TOL = 1e-5
# Largest degree of a free-form surface or curve (the exporters write 1 to 9; Bezier
# extraction and the kernels' fixed-size buffers are sized by it).
NURBS_MAX_DEGREE = 15
# Ray tracing NURBS patches (nurbs/trace.py): a sub-patch is halved at most NURBS_MAX_LEVEL
# times per ray (2^-30 of a patch is far below what a pixel of any sensible view resolves;
# a leaf held there above the tolerance is counted and reported); Newton's method takes at
# most NURBS_NEWTON_STEPS steps and has converged when a step moves the patch parameters by
# at most NURBS_NEWTON_TOL (quadratic convergence: the next step would be far below a double's
# resolution; rounding of the residual keeps the last steps of grazing rays near 1e-12);
# a converged root lies on the ray when its distance to it is at most NURBS_ON_RAY of the
# point's coordinates and distance (rounding is about 1e-16 of them).
NURBS_MAX_LEVEL = 30
NURBS_NEWTON_STEPS = 24
NURBS_NEWTON_TOL = 1e-10
NURBS_ON_RAY = 1e-9
# A normal dP/du x dP/dv shorter than this fraction of |dP/du|^2 + |dP/dv|^2 is taken as
# degenerate (a side shrunk to a point): the normal is taken a short step inside the patch.
NURBS_DEGENERATE = 1e-10
# Each thread keeps the children of the top NURBS_MEMO_LEVELS levels of a patch's quadtree
# (the splits every ray into the patch repeats: 85 nodes of 4 children) for up to
# NURBS_MEMO_PATCHES patches at a time (slot = patch % slots), in at most NURBS_MEMO_BYTES
# (bicubic patches: 204 KB a slot, so 64 slots, 13 MB; degree 9: 14 slots). Levels 3 and 4
# measured: 25 % and 30 % off the trace time of the torus and plate scenes.
NURBS_MEMO_LEVELS = 4
NURBS_MEMO_PATCHES = 64
NURBS_MEMO_BYTES = 16 << 20
# The trim kd-tree (nurbs/trimtree.py): a node with at most TRIM_LEAF_UNITS monotone curve
# units is a leaf; empty space of more than TRIM_EMPTY_FRACTION of a node's side is cut off
# first as an empty leaf (classified once, inside or outside); no node is deeper than
# TRIM_MAX_DEPTH (the traversal's fixed stack holds TRIM_STACK_SIZE nodes, more than enough).
# The patent's leaf-size stops (a leaf's area below TRIM_MIN_AREA of the tree's box, or its
# longer side below TRIM_MIN_SIDE of the box's diagonal: 0.0006 and 0.025 there) are off by
# default: they bound the depth, so long loops keep many units per leaf (benchmarks/trim.py
# --patent-stops measures them; BENCHMARKS.md).
TRIM_LEAF_UNITS = 4
TRIM_MIN_AREA = 0.0
TRIM_MIN_SIDE = 0.0
TRIM_EMPTY_FRACTION = 0.25
TRIM_MAX_DEPTH = 48
TRIM_STACK_SIZE = 128
# Halvings of the exact crossing test of a monotone unit whose box straddles the query
# point: each halves the parameter interval; 64 reach the last bit of a double parameter.
TRIM_BISECT_STEPS = 64

# Memory budget of a render (``--max-memory``, ``[render] max_memory``). The default is this
# fraction of the memory the kernel says is available when the render starts (MemAvailable:
# free memory plus what the page cache can give back), or of the physical memory where that
# cannot be read: half leaves room for the rest of the machine and for the estimate's error,
# and taking what is available rather than the total keeps a render from pushing other
# processes into swap or the OOM killer.
MEMORY_DEFAULT_FRACTION = 0.5
# Without /proc/meminfo or sysconf: 4 GiB.
MEMORY_FALLBACK_BYTES = 4 << 30

# What the budget is checked against (estimates, bytes; each above the measured figure,
# see patches/table.py: memory_estimate and tests/test_memory.py):
# per pixel: hits, requests, candidate lists, channel planes and the EXR / PNG write
# (measured 160-235 B at 4096x256 and 2048x2048)
MEMORY_BYTES_PER_PIXEL = 320
# per patch of the table: its arrays, the cage's refined levels, the shells' projection
MEMORY_BYTES_PER_PATCH = 2048
# per level of an irregular patch (Catmull-Clark or Loop): its pieces (3 Bezier nets and
# boxes per level) and the isolation's cut of its neighbourhood
MEMORY_BYTES_PER_ISOLATED_LEVEL = 16384
# per face of an isolation's frontier, counted over every level it refines (measured ~4.4
# KB: the refined cut of its neighbourhood, points, the regular children's Bezier nets, all
# kept for the build): a frontier that grows with each level (an isolation along a
# non-manifold edge doubles it) is stopped where it would pass half the budget
MEMORY_BYTES_PER_ISOLATION_FACE = 8192
# and, whatever the budget, an isolation stops before its frontier passes this many faces
# per irregular patch and level (the scenes' isolations take 1-10: an irregular corner keeps
# about one face per level) or ISOLATION_MIN_FACES, whichever is more: what grows faster
# is a feature along an edge, refined far below the pixels (a 32x24 render of a fuzzed
# cage with a non-manifold edge took minutes at the memory limit alone)
ISOLATION_FACES_PER_PATCH_LEVEL = 64
ISOLATION_MIN_FACES = 1 << 16
# per exact side sample of an isolated Loop patch (a point, and its share of the sorting)
MEMORY_BYTES_PER_SIDE_SAMPLE = 64
# a thread's memo of split Bezier nets (geometry/bezier.py) is kept within what the budget
# leaves over, but not below this (below it rays split on the spot: slower, same image)
MEMORY_MEMO_MIN_BYTES = 8 << 20
# scanlines in one of an EXR's ZIP blocks (OpenEXR): a streamed render's bands (but the
# last) are whole blocks, so that the blocks io.exr.ExrBands encodes are the image's
EXR_LINES_PER_BLOCK = 16
# A render streamed to its output (render._paint_bands) is shaded, painted and handed over
# in bands of whole rows of about this many pixels (whole EXR blocks of lines; 192 rows of
# 1280): its channels, normals and the picture's arrays are a band's
STREAM_BAND_PIXELS = 1 << 18
# ... and an image of more pixels than this (2560x1600), or of cages of at least
# STREAM_TRACE_FACES faces in all, is traced band by band too, in bands of about
# STREAM_TRACE_BAND_PIXELS (96 rows of 1280): its hit records, candidate lists and shading
# arrays are then a band's. Tracing in bands costs time (BENCHMARKS.md, "Renders streamed
# in bands": each band is a pass of the rounds, and its rays' patches are built in calls of
# their own, whose fixed cost is the isolation's levels: 3-26 % more render time on the
# benchmark scenes at 1280x720, where streamed renders traced whole took 0.94-1.00 of it).
# An image this large pays for the memory it saves; so does a large cage, whose loading and
# patch table outweigh the bands' extra calls, and whose render must leave room for the
# table (the sword refined twice, 358,048 faces, a tenth of it in view: 0.23-0.24 of the
# whole view's memory above the interpreter's, against 0.29-0.30 traced whole; BENCHMARKS.md,
# "Memory of the streamed render")
STREAM_TRACE_PIXELS = 1 << 22
STREAM_TRACE_FACES = 1 << 16
STREAM_TRACE_BAND_PIXELS = 1 << 17

# Adaptive anti-aliasing (picture.py): a pixel gets more rays when it and a neighbour (right
# or below) differ in coverage or object, in depth by more than AA_DEPTH_STEP of the
# nearer, in normal by more than AA_NORMAL_DEG degrees, or in displayed (sRGB) luminance by
# more than AA_CONTRAST (shadow edges, highlights; smooth shading changes by a few codes in
# 255 between neighbours)
AA_DEPTH_STEP = 0.05
AA_NORMAL_DEG = 25.0
AA_CONTRAST = 0.08

# Ambient occlusion (shade.ambient_occlusion, [render] ao / --ao): its rays look this far,
# as a fraction of the diagonal of the box of the scene's control points (a crevice or a
# contact darkens; a wall across the room does not), and are traced this many at a time
AO_DISTANCE = 0.2
AO_CHUNK_RAYS = 1 << 20
# ... and each pixel's estimate is smoothed with its neighbours within this many pixels on
# the same surface (shade.smooth_occlusion; 0: not smoothed): 16 rays alone leave a grain of
# about 8 % where a tenth of the hemisphere is closed. A tile is traced with this many
# pixels more around it, so that its pixels are the whole image's (render.crop_window).
AO_SMOOTH_RADIUS = 3


def default_max_memory() -> int:
    """The default memory budget of a render in bytes: ``MEMORY_DEFAULT_FRACTION`` of
    MemAvailable (Linux), else of the physical memory, else ``MEMORY_FALLBACK_BYTES``."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(MEMORY_DEFAULT_FRACTION * int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    try:
        import os

        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        if total > 0:
            return int(MEMORY_DEFAULT_FRACTION * total)
    except (AttributeError, ValueError, OSError):
        pass
    return MEMORY_FALLBACK_BYTES

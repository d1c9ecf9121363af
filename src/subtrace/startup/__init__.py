"""A command's start-up work: compiling the render's kernels ahead of their use on a cold
cache (:mod:`~subtrace.startup.warmup`) and reading a warm cache's kernels ahead
(:mod:`~subtrace.startup.preload`). Above the rooms whose kernels they compile (trace,
shade, lights, accel), below the renderer that starts them (``prepare``, ``render``)."""

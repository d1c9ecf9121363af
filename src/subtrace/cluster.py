"""Frames on a Dask cluster (``pip install subtrace[dask]``): ``subtrace render ...
--turntable N --dask [ADDRESS]``.

Without an address, a ``distributed.LocalCluster`` of worker processes on this machine (one
per core, one thread each: each frame's kernels take one core); with one
(``tcp://host:8786``), the scheduler there. Each frame is a task: the worker renders the
frame's scene (reading the cages itself, so nothing large crosses the network), writes its
files through the same atomic writer as a local render and returns the paths and the
render's statistics. The memory budget of a frame is half its worker's memory limit (unless
the scene or ``--max-memory`` sets one) and its threads are the worker's.

Failures: a worker that dies mid-task has its task run again elsewhere (``retries``); a task
that fails on bad input (a :class:`subtrace.errors.SubtraceError`) stops the job, the other
tasks are cancelled, and the error is the same one line as a local render's. A frame's file
is written whole or not at all, so a stopped job leaves only complete frames.
"""

from __future__ import annotations

RETRIES = 2  # further tries of a task whose worker died


def render_frame(scene, out, png, picture, bits, accel):
    """Worker side: render ``scene`` and write ``out`` (and ``png``); returns
    (out, png, statistics as a dict). Threads: the worker's; memory: half its limit."""
    import dataclasses

    import numpy as np

    from subtrace.io.exr import write_exr, write_picture, write_png
    from subtrace.io.scene import apply_overrides
    from subtrace.render import render_scene, result_attributes

    threads = None
    try:
        from distributed import get_worker

        worker = get_worker()
        threads = max(1, int(worker.state.nthreads))
        limit = int(worker.memory_manager.memory_limit or 0)
        if limit and scene.render.max_memory is None:
            scene = apply_overrides(scene, max_memory=f"{limit // 2 // (1 << 20)}M")
    except (ImportError, ValueError, AttributeError):
        pass  # (called outside a worker: every core, the default budget)
    result = render_scene(scene, threads=threads, accel=accel)
    if picture is None:
        write_exr(out, result.channels, result_attributes(result, scene), png_path=png)
    else:
        write_picture(out, result.channels, bits)
        if png:
            ch = result.channels
            write_png(png, np.stack([ch["R"], ch["G"], ch["B"]], axis=-1))
    return out, png, dataclasses.asdict(result.stats)


def client_for(address):
    """A ``distributed.Client``: on ``address``, or on a new LocalCluster (address None)."""
    from subtrace.errors import SubtraceError

    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise SubtraceError("--dask needs Dask's distributed scheduler: pip install "
                            "'subtrace[dask]' (or pip install 'dask[distributed]')") from None
    import logging

    # the scheduler's and workers' own log lines (a nanny killing a worker as the local
    # cluster closes) are not the command's output
    for name in ("distributed", "distributed.nanny", "distributed.scheduler"):
        logging.getLogger(name).setLevel(logging.ERROR)
    if address is None:
        import os

        n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        cluster = LocalCluster(n_workers=max(1, n or 1), threads_per_worker=1, processes=True,
                               dashboard_address=None)
        return Client(cluster)
    try:
        return Client(address, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise SubtraceError(f"--dask {address}: no Dask scheduler there ({exc})") from None


def run_frames(address, jobs, accel, report):
    """Render ``jobs`` = [(scene, out, png, picture, bits)] as tasks; ``report(out, png,
    stats)`` for each as it finishes. Raises the first task's error (others cancelled)."""
    from distributed import as_completed

    client = client_for(address)
    try:
        futures = [client.submit(render_frame, *job, accel, key=f"subtrace-frame-{k}-{job[1]}",
                                 retries=RETRIES, pure=False) for k, job in enumerate(jobs)]
        try:
            for future in as_completed(futures):
                out, png, stats = future.result()
                report(out, png, stats)
        except BaseException:
            client.cancel(futures)
            raise
    finally:
        cluster = getattr(client, "cluster", None)
        client.close()
        if cluster is not None and address is None:
            cluster.close()

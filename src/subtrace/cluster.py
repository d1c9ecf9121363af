"""Frames on a Dask cluster (``pip install subtrace[dask]``): ``subtrace render ...
--turntable N --dask [ADDRESS]``.

Without an address, a ``distributed.LocalCluster`` of worker processes on this machine (one
per core, one thread each: each frame's kernels take one core); with one
(``tcp://host:8786``), the scheduler there. Each frame is a task: the worker renders the
frame's scene (reading the cages itself, so nothing large crosses the network), writes its
files through the same atomic writer as a local render and returns the paths and the
render's statistics. The memory budget of a frame is half its worker's memory limit (unless
the scene or ``--max-memory`` sets one) and its threads are the worker's.

Tiles (``--tile N``): each tile of a frame is a task that writes its channels beside the
frame (``tiles.tile_path``), and one more task per frame, run once its tiles are done,
puts them together and writes the frame (workers write the frames: the client only waits),
removing the tiles. Tiles of one frame reassemble into the local render, bit for bit.

Failures: a worker that dies mid-task has its task run again elsewhere (``retries``); a task
that fails on bad input (a :class:`subtrace.errors.SubtraceError`) stops the job, the other
tasks are cancelled, and the error is the same one line as a local render's. A frame's file
is written whole or not at all, so a stopped job leaves only complete frames. A job stopped
(an error, or an interrupt: ``runtime.signals.register_cleanup``, run once the local
cluster's workers are killed) removes its tiles' files and the temporaries its killed
workers were writing.
"""

from __future__ import annotations

RETRIES = 2  # further tries of a task whose worker died


def _on_worker(scene):
    """(scene, threads) for a task on this worker: its threads, and half its memory limit
    as the budget unless the scene sets one."""
    from subtrace.io.scene import apply_overrides

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
    return scene, threads


def render_frame(scene, out, png, picture, bits, accel, crop=None):
    """Worker side: render ``scene`` (its tile ``crop``, or all) and write ``out`` (and
    ``png``); returns (out, png, statistics as a dict). Threads: the worker's; memory: half
    its limit."""
    import dataclasses

    from subtrace.jobs import result_files, write_frame
    from subtrace.render import render_scene

    scene, threads = _on_worker(scene)
    result = render_scene(scene, threads=threads, accel=accel, crop=crop)
    write_frame(out, png, picture, bits, result.channels, result_files(result, scene),
                scene.render.transparent)
    return out, png, dataclasses.asdict(result.stats)


def render_tile(scene, crop, path, accel):
    """Worker side: render the tile ``crop`` of ``scene`` and write its channels to
    ``path`` (``tiles.write_tile``); returns (crop, path, the header of the image,
    statistics as a dict)."""
    import dataclasses

    from subtrace.jobs import result_files
    from subtrace.render import render_scene
    from subtrace.tiles import write_tile

    scene, threads = _on_worker(scene)
    result = render_scene(scene, threads=threads, accel=accel, crop=crop)
    write_tile(path, result.channels)
    header = result_files(result, scene)
    header.pop("window", None)
    header.pop("subtrace:crop", None)
    return crop, path, header, dataclasses.asdict(result.stats)


def finish_frame(tiles, size, out, png, picture, bits, transparent):
    """Worker side: put the ``tiles`` (:func:`render_tile`'s results) of a ``size`` =
    (width, height) frame together, write ``out`` (and ``png``) and remove the tiles'
    files; returns (out, png, the tiles' statistics merged: ``tiles.merge_stats``). The
    header is the first tile's, with the merged statistics."""
    import os

    from subtrace.jobs import write_frame
    from subtrace.tiles import assemble, merge_stats, read_tile

    stats = merge_stats([t[3] for t in tiles])
    channels = assemble(*size, ((crop, read_tile(path)) for crop, path, _, _ in tiles))
    header = dict(tiles[0][2])
    header.update({f"subtrace:{k}": v for k, v in stats.items()})
    header["subtrace:tiles"] = len(tiles)
    write_frame(out, png, picture, bits, channels, header, transparent)
    for _, path, _, _ in tiles:
        try:
            os.unlink(path)
        except OSError:
            pass
    return out, png, stats


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


def run_jobs(dask, jobs, crop, tile, picture, bits, accel, report=None, wait=True):
    """Render the frames ``jobs`` = [(number, scene, out, png)] (``frames.frame_scenes``)
    on ``dask`` (None: a new LocalCluster; an address; or a ``distributed.Client``, left
    open): a task per frame (its tile ``crop``, or all), or with ``tile`` N a task per tile
    of at most N x N pixels and one per frame putting them together. ``report(FrameResult)``
    as each frame is written. With ``wait`` False: the frames' futures (the client must be
    the caller's). Raises the first task's error (the others cancelled, tiles removed)."""
    import uuid

    from subtrace.jobs import FrameResult
    from subtrace.tiles import tile_grid, tile_path

    try:
        from distributed import Client
    except ImportError:
        Client = ()  # (client_for says how to install it)
    own = not isinstance(dask, Client)
    client = client_for(dask) if own else dask
    from distributed import as_completed

    from subtrace.runtime import signals

    token = uuid.uuid4().hex[:8]  # (keys unique to this job)
    futures, tiles, number = [], [], {}
    outputs = [p for _, _, out, png in jobs for p in (out, png) if p]
    leftovers = lambda: _remove(tiles, outputs)  # noqa: E731
    signals.register_cleanup(leftovers)
    stopped = False
    try:
        for k, scene, out, png in jobs:
            name = f"{'image' if k is None else k}-{token}"
            if tile is None:
                f = client.submit(render_frame, scene, out, png, picture, bits, accel, crop,
                                  key=f"subtrace-frame-{name}", retries=RETRIES, pure=False)
            else:
                size = (scene.camera.width, scene.camera.height)
                parts = [client.submit(render_tile, scene, c, tile_path(out, c), accel,
                                       key=f"subtrace-tile-{name}-{c[0]}-{c[1]}",
                                       retries=RETRIES, pure=False)
                         for c in tile_grid(*size, tile)]
                tiles += [tile_path(out, c) for c in tile_grid(*size, tile)]
                f = client.submit(finish_frame, parts, size, out, png, picture, bits,
                                  scene.render.transparent, key=f"subtrace-frame-{name}",
                                  retries=RETRIES, pure=False)
            futures.append(f)
            number[f.key] = k
        if not wait:
            return futures
        try:
            for future in as_completed(futures):
                out, png, stats = future.result()
                if report is not None:
                    report(FrameResult(number[future.key], out, png, stats))
        except BaseException:
            stopped = True
            client.cancel(futures)
            raise
    finally:
        if own:
            cluster = getattr(client, "cluster", None)
            client.close()
            if cluster is not None and dask is None:
                cluster.close()
        if stopped:  # (once an own cluster's workers are gone: none writes any more)
            _remove(tiles, outputs)
        signals.forget_cleanup(leftovers)
    return futures


def _remove(tiles, outputs) -> None:
    """Remove what a stopped job leaves: the files of its ``tiles`` (those there), and the
    temporaries of its tiles and ``outputs`` whose workers are gone
    (``runtime.atomic.orphaned_temps``)."""
    import os

    from subtrace.runtime.atomic import orphaned_temps

    for path in list(tiles) + [t for p in list(tiles) + list(outputs) for t in
                               orphaned_temps(p)]:
        try:
            os.unlink(path)
        except OSError:
            pass

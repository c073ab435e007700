"""Where the work runs: a local process pool, a Dask cluster, or inline; results in
order with a bounded number in flight."""

from __future__ import annotations

import contextlib
import functools
import itertools
import multiprocessing
import sys
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import (
    FIRST_COMPLETED,
    Executor,
    Future,
    ProcessPoolExecutor,
    wait,
)
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..imaging.partition import (
    worker_ready,
)
from ..recognition.colour_recognition import (
    ColourPrototypes,
)
from ..recognition.templates import ModelTemplate
from ..settings import DetectionSettings
from ..stages import Progress
from ..types import (
    ModelLibrary,
    PointCloud,
    Segmentation,
)
from .walls import (
    WallResult,
    _process_wall_job,
    _templates_job,
    _wall_cloud,
    process_wall,
)
from .worker_env import _environment, _worker_count, worker_environment


def wall_pool(settings: DetectionSettings, n_walls: int | None = None) -> ProcessPoolExecutor | None:
    """The worker processes for the per-wall stages (None when they run in this process).

    The workers are started at once (spawned), each importing only what reading the scan
    needs (:func:`~sbsc_core.imaging.partition.worker_ready`, a fraction of a second), so a caller
    that creates the pool before reading the scan has them ready for the reading tasks;
    :func:`detect_scans` has them import the rest while segmentation runs. The caller shuts
    the pool down.
    """
    workers = _worker_count(settings)
    if workers <= 1 or (n_walls is not None and n_walls <= 1):
        return None
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    with _environment(worker_environment()):  # each submit below starts one worker (a copy of the environment)
        for _ in range(workers):
            pool.submit(worker_ready)
    return pool


def close_pool(pool: ProcessPoolExecutor) -> None:
    """Shut ``pool`` down, from a ``finally`` block: waiting for its workers, unless what ends
    the block is a stop (a ``BaseException`` that is not an ``Exception``: the command's
    SIGTERM / SIGINT, whose handler has already terminated the workers). Then it does not
    wait: the pool's manager thread may be blocked for good reading a result that a killed
    worker had half sent (CPython's ProcessPoolExecutor), and joining it would hang the stop."""
    exc = sys.exc_info()[1]
    pool.shutdown(wait=exc is None or isinstance(exc, Exception), cancel_futures=True)


def _walls_results(cloud: PointCloud, seg: Segmentation, templates: dict[str, ModelTemplate],
                   prototypes: ColourPrototypes, s: DetectionSettings,
                   *, pool: ProcessPoolExecutor | None = None) -> Iterator[tuple[str, WallResult, dict[str, float]]]:
    """Process every wall, in worker processes (``pool``, or one of ``s.workers`` made here)
    when there are several walls.

    Each worker receives only its wall's points; at most two walls per worker are in flight,
    so the scan is never copied whole. Results come back in the order of ``seg.walls``.
    """
    own = pool is None and len(seg.walls) > 1
    if own:
        pool = wall_pool(s, len(seg.walls))
    if pool is None or len(seg.walls) <= 1:
        for wall in seg.walls:
            res, t_stage = process_wall(cloud, wall, templates, prototypes, s)
            yield wall.id, res, t_stage
        return
    try:
        pending: deque = deque()
        todo = iter(seg.walls)
        for wall in itertools.islice(todo, 2 * _worker_count(s)):
            pending.append(pool.submit(_process_wall_job, *_wall_cloud(cloud, wall), templates, prototypes, s))
        while pending:
            yield pending.popleft().result()
            nxt = next(todo, None)
            if nxt is not None:
                pending.append(pool.submit(_process_wall_job, *_wall_cloud(cloud, nxt), templates,
                                           prototypes, s))
    finally:
        if own:
            close_pool(pool)


class InlineExecutor(Executor):
    """Runs each task at once in this process (one worker, or a single wall)."""

    def submit(self, fn, /, *args, **kwargs) -> Future:  # type: ignore[override]
        fut: Future = Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: BLE001 - handed to the caller through the future
            fut.set_exception(exc)
        return fut


@contextlib.contextmanager
def wall_executor(settings: DetectionSettings, scheduler: str | None = None) -> Iterator[Executor]:
    """Where the per-part and per-wall tasks run.

    With ``scheduler`` (``tcp://HOST:PORT``) they run on that Dask distributed cluster, whose
    workers must reach the scan files and the scratch folder at the same paths; otherwise in
    a local pool of ``settings.workers`` spawned processes (in this process for one worker).
    """
    if scheduler:
        try:
            from distributed import Client
        except ImportError:  # pragma: no cover - a declared dependency
            raise InputError("--scheduler", "dask distributed is not installed") from None
        try:
            client = Client(scheduler, set_as_default=False, timeout="10s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError("--scheduler", f"cannot reach the Dask scheduler at {scheduler} ({exc})") from None
        try:
            yield client.get_executor(pure=False)
        finally:
            client.close()
        return
    pool = wall_pool(settings)
    if pool is None:
        yield InlineExecutor()
        return
    try:
        yield pool
    finally:
        close_pool(pool)


Job = tuple | Mapping[str, object]
"""One task's arguments: positional (a tuple) or by name (a mapping, for keyword-only options)."""


def _submit(ex: Executor, fn: Callable, job: Job) -> Future:
    return ex.submit(fn, **job) if isinstance(job, Mapping) else ex.submit(fn, *job)


def call_job(fn: Callable, kwargs: Mapping[str, object]) -> object:
    """``fn(**kwargs)``: one task of a stream of tasks of several kinds (:func:`_as_done`
    runs one function on every job: this one, with jobs ``(fn, kwargs)``)."""
    return fn(**kwargs)


def _as_done(ex: Executor, jobs: Iterable[Job], fn: Callable, in_flight: int) -> Iterator[tuple[int, object]]:
    """``(k, fn(*job))`` (``fn(**job)`` for a mapping) for the k-th job, as the tasks finish, with
    at most ``in_flight`` submitted at once.

    A new job is submitted as soon as any task finishes (not only the oldest), so that a
    long task never leaves the other workers idle; the caller puts the results back in
    order where it matters. Tasks finished together are given in job order.
    """
    pending: dict[Future, int] = {}
    todo = enumerate(jobs)
    try:
        for k, job in itertools.islice(todo, in_flight):
            pending[_submit(ex, fn, job)] = k
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in sorted(done, key=pending.__getitem__):
                k = pending.pop(fut)
                res = fut.result()
                nxt = next(todo, None)
                if nxt is not None:
                    pending[_submit(ex, fn, nxt[1])] = nxt[0]
                yield k, res
    finally:
        for f in pending:
            f.cancel()


def surface_stage(executor: Executor, *, stage: str, part_fn: Callable, part_jobs: list[Job],
                  job_fn: Callable,
                  surfaces: Sequence, library: ModelLibrary, classes: list[str], s: DetectionSettings,
                  scratch: Path, parked: Path | None, in_flight: int, progress: Progress,
                  part_executor: Executor | None = None, binned: np.ndarray | None = None,
                  ) -> tuple[np.ndarray, dict[str, WallResult], dict[str, ModelTemplate]]:
    """A stage on surfaces beyond the walls (ceiling tiles, column faces), run as the walls' is.

    ``part_fn(*job)`` (``part_fn(**job)`` for a mapping) bins one scan part's points into the
    surfaces' partitions and returns the points written per surface; then ``job_fn(scratch, k,
    surface, templates=, prototypes=, s=, images=)`` runs the walls' stages on surface number ``k``
    and returns ``(id, result, timings)``, the result parked (its images written to the folder
    ``images``, :func:`~.walls.park_wall`) unless ``images`` is None.
    Surfaces that got no point are left out (no work, no result). Returns the points binned
    per surface, the results by surface id (parked in ``parked`` unless it is None) and the
    templates of ``classes``. ``part_executor`` (default:
    ``executor``) runs the binning (an in-memory cloud's parts are binned in this process).
    ``binned``: the points already binned per surface (by the walls' partition pass): the
    parts are not binned again.
    """
    kept = np.zeros(len(surfaces), np.int64)
    if binned is not None:
        kept += np.asarray(binned, np.int64)
        part_jobs = []
    for _, written in _as_done(part_executor or executor, part_jobs, part_fn, in_flight):
        kept += np.asarray(written, np.int64)
    templates, prototypes = _templates_job(library, s, classes)
    # the biggest surfaces first, so that no worker is left with a big one at the end; the
    # results are put back in the surfaces' order
    jobs = sorted(((str(scratch), k, sf) for k, sf in enumerate(surfaces) if kept[k] > 0), key=lambda j: -int(kept[j[1]]))
    # each task writes its surface's images itself: this process only receives the small results
    job = functools.partial(job_fn, templates=templates, prototypes=prototypes, s=s,
                            images=None if parked is None else str(parked))
    done: dict[int, tuple[str, WallResult]] = {}
    for i, (j, (sid, res, _)) in enumerate(_as_done(executor, jobs, job, in_flight)):
        done[jobs[j][1]] = (sid, res)
        progress(stage, (i + 1) / len(jobs))
    return kept, dict(done[k] for k in sorted(done)), templates

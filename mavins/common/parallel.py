"""Run many independent jobs: on local cores, in-process, or on a Dask cluster.

One function, :func:`run_jobs`, is the project's way to map a job over items
(Monte Carlo runs of ``mavins analyze``; batches of ``mavins nav``)::

    results = run_jobs(simulate_one, seeds, jobs=4, label="monte carlo")

* ``func`` must be a picklable top-level function (module-level ``def``) and
  every item and result picklable: they travel to other processes.
* ``jobs`` = number of worker processes (default: the machine's cores);
  ``jobs=1`` runs every job in this process, one after the other (no pickling,
  easiest to debug).
* ``cluster="tcp://host:8786"`` submits the jobs to a running Dask distributed
  scheduler instead (OSError when it cannot be reached within CONNECT_TIMEOUT_S) (``pip install mavins[cluster]``); ``jobs`` is then
  ignored: the cluster's workers decide. Every worker must be able to import
  the module of ``func`` (install mavins there).
* Results come back as a list in item order, whatever the order the jobs
  finish in, so a run is reproducible when each job's randomness comes from its
  item (a seed), never from the worker or the order.
* A job that raises stops the run: the jobs not started are cancelled and
  :class:`JobError` names the item's index and value, chained to the job's
  exception.
* A progress bar (mavins.common.progress) counts finished jobs on a terminal.

The local pool forks (on platforms that have fork): workers start with the
parent's imported modules and compiled kernels, so each job pays only its
own work. Warm anything expensive the jobs share (caches, compiled kernels)
before calling, and it is inherited.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_EXCEPTION, Future, ProcessPoolExecutor, wait
from typing import TypeVar

from .progress import Progress

CONNECT_TIMEOUT_S = 10.0  # how long to wait for a Dask scheduler before giving up

T = TypeVar("T")
R = TypeVar("R")

__all__ = ["JobError", "default_jobs", "run_jobs"]


class JobError(RuntimeError):
    """A job failed; ``index`` and ``item`` say which (the job's exception is ``__cause__``)."""

    def __init__(self, index: int, item: object, exc: BaseException) -> None:
        text = repr(item)
        if len(text) > 200:
            text = text[:200] + "..."
        super().__init__(f"job {index} ({text}) failed: {type(exc).__name__}: {exc}")
        self.index = index
        self.item = item


def default_jobs() -> int:
    """Worker processes by default: the cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def run_jobs(
    func: Callable[[T], R],
    items: Sequence[T],
    *,
    jobs: int | None = None,
    cluster: str | None = None,
    label: str = "jobs",
) -> list[R]:
    """``[func(item) for item in items]``, on ``jobs`` local processes or a Dask cluster (module docstring).

    Raises ValueError for ``jobs < 1``, JobError when a job fails, and
    ImportError when ``cluster`` is given but dask.distributed is not installed.
    """
    items = list(items)
    if jobs is None:
        jobs = default_jobs()
    if jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    if cluster is not None:
        return _run_dask(func, items, cluster, label)
    if jobs == 1 or len(items) <= 1:
        return _run_here(func, items, label)
    return _run_pool(func, items, min(jobs, len(items)), label)


def _run_here(func: Callable[[T], R], items: list[T], label: str) -> list[R]:
    out: list[R] = []
    with Progress(label, len(items)) as bar:
        for i, item in enumerate(items):
            try:
                out.append(func(item))
            except Exception as exc:
                raise JobError(i, item, exc) from exc
            bar.update(i + 1)
    return out


def _context() -> multiprocessing.context.BaseContext:
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("fork" if "fork" in methods else None)


def _run_pool(func: Callable[[T], R], items: list[T], jobs: int, label: str) -> list[R]:
    results: list[R | None] = [None] * len(items)
    with ProcessPoolExecutor(max_workers=jobs, mp_context=_context()) as pool:
        futures: dict[Future[R], int] = {pool.submit(func, item): i for i, item in enumerate(items)}
        pending = set(futures)
        try:
            with Progress(label, len(items)) as bar:
                while pending:
                    done, pending = wait(pending, return_when=FIRST_EXCEPTION)
                    for fut in sorted(done, key=futures.__getitem__):
                        i = futures[fut]
                        exc = fut.exception()
                        if exc is not None:
                            raise JobError(i, items[i], exc) from exc
                        results[i] = fut.result()
                    bar.update(len(items) - len(pending))
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)
            raise
    return results  # type: ignore[return-value]


def _run_dask(func: Callable[[T], R], items: list[T], address: str, label: str) -> list[R]:
    try:
        from distributed import Client, as_completed
    except ImportError as exc:
        raise ImportError("--cluster needs Dask distributed: pip install 'mavins[cluster]'") from exc
    results: list[R | None] = [None] * len(items)
    with Client(address, timeout=CONNECT_TIMEOUT_S) as client:
        futures = client.map(func, items, pure=False)
        index = {fut.key: i for i, fut in enumerate(futures)}
        try:
            with Progress(label, len(items)) as bar:
                for count, fut in enumerate(as_completed(futures), start=1):
                    i = index[fut.key]
                    if fut.status == "error":
                        exc = fut.exception()
                        raise JobError(i, items[i], exc) from exc
                    results[i] = fut.result()
                    bar.update(count)
        except BaseException:
            client.cancel(futures)
            raise
    return results  # type: ignore[return-value]

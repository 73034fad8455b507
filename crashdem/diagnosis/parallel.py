"""Independent diagnosis work fanned out over the cores of this machine.

The DEM-truth runs (``generator_dem.prefetch``) and the concealed-case diagnoses of the
generators (``generator.diagnose_cases``, ``generator_planar.diagnose_cases``) are independent
of each other and deterministic wherever they execute: each run is single-threaded
(``scenario.threads = 1``) and each screening fit is plain NumPy/SciPy in one process, so a
result does not depend on the process it ran in nor on how many there are. They are run on a
pool of ``spawn`` worker processes (a forked child of a process whose Numba threading layer is
running can hang), started on first use and kept for the process's lifetime, each with one
BLAS thread (``WORKER_THREAD_ENV``).

For a cluster (several machines) the confirmation runs of ``crashdem diagnose`` go to Dask
instead (``crashdem.diagnosis.distributed``).
"""
from __future__ import annotations

import atexit
import concurrent.futures
import contextlib
import multiprocessing
import os
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

__all__ = ["WORKERS_ENV", "check_workers", "default_workers", "map_processes"]

T = TypeVar("T")

#: environment variable that sets the number of worker processes
WORKERS_ENV = "CRASHDEM_DEM_WORKERS"

_POOLS: dict[int, concurrent.futures.ProcessPoolExecutor] = {}


def default_workers() -> int:
    """Worker processes: ``$CRASHDEM_DEM_WORKERS`` (an integer >= 1), else the cores this
    process may use."""
    text = os.environ.get(WORKERS_ENV)
    if text is not None and text.strip():
        try:
            n = int(text)
        except ValueError:
            n = -1
        if n < 1:
            raise ValueError(f"{WORKERS_ENV}={text!r}: must be an integer >= 1 (worker processes)")
        return n
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def check_workers(workers: int | None) -> int:
    """``workers`` checked (an integer >= 1), None -> ``default_workers()``."""
    if workers is None:
        return default_workers()
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers={workers!r}: must be an integer >= 1 (None: the cores, "
                         f"or ${WORKERS_ENV})")
    return workers


#: BLAS / OpenMP thread counts of the worker processes: one each, as the workers already use
#: every core. Measured (4 glider diagnoses, 75.5 s one after the other, on 2 cores): 58 s on
#: two workers with OpenBLAS's default two threads each, 41.5 s with one
WORKER_THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


@contextlib.contextmanager
def _one_blas_thread():
    """``WORKER_THREAD_ENV`` in this process's environment while workers are spawned (they read
    it when NumPy loads its BLAS, before any initializer could run), restored afterwards."""
    old = {k: os.environ.get(k) for k in WORKER_THREAD_ENV}
    os.environ.update(WORKER_THREAD_ENV)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@atexit.register
def _shutdown() -> None:
    """Stop the worker pools while the interpreter is still whole (left to garbage collection
    at exit, an executor's callback meets half-torn-down modules and prints a traceback)."""
    while _POOLS:
        _, pool = _POOLS.popitem()
        pool.shutdown(wait=True, cancel_futures=True)


def _pool(n: int) -> concurrent.futures.ProcessPoolExecutor:
    pool = _POOLS.get(n)
    if pool is None or getattr(pool, "_broken", False):  # a worker died (killed, out of memory)
        pool = concurrent.futures.ProcessPoolExecutor(
            max_workers=n, mp_context=multiprocessing.get_context("spawn"))
        _POOLS[n] = pool
    return pool


def map_processes(fn: Callable[[Any], T], items: Iterable[Any], workers: int | None = None, *,
                  return_exceptions: bool = False) -> list[T | BaseException]:
    """``[fn(x) for x in items]`` on ``min(workers, len(items))`` worker processes, in the order
    of ``items`` (in this process when that is one). ``fn`` must be importable by name (a
    module-level function) and its arguments and results picklable. An exception of ``fn`` is
    raised here (the first in ``items`` order; on workers after every item has finished), or
    returned in its place with ``return_exceptions``."""
    items = list(items)
    n = min(check_workers(workers), len(items))
    if n < 2:
        out: list[Any] = []
        for x in items:
            try:
                out.append(fn(x))
            except Exception as e:  # returned or raised below, as in parallel
                if not return_exceptions:
                    raise
                out.append(e)
        return out
    pool = _pool(n)
    with _one_blas_thread():  # the workers start while submitting
        futures = [pool.submit(fn, x) for x in items]
    out = []
    for fut in futures:
        try:
            out.append(fut.result())
        except Exception as e:  # noqa: BLE001 - returned or raised below
            out.append(e)
    if not return_exceptions:
        for x in out:
            if isinstance(x, BaseException):
                raise x
    return out

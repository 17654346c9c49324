"""Parallel jobs: one loop for the experiment, the evaluation, the reference table, the ablation and
multi-seed PPO training, on local worker processes or on a Ray cluster.

:func:`run_jobs` maps a function over a list of jobs and yields ``(index, result)`` as the jobs
finish (in completion order; the caller puts the results in order). The result of a job depends
only on the job, never on the backend or the number of workers: the callers' outputs are
identical for the same seeds whichever backend ran them.

* ``backend="local"`` (default): ``workers`` ``spawn``-ed processes of a ``ProcessPoolExecutor``;
  each exits as soon as its parent is gone (:func:`watch_parent`), and starts with
  ``OMP/OPENBLAS/MKL/NUMBA_NUM_THREADS=1`` (one single-threaded job per core). With one worker
  (or one job) the jobs run in this process, one after another.
* ``backend="ray"``: Ray tasks with ``num_cpus=1`` (and the same thread variables), at most
  ``workers`` in flight. ``address`` connects to a running cluster (``"auto"`` or ``"HEAD:6379"``
  on a node of it; ``"ray://HEAD:10001"`` from elsewhere, which needs ``ray[client]``); without it a
  local Ray instance with ``num_cpus=workers`` is started for the call and shut down after it. A
  Ray session that is already initialised is used as it is and left running. Ray is an optional
  extra: ``pip install -e ".[ray]"``, on every node of a cluster (the tasks import this package).
  Results come back to this process, which writes every results file, except PPO training (its
  jobs write their run folders: a folder every node shares).

If this process dies: local workers exit within ``PARENT_POLL_S`` (:func:`watch_parent`). With
Ray, SIGTERM shuts the driver down (Ray's handler) and its tasks end; on SIGKILL the raylet ends
the tasks of the dead driver within seconds, and a local instance started here goes with it (its
two agent processes follow within about two minutes); a cluster keeps running.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import multiprocessing as mp
import os
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any, TypeVar

from soaring_env._validation import ConfigError, check_int

J = TypeVar("J")
R = TypeVar("R")

#: Backend names, the default first.
BACKENDS = ("local", "ray")
#: Thread-pool sizes set to 1 in every worker: one single-threaded job per core.
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
RAY_INSTALL = 'pip install -e ".[ray]"'
#: How often a local worker checks that its parent is still alive [s].
PARENT_POLL_S = 0.5


def check_backend(backend: str, workers: int | None = None, address: str | None = None) -> None:
    """Raise a :class:`ConfigError` naming the field, the value and what is allowed, for an unknown
    ``backend``, ``workers`` < 1 (None: every CPU) or an ``address`` without ``backend="ray"``."""
    if not isinstance(backend, str) or backend not in BACKENDS:
        raise ConfigError(f"backend={backend!r} is unknown; allowed: {', '.join(BACKENDS)}")
    if workers is not None:
        check_int("workers", workers, 1)
    if address is not None:
        if not isinstance(address, str) or not address.strip():
            raise ConfigError(f"address={address!r} must be a Ray cluster address such as 'auto' or 'ray://host:10001'")
        if backend != "ray":
            raise ConfigError(f"address={address!r} is a Ray cluster address; it needs backend='ray' (not {backend!r})")


def run_jobs(
    fn: Callable[[J], R],
    jobs: Sequence[J],
    *,
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
) -> Iterator[tuple[int, R]]:
    """Run ``fn(job)`` for every job; yield ``(index into jobs, result)`` as each job finishes.

    :param fn: a module-level function (it is pickled by reference for the workers; functions of a
        script's ``__main__`` work too). Its exceptions propagate (on Ray: as a ``RayTaskError`` that
        is also an instance of the original exception's class).
    :param jobs: picklable job descriptions.
    :param workers: jobs at a time (None: one per CPU: ``os.cpu_count()`` locally, the whole Ray
        instance or cluster with ``backend="ray"``).
    :param backend: ``"local"`` or ``"ray"`` (see the module docstring).
    :param address: with ``backend="ray"``: the address of a running cluster (None: start a local one).

    The arguments (and that ray is installed) are checked at once; the jobs start on the first
    ``next``. Closing the iterator early (or an exception of a job) cancels the jobs not yet
    started; local jobs already running finish first, Ray tasks are cancelled.
    """
    check_backend(backend, workers, address)
    jobs = list(jobs)
    if backend == "ray":
        return _ray_jobs(_import_ray(), fn, jobs, workers, address)
    n = min(workers if workers is not None else os.cpu_count() or 1, len(jobs))
    if n <= 1:
        return ((i, fn(job)) for i, job in enumerate(jobs))
    return _local_jobs(fn, jobs, n)


def watch_parent(parent_pid: int) -> None:
    """Pool-worker initializer: a daemon thread ends the worker once ``parent_pid`` is no longer its
    parent (the parent died; the worker was re-parented). Polls every ``PARENT_POLL_S`` seconds."""

    def poll() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        os._exit(1)  # no cleanup: the parent that would collect the result is gone

    threading.Thread(target=poll, name="watch-parent", daemon=True).start()


@contextlib.contextmanager
def _single_threaded_children() -> Iterator[None]:
    """Set the unset :data:`THREAD_VARS` to 1 while processes are started (they inherit them), then
    restore this process's environment."""
    saved = {v: os.environ.get(v) for v in THREAD_VARS}
    for v in THREAD_VARS:
        os.environ.setdefault(v, "1")
    try:
        yield
    finally:
        for v, old in saved.items():
            if old is None:
                os.environ.pop(v, None)
            else:
                os.environ[v] = old


def _local_jobs(fn: Callable[[J], R], jobs: list[J], n: int) -> Iterator[tuple[int, R]]:
    """``n`` spawned worker processes; they get the single-thread variables at spawn time (this
    process's own environment is restored afterwards) and exit with this process."""
    with _single_threaded_children():
        # workers exit when this process dies (SIGTERM, SIGKILL): watch_parent polls their parent PID
        pool = ProcessPoolExecutor(n, mp.get_context("spawn"), initializer=watch_parent, initargs=(os.getpid(),))
        index: dict[Future[R], int] = {pool.submit(fn, job): i for i, job in enumerate(jobs)}  # spawns the workers
    try:
        pending = set(index)
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in sorted(finished, key=index.__getitem__):
                yield index[fut], fut.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise ConfigError(f"backend='ray' needs the ray package: {RAY_INSTALL}") from None
    return ray


def _ray_jobs(
    ray: Any, fn: Callable[[J], R], jobs: list[J], workers: int | None, address: str | None
) -> Iterator[tuple[int, R]]:
    """Ray tasks, ``workers`` (None: all) in flight; a new one is submitted as soon as one finishes."""
    started = not ray.is_initialized()
    task = ray.remote(num_cpus=1)(fn)
    if started and address is None:  # a local instance: its workers inherit the thread variables
        with _single_threaded_children():
            # "local": a new instance even where `ray start` left a cluster on this machine
            ray.init(address="local", num_cpus=workers, include_dashboard=False, logging_level=logging.ERROR)
    else:  # a cluster's workers get them through the task's runtime env (about 2 s once, to set it up)
        if started:
            try:
                ray.init(address=address, logging_level=logging.ERROR)
            except (ConnectionError, ValueError) as exc:  # (Ray retries an unreachable one for about a minute)
                raise ConfigError(
                    f"address={address!r}: no Ray cluster to connect to ({exc}); start one with `ray start --head` "
                    "or give the address it printed"
                ) from None
        task = task.options(runtime_env={"env_vars": dict.fromkeys(THREAD_VARS, "1")})
    try:
        todo = iter(enumerate(jobs))
        pending: dict[Any, int] = {}

        def submit(k: int) -> None:
            for i, job in itertools.islice(todo, k):
                pending[task.remote(job)] = i

        submit(len(jobs) if workers is None else workers)
        try:
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                i = pending.pop(ready[0])
                result = ray.get(ready[0])
                submit(1)  # keep the workers busy while the caller handles the result
                yield i, result
        finally:
            for ref in pending:  # an exception or an early close: the rest is not wanted
                ray.cancel(ref, force=True)
    finally:
        if started:
            ray.shutdown()


__all__ = ["BACKENDS", "PARENT_POLL_S", "THREAD_VARS", "check_backend", "run_jobs", "watch_parent"]

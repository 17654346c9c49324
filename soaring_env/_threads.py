"""Row-parallel execution of the batched kernels on worker threads.

The compiled kernels of a batched step (the rollout, the post-step bookkeeping) treat every row
independently and are compiled with ``nogil=True``, so contiguous blocks of rows can run on several
threads at once. Each row is computed by the same code on the same inputs whatever block it lands
in, so results are bit-identical for any thread count.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

from soaring_env._validation import ConfigError

#: below this many rows per thread the hand-off (tens of microseconds) costs more than it saves
MIN_ROWS_PER_THREAD = 64
#: more threads than this is a mistake rather than a machine
MAX_THREADS = 256


def check_threads(value: object) -> int:
    """``value`` as a thread count (an integer >= 1), or a :class:`ConfigError` naming it."""
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_THREADS:
        raise ConfigError(f"num_threads={value!r} must be an integer in 1..{MAX_THREADS} (1: no worker threads)")
    return int(value)


class RowThreads:
    """Runs ``call(rows)`` on contiguous row blocks: one in the calling thread, the others on
    ``num_threads - 1`` worker threads (created once, kept until :meth:`close`)."""

    def __init__(self, num_threads: int = 1) -> None:
        self.num_threads = check_threads(num_threads)
        self._pool = ThreadPoolExecutor(self.num_threads - 1) if self.num_threads > 1 else None

    def run(self, n_rows: int, call: Callable[[slice], object]) -> None:
        """``call(slice(lo, hi))`` over blocks covering ``0 .. n_rows``; returns when all are done
        (an exception of any block is raised here)."""
        k = min(self.num_threads, n_rows // MIN_ROWS_PER_THREAD)
        if self._pool is None or k < 2:
            call(slice(0, n_rows))
            return
        edges = [n_rows * i // k for i in range(k + 1)]
        futures = [self._pool.submit(call, slice(edges[i], edges[i + 1])) for i in range(1, k)]
        try:
            call(slice(edges[0], edges[1]))
        finally:
            for f in futures:
                f.result()

    def close(self) -> None:
        """Stop the worker threads (idempotent); later calls run in the calling thread."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


#: the single-threaded runner, shared by every caller that asks for none
SERIAL = RowThreads(1)

__all__ = ["MAX_THREADS", "MIN_ROWS_PER_THREAD", "SERIAL", "RowThreads", "check_threads"]

"""Run-directory hygiene for the experiment and the evaluation: one writer per output folder, results
files whose errors name the file, and the scripts' common command-line checks (the worker
processes, which never outlive their parent, are :mod:`baselines.backends`'s).

* :func:`holds_dir_lock` -- a decorator: the function holds an exclusive ``fcntl.flock`` on
  ``<out>/.lock`` (the file holds the PID) while it runs; a second run into the same folder refuses
  to start with a :class:`ConfigError` naming the folder and the PID. The kernel drops the lock
  when its holder dies, even by SIGKILL, so a stale lock file never blocks a later run.
* :func:`read_json` -- ``json.loads`` of a file, with a :class:`ConfigError` naming the file.
* :func:`check_cli_args` -- the scripts' common command-line checks; :func:`add_backend_args` --
  their ``--backend``, ``--address`` and ``--workers`` options (:mod:`baselines.backends`).
"""

from __future__ import annotations

import functools
import inspect
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from baselines.backends import BACKENDS, check_backend
from soaring_env._validation import ConfigError

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: no locking
    fcntl = None  # type: ignore[assignment]

F = TypeVar("F", bound=Callable[..., Any])
LOCK_FILE = ".lock"


class DirLock:
    """An exclusive, non-blocking lock on ``<directory>/.lock``; :meth:`release` (or exit) drops it."""

    def __init__(self, directory: str | os.PathLike[str], what: str = "run") -> None:
        d = Path(directory)
        if d.exists() and not d.is_dir():
            raise ConfigError(f"output folder {str(d)!r} is a file; a directory is required")
        d.mkdir(parents=True, exist_ok=True)
        self.path = d / LOCK_FILE
        self._fh = open(self.path, "a+")
        if fcntl is None:
            return
        try:
            fcntl.flock(self._fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._fh.seek(0)
            holder = self._fh.read().strip() or "unknown"
            self._fh.close()
            raise ConfigError(
                f"output folder {str(d)!r} is in use by another {what} (PID {holder}, lock {str(self.path)!r}); "
                "wait for it to finish or choose another output folder"
            ) from None
        self._fh.seek(0)
        self._fh.truncate()
        self._fh.write(f"{os.getpid()}\n")
        self._fh.flush()

    def release(self) -> None:
        if not self._fh.closed:
            self._fh.close()  # closing the descriptor drops the flock

    def __enter__(self) -> DirLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def holds_dir_lock(directory_of: Callable[[inspect.BoundArguments], Any], what: str = "run") -> Callable[[F], F]:
    """Decorate a function so that it runs holding the :class:`DirLock` of the folder that
    ``directory_of(bound_arguments)`` names."""

    def wrap(fn: F) -> F:
        sig = inspect.signature(fn)

        @functools.wraps(fn)
        def locked(*args: Any, **kwargs: Any) -> Any:
            bound = sig.bind(*args, **kwargs)
            bound.apply_defaults()
            with DirLock(directory_of(bound), what):
                return fn(*args, **kwargs)

        return locked  # type: ignore[return-value]

    return wrap


def read_json(path: str | os.PathLike[str], what: str = "results file") -> Any:
    """The parsed JSON of ``path``; unreadable or corrupt files raise a :class:`ConfigError` naming it."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(
            f"{what} {str(path)!r} cannot be read ({type(exc).__name__}: {exc}); "
            "move it away (or start afresh) and run again"
        ) from None


def check_cli_args(
    parser: Any,
    args: Any,
    *,
    counts: tuple[str, ...] = (),
    seeds: tuple[str, ...] = (),
    positive: tuple[str, ...] = (),
    dirs: tuple[str, ...] = (),
) -> None:
    """The common command-line checks, answered with ``parser.error`` (usage, ``error:`` line, exit 2):
    ``counts`` >= 1 (``heldout`` may be 0), ``seeds`` >= 0 (an int or a list of ints), ``positive``
    > 0 and finite, ``dirs`` not pointing at an existing file. ``None`` values are not checked.
    Where ``args`` has a ``backend`` (:func:`add_backend_args`), the backend, ``--address`` and
    ``--workers`` are checked too (:func:`baselines.backends.check_backend`)."""
    if hasattr(args, "backend") and "workers" not in counts:
        counts = (*counts, "workers")
    for name in counts:
        v = getattr(args, name)
        low = 0 if name == "heldout" else 1
        if v is not None and v < low:
            parser.error(f"--{name.replace('_', '-')}={v} must be >= {low}")
    for name in seeds:
        v = getattr(args, name)
        for s in v if isinstance(v, list) else [v]:
            if s is not None and s < 0:
                parser.error(f"--{name.replace('_', '-')}: seed {s} must be >= 0")
    for name in positive:
        v = getattr(args, name)
        if v is not None and not (v > 0 and v < float("inf")):
            parser.error(f"--{name.replace('_', '-')}={v} must be a finite number > 0")
    for name in dirs:
        v = getattr(args, name)
        if v is not None and Path(v).exists() and not Path(v).is_dir():
            parser.error(f"--{name.replace('_', '-')}={str(v)!r} is a file; an output directory is required")
    if hasattr(args, "backend"):
        try:
            check_backend(args.backend, args.workers, args.address)
        except ConfigError as exc:
            parser.error(str(exc))


def cli_workers(args: Any, local_default: int) -> int | None:
    """``--workers`` as given; unset: ``local_default`` with ``--backend local``, None (every CPU of
    the cluster) with ``--backend ray``."""
    if args.workers is not None:
        return int(args.workers)
    return local_default if args.backend == "local" else None


def add_backend_args(parser: Any, workers_default: str) -> None:
    """Add ``--backend {local,ray}``, ``--address`` and ``--workers`` (default None: the script's
    local default, described by ``workers_default``, or every CPU of the Ray cluster)."""
    parser.add_argument(
        "--backend",
        choices=BACKENDS,
        default="local",
        help="where the jobs run: local worker processes (default) or a Ray cluster (pip install -e '.[ray]')",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="with --backend ray: a running cluster ('auto' or HEAD:6379 on a node of it; ray://HEAD:10001 "
        "from elsewhere, with pip install 'ray[client]'); default: a local Ray instance for this run",
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=None,
        help=f"jobs at a time (default: {workers_default} locally; every CPU of the cluster with --backend ray)",
    )


def progress_bar(total: int, initial: int, enabled: bool, desc: str, unit: str) -> Any:
    """A tqdm bar over ``total`` items of which ``initial`` are done, or None (disabled, or tqdm --
    an optional extra -- not installed)."""
    if not enabled:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return tqdm(total=total, initial=initial, desc=desc, unit=unit)

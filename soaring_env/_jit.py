"""Compilation flags shared by every numba kernel, and a cache key that covers their dependencies.

numba's on-disk cache (``cache=True``) checks only the source file of the function it compiles, not
the files of the functions and constants that function pulls in: after an edit to
``physics/thermals.py`` the rollout kernel in ``primitives.py`` would load its old machine code.
Importing this module (every kernel module does, before it defines a kernel) installs a cache
locator that adds a hash of *every* ``.py`` file of the kernel's top-level package that imports numba
(``soaring_env``, ``baselines``) to numba's source stamp: an edit to any of them makes every cached
kernel of that package stale, and numba recompiles and rewrites it. Rule for new kernels: a kernel
may use globals only from modules that import numba (those are the ones hashed).

It also says once per process, on stderr, when a kernel of these packages misses the on-disk cache
and is about to compile (:data:`COMPILE_NOTICE`): otherwise a first run sits silent for tens of seconds.
"""

from __future__ import annotations

import functools
import hashlib
import os
import sys
from pathlib import Path
from typing import Any, Literal

#: LLVM fast-math flags: contraction (FMA), reciprocal and reassociation only. Never ``nnan`` /
#: ``ninf``: the kernels test for NaN (e.g. "no previous airspeed") and must keep IEEE semantics there.
FASTMATH = {"contract", "arcp", "reassoc"}

#: numba's error model for every kernel of soaring_env: "numpy" makes ``a / b`` the plain IEEE division.
#: The default ("python") tests every divisor for zero to raise ZeroDivisionError, and that branch keeps
#: LLVM from vectorizing any loop that divides. The kernels guard their divisors themselves (validated
#: positive scales, durations and radii); a zero divisor gives inf, never an exception.
ERROR_MODEL: Literal["numpy"] = "numpy"

#: Top-level packages whose kernels get the package-wide cache key.
KERNEL_PACKAGES = ("soaring_env", "baselines")

#: Printed on stderr before the first compilation of one of our kernels in a process (a cold or
#: stale on-disk cache; a warm cache compiles nothing and prints nothing).
COMPILE_NOTICE = "soaring-env: compiling numba kernels (first run only, ~10-30 s; cached on disk after) ..."


@functools.cache
def package_source_hash(root: str) -> str:
    """SHA-256 over the paths and contents of every ``.py`` file under ``root`` that imports numba."""
    h = hashlib.sha256()
    for path in sorted(Path(root).rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        data = path.read_bytes()
        if b"from numba" in data or b"import numba" in data:
            h.update(str(path.relative_to(root)).encode() + b"\0" + data + b"\0")
    return h.hexdigest()


def _package_root(py_file: str) -> str | None:
    """The directory of the kernel package (``.../soaring_env``) that ``py_file`` lies in, if any."""
    p = Path(os.path.abspath(py_file))
    for parent in p.parents:
        if parent.name in KERNEL_PACKAGES and (parent / "__init__.py").is_file():
            if not (parent.parent / "__init__.py").is_file():  # the top-level package, not a namesake inside one
                return str(parent)
    return None


def _install_cache_key() -> None:
    """Put a locator in front of numba's own that wraps whichever of them would have been used and
    extends its source stamp with :func:`package_source_hash` (numba's documented extension point
    for cache locators is this list; with ``NUMBA_CACHE_LOCATOR_CLASSES`` set, the user's choice wins)."""
    try:
        from numba.core.caching import CacheImpl, _CacheLocator
    except ImportError:  # pragma: no cover - a numba without the locator machinery: nothing to extend
        return
    if any(getattr(c, "_soaring_env_key", False) for c in CacheImpl._locator_classes):
        return

    class PackageKeyLocator(_CacheLocator):
        """numba's locator for the function, with the package hash added to its source stamp."""

        _soaring_env_key = True

        def __init__(self, inner: Any, key: str) -> None:
            self._inner = inner
            self._key = key

        def ensure_cache_path(self) -> None:
            self._inner.ensure_cache_path()

        def get_cache_path(self) -> str:
            return self._inner.get_cache_path()

        def get_source_stamp(self) -> Any:
            return (self._inner.get_source_stamp(), self._key)

        def get_disambiguator(self) -> str:
            return self._inner.get_disambiguator()

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            root = _package_root(py_file)
            if root is None:
                return None
            for other in CacheImpl._locator_classes:
                if other is cls:
                    continue
                inner = other.from_function(py_func, py_file)  # type: ignore[attr-defined]
                if inner is not None:
                    return cls(inner, package_source_hash(root))
            return None

    CacheImpl._locator_classes.insert(0, PackageKeyLocator)


def _install_compile_notice() -> None:
    """Print :data:`COMPILE_NOTICE` when numba starts compiling one of our kernels.

    numba's dispatcher looks an overload up in the on-disk cache first and fires the documented
    ``"numba:compile"`` event (``numba.core.event``) only on a miss, just before it compiles: so
    the notice appears exactly when the cache is cold or stale, before the wait, and never from a
    warm cache. Compilations of callees and of later kernels in the same process stay silent.
    """
    try:
        from numba.core import event
    except ImportError:  # pragma: no cover - a numba without the event API: no notice
        return
    if globals().get("_notice_installed"):  # a reload re-runs this module in its old namespace
        return
    globals()["_notice_installed"] = True

    class CompileNotice(event.Listener):
        def __init__(self) -> None:
            self.shown = False

        def on_start(self, ev: Any) -> None:
            if self.shown:
                return
            func = getattr(ev.data.get("dispatcher"), "py_func", None)
            if str(getattr(func, "__module__", "")).split(".")[0] in KERNEL_PACKAGES:
                self.shown = True
                print(COMPILE_NOTICE, file=sys.stderr, flush=True)

        def on_end(self, ev: Any) -> None:
            pass

    event.register("numba:compile", CompileNotice())


_install_cache_key()
_install_compile_notice()

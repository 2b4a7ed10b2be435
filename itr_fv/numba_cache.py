"""Where the package's compiled numba kernels are cached: never inside the installed package.

numba's default (``cache=True`` with no ``NUMBA_CACHE_DIR``) writes the compiled kernels
into ``__pycache__`` beside the source. For an installed package that is
``site-packages/itr_fv/__pycache__``: files pip did not install and does not remove. After
``pip uninstall`` (or the uninstall that ``pip install -e`` does first) the folder
``site-packages/itr_fv/`` survives holding only that cache, and Python then imports it as an
empty namespace package that hides the editable install (``ImportError: cannot import name
'Materials' from 'itr_fv' (unknown location)``).

:func:`njit` is ``numba.njit(cache=True, ...)`` with the cache put in a per-user folder
instead: ``$NUMBA_CACHE_DIR`` when the user set it (numba's own setting, honoured as is),
else ``$ITR_CACHE_DIR/numba``, else ``$XDG_CACHE_HOME/itr-composites/numba`` (default
``~/.cache/itr-composites/numba``), else, when that cannot be written, a folder under the
system's temporary directory. numba keys the entries by source path, so an installed copy
and a checkout do not share (or invalidate) each other's kernels. numba's global setting is
changed only while the package's own kernels are being decorated.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numba
import numba.core.config as _numba_config

__all__ = ["cache_dir", "njit"]

_resolved: str | None = None


def _writable(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError:
        return False
    return True


def cache_dir() -> str:
    """The folder that holds the package's numba cache (created on first use)."""
    global _resolved
    if _resolved is not None:
        return _resolved
    if _numba_config.CACHE_DIR:
        _resolved = str(_numba_config.CACHE_DIR)
        return _resolved
    env = os.environ.get("ITR_CACHE_DIR")
    if env:
        candidates = [Path(env) / "numba"]
    else:
        xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
        candidates = [Path(xdg) / "itr-composites" / "numba"]
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    candidates.append(Path(tempfile.gettempdir()) / f"itr-composites-numba-{uid}")
    for path in candidates:
        if _writable(path):
            _resolved = str(path)
            return _resolved
    _resolved = ""  # nowhere writable: compile every time rather than write into the package
    return _resolved


def njit(**options) -> Callable:
    """``numba.njit(cache=True, **options)`` with the cache in :func:`cache_dir`."""
    def decorate(func: Callable) -> Callable:
        where = cache_dir()
        saved = _numba_config.CACHE_DIR
        _numba_config.CACHE_DIR = where
        try:
            return numba.njit(cache=bool(where), **options)(func)
        finally:
            _numba_config.CACHE_DIR = saved
    return decorate

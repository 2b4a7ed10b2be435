"""Safe file output: atomic writes and output-path checks.

Every file the package writes goes through :func:`atomic_path`: the content is written to
a temporary file in the destination folder and renamed onto the final name only when it is
complete (``os.replace`` is atomic on one file system). A run killed part way (SIGTERM,
SIGKILL, a full disk) therefore leaves either the previous file or no file under the final
name, never a truncated one. Who may write into a results folder, and its ``manifest.json``,
are :mod:`itr_fv.run_folder`'s business (it watches the writes made here).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

__all__ = ["output_file", "file_above", "atomic_path", "write_text", "sha256", "counted",
           "read_manifest", "read_toml", "watch_writes", "MANIFEST", "TMP_PREFIX"]

MANIFEST = "manifest.json"
#: Name prefix of the temporary file of a write in progress.
TMP_PREFIX = ".itr-partial-"
#: Called with the final path of every file :func:`atomic_path` has put in place.
_WATCHERS: list[Callable[[Path], None]] = []


def watch_writes(callback: Callable[[Path], None]) -> None:
    """Call ``callback(path)`` after every file :func:`atomic_path` puts in place (the run
    folders of :mod:`itr_fv.run_folder` record their files this way)."""
    if callback not in _WATCHERS:
        _WATCHERS.append(callback)


def output_file(path: str | os.PathLike, suffix: str | None = None,
                argument: str = "path") -> Path:
    """Check an output file name: not a folder, the right suffix; returns it as a Path.

    Raises
    ------
    ValueError
        If ``path`` is an existing directory, has another suffix than ``suffix``, or its
        parent exists and is not a directory.
    """
    p = Path(path)
    if suffix is not None and p.suffix.lower() != suffix:
        raise ValueError(f"{argument}: expected a {suffix} file name, got {str(p)!r}")
    if p.is_dir():
        raise ValueError(f"{argument}: {str(p)!r} is a folder; give a file name inside it")
    blocking = file_above(p)
    if blocking is not None:
        raise ValueError(f"{argument}: {str(blocking)!r} exists and is not a folder")
    return p


def file_above(path: str | os.PathLike) -> Path | None:
    """The nearest existing parent of ``path`` where that is not a folder (so nothing can be
    made below it), else None."""
    for parent in Path(path).parents:
        if parent.exists():
            return None if parent.is_dir() else parent
    return None


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Context manager giving a temporary path that becomes ``path`` on success.

    The temporary file lies in the destination folder (created if needed) and keeps the
    final suffix (writers such as VTK choose the format by it). On any exception, including
    KeyboardInterrupt and the SystemExit the command line raises on SIGTERM, it is removed
    and the final name is left as it was.
    """
    final = Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=TMP_PREFIX + final.stem + ".", suffix=final.suffix,
                               dir=final.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        if not tmp_path.exists() or tmp_path.stat().st_size == 0:
            raise OSError(f"{final}: the writer produced no output")
        os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes 0600; a plain open respects umask
        os.replace(tmp_path, final)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise
    for watcher in _WATCHERS:
        watcher(final)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write a text file atomically (UTF-8); returns its path."""
    final = Path(path)
    with atomic_path(final) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return final


def read_toml(path: str | os.PathLike, what: str) -> dict:
    """The table of a TOML file (a byte-order mark is fine); a ValueError naming the file
    when it is missing (``no such <what>``) or not TOML."""
    import tomllib

    p = Path(path)
    try:
        return tomllib.loads(p.read_text(encoding="utf-8-sig"))
    except FileNotFoundError:
        raise ValueError(f"{p}: no such {what}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{p}: not valid TOML ({exc})") from None


def sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's content."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_manifest(folder: str | os.PathLike) -> dict | None:
    """The manifest of a results folder, or None if there is none (or it is unreadable)."""
    p = Path(folder) / MANIFEST
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun`` in the number it takes: ``"1 worker"``, ``"3 workers"``, ``"0 workers"``
    (``plural``: where adding "s" is wrong, e.g. ``"entries"``)."""
    return f"{n} {noun if n == 1 else (plural or noun + 's')}"

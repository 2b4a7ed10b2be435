"""Output folders that belong to one command: claimed before anything is written, refused
when they hold anything else.

A results folder belongs to the run that claims it. :func:`claim` checks the folder before
any work and writes a *running* ``manifest.json`` into it: a signature (this package and the
command, e.g. ``itr reproduce``), the files the run has written so far and the sub-folders it
owns (a solve store). Every file then written into the folder through
:func:`itr_fv.io.atomic_path` is added to that manifest as it lands, so a run killed at any
moment still says which files are its own. :func:`itr_fv.io.write_manifest` closes the run
(state ``complete``, sizes and SHA-256 of every file).

What is refused, before anything is touched (:class:`FolderRefused`, one line):

- a folder that holds anything, but no manifest of this package (a user's own
  ``manifest.json`` included);
- a folder whose manifest was written by another command (``itr demo``'s folder given to
  ``itr identify``);
- a folder of the same command holding a file its manifest does not list, or a listed file
  changed since the run wrote it.

An empty or new folder is claimed; a folder of an earlier run of the same command is claimed
again: the files its manifest lists are removed (the new run writes them anew) and its owned
sub-folders are kept, which is how a killed run resumes its finished solves.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import threading
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from .io import MANIFEST, TMP_PREFIX, file_above, read_manifest, sha256, watch_writes, write_text

__all__ = ["FolderRefused", "PACKAGE", "check", "claim", "release", "claimed", "signature",
           "signature_of", "begin_run", "write_manifest", "versions"]

#: The package name a manifest's signature must carry.
PACKAGE = "itr-composites"
#: Foreign names listed in a refusal before "and N more".
_SHOWN = 3


class FolderRefused(ValueError):
    """An output folder that is not the run's to write into (one line, names the folder)."""


@dataclass
class _Run:
    folder: Path
    command: str
    files: dict[str, dict] = field(default_factory=dict)
    folders: set[str] = field(default_factory=set)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def manifest(self, state: str, body: dict | None = None) -> dict:
        return {"written_by": signature(self.command), "state": state,
                "updated": _now(), **(body or {}),
                "files": [{"path": n, **e} for n, e in self.files.items()],
                "folders": sorted(self.folders)}


_RUNS: dict[Path, _Run] = {}
_RUNS_LOCK = threading.Lock()


def signature(command: str) -> dict:
    """The signature a manifest of ``command`` carries: package, version, command."""
    from . import __version__
    return {"package": PACKAGE, "version": __version__, "command": command}


def signature_of(folder: str | os.PathLike) -> dict | None:
    """The signature of the manifest in ``folder`` (None: no manifest of this package)."""
    m = read_manifest(folder)
    sig = m.get("written_by") if isinstance(m, dict) else None
    if isinstance(sig, dict) and sig.get("package") == PACKAGE and \
            isinstance(sig.get("command"), str):
        return sig
    return None


def _names(items: list[str]) -> str:
    shown = ", ".join(items[:_SHOWN])
    return shown + (f" and {len(items) - _SHOWN} more" if len(items) > _SHOWN else "")


def _foreign(folder: Path, manifest: dict) -> list[str]:
    """Entries of ``folder`` that the run of ``manifest`` did not write, or changed since."""
    listed = {e.get("path"): e for e in manifest.get("files", []) if isinstance(e, dict)}
    owned = set(manifest.get("folders", []))
    out = []
    for entry in sorted(folder.iterdir()):
        name = entry.name
        if name == MANIFEST or name.startswith(TMP_PREFIX):
            continue
        if name in owned and entry.is_dir():
            continue
        known = listed.get(name)
        if known is None or not entry.is_file():
            out.append(name)
        elif known.get("sha256") and sha256(entry) != known["sha256"]:
            out.append(f"{name} (changed since itr wrote it)")
    return out


def check(folder: str | os.PathLike, command: str, *, argument: str = "--out") -> dict | None:
    """Whether ``command`` may write into ``folder``; writes nothing.

    Returns
    -------
    dict or None
        The earlier run's manifest (None: the folder is new or empty).

    Raises
    ------
    FolderRefused
        ``folder`` is a file, or holds anything that is not an earlier ``command`` run's.
    """
    path = Path(folder)
    shown = f"{argument}: {str(folder)!r}"
    if path.exists() and not path.is_dir():
        raise FolderRefused(f"{shown} is a file, not a folder")
    blocking = file_above(path)
    if blocking is not None:
        raise FolderRefused(f"{argument}: {str(blocking)!r} is a file, not a folder")
    if not path.is_dir() or not any(path.iterdir()):
        return None
    entries = sorted(e.name for e in path.iterdir() if not e.name.startswith(TMP_PREFIX))
    sig = signature_of(path)
    if sig is None:
        what = ("its manifest.json was not written by itr" if (path / MANIFEST).exists()
                else "it holds no itr manifest")
        raise FolderRefused(f"{shown} is not empty and {what} ({_names(entries)}); nothing "
                            "was changed: name a new or empty folder")
    if sig["command"] != command:
        raise FolderRefused(f"{shown} holds the output of '{sig['command']}', not of "
                            f"'{command}'; nothing was changed: name a new or empty folder")
    manifest = read_manifest(path) or {}
    foreign = _foreign(path, manifest)
    if foreign:
        raise FolderRefused(f"{shown} holds files the earlier '{command}' run did not write: "
                            f"{_names(foreign)}; nothing was changed: move them or name a "
                            "new folder")
    return manifest


def claim(folder: str | os.PathLike, command: str, *, folders: Iterable[str] = (),
          argument: str = "--out") -> dict | None:
    """Claim ``folder`` for a run of ``command`` (see the module's rules).

    Parameters
    ----------
    folder : path
        The output folder (created).
    command : str
        The command as a user types it, e.g. ``"itr reproduce"``.
    folders : iterable of str
        Sub-folders the run owns (kept from an earlier run, e.g. ``"solves"``).
    argument : str
        The argument the folder came from, for the messages.

    Returns
    -------
    dict or None
        The earlier run's manifest (None: the folder was new or empty).

    Raises
    ------
    FolderRefused
        Before anything is touched, see :func:`check`.
    """
    path = Path(folder).absolute()
    with _RUNS_LOCK:
        run = _RUNS.get(path)
    if run is not None and run.command == command:
        run.folders.update(folders)
        return None
    earlier = check(folder, command, argument=argument)
    path.mkdir(parents=True, exist_ok=True)
    run = _Run(path, command, folders=set(folders))
    if earlier is not None:
        run.folders.update(f for f in earlier.get("folders", []) if (path / f).is_dir())
        for entry in earlier.get("files", []):
            name = entry.get("path") if isinstance(entry, dict) else None
            if name and "/" not in name and "\\" not in name and name != MANIFEST:
                (path / name).unlink(missing_ok=True)
    for stale in path.glob(TMP_PREFIX + "*"):
        if stale.is_file():
            stale.unlink(missing_ok=True)
    with _RUNS_LOCK:
        _RUNS[path] = run
    _write(run, "running")
    return earlier


def claimed(folder: str | os.PathLike) -> str | None:
    """The command that holds ``folder`` in this process (None: not claimed)."""
    with _RUNS_LOCK:
        run = _RUNS.get(Path(folder).absolute())
    return None if run is None else run.command


def release(folder: str | os.PathLike) -> None:
    """Forget this process's claim on ``folder`` (its manifest stays as it is)."""
    with _RUNS_LOCK:
        _RUNS.pop(Path(folder).absolute(), None)


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def _write(run: _Run, state: str, body: dict | None = None) -> Path:
    data = run.manifest(state, body)
    return write_text(run.folder / MANIFEST, json.dumps(data, indent=2) + "\n")


def _entry(path: Path) -> dict:
    return {"bytes": path.stat().st_size, "sha256": sha256(path)}


def _on_written(final: Path) -> None:
    """Add a file that just landed to the manifest of the run whose folder holds it."""
    final = final.absolute()
    with _RUNS_LOCK:
        runs = list(_RUNS.values())
    for run in runs:
        try:
            rel = final.relative_to(run.folder)
        except ValueError:
            continue
        parts = rel.parts
        if not parts or parts == (MANIFEST,):
            return
        with run.lock:
            if len(parts) == 1:
                run.files[parts[0]] = _entry(final)
            elif parts[0] in run.folders:
                return
            else:
                run.folders.add(parts[0])
            _write(run, "running")
        return


watch_writes(_on_written)


def versions() -> dict[str, str]:
    """Versions of Python, this package and its main libraries."""
    from importlib import metadata
    out = {"python": platform.python_version()}
    for dist in (PACKAGE, "numpy", "scipy", "numba", "pyamg", "pyvista"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            continue
    return out


def begin_run(folder: str | os.PathLike, job: str, *, folders: Iterable[str] = (),
              argument: str = "--out") -> dict | None:
    """Claim ``folder`` for the run of ``itr <job>`` (:func:`claim`); a no-op where this
    process has already claimed it for that job (the command line claims before any work,
    the job's function again)."""
    return claim(folder, f"itr {job}", folders=folders, argument=argument)


def write_manifest(folder: str | os.PathLike, files: Sequence[str | os.PathLike],
                   inputs: Mapping[str, object], *, job: str,
                   argv: Sequence[str] | None = None) -> Path:
    """Close the run of ``itr <job>`` in ``folder``: its complete ``manifest.json``,
    written last; returns its path. The claim is released.

    Parameters
    ----------
    folder : path
        The results folder.
    files : sequence of paths
        Files of this run (inside ``folder``), listed first and in this order, then any
        other file the run wrote there; each with size and SHA-256.
    inputs : mapping
        The run's settings (JSON-serialisable).
    job : str
        The command after ``itr`` (``"reproduce"``, ``"demo"``, ...): the signature.
    argv : sequence of str, optional
        The command line (default ``sys.argv``).
    """
    command = f"itr {job}"
    path = Path(folder).absolute()
    with _RUNS_LOCK:
        run = _RUNS.get(path)
    if run is None or run.command != command:
        claim(path, command)
        with _RUNS_LOCK:
            run = _RUNS[path]
    body = {"created": _now(), "command": list(sys.argv if argv is None else argv),
            "inputs": dict(inputs), "versions": versions()}
    with run.lock:
        order = []
        for f in files:
            p = Path(f).absolute()
            if p.parent == path and p.name != MANIFEST:
                run.files[p.name] = _entry(p)
                order.append(p.name)
        names = list(dict.fromkeys(order)) + [n for n in run.files if n not in order]
        run.files = {n: run.files[n] for n in names}
        manifest = _write(run, "complete", body)
    release(path)
    return manifest

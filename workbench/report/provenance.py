"""Where a report came from: time, code revision, software versions, inputs."""

from __future__ import annotations

import hashlib
import os
import platform
import shlex
import subprocess
import sys
from datetime import datetime
from importlib import metadata
from pathlib import Path
from typing import Any, Iterable, Sequence

__all__ = ["provenance", "git_revision", "file_sha256", "PACKAGES"]

#: Distributions whose versions are recorded, in this order.
PACKAGES = ("workbench", "casadi", "control", "numpy", "scipy", "matplotlib")

_SOURCE = Path(__file__).resolve().parents[2]  # the folder holding the workbench package


def git_revision(path: str | os.PathLike | None = None, timeout: float = 5.0) -> str:
    """Short hash of the git checkout holding ``path``, with ``" (dirty)"`` if modified.

    Parameters
    ----------
    path : path-like, optional
        A folder inside the working tree; default the folder of the installed
        workbench sources.
    timeout : float
        Seconds allowed for each git call.

    Returns
    -------
    str
        ``"ef30144"``, ``"ef30144 (dirty)"`` when tracked files are modified or
        untracked files are not ignored, or ``"unknown (...)"`` saying why (no git,
        not a checkout), never an exception.
    """
    cwd = os.fspath(path) if path is not None else os.fspath(_SOURCE)

    def git(*args: str) -> str:
        out = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True,
                             timeout=timeout, check=True)
        return out.stdout.strip()

    try:
        rev = git("rev-parse", "--short", "HEAD")
    except FileNotFoundError:
        return "unknown (git not found)"
    except subprocess.TimeoutExpired:
        return "unknown (git did not answer)"
    except (subprocess.CalledProcessError, OSError):
        return "unknown (not a git checkout)"
    try:
        dirty = bool(git("status", "--porcelain"))
    except (subprocess.SubprocessError, OSError):
        return f"{rev} (status unknown)"
    return f"{rev} (dirty)" if dirty else rev


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes, hex digits."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 16), b""):
            h.update(chunk)
    return h.hexdigest()


def _version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        pass
    try:
        module = __import__(dist)
        return str(getattr(module, "__version__", "installed, version unknown"))
    except Exception:  # noqa: BLE001 - a broken package must not stop a report
        return "not installed"


def provenance(plant_file: str | os.PathLike | None = None,
               command_line: str | Sequence[str] | None = None,
               extra: Iterable[tuple[str, Any]] = (),
               packages: Sequence[str] = PACKAGES,
               repo: str | os.PathLike | None = None) -> tuple[tuple[str, Any], ...]:
    """Collect what is needed to reproduce a report, as ordered (label, value) pairs.

    Parameters
    ----------
    plant_file : path-like, optional
        Plant TOML file the design used; its path and SHA-256 are recorded (a file
        that cannot be read is recorded as such, not raised).
    command_line : str or sequence of str, optional
        The command that made the report; default ``sys.argv``.
    extra : iterable of (label, value)
        Further items (design settings, data files), appended in order.
    packages : sequence of str
        Distributions whose versions are recorded.
    repo : path-like, optional
        Folder of the git working tree to describe; default the workbench sources.

    Returns
    -------
    tuple of (str, value)
        ``date`` (ISO 8601, local time with offset), ``git revision``, ``python``,
        one item per package, ``platform``, ``plant file``, ``plant sha256``,
        ``command line``, then ``extra``.

    Examples
    --------
    >>> items = provenance(command_line=["python", "designs/situm_pd.py"])
    >>> [label for label, _ in items][:3]
    ['date', 'git revision', 'python']
    """
    items: list[tuple[str, Any]] = [
        ("date", datetime.now().astimezone().isoformat(timespec="seconds")),
        ("git revision", git_revision(repo)),
        ("python", f"{platform.python_version()} ({platform.python_implementation()})"),
    ]
    items += [(name, _version(name)) for name in packages]
    items.append(("platform", platform.platform()))
    if plant_file is not None:
        p = Path(plant_file)
        items.append(("plant file", str(p)))
        try:
            items.append(("plant sha256", file_sha256(p)))
        except OSError as exc:
            items.append(("plant sha256", f"unreadable: {exc.strerror or exc}"))
    if command_line is None:
        command_line = sys.argv
    if not isinstance(command_line, str):
        command_line = shlex.join(str(a) for a in command_line)
    items.append(("command line", command_line))
    items += [(str(label), value) for label, value in extra]
    return tuple(items)

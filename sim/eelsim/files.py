"""Writing output files whole and readable: atomic replacement that follows the user's umask.

An output is written to a temporary file beside it and renamed into place, so a reader (or a run
killed half-way, or a disk that fills up) never sees half a file. ``tempfile.mkstemp`` creates that
file with mode 0600 whatever the umask; :func:`atomic_writer` gives it the mode a plain ``open``
would have had (0666 less the umask), so other lab users can read recordings, checkpoints and
datasets. The host (``eelhost.files``) writes its outputs with these too.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

__all__ = ["atomic_write", "atomic_writer", "default_file_mode"]


def default_file_mode() -> int:
    """The mode ``open(path, "w")`` gives a new file: 0666 less the process's umask."""
    mask = os.umask(0o022)  # reading the umask means setting it; restore it at once
    os.umask(mask)
    return 0o666 & ~mask


@contextmanager
def atomic_writer(path: str | Path, mode: str = "w", **open_args: Any) -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path``; on success it replaces ``path`` whole.

    Parameters
    ----------
    path : str or Path
        The file to write (its folder is created).
    mode : str
        ``"w"`` (text) or ``"wb"`` (bytes).
    **open_args
        Passed to ``os.fdopen`` (``encoding``, ``newline``).

    Yields
    ------
    file
        The open temporary file; on an exception it is removed and ``path`` is left as it was
        (an ``OSError`` of the writing, such as a full disk, then names ``path``).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, default_file_mode())
        with os.fdopen(fd, mode, **open_args) as f:
            yield f
        os.replace(tmp, path)
    except OSError as err:
        Path(tmp).unlink(missing_ok=True)
        if err.filename is None:  # a write or flush: name the file, not the temporary
            raise OSError(err.errno, err.strerror, str(path)) from err
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write(path: str | Path, data: str | bytes) -> Path:
    """Write ``data`` (text or bytes) to ``path`` atomically (:func:`atomic_writer`); return it."""
    with atomic_writer(path, "wb" if isinstance(data, bytes) else "w") as f:
        f.write(data)
    return Path(path)

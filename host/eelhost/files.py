"""Writing output files whole and readable, and saying on one line when they cannot be written.

:func:`atomic_writer` and :func:`atomic_write` (from :mod:`eelsim.files`, which the twin's own
writer uses too): an output is written to a temporary file beside it and renamed into place, so a
reader (or a run killed half-way, or a full disk) never sees half a file, with the mode a plain
``open`` gives (0666 less the umask), so other lab users can read recordings, checkpoints and
datasets.

An output that cannot be written (a read-only folder, a full disk, ``--out`` naming a file where a
folder is meant, a closed or full stdout) is the user's situation, not a bug: :func:`output_failure`
tells such an ``OSError`` from others and words it on one line, and the command line prints that
line (docs/cli.md, "Outputs"). :func:`check_output_folder` and :func:`check_output_stem` try a
command's output place before any long work starts (creating nothing), so a read-only folder is
said at once, not after an hour of fitting.
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path

from eelhost.errors import UserError
from eelsim.files import atomic_write, atomic_writer, default_file_mode

__all__ = [
    "OutputError",
    "replace_marked_block",
    "atomic_write",
    "atomic_writer",
    "check_output_folder",
    "check_output_stem",
    "default_file_mode",
    "output_failure",
]

# The errors of writing an output that come from where it is written, not from eelbot: each with
# what the user can do about it.
OUTPUT_ERRNOS = {
    errno.EACCES: "permission denied (a read-only or another user's folder)",
    errno.EPERM: "not permitted",
    errno.EROFS: "the file system is read-only",
    errno.ENOSPC: "no space left on the device (the disk is full)",
    errno.EDQUOT: "the disk quota is used up",
    errno.EFBIG: "the file is too large for the file system",
    errno.EISDIR: "a folder is there, where a file is to be written",
    errno.ENOTDIR: "a file is there, where a folder is needed",
    errno.EEXIST: "a file is there, where a folder is needed",
    errno.ENAMETOOLONG: "the name is too long",
    errno.EPIPE: "the reader went away (a closed pipe)",
}


class OutputError(UserError, OSError):
    """An output that cannot be written; the message names the file or folder and why."""


def output_failure(err: BaseException) -> str | None:
    """The one-line account of an output that could not be written, or None for other errors.

    Parameters
    ----------
    err : BaseException
        Any exception; only an ``OSError`` whose errno is one of :data:`OUTPUT_ERRNOS` counts.

    Returns
    -------
    str or None
        ``cannot write PATH: why`` (``an output`` when the error names no file; the command line
        says ``stdout`` when that is what cannot be written).
    """
    if isinstance(err, OutputError):
        return str(err)
    if not isinstance(err, OSError) or err.errno not in OUTPUT_ERRNOS:
        return None
    where = err.filename if err.filename is not None else "an output"
    return f"cannot write {where}: {OUTPUT_ERRNOS[err.errno]}"


def check_output_folder(folder: str | Path, option: str = "--out") -> Path:
    """Check, before any work, that files can be written in ``folder``; create nothing.

    The folder itself, or the nearest folder above it that exists (the writers create the rest
    when they write), must be a folder in which a file can be created: a small file is written
    and removed there. Nothing is left behind, so a command refused later for another reason
    leaves no empty output folder.

    Parameters
    ----------
    folder : str or Path
        The output folder.
    option : str
        The option it came from, for the message.

    Returns
    -------
    Path
        The folder.

    Raises
    ------
    OutputError
        ``--out`` (or a folder above it) names a file, or the place cannot be written
        (read-only, full, not permitted).
    """
    folder = Path(folder)
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():  # the folder, or one above it, is a file
        raise OutputError(f"{option}: {existing} is a file, not a folder; choose another {option}")
    try:
        fd, probe = tempfile.mkstemp(dir=existing, prefix=".eelbot-write-check.", suffix=".tmp")
        try:
            os.write(fd, b"x")
        finally:
            os.close(fd)
            Path(probe).unlink(missing_ok=True)
    except OSError as err:
        why = OUTPUT_ERRNOS.get(err.errno or 0, err.strerror or str(err))
        raise OutputError(f"{option}: cannot write in {folder}: {why}") from None
    return folder


def check_output_stem(stem: str | Path, suffixes: tuple[str, ...] = (), option: str = "--out") -> Path:
    """Check the folder of an output path without extension (``--out out/run/path1``), before work.

    Parameters
    ----------
    stem : str or Path
        The output path without extension.
    suffixes : tuple of str
        The extensions written beside it; none of ``stem + suffix`` may be a folder.
    option : str
        The option it came from.

    Returns
    -------
    Path
        The stem.

    Raises
    ------
    OutputError
        As :func:`check_output_folder`, or a ``stem + suffix`` that is a folder.
    """
    stem = Path(stem)
    if stem.name in ("", ".", ".."):
        raise OutputError(f"{option}: {stem} names a folder; give a path without extension, "
                          f"such as {stem / 'run'}")
    check_output_folder(stem.parent, option)
    for suffix in suffixes:
        target = stem.with_name(stem.name + suffix)
        if target.is_dir():
            raise OutputError(f"{option}: {target} is a folder, where a file is to be written")
    return stem


def replace_marked_block(path: str | Path, begin: str, end: str, block: str) -> None:
    """Put ``block`` (which starts with ``begin`` and ends with ``end``) in place of the page's.

    A benchmark writes its figures into a docs page between two marker lines; the rest of the
    page, written by hand, is kept. The block is appended when the page has no markers yet (or
    does not exist). The page is written whole (:func:`atomic_write`).

    Parameters
    ----------
    path : str or Path
        The markdown page.
    begin, end : str
        The marker lines.
    block : str
        The new block, markers included.
    """
    path = Path(path)
    text = path.read_text() if path.exists() else ""
    if begin in text and end in text:
        head, rest = text.split(begin, 1)
        text = head + block + rest.split(end, 1)[1]
    else:
        text = text.rstrip("\n") + ("\n\n" if text else "") + block + "\n"
    atomic_write(path, text)

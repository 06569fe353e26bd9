"""Output folders written as one transaction, and output files checked before the work:
the core's transaction (``_core.formats.OutputFolder``, the one calibproj-native uses),
with what Python adds to it (failed writes reported as ``OutputError``, log messages
naming the final folder).

``OutputFolder(path, force=...)`` is what every command that writes a folder goes
through (``calibrate``, ``generate``, ``simulate``, ``demo``):

1. ``open()``, before any long work, checks that the folder can be written, and says
   so in one line naming the path when it cannot: ``path`` is an existing file, its
   parent folder is not writable (permissions, read-only file system), the disk is
   full (less than ``MIN_FREE_BYTES`` free, or a probe write fails), the folder
   already holds results and ``force`` is off, or it holds other files (which
   ``force`` never deletes). It takes a lock (``flock``
   on ``.<name>.lock`` beside the folder), so that a second run on the same folder
   fails at once instead of mixing its files with the first one's, and creates
   the staging folder ``.<name>.tmp-XXXXXX`` beside it;
2. the work writes into ``staging``;
3. ``commit()`` moves the staging folder into place in two renames (the previous
   folder aside, the new one in), then deletes the previous folder: ``force`` replaces
   the whole previous folder, never a part of it. Leaving the ``with`` block
   without an exception commits; an exception or an interruption deletes the staging
   folder and leaves the previous folder as it was. Log messages made while the work
   writes name the final folder, not the staging one (``messages_naming``).

A run killed outright (power cut, ``kill -9``) leaves at most a hidden staging folder,
which the next run on the same path deletes; a folder at ``path`` is always a
complete one. ``OutputFile`` does the checks and the locking for a command that writes
single files (``detect``), whose files are each written atomically.
"""

from __future__ import annotations

import errno
import logging
import os
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path
from types import TracebackType

from calibproj import _core

# Below this much free space on the disk of the output, a run is refused before it
# starts (the results of a calibration take a few megabytes).
MIN_FREE_BYTES = _core.formats.min_free_bytes

# An output path that cannot be written, with the path named in the message (a ValueError).
OutputError = _core.formats.OutputError
# Another run (Python or native) holds the lock of the same output (a RuntimeError).
OutputBusyError = _core.formats.OutputBusyError

# Errors of a write whatever the file: the disk or the quota is full, the file system
# is read-only, the file too large.
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG})


def _is_write_failure(error: OSError, folder: Path) -> bool:
    """An error of writing into ``folder`` (rather than of reading an input)."""
    if error.errno in WRITE_ERRNOS:
        return True
    filename = error.filename
    if filename is None:
        return False
    return Path(os.fsdecode(filename)).resolve().is_relative_to(folder.resolve())


def _described(error: OSError) -> str:
    """``No space left on device`` rather than ``[Errno 28] No space left on device: 'x'``."""
    return error.strerror or str(error)


class OutputFolder:
    """A folder written as one transaction (module docstring).

    Args:
        path: the folder to write.
        force: replace an existing folder that holds something; without it such a
            folder is an error (``OutputError``, naming ``--force``).
        signature: files of which at least one marks a folder this command wrote; a
            non-empty folder holding none of them is refused, with ``force`` or without
            (so that ``--force`` never deletes a folder of other files). Empty: any
            existing folder may be replaced with ``force``.
        min_free_bytes: the free space below which ``open()`` refuses (default
            ``MIN_FREE_BYTES``).
    """

    def __init__(self, path: str | os.PathLike, *, force: bool = False, signature: Sequence[str] = (),
                 min_free_bytes: int = MIN_FREE_BYTES) -> None:
        self._core = _core.formats.OutputFolder(path, force=force, signature=list(signature),
                                                min_free_bytes=min_free_bytes)
        self.committed = False

    @property
    def path(self) -> Path:
        """The folder (where a symbolic link leads, once open)."""
        return Path(self._core.path)

    @property
    def staging(self) -> Path | None:
        """The staging folder while it is open, else None."""
        staging = self._core.staging
        return None if staging is None else Path(staging)

    def open(self) -> OutputFolder:
        """Check, lock, and create the staging folder (before any long work)."""
        self._core.open()
        return self

    @contextmanager
    def writing(self) -> Iterator[Path]:
        """The staging folder; a write that fails in it (a full disk, ...) is reported as
        an ``OutputError`` naming the output folder. Other errors (an input file that
        cannot be read, ...) pass unchanged."""
        staging = self.staging
        if staging is None:
            raise RuntimeError("OutputFolder.writing() before open()")
        try:
            with messages_naming(staging, self.path):
                yield staging
        except OSError as error:
            if not _is_write_failure(error, staging):
                raise
            raise OutputError(f"{self.path}: cannot write the output ({_described(error)})") from None

    def commit(self) -> Path:
        """Move the staging folder into place; returns the folder's path."""
        if not self.committed:
            self._core.commit()
            self.committed = True
        return self.path

    def abort(self) -> None:
        """Delete the staging folder and release the lock; the previous folder stays."""
        self._core.abort()

    def __enter__(self) -> OutputFolder:
        return self if self.staging is not None else self.open()

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:
        if kind is None:
            self.commit()
        else:
            self.abort()


@contextmanager
def messages_naming(staging: Path, final: Path) -> Iterator[None]:
    """Log messages made while the block runs name ``final`` where they would name
    ``staging``: what a run reports writing (``report written: ...``) is named where
    the user will find it, not in a staging folder that is gone when the run ends.

    The logging module's record factory is wrapped for the block (from any thread);
    nested blocks (the demo's folder holds the results' staging folder) rename the
    innermost staging folder first."""
    pairs = {str(staging): str(final)}
    with suppress(OSError):
        pairs[str(staging.resolve())] = str(final.resolve())
    pairs = dict(sorted(pairs.items(), key=lambda pair: -len(pair[0])))  # longest first

    def own(message: str) -> str:
        for old, new in pairs.items():
            message = message.replace(old, new)
        return message

    previous = logging.getLogRecordFactory()
    outer = getattr(previous, "rename", None)
    base = getattr(previous, "base", previous)
    rename = own if outer is None else (lambda message: outer(own(message)))

    def factory(*args: object, **kwargs: object) -> logging.LogRecord:
        record = base(*args, **kwargs)
        try:
            message = record.getMessage()
        except (TypeError, ValueError):  # a malformed call: logging reports it when it emits
            return record
        renamed = rename(message)
        if renamed != message:
            record.msg, record.args = renamed, None
        return record

    factory.rename = rename  # type: ignore[attr-defined]
    factory.base = base  # type: ignore[attr-defined]
    logging.setLogRecordFactory(factory)
    try:
        yield
    finally:
        if logging.getLogRecordFactory() is factory:
            logging.setLogRecordFactory(previous)


class OutputFile:
    """The checks and the lock of ``OutputFolder`` for commands that write single files.

    ``open()`` fails in one line naming the path when ``path`` is an existing folder,
    one of the run's ``inputs``, an existing file and ``force`` is off, its folder
    cannot be written, the disk is full, or another run holds its lock; ``writing()``
    reports a failed write the same way; ``close()`` releases the lock.
    """

    def __init__(self, path: str | os.PathLike, *, force: bool = False,
                 inputs: Sequence[str | os.PathLike] = (), min_free_bytes: int = MIN_FREE_BYTES) -> None:
        self._core = _core.formats.OutputFile(path, force=force, inputs=list(inputs), min_free_bytes=min_free_bytes)

    @property
    def path(self) -> Path:
        return Path(self._core.path)

    def open(self) -> OutputFile:
        self._core.open()
        return self

    @contextmanager
    def writing(self) -> Iterator[Path]:
        """The path; a write that fails (a full disk, ...) is reported as an
        ``OutputError`` naming it."""
        try:
            yield self.path
        except OSError as error:
            if not _is_write_failure(error, self.path.parent):
                raise
            raise OutputError(f"{self.path}: cannot write ({_described(error)})") from None

    def close(self) -> None:
        self._core.close()

    def __enter__(self) -> OutputFile:
        return self.open()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

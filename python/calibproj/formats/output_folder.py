"""Output folders written as one transaction, and output files checked before the work.

``OutputFolder(path, force=...)`` is what every command that writes a folder goes
through (``calibrate``, ``generate``, ``simulate``, ``demo``):

1. ``open()``, before any long work, checks that the folder can be written, and says
   so in one line naming the path when it cannot: ``path`` is an existing file, its
   parent folder is not writable (permissions, read-only file system), the disk is
   full (less than ``MIN_FREE_BYTES`` free, or a probe write fails), the folder
   already holds results and ``force`` is off, or it holds other files (which
   ``force`` never deletes). It takes a lock (``fcntl.flock``
   on ``.<name>.lock`` beside the folder), so that a second run on the same folder
   fails at once instead of mixing its files with the first one's, and creates
   the staging folder ``.<name>.tmp-XXXXXXXX`` beside it;
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

import array
import errno
import fcntl
import logging
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path
from types import TracebackType

# Below this much free space on the disk of the output, a run is refused before it
# starts (the results of a calibration take a few megabytes).
MIN_FREE_BYTES = 8 * 1024 * 1024
PROBE_PREFIX = ".calibproj-probe-"
PROBE_BYTES = 64 * 1024
# Linux's inode flags (linux/fs.h): FS_IOC_GETFLAGS reads them.
_FS_IOC_GETFLAGS = 0x80086601
_FS_IMMUTABLE_FL = 0x10
_FS_APPEND_FL = 0x20
PREVIOUS = "previous"  # the previous folder, inside the folder it is moved aside to


class OutputError(ValueError):
    """An output path that cannot be written, with the path named in the message."""


class OutputBusyError(RuntimeError):
    """Another run holds the lock of the same output."""


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


class _Lock:
    """An exclusive ``flock`` on a lock file, taken without waiting."""

    def __init__(self, path: Path, target: Path) -> None:
        self.path = path
        self.target = target
        self.fd: int | None = None

    def acquire(self) -> None:
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
            except OSError as error:
                raise OutputError(f"{self.target}: cannot write in {self.target.parent} "
                                  f"({_described(error)})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as error:
                os.close(fd)
                if error.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise OutputBusyError(f"{self.target}: another calibproj run is writing it (lock held on "
                                          f"{self.path}); wait for it to end or choose another output") from None
                raise OutputError(f"{self.target}: cannot lock {self.path} ({_described(error)})") from None
            # The file may have been unlinked by the run that held it just before:
            # then the lock is on a file nobody else sees, and is taken again.
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if same:
                self.fd = fd
                return
            os.close(fd)

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            self.path.unlink(missing_ok=True)
        finally:
            os.close(self.fd)
            self.fd = None


def _require_replaceable(path: Path) -> None:
    """OutputError when ``path`` carries the immutable or append-only flag (chattr +i,
    +a): it could not be renamed or replaced, which the final move of a run would find
    only after all the work."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK)
    except OSError:
        return
    try:
        flags = array.array("i", [0])
        fcntl.ioctl(fd, _FS_IOC_GETFLAGS, flags, True)
    except OSError:  # a file system without these flags
        return
    finally:
        os.close(fd)
    if flags[0] & (_FS_IMMUTABLE_FL | _FS_APPEND_FL):
        raise OutputError(f"{path}: cannot be replaced (it is immutable or append-only; chattr -i -a lifts that)")


def _missing_folders(folder: Path) -> list[Path]:
    """The folders on the way to ``folder`` that do not exist yet, deepest first: those a
    run creates for its output, and removes again when it ends without writing into them."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


def _remove_empty_folders(folders: list[Path]) -> None:
    """Remove the folders that are still empty, deepest first (one that holds the output,
    or anything else, stays, and so do those above it)."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            return


def _check_parent_made(target: Path, created: list[Path]) -> Path:
    """``_check_parent``, the folders it made (``created``) removed again when it fails."""
    try:
        return _check_parent(target)
    except BaseException:
        _remove_empty_folders(created)
        raise


def _check_parent(target: Path) -> Path:
    """Create the parent folder if needed; OutputError when it cannot be written or the disk is full."""
    parent = target.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputError(f"{target}: {parent} is not a folder") from None
    except OSError as error:
        raise OutputError(f"{target}: cannot create {parent} ({_described(error)})") from None
    if not parent.is_dir():
        raise OutputError(f"{target}: {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{target}: cannot write in {parent} (permission denied)")
    try:
        stats = os.statvfs(parent)
    except OSError as error:
        raise OutputError(f"{target}: cannot inspect {parent} ({_described(error)})") from None
    if stats.f_flag & os.ST_RDONLY:
        raise OutputError(f"{target}: cannot write in {parent} (read-only file system)")
    free = stats.f_bavail * stats.f_frsize
    if free < MIN_FREE_BYTES:
        raise OutputError(f"{target}: the disk is full ({free / 2**20:.1f} MiB free in {parent}, "
                          f"{MIN_FREE_BYTES / 2**20:.0f} MiB needed to start)")
    return parent


def _probe(folder: Path, target: Path) -> None:
    """Write and delete a small file in ``folder``: OutputError naming ``target`` if it fails."""
    try:
        with tempfile.TemporaryFile(dir=folder, prefix=PROBE_PREFIX) as handle:
            handle.write(b"\0" * PROBE_BYTES)
            handle.flush()
            os.fsync(handle.fileno())
    except OSError as error:
        raise OutputError(f"{target}: cannot write ({_described(error)})") from None


@contextmanager
def _signals_held() -> Iterator[None]:
    """SIGINT and SIGTERM held back (delivered afterwards) around a few renames."""
    held = {signal.SIGINT, signal.SIGTERM}
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


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
    """

    def __init__(self, path: str | os.PathLike, *, force: bool = False, signature: Sequence[str] = ()) -> None:
        self.path = Path(path)
        self.force = force
        self.signature = tuple(signature)
        self.staging: Path | None = None
        self.committed = False
        self._lock: _Lock | None = None
        self._created: list[Path] = []  # folders made for it, deepest first

    # -- opening ----------------------------------------------------------------------

    def open(self) -> OutputFolder:
        """Check, lock, and create the staging folder (before any long work)."""
        if self.path.is_symlink():
            self.path = self.path.resolve()
        if self.path.exists() and not self.path.is_dir():
            raise OutputError(f"{self.path}: exists and is not a folder")
        self._created = _missing_folders(self.path.parent)
        parent = _check_parent_made(self.path, self._created)
        self._lock = _Lock(parent / f".{self.path.name}.lock", self.path)
        self._lock.acquire()
        try:
            self._recover(parent)
            self._check_existing()
            self.staging = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.tmp-", dir=parent))
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(self.staging, 0o777 & ~umask)  # mkdtemp makes 0700
            _probe(self.staging, self.path)
        except OSError as error:
            self.abort()
            raise OutputError(f"{self.path}: cannot write in {parent} ({_described(error)})") from None
        except BaseException:
            self.abort()
            raise
        return self

    def _recover(self, parent: Path) -> None:
        """Tidy what a run killed outright left (we hold the lock): its staging folders
        go; a previous folder moved aside but never replaced goes back in place."""
        for stale in parent.glob(f".{self.path.name}.tmp-*"):
            shutil.rmtree(stale, ignore_errors=True)
        for aside in sorted(parent.glob(f".{self.path.name}.old-*")):
            if not self.path.exists() and (aside / PREVIOUS).is_dir():
                os.rename(aside / PREVIOUS, self.path)
            shutil.rmtree(aside, ignore_errors=True)

    def _check_existing(self) -> None:
        if not self.path.is_dir():
            return
        content = sorted(p.name for p in self.path.iterdir())
        if not content:
            _require_replaceable(self.path)
            return
        if self.signature:
            found = [name for name in self.signature if (self.path / name).exists()]
            if not found:
                shown = ", ".join(content[:4]) + (", ..." if len(content) > 4 else "")
                raise OutputError(f"{self.path}: is not empty ({shown}) and holds no output of this command; "
                                  f"choose another folder")
            if not self.force:
                raise OutputError(f"{self.path}: already holds results ({', '.join(found)}); "
                                  f"use --force to overwrite them")
        elif not self.force:
            raise OutputError(f"{self.path}: already exists; use --force to replace it")
        _require_replaceable(self.path)

    # -- writing ----------------------------------------------------------------------

    @contextmanager
    def writing(self) -> Iterator[Path]:
        """The staging folder; a write that fails in it (a full disk, ...) is reported as
        an ``OutputError`` naming the output folder. Other errors (an input file that
        cannot be read, ...) pass unchanged."""
        if self.staging is None:
            raise RuntimeError("OutputFolder.writing() before open()")
        staging = self.staging
        try:
            with messages_naming(staging, self.path):
                yield staging
        except OSError as error:
            if not _is_write_failure(error, staging):
                raise
            raise OutputError(f"{self.path}: cannot write the output ({_described(error)})") from None

    def commit(self) -> Path:
        """Move the staging folder into place; returns the folder's path."""
        if self.committed:
            return self.path
        if self.staging is None:
            raise RuntimeError("OutputFolder.commit() before open()")
        aside = None
        try:
            try:
                with _signals_held():
                    if self.path.exists():
                        aside = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.old-", dir=self.path.parent))
                        os.rename(self.path, aside / PREVIOUS)
                    try:
                        os.rename(self.staging, self.path)
                    except OSError:
                        if aside is not None:
                            os.rename(aside / PREVIOUS, self.path)
                        raise
                    self.committed = True
                    self.staging = None
                    _sync_folder(self.path.parent)
            except OSError as error:
                raise OutputError(f"{self.path}: cannot move the output into place ({_described(error)})") from None
            finally:
                if aside is not None and (self.committed or not (aside / PREVIOUS).exists()):
                    shutil.rmtree(aside, ignore_errors=True)
        finally:
            self.abort()
        return self.path

    def abort(self) -> None:
        """Delete the staging folder and release the lock; the previous folder stays."""
        if self.staging is not None and not self.committed:
            shutil.rmtree(self.staging, ignore_errors=True)
            self.staging = None
        self._release()

    def _release(self) -> None:
        if self._lock is not None:
            self._lock.release()
            self._lock = None
        _remove_empty_folders(self._created)

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


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.samefile(b)
    except OSError:  # b is gone or unreadable: not the same file
        return False


def _sync_folder(folder: Path) -> None:
    """Make the renames in ``folder`` durable."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


class OutputFile:
    """The checks and the lock of ``OutputFolder`` for commands that write single files.

    ``open()`` fails in one line naming the path when ``path`` is an existing folder,
    one of the run's ``inputs``, an existing file and ``force`` is off, its folder
    cannot be written, the disk is full, or another run holds its lock; ``writing()``
    reports a failed write the same way; ``close()`` releases the lock.
    """

    def __init__(self, path: str | os.PathLike, *, force: bool = False,
                 inputs: Sequence[str | os.PathLike] = ()) -> None:
        self.path = Path(path)
        self.force = force
        self.inputs = [Path(p) for p in inputs]
        self._lock: _Lock | None = None
        self._created: list[Path] = []  # folders made for it, deepest first

    def open(self) -> OutputFile:
        if self.path.is_dir():
            raise OutputError(f"{self.path}: is a folder; give the path of a file")
        if self.path.exists():
            if any(_same_file(self.path, given) for given in self.inputs):
                raise OutputError(f"{self.path}: is an input of this run; write the output elsewhere")
            if not self.force:
                raise OutputError(f"{self.path}: exists (use --force to replace it)")
            _require_replaceable(self.path)
        self._created = _missing_folders(self.path.parent)
        parent = _check_parent_made(self.path, self._created)
        self._lock = _Lock(parent / f".{self.path.name}.lock", self.path)
        self._lock.acquire()
        try:
            _probe(parent, self.path)
        except BaseException:
            self.close()
            raise
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
        if self._lock is not None:
            self._lock.release()
            self._lock = None
        _remove_empty_folders(self._created)

    def __enter__(self) -> OutputFile:
        return self.open()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

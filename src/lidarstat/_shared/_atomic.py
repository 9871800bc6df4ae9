"""Atomic file output that leaves nothing behind, even when the process is killed.

On Linux the data goes to an unnamed ``O_TMPFILE`` file in the target's folder: it has no
name until it is complete, so the kernel frees it whatever way the process ends (SIGKILL
included). When complete it is linked into place: directly when the target is absent,
else under a hidden name renamed onto the target at once (the only moment a name exists).
Where ``O_TMPFILE`` is unsupported (other systems, some file systems) a hidden named
temporary beside the target is used instead and removed on any exit that unwinds
(exceptions, SIGTERM and Ctrl-C through :func:`lidarstat.cli.main`).
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_path", "output_group", "unnamed_file"]


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _open_unnamed(directory: Path, path: Path) -> int | None:
    """An ``O_TMPFILE`` descriptor in `directory` that can be reopened by path, or None.

    Errors (folder missing, not writable) name `path`, the file the caller asked for.
    """
    flag = getattr(os, "O_TMPFILE", None)
    if flag is None:
        return None
    try:
        fd = os.open(directory, flag | os.O_RDWR | getattr(os, "O_CLOEXEC", 0), 0o666)
    except OSError as exc:
        if exc.errno in (errno.EOPNOTSUPP, errno.EISDIR, errno.EINVAL, errno.ENOSYS):
            return None  # file system or kernel without O_TMPFILE
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    try:  # writers reopen it through /proc: check that works here (a umask of 077 ...)
        os.close(os.open(_proc_path(fd), os.O_WRONLY))
    except OSError:
        os.close(fd)
        return None
    return fd


def _proc_path(fd: int) -> str:
    return f"/proc/{os.getpid()}/fd/{fd}"


def _linkat(fd: int, dst: Path, shown: Path | None = None) -> None:
    """``linkat(2)`` of the unnamed file `fd` to `dst`, following the /proc magic link.

    ``os.link`` calls ``link(2)``, which would link the /proc entry itself (EXDEV); the
    ``AT_SYMLINK_FOLLOW`` form needs no privilege.
    """
    global _LIBC
    if _LIBC is None:
        import ctypes

        _LIBC = ctypes.CDLL(None, use_errno=True)
    if _LIBC.linkat(_AT_FDCWD, os.fsencode(_proc_path(fd)), _AT_FDCWD, os.fsencode(dst),
                    _AT_SYMLINK_FOLLOW) != 0:
        import ctypes

        code = ctypes.get_errno()
        raise OSError(code, os.strerror(code), str(shown or dst))


_LIBC = None
_AT_FDCWD = -100
_AT_SYMLINK_FOLLOW = 0x400
#: linkat errors that mean "not here" (no /proc, a file system or sandbox refusing it)
_LINK_REFUSED = (errno.EXDEV, errno.EPERM, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL,
                 errno.ENOENT)


def _hidden_name(path: Path) -> Path:
    return path.parent / f".{path.name}.{os.urandom(6).hex()}.tmp"


def _link_into_place(fd: int, path: Path) -> None:
    """Give the unnamed file of `fd` the name `path` (replacing any file there)."""
    try:  # the target absent: one link, nothing transient
        _linkat(fd, path)
        return
    except FileExistsError:
        pass
    except OSError as exc:
        if exc.errno not in _LINK_REFUSED:
            raise
        _copy_into_place(fd, path)  # linking refused here: copy into a named temporary
        return
    while True:  # a fresh hidden name, then an atomic rename over the target
        tmp = _hidden_name(path)
        try:
            _linkat(fd, tmp, path)
            break
        except FileExistsError:
            continue
    _replace(tmp, path)


def _replace(tmp: Path, path: Path) -> None:
    try:
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _copy_into_place(fd: int, path: Path) -> None:
    """Copy the unnamed file's data to a new hidden file and rename that onto `path`."""
    tmp = _hidden_name(path)
    try:
        out = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    try:
        with open(fd, "rb", closefd=False) as src, open(out, "wb") as dst:
            src.seek(0)
            while block := src.read(1 << 22):
                dst.write(block)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _replace(tmp, path)


def _reraise(exc: OSError, tmp: str, path: Path):
    """Re-raise `exc`, naming `path` where it names the temporary `tmp`."""
    if exc.filename is not None and str(exc.filename) == tmp and exc.errno is not None:
        raise type(exc)(exc.errno, exc.strerror, str(path)) from exc
    raise exc


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, suffix: str | None = None) -> Iterator[Path]:
    """Yield a path to write; its content appears at `path` only if the block succeeds.

    The yielded path names an unnamed temporary file in `path`'s folder (on Linux,
    ``/proc/<pid>/fd/<n>`` of an ``O_TMPFILE`` file): writers open it by name as usual,
    truncating or appending, but it has no suffix, so they must be told the format
    explicitly (laspy ``do_compress``, matplotlib ``format``, NumPy through a file object).
    If the block raises, or the process dies, `path` is left as it was and no temporary
    remains. Errors naming the temporary are re-raised naming `path`. Inside an
    :func:`output_group` the file appears when the group ends.

    Parameters
    ----------
    path : path-like
        Final destination.
    suffix : str, optional
        Suffix of the named temporary used where unnamed files are unsupported (defaults
        to the destination's).

    Yields
    ------
    Path
        Where to write.
    """
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    fd = _open_unnamed(directory, path)
    if fd is None:
        yield from _named(path, directory, path.suffix if suffix is None else suffix)
        return
    tmp = _proc_path(fd)
    pending = _PENDING.get()
    try:
        try:
            yield Path(tmp)
            if pending is not None:
                pending.append(_Pending(path, fd=fd))
                fd = None  # the group links and closes it
            else:
                _link_into_place(fd, path)
        except OSError as exc:
            _reraise(exc, tmp, path)
    finally:
        if fd is not None:
            os.close(fd)


class _Pending:
    """A complete temporary waiting for the end of its :func:`output_group`."""

    def __init__(self, path: Path, *, fd: int | None = None, tmp: Path | None = None):
        self.path, self.fd, self.tmp = path, fd, tmp

    def commit(self) -> None:
        try:
            if self.fd is not None:
                _link_into_place(self.fd, self.path)
            else:
                os.chmod(self.tmp, 0o666 & ~_umask())
                _replace(self.tmp, self.path)
                self.tmp = None
        except OSError as exc:
            _reraise(exc, str(self.tmp), self.path)

    def discard(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
        if self.tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(self.tmp)
            self.tmp = None


_PENDING: contextvars.ContextVar[list | None] = contextvars.ContextVar(
    "lidarstat_pending_outputs", default=None)


@contextlib.contextmanager
def output_group(defer: bool = True) -> Iterator[None]:
    """Outputs written in the block appear together when it ends, or none of them.

    Every :func:`atomic_path` inside the block keeps its complete temporary until the
    block ends without an exception; then all are put in place, in the order written.
    On an exception (SIGTERM and Ctrl-C included) none appears, so a command that fails
    half-way leaves no part of its results.

    Parameters
    ----------
    defer : bool
        False: outputs written in the block appear at once (for a step that reads back
        what it wrote inside an enclosing group).
    """
    pending: list[_Pending] | None = [] if defer else None
    token = _PENDING.set(pending)
    try:
        yield
    except BaseException:
        _PENDING.reset(token)
        for item in pending or ():
            item.discard()
        raise
    _PENDING.reset(token)
    try:
        for item in pending or ():
            item.commit()
    finally:
        for item in pending or ():
            item.discard()


def _named(path: Path, directory: Path, suffix: str) -> Iterator[Path]:
    """The fallback of :func:`atomic_path`: a hidden named temporary beside `path`."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{suffix}",
                                   dir=directory)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    os.close(fd)
    tmp_path = Path(tmp)
    pending = _PENDING.get()
    try:
        try:
            yield tmp_path
            if pending is not None:
                pending.append(_Pending(path, tmp=tmp_path))
                return
            # mkstemp creates 0600; give the result the permissions a plain open() would
            os.chmod(tmp_path, 0o666 & ~_umask())
            os.replace(tmp_path, path)
        except OSError as exc:
            _reraise(exc, tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise


def unnamed_file(directory: str | os.PathLike | None = None):
    """A binary read/write scratch file without a name (freed by the kernel on any exit).

    ``O_TMPFILE`` where supported, else a named file unlinked as soon as it is open
    (:func:`tempfile.TemporaryFile`); either way nothing remains after the process ends,
    however it ends.

    Parameters
    ----------
    directory : path-like, optional
        Folder (file system) that holds the data; default the system's temporary folder.

    Returns
    -------
    file object
        Unbuffered, opened ``w+b``.
    """
    return tempfile.TemporaryFile(mode="w+b", buffering=0,
                                  dir=None if directory is None else os.fspath(directory))

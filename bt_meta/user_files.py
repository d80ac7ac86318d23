"""Reading files a user names, and checking places a user asks us to write, without hanging or leaking.

Every loader (task files, tree XML, scenes, grounding files, robot descriptions) reads through
:func:`read_user_text` / :func:`read_user_bytes`, so a path that holds a NUL byte or is too long, a symlink loop, a
folder, a named pipe, a device such as ``/dev/zero`` or a file larger than the bound gives one located
:class:`~bt_meta.errors.UserInputError` instead of an ``OSError`` traceback, a read that never ends, or a
``MemoryError``. The file is opened non-blocking (a named pipe then never waits for a writer) and checked to be a
regular file on the open descriptor, so it cannot be swapped between the check and the read.

Offers:

* :data:`MAX_USER_FILE_BYTES` -- the default size bound (8 MiB; every shipped file is far below it)
* :func:`read_user_bytes`, :func:`read_user_text` -- the checked read (text: UTF-8, a bad byte located)
* :func:`check_path_text` -- the NUL-byte and length checks alone (for paths that are not opened at once)
* :func:`check_output_file`, :func:`make_output_folder` -- an output location checked before any work starts
* :func:`describe_os_error` -- an ``OSError`` as a short phrase (``symlink loop``, ``permission denied``)
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from bt_meta.errors import UserInputError

MAX_USER_FILE_BYTES = 8 * 1024 * 1024
MAX_PATH_CHARS = 4096
MAX_NAME_CHARS = 255

_OS_ERROR_PHRASES = {
    errno.ENOENT: "no such file",
    errno.ELOOP: "symlink loop (too many levels of symbolic links)",
    errno.ENAMETOOLONG: "path too long",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
    errno.ENOTDIR: "a part of the path is not a folder",
    errno.EISDIR: "is a folder, not a file",
    errno.EROFS: "read-only file system",
    errno.ENOSPC: "no space left on the device",
}


def describe_os_error(error: OSError) -> str:
    """A short phrase for ``error`` without the path (the caller's message already names it)."""
    return _OS_ERROR_PHRASES.get(error.errno or 0) or error.strerror or type(error).__name__


def _kind_of(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a named pipe"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def check_path_text(path: str | os.PathLike[str], what: str = "file",
                    error: type[UserInputError] = UserInputError) -> str:
    """``path`` as text, refused when it holds a NUL byte or is longer than a file system accepts."""
    text = os.fspath(path)
    if isinstance(text, bytes):  # pragma: no cover - bt-meta passes str paths
        text = os.fsdecode(text)
    shown = text if len(text) <= 200 else text[:200] + "..."
    if "\x00" in text:
        raise error(f"the {what} path holds a NUL byte", shown.replace("\x00", "\\0"))
    if len(text) > MAX_PATH_CHARS or any(len(part) > MAX_NAME_CHARS for part in text.split(os.sep)):
        raise error(f"the {what} path is too long ({len(text)} characters)", shown)
    return text


def read_user_bytes(path: str | os.PathLike[str], *, what: str = "file", max_bytes: int = MAX_USER_FILE_BYTES,
                    error: type[UserInputError] = UserInputError) -> bytes:
    """The bytes of the regular file ``path``, at most ``max_bytes``; anything else is one located ``error``."""
    text = check_path_text(path, what, error)
    try:
        fd = os.open(text, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        if exc.errno == errno.ENOENT:
            raise error(f"no such {what}", text) from None
        raise error(f"cannot read the {what}: {describe_os_error(exc)}", text) from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise error(f"the {what} is {_kind_of(mode)}, not a regular file", text)
        chunks: list[bytes] = []
        size = 0
        while True:
            chunk = os.read(fd, min(1 << 20, max_bytes + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
            if size > max_bytes:
                raise error(f"the {what} is larger than {max_bytes} bytes", text)
        return b"".join(chunks)
    except OSError as exc:
        raise error(f"cannot read the {what}: {describe_os_error(exc)}", text) from None
    finally:
        os.close(fd)


def read_user_text(path: str | os.PathLike[str], *, what: str = "file", max_bytes: int = MAX_USER_FILE_BYTES,
                   error: type[UserInputError] = UserInputError) -> str:
    """The UTF-8 text of the regular file ``path``; a byte that is not UTF-8 is located by line and column."""
    data = read_user_bytes(path, what=what, max_bytes=max_bytes, error=error)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        before = data[: exc.start]
        line = before.count(b"\n") + 1
        column = len(before[before.rfind(b"\n") + 1:].decode("utf-8", errors="replace")) + 1
        raise error(f"the {what} is not UTF-8 text (byte 0x{data[exc.start]:02x})", os.fspath(path), line,
                    column) from None


def check_output_file(path: str | os.PathLike[str], what: str = "output file",
                      error: type[UserInputError] = UserInputError) -> Path:
    """Refuse, before any work, an output file whose folder is missing or is not writable, or that is a folder."""
    text = check_path_text(path, what, error)
    target = Path(text)
    if target.is_dir():
        raise error(f"the {what} is a folder", text)
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise error(f"the folder of the {what} does not exist ({parent})", text)
    if not os.access(parent, os.W_OK | os.X_OK):
        raise error(f"cannot write the {what}: permission denied in {parent}", text)
    if target.exists() and not os.access(target, os.W_OK):
        raise error(f"cannot write the {what}: permission denied", text)
    return target


def make_output_folder(path: str | os.PathLike[str], what: str = "output folder",
                       error: type[UserInputError] = UserInputError) -> Path:
    """Create the folder the user named (and its parents) before any work; refuse one that cannot be made."""
    text = check_path_text(path, what, error)
    folder = Path(text)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise error(f"the {what} exists and is not a folder", text) from None
    except OSError as exc:
        raise error(f"cannot make the {what}: {describe_os_error(exc)}", text) from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise error(f"cannot write in the {what}: permission denied", text)
    return folder

"""Files and folders that survive a crash or a power loss (issue 35): what a reader finds is the
old version or the new one, complete, never a half-written file or a missing model.

A file is written to a temporary name in its own folder, flushed and fsynced, renamed over the
old one, and the folder is fsynced (the rename itself is only durable once the folder is). A
folder (a COLMAP model, DIR/sparse/0) is swapped with the one it replaces in one step by Linux's
renameat2(RENAME_EXCHANGE), so the name never points at nothing, then the old one is removed.
"""
import ctypes
import errno
import os
import shutil
import tempfile


def fsync_folder(path):
    """Makes the entries of a folder (files made, renamed or removed in it) durable."""
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomically(path, data):
    """`data` (bytes or str) into `path`: the old content or the new, never half of it, and
    durable when this returns."""
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix="." + os.path.basename(path) + ".")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data.encode("utf-8") if isinstance(data, str) else data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)  # mkstemp makes it 0600; the files it replaces are the umask's
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    fsync_folder(folder)


def append_durably(path, text):
    """Appends `text` to a log (DIR/ledger.txt) and fsyncs it: an append-only file is not
    rewritten (that would cost its whole length per line); a crash can at worst cut its last
    line short."""
    new = not os.path.exists(path)
    with open(path, "a") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    if new:
        fsync_folder(os.path.dirname(os.path.abspath(path)))


_AT_FDCWD = -100
_RENAME_EXCHANGE = 2  # linux/fs.h
_renameat2 = None


def exchange(a, b):
    """Swaps the folders (or files) `a` and `b` in one step (renameat2 with RENAME_EXCHANGE,
    Linux 3.15, glibc 2.28). Raises OSError; errno EINVAL or ENOSYS (or NotImplementedError) when
    the kernel, the C library or the file system cannot."""
    global _renameat2
    if _renameat2 is None:
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            fn = libc.renameat2
        except (OSError, AttributeError):
            raise NotImplementedError("renameat2 is not in this C library")
        fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
        fn.restype = ctypes.c_int
        _renameat2 = fn
    if _renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) != 0:
        e = ctypes.get_errno()
        raise OSError(e, "renameat2(RENAME_EXCHANGE) %s, %s: %s" % (a, b, os.strerror(e)))


def _fsync_tree(folder):
    """The files of a folder someone else wrote (COLMAP does not fsync), and the folder."""
    for name in os.listdir(folder):
        path = os.path.join(folder, name)
        if os.path.isfile(path) and not os.path.islink(path):
            fd = os.open(path, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
    fsync_folder(folder)


def replace_folder(made, output):
    """Moves the complete folder `made` to `output`, replacing what was there, so that `output`
    is at every moment the old folder or the new one, also after a crash or a power loss at any
    point: `made`'s files are fsynced, the two are exchanged in one step, the parent is fsynced,
    then the old one (now at `made`'s name) is removed. `made` must be on the same file system
    (beside `output`, as the callers' temporary folders are)."""
    made, output = os.path.abspath(made), os.path.abspath(output)
    parent = os.path.dirname(output)
    os.makedirs(parent, exist_ok=True)
    _fsync_tree(made)
    if not os.path.exists(output):
        os.rename(made, output)
        fsync_folder(parent)
        return
    try:
        exchange(made, output)
        old = made
    except (OSError, NotImplementedError) as e:
        if isinstance(e, OSError) and e.errno not in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
            raise
        # Only where renameat2 cannot exchange (a kernel before 3.15, a file system without
        # RENAME_EXCHANGE): two renames, and between them `output` is absent.
        old = output + ".old.%d" % os.getpid()
        os.rename(output, old)
        os.rename(made, output)
    fsync_folder(parent)
    if os.path.dirname(old) != parent:
        fsync_folder(os.path.dirname(old))
    shutil.rmtree(old, ignore_errors=True)

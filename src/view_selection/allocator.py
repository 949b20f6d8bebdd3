"""glibc's heap, set for a process that extracts features while it holds earlier ones.

OpenCV's SIFT builds its scale space in buffers of a few MB an image, freed when the image is
done. A process that also holds what earlier images gave (colmap_bridge: its feature cache, the
live model, numpy arrays on the heap) gets those buffers from the top of glibc's heap, which
grows by brk and is trimmed back at every free, so each image's buffers are fresh pages again.
SIFT's CPU then grows with what the process holds: on the built-in walk's QVGA keyframes, 20-29
ms an image in a fresh process, 70-99 ms once it held the features of 48-120 images, with
OpenCV on one thread (dev/benchmark_extraction). colmap_bridge's extraction stage measured 67-77
ms a keyframe live, where SIFT alone took 20-37 ms.

glibc's M_TOP_PAD (mallopt) makes the heap grow and stay in steps of `pad` bytes: the same
measurement gives 17-21 ms at 64 MB and 22-24 ms at 16 MB, whatever is held. Setting it also
fixes glibc's mmap threshold at its default (128 kB), as any mallopt of these does.
"""
import ctypes
import ctypes.util

M_TOP_PAD = -2  # glibc's malloc.h
TOP_PAD_BYTES = 64 << 20


def pad_heap(pad=TOP_PAD_BYTES, libc=None):
    """mallopt(M_TOP_PAD, pad) in this process. Returns True when glibc took it, False where
    there is no glibc (another libc) or it refused; never raises."""
    try:
        lib = ctypes.CDLL(libc or ctypes.util.find_library("c") or "libc.so.6")
        mallopt = lib.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return mallopt(M_TOP_PAD, int(pad)) == 1

"""glibc's heap, set for a process that extracts features while it holds earlier ones.

OpenCV's SIFT builds its scale space in buffers of a few MB an image, freed when the image is
done. In a process that also holds what earlier images gave (colmap_bridge: its feature cache,
the live model; numpy arrays on the heap), SIFT's CPU grows with what the process holds:
`dev/benchmark_extraction` on a rendered walk's QVGA keyframes, OpenCV on one thread, gave 23 ms
an image with nothing held and 53-68 ms with the features of 48-120 images held. colmap_bridge's
extraction stage measured 67-77 ms a keyframe live, where SIFT alone took 20-37 ms. As far as
measured, it is where those buffers come from: the top of glibc's heap, grown and given back
around each image (glibc's M_TRIM_THRESHOLD or M_MMAP_THRESHOLD alone did not help).

glibc's M_TOP_PAD (mallopt) makes the heap grow and stay in steps of `pad` bytes: the same
benchmark gives 15-16 ms at 64 MB, whatever is held (at 16 MB: 16 ms up to 72 images held, 26-32
ms beyond). Setting it also fixes glibc's mmap threshold at its default (128 kB), as any mallopt
of these does.
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

"""allocator.pad_heap: glibc's heap grows in steps of the pad (each measured case in a process of
its own: mallopt is the process's)."""
import subprocess
import sys
import textwrap

from view_selection.allocator import TOP_PAD_BYTES, pad_heap

# The main arena's size after one malloc that must grow it, with or without the pad first.
ARENA_AFTER_GROWTH = textwrap.dedent("""
    import ctypes, sys
    sys.path[:0] = %r
    from view_selection.allocator import pad_heap
    if sys.argv[1] == "pad":
        assert pad_heap(%d)
    class MallInfo2(ctypes.Structure):
        _fields_ = [(n, ctypes.c_size_t) for n in
                    ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
                     "fordblks", "keepcost")]
    libc = ctypes.CDLL("libc.so.6")
    libc.mallinfo2.restype = MallInfo2
    libc.malloc.restype = ctypes.c_void_p
    before = libc.mallinfo2().arena
    # 100 kB: below the mmap threshold (128 kB), more than the arena has free, so it grows by brk
    blocks = [libc.malloc(100000) for _ in range(40)]
    print(libc.mallinfo2().arena - before)
""")


def arena_growth(mode, pad=TOP_PAD_BYTES):
    out = subprocess.run([sys.executable, "-c", ARENA_AFTER_GROWTH % (sys.path, pad), mode], check=True,
                         stdout=subprocess.PIPE, universal_newlines=True, timeout=60).stdout
    return int(out.split()[-1])


def test_the_pad_makes_the_heap_grow_by_at_least_the_pad():
    plain, padded = arena_growth("plain"), arena_growth("pad")
    assert plain < 16 << 20          # 40 blocks of 100 kB: about 4 MB without the pad
    assert padded >= TOP_PAD_BYTES   # one step of the pad at least


def test_a_smaller_pad_is_a_smaller_step():
    assert (4 << 20) <= arena_growth("pad", 8 << 20) < TOP_PAD_BYTES


def test_pad_heap_takes_effect_here_and_says_so_where_it_cannot():
    assert pad_heap() is True
    assert pad_heap(libc="libno_such_libc.so.0") is False

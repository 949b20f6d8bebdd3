"""The progress reporter's rules with an injected clock (no sleeps): plain lines at most every 10 s
into a log, one line rewritten in place on a terminal, short work silent, the estimate at the
stage's mean rate."""
import io

from view_selection.progress import Progress, duration_text


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def reporter(terminal):
    clock, out = Clock(), io.StringIO()
    return Progress(out, terminal=terminal, clock=clock), clock, out


def test_a_log_gets_a_plain_line_at_most_every_ten_seconds():
    p, clock, out = reporter(False)
    shown = []
    for done in range(0, 2886, 4):  # 2885 pairs at 64 a second: 45 s (steps exact in binary)
        clock.now = 100.0 + done / 64.0
        p.report("matching", done, 2885, "pairs")
        shown = out.getvalue().splitlines()
    p.report("matching", 2885, 2885, "pairs")
    p.end()
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue()
    # Lines at 10, 20, 30 and 40 s, then the stage's last one.
    assert lines == ["matching 640/2885 pairs, about 35 s left", "matching 1280/2885 pairs, about 25 s left",
                     "matching 1920/2885 pairs, about 15 s left", "matching 2560/2885 pairs, about 5 s left",
                     "matching 2885/2885 pairs, 45 s"], lines
    assert len(shown) == 4


def test_the_estimate_is_the_stages_mean_rate():
    p, clock, out = reporter(False)
    p.report("matching", 0, 2885, "pairs")
    assert p.estimate() is None  # nothing done yet: no rate
    clock.now += 30.0
    p.report("matching", 1200, 2885, "pairs")
    assert abs(p.estimate() - 30.0 / 1200 * 1685) < 1e-9
    assert p.line() == "matching 1200/2885 pairs, about 42 s left"
    clock.now += 3570.0  # a stall slows the rate: the estimate grows with it
    assert p.line() == "matching 1200/2885 pairs, about 84 min left"
    p.report("matching", 1201, 2885, "pairs")
    assert p.line() == "matching 1201/2885 pairs, about 84 min left"
    assert duration_text(0.2) == "1 s" and duration_text(89) == "89 s" and duration_text(150) == "3 min"
    assert duration_text(5400) == "1.5 h"


def test_short_work_prints_nothing():
    for terminal in (False, True):
        p, clock, out = reporter(terminal)
        for done in range(11):
            p.report("extracting features", done, 10, "images")
            clock.now += 0.05
        p.end()
        assert out.getvalue() == "", (terminal, out.getvalue())


def test_a_terminal_gets_one_line_rewritten_in_place():
    p, clock, out = reporter(True)
    for done in range(0, 101):  # 100 images, 1/16 s each
        clock.now = 100.0 + done / 16.0
        p.report("extracting features", done, 100, "images")
    p.end()
    text = out.getvalue()
    assert text.count("\n") == 1 and text.endswith("\n")  # one line, ended once
    draws = text.split("\r")[1:]
    # Shown after the first second, then every 0.25 s (each 4th image) to the last, once.
    assert [d.split()[2] for d in draws] == ["%d/100" % n for n in range(16, 101, 4)], draws
    assert draws[0] == "extracting features 16/100 images, about 5 s left\033[K"
    assert draws[-1] == "extracting features 100/100 images, 6 s\033[K\n"  # then the line is ended


def test_a_new_stage_starts_a_new_estimate_and_a_note_follows_the_rules():
    p, clock, out = reporter(False)
    for done in range(0, 21):
        p.report("extracting features", done, 20, "images")
        clock.now += 1.0
    p.report("matching", 0, 10, "pairs")
    clock.now += 11.0
    p.report("matching", 1, 10, "pairs")
    assert p.line() == "matching 1/10 pairs, about 2 min left"  # 11 s a pair, not the extraction's 1 s
    p.end()
    for q in range(30):  # a child's own progress lines, one a second
        p.note("refining: round %d" % q)
        clock.now += 1.0
    p.end()
    lines = out.getvalue().splitlines()
    assert lines == ["extracting features 10/20 images, about 10 s left",
                     "extracting features 20/20 images, 20 s",
                     "matching 1/10 pairs, about 2 min left",
                     "matching 1/10 pairs, 11 s",  # ended early: how far it got
                     "refining: round 10", "refining: round 20"], lines


def test_clear_ends_the_drawn_line_before_other_output():
    p, clock, out = reporter(True)
    p.report("matching", 0, 10, "pairs")
    clock.now += 2.0
    p.report("matching", 4, 10, "pairs")
    p.clear()
    out.write("a log line\n")
    clock.now += 1.0
    p.report("matching", 5, 10, "pairs")
    assert out.getvalue() == "\rmatching 4/10 pairs, about 3 s left\033[K\na log line\n" \
                             "\rmatching 5/10 pairs, about 3 s left\033[K"


def test_the_whole_count_shows_at_once_and_a_count_that_goes_back_starts_again():
    p, clock, out = reporter(False)
    for done in range(0, 13):  # 12 images, 1 s each: a line at 10 s, and the last at once
        p.report("extracting features", done, 12, "images")
        clock.now += 1.0
    assert out.getvalue().splitlines() == ["extracting features 10/12 images, about 2 s left",
                                           "extracting features 12/12 images, 12 s"]
    for done in range(0, 5):  # the same stage again on another batch: a new estimate from 0
        p.report("extracting features", done, 4, "images")
        clock.now += 4.0
    p.end()
    assert out.getvalue().splitlines()[2:] == ["extracting features 3/4 images, about 4 s left",
                                               "extracting features 4/4 images, 16 s"]

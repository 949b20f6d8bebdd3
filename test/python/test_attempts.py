from view_selection.live.attempts import Attempts


def test_backoff_then_give_up():
    now = [0.0]
    a = Attempts(max_attempts=3, first_wait=2.0, factor=4.0, clock=lambda: now[0])
    assert a.due("x") and not a.suspect("x")
    assert not a.failed("x", "boom")
    assert a.suspect("x") and not a.due("x")
    now[0] = 2.0
    assert a.due("x")
    assert not a.failed("x", "boom again")
    now[0] = 9.9
    assert not a.due("x")  # 2 * 4 s after the second failure
    now[0] = 10.0
    assert a.due("x")
    assert a.failed("x", "third")
    assert a.given_up("x") and not a.due("x")
    assert a.skipped() == [{"item": "x", "attempts": 3, "error": "third"}]


def test_success_forgets_the_failures():
    a = Attempts(max_attempts=2, clock=lambda: 100.0)
    a.failed("y", "once")
    a.succeeded("y")
    assert a.due("y") and not a.suspect("y") and a.skipped() == []


def test_the_count_of_items_given_up_follows_failures_and_successes():
    a = Attempts(max_attempts=2, clock=lambda: 0.0)
    for item in ("a", "b", "c"):
        a.failed(item, "x")
    assert a.given_up_count() == 0
    a.failed("a", "x")
    a.failed("b", "x")
    a.failed("b", "x")  # failed again after it was given up: still one
    assert a.given_up_count() == 2 == len(a.skipped())
    a.succeeded("a")  # a given-up item that came through after all (a restart's retry)
    a.succeeded("c")
    assert a.given_up_count() == 1 == len(a.skipped())


def test_a_suspect_is_not_charged_and_a_success_clears_it():
    a = Attempts(max_attempts=3, clock=lambda: 0.0)
    a.suspected("p")
    assert a.suspect("p") and a.due("p") and a.failures == {} and a.skipped(all_failed=True) == []
    a.succeeded("p")
    assert not a.suspect("p")

"""The development sampler (stack_sampler.py): a working thread's functions are counted, a
waiting one's are not, and the counts reach the file."""
import threading
import time

from view_selection.stack_sampler import StackSampler


def spin_here(stop):
    while not stop.is_set():
        sum(range(2000))


def wait_here(stop):
    stop.wait()


def test_working_functions_are_counted_and_waiting_ones_are_not(tmp_path):
    path = tmp_path / "stacks.txt"
    sampler = StackSampler(str(path), period=0.002)
    stop = threading.Event()
    threads = [threading.Thread(target=spin_here, args=(stop,)), threading.Thread(target=wait_here, args=(stop,))]
    sampler.start()
    for t in threads:
        t.start()
    deadline, idle = time.monotonic() + 30, threading.Event()
    while sampler.samples < 50 and time.monotonic() < deadline:
        idle.wait(0.01)  # waiting as the bridge's threads do (a sleep from Python code would count)
    stop.set()
    for t in threads:
        t.join()
    sampler.write()
    sampler.join(timeout=5)
    counted = {label.split(" ")[-1]: n for label, n in sampler.inclusive.items()}
    assert counted.get("spin_here", 0) >= 0.8 * sampler.samples
    assert "wait_here" not in counted
    text = path.read_text()
    assert "spin_here" in text and text.startswith("%d working samples" % sampler.samples)

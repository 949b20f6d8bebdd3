"""The whole model's poses refined while the recording goes on (refinement/background.py), without
refine_model: where the next run and the finish start from, and when the finish takes them.
test/python_colmap/test_background_poses.py runs it with refine_model and COLMAP's database."""
import os
import subprocess
import types

import numpy as np

from view_selection import geometry
from view_selection.refinement import background, local


class Finish:
    """refiner.ModelRefinement's seam: records what the finish was given."""

    def __init__(self):
        self.log = lambda level, text: None
        self.options = types.SimpleNamespace(max_seconds=5.0)
        self.given = "not called"

    def apply(self, project, model_path, model=None, matched=0, start_poses=None):
        self.given = start_poses
        return {"refined": True}


def session(n=4):
    """A work with n keyframes along x (the node's poses), and BackgroundPoses attached."""
    fed = {"k%d" % i: ((float(i), 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)) for i in range(1, n + 1)}
    images = {i: types.SimpleNamespace(name="k%d" % i) for i in range(1, n + 1)}
    work = types.SimpleNamespace(fed_poses=fed, model=types.SimpleNamespace(images=images))
    runs = background.BackgroundPoses(Finish())
    runs.attach(work)
    return work, runs


def took(runs, iid, pose, node):
    """As _finish_run takes a run's pose."""
    runs.poses[iid] = (pose, node)
    runs.ids = sorted(runs.poses)


def centre(qt):
    return np.array(geometry.centre_of(*qt))


def test_nothing_to_start_from_before_a_run_took_poses():
    work, runs = session()
    assert runs.start_poses() == {}
    runs.apply(types.SimpleNamespace(deadline=None), "model")
    assert runs.finish_refinement.given is None  # the finish from the node's poses


def test_a_keyframe_keeps_the_runs_pose_until_the_node_moves_it_and_the_newer_ones_follow_the_correction():
    work, runs = session()
    shifted = {i: geometry.world_to_camera((i + 0.5, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)) for i in (1, 2)}
    for i in (1, 2):
        took(runs, i, shifted[i], work.fed_poses["k%d" % i])
    start = runs.start_poses()
    assert np.allclose(centre(start[1]), [1.5, 0, 0]) and np.allclose(centre(start[2]), [2.5, 0, 0])
    # 3 and 4 came since: their node poses moved by keyframe 2's correction (0.5 along x)
    assert np.allclose(centre(start[3]), [3.5, 0, 0]) and np.allclose(centre(start[4]), [4.5, 0, 0])
    # a loop closure moved keyframe 2's node pose: it is predicted again, from keyframe 1
    work.fed_poses["k2"] = ((2.2, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    start = runs.start_poses()
    assert np.allclose(centre(start[2]), [2.7, 0, 0])
    assert np.allclose(start[2][0], local.corrected(work.fed_poses["k2"], shifted[1], work.fed_poses["k1"])[0])


def took_half(work, runs):
    """Runs' poses for keyframes 1 and 2 of 4 (MIN_TAKEN_SHARE)."""
    for i in (1, 2):
        took(runs, i, geometry.world_to_camera((i + 0.5, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)), work.fed_poses["k%d" % i])


def test_the_finish_starts_from_the_runs_poses_only_where_the_node_is_off_the_matches():
    work, runs = session()
    took_half(work, runs)
    project = types.SimpleNamespace(deadline=None)
    for node_px, used in ((0.31, False), (1.3, True)):  # exact poses: within the noise; drift: off
        runs.history = [{"taken": 4, "keyframes": 4, "sampson_px": [0.29, 0.27], "sampson_node_px": node_px}]
        section = runs.apply(project, "model", matched=700000)  # a 10-minute walk's
        assert (runs.finish_refinement.given is not None) == used, node_px
        assert section["background"]["started_from"] == used
    # a run that took nothing (its node poses all moved meanwhile) does not count
    runs.history.append({"taken": 0, "keyframes": 4, "sampson_px": [0.29, 0.27], "sampson_node_px": 0.3})
    assert runs.node_off()


def test_a_replay_counts_its_own_charge_for_a_run_not_the_cpu_it_measured(tmp_path):
    # A run that failed after 3 s of CPU (refine_model's status 1): the bridge counts the 3 s and
    # the Python's; a replay (refinement/session.py) counts what its charge gives, whatever the
    # machine measured.
    def failed_run():
        folder = tmp_path / "run"
        folder.mkdir(exist_ok=True)
        run = local._Run("poses", [1, 2], [], str(folder), None, {}, set(), 0.5, 10.0, 70.0)
        run.status, run.rusage = 1, types.SimpleNamespace(ru_utime=2.0, ru_stime=1.0)
        return run

    charged = []
    for charge in (None, lambda entry: charged.append(entry) or 0.2):
        work, runs = session()
        runs.charge = charge
        runs._finish_run(failed_run())
        assert runs.failures == 1 and runs.runs == 0
        if charge is None:
            assert 3.5 <= runs.cpu_seconds < 3.6, runs.cpu_seconds  # the child's 3 s and the 0.5 before
        else:
            assert runs.cpu_seconds == 0.2 and charged == [None]


def test_the_finish_waits_for_a_run_under_way_only_when_it_should_end_in_time():
    import time
    work, runs = session()
    project = types.SimpleNamespace(deadline=None)
    runs.running = types.SimpleNamespace(started=time.monotonic())
    assert runs.finish_waits(project) == runs.finish_wait  # no run ended yet: its time is not known
    runs.history = [{"seconds": 0.3}]  # a short model: the run should end within the wait
    assert runs.finish_waits(project) == runs.finish_wait
    runs.history = [{"seconds": 10.0}]  # 2,500 keyframes: it will not, the finish does not wait
    assert runs.finish_waits(project) == 0.0
    runs.running.started -= 9.8  # nearly done
    assert runs.finish_waits(project) == runs.finish_wait
    project.deadline = time.monotonic() + 2.0  # at shutdown: a quarter of what is left at most
    assert runs.finish_waits(project) <= 0.5


def test_a_run_waits_while_the_process_as_a_whole_is_over_its_share(monkeypatch):
    now, used = [0.0], [10.0]
    monkeypatch.setattr(background, "process_cpu", lambda: used[0])
    runs = background.BackgroundPoses(Finish(), cpu_share=0.07, process_share=0.45, clock=lambda: now[0])
    assert runs.allowance() == 0.0  # the first step: the session's clock and the process's CPU start
    now[0], used[0] = 100.0, 10.0 + 30.0  # 0.3 of a core: the runs' own share decides
    assert abs(runs.allowance() - 7.0) < 1e-9
    used[0] = 10.0 + 44.0  # the bridge's own work came to 0.44 of a core: 1 s left under 0.45
    assert abs(runs.allowance() - 1.0) < 1e-9
    used[0] = 10.0 + 50.0  # over it: no run, whatever the runs' own share has left
    assert runs.allowance() < 0
    runs.process_share = None  # ~refine_poses_live_bridge_cpu: 0
    assert abs(runs.allowance() - 7.0) < 1e-9


def test_a_finish_that_converges_by_itself_starts_from_the_node_poses():
    work, runs = session()
    took_half(work, runs)
    runs.history = [{"taken": 4, "keyframes": 4, "sampson_px": [0.29, 0.27], "sampson_node_px": 1.3}]
    project = types.SimpleNamespace(deadline=None)
    # a minute's walk (92,341 matched observations): 5 s pay for 36 iterations; 10 minutes' do not
    for matched, started in ((92341, False), (700000, True)):
        section = runs.apply(project, "model", matched=matched)
        assert section["background"]["started_from"] == started, matched
        assert section["background"]["finish_converges"] == (not started)
        assert (runs.finish_refinement.given is not None) == started
    runs.finish_refinement.options.max_seconds = 60.0  # a longer ~refine_max_seconds converges there too
    assert runs.apply(project, "model", matched=700000)["background"]["started_from"] is False
    assert background.finish_converges(0.0, 10 ** 9)  # no limit


def clocked_runs(observations):
    """BackgroundPoses on a clock at 100 s after its first step, over a live model of three images
    with `observations` matched observations; `started` records the live model's observations at
    each run started (its _start)."""
    now = [0.0]
    runs = background.BackgroundPoses(Finish(), clock=lambda: now[0])
    live = types.SimpleNamespace(matched_pairs={(1, 2), (2, 3), (1, 3)}, images={1: 0, 2: 0, 3: 0},
                                 by_image={1: [0], 2: [0], 3: [0]}, parent=dict.fromkeys(range(observations)))
    runs.attach(types.SimpleNamespace(model=live))
    started = []
    runs._start = lambda: started.append(len(live.parent))
    runs.step()  # the first step starts the session's clock
    now[0] = 100.0
    return runs, live, started


def test_no_run_starts_while_the_finish_would_refine_the_model_to_convergence_by_itself():
    runs, live, started = clocked_runs(1000)
    assert not runs.step() and started == []  # 1,000 matched observations: the finish converges
    live.parent = dict.fromkeys(range(200000))  # past what 5 s refine to convergence (167,000)
    runs.step()
    assert started == [200000]


def test_a_pose_sent_again_with_other_last_bits_keeps_the_runs_pose_and_one_the_node_moved_does_not():
    work, runs = session()
    shifted = {i: geometry.world_to_camera((i + 0.5, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)) for i in (1, 2)}
    for i in (1, 2):
        took(runs, i, shifted[i], work.fed_poses["k%d" % i])
    # the stream's resync gave every keyframe again: keyframe 1 1e-12 m off, keyframe 2 moved 0.2 m
    work.fed_poses["k1"] = ((1.0 + 1e-12, 0.0, 0.0), (1.0, 0.0, 0.0, 1e-13))
    work.fed_poses["k2"] = ((2.2, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    start = runs.start_poses()
    assert start[1] == shifted[1] and runs.moved == 1
    assert np.allclose(centre(start[2]), [2.7, 0, 0])  # keyframe 1's correction, from its new pose
    # both moved (a loop closure): each predicted by the nearest one's correction all the same
    work.fed_poses["k1"] = ((1.1, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    start = runs.start_poses()
    assert runs.moved == 2 and len(start) == 4
    assert np.allclose(centre(start[1]), [1.6, 0, 0]) and np.allclose(centre(start[4]), [4.5, 0, 0])
    assert local.same_pose(((0, 0, 0), (1, 0, 0, 0)), ((0, 0, 0), (-1, 0, 0, 0)))  # q and -q
    assert not local.same_pose(((0, 0, 0), (1, 0, 0, 0)), None) and local.same_pose(None, None)


def test_the_finish_starts_from_the_runs_poses_only_where_they_took_half_the_keyframes():
    # The other walk's 30 minutes: the runs stopped at 864 of 7,474 keyframes; the rest would be
    # predicted from the nearest one's correction.
    work, runs = session(n=10)
    runs.history = [{"taken": 4, "keyframes": 4, "sampson_px": [0.29, 0.27], "sampson_node_px": 1.3}]
    project = types.SimpleNamespace(deadline=None)
    for taken, started in ((4, False), (5, True)):
        for i in range(1, taken + 1):
            took(runs, i, geometry.world_to_camera((i + 0.5, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)),
                 work.fed_poses["k%d" % i])
        section = runs.apply(project, "model", matched=700000)
        assert section["background"]["started_from"] == started, taken
        assert ("MIN_TAKEN_SHARE" in section["background"].get("not_started_from_because", "")) == (not started)
    # a keyframe the node moved since is not one the runs took
    work.fed_poses["k5"] = ((5.3, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    assert runs.apply(project, "model", matched=700000)["background"]["started_from"] is False


def test_while_the_matching_is_behind_the_run_under_way_yields_the_cpu_and_none_starts(tmp_path):
    runs, live, started = clocked_runs(200000)  # past what the finish refines to convergence
    assert not runs.step(behind=True) and started == []  # a run is due, but the matching comes first
    runs.step()
    assert started == [200000]  # caught up: it starts

    # A run under way (a real child): made 10 nicer once, every thread of it, while behind.
    child = subprocess.Popen(["sleep", "30"])
    try:
        runs.running = local._Run("poses", [1, 2, 3], [], str(tmp_path), child, {}, set(), 0.0, 60.0, 120.0)
        nice = os.getpriority(os.PRIO_PROCESS, child.pid)
        assert runs.step() and os.getpriority(os.PRIO_PROCESS, child.pid) == nice  # not behind: as it was
        assert runs.step(behind=True)  # still under way
        assert os.getpriority(os.PRIO_PROCESS, child.pid) == min(19, nice + local.YIELD_NICE)
        assert runs.step(behind=True) and os.getpriority(os.PRIO_PROCESS, child.pid) == min(19, nice + local.YIELD_NICE)
        assert runs.yielded == 1 and runs.summary()["yielded"] == 1
    finally:
        child.kill()
        child.wait()

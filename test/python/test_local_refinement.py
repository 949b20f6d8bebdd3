"""The refinement while the recording goes on (refinement/local.py), without COLMAP: which images a
window frees and which it holds, the crop of the live model, and the poses of keyframes not yet
refined. test/python_colmap/test_local_refinement.py runs it with refine_model."""
import numpy as np

from view_selection import geometry
from view_selection.keyframes import Keyframe
from view_selection.refinement import local
from test_live_model import build, scene


def no_covisibility(free):
    return {}


def test_a_local_window_frees_the_oldest_never_refined_and_fills_up_with_the_refined_before_them():
    order = list(range(1, 31))
    free, fixed = local.choose_window(order, observed=order, refined=range(1, 16), covisible=no_covisibility,
                                      kind="local", size=20)
    assert free == list(range(11, 31))  # 15 new, 5 refined ones before them
    assert fixed == [10]                # the neighbour in keyframe order: its SLAM motion prior


def test_a_local_window_takes_at_most_its_size_of_the_new_ones_oldest_first():
    order = list(range(1, 51))
    free, fixed = local.choose_window(order, observed=order, refined=range(1, 6), covisible=no_covisibility,
                                      kind="local", size=20)
    assert free == list(range(6, 26))
    assert fixed == [5, 26]  # both neighbours; 26 is newer, not refined, and held


def test_images_without_points_are_not_freed_by_a_local_window():
    order = list(range(1, 11))
    observed = [1, 2, 3, 5, 6, 8, 9, 10]
    free, fixed = local.choose_window(order, observed, refined=[1, 2], covisible=no_covisibility, kind="local", size=4)
    assert free == [3, 5, 6, 8]
    assert fixed == [2, 4, 7, 9]


def test_the_covisible_are_held_the_most_shared_first_up_to_max_fixed():
    order = list(range(1, 21))
    shared = {1: 50, 2: 5, 3: 80, 4: 0, 19: 300, 20: 10}  # 19, 20 are free themselves

    def covisible(free):
        assert free == {17, 18, 19, 20}
        return shared

    free, fixed = local.choose_window(order, order, refined=range(1, 17), covisible=covisible, kind="local",
                                      size=4, max_fixed=2)
    assert free == [17, 18, 19, 20]
    assert fixed == [1, 3, 16]  # the two that share the most, and the neighbour; 2 and 4 left out


def test_nothing_new_frees_nothing():
    order = list(range(1, 6))
    assert local.choose_window(order, order, refined=order, covisible=no_covisibility, kind="local") == ([], [])


def test_the_finish_frees_what_changed_and_holds_everything_they_see():
    order = list(range(1, 41))
    shared = {i: 1 for i in range(1, 41)}  # every one sees some of the changed ones
    free, fixed = local.choose_window(order, order, refined=range(1, 31), covisible=lambda f: shared,
                                      kind="changed", changed=[7, 31, 32, 33, 34, 35, 36, 37, 38, 39, 40],
                                      max_fixed=2)
    assert free == [7] + list(range(31, 41))  # an old keyframe that got a new pair, and the new ones
    assert fixed == [i for i in range(1, 31) if i != 7]  # no max_fixed at the finish


def test_a_global_run_frees_everything():
    order = [3, 5, 9]
    assert local.choose_window(order, order, refined=[], covisible=no_covisibility, kind="global") == (order, [])


# -- the live model cropped ----------------------------------------------------------------
def test_the_crop_keeps_the_points_a_free_image_sees_with_their_observations_in_the_window():
    points, poses, kps = scene(n_images=6, n_points=80)
    # 1-2-3 chained, 4-5-6 chained, 3-4 joins them: tracks span all six images
    m = build(points, poses, kps, pairs=[(0, 1), (1, 2), (2, 3), (3, 4), (4, 5)])
    counts = local.covisible_in(m, {6})
    assert counts[6] == counts[5] > 0 and counts.get(1, 0) == counts[6]
    cropped = local.crop(m, free=[6], fixed=[5])
    assert sorted(cropped.images) == [5, 6]
    assert len(cropped.points) == counts[6]
    for p in cropped.points.values():
        assert sorted(p.image_ids.tolist()) == [5, 6]  # images 1-4 left out
        for iid, kp in zip(p.image_ids, p.point2D_idxs):
            assert cropped.images[int(iid)].point3D_ids[int(kp)] == p.id
    # a point seen only by held images is not in the problem
    only_fixed = local.crop(m, free=[1], fixed=[5, 6])
    assert all(1 in p.image_ids.tolist() for p in only_fixed.points.values())
    assert local.window_pairs(m, [6], [5]) == [(5, 6)]
    assert local.window_pairs(m, [5], [4, 6]) == [(4, 5), (5, 6)]


# -- poses ---------------------------------------------------------------------------------
def rigid(r, t, centre, orientation):
    """A camera-to-world pose moved by x -> r x + t."""
    rc = r @ geometry.rotation_of(orientation)
    return tuple(r @ np.asarray(centre) + t), geometry.quaternion_of(rc)


def test_a_keyframe_not_refined_takes_the_correction_of_the_refined_one_before_it():
    axis = np.array([0.3, -0.2, 0.9]) / np.linalg.norm([0.3, -0.2, 0.9])
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    r = np.eye(3) + np.sin(0.1) * k + (1 - np.cos(0.1)) * k @ k
    t = np.array([0.05, -0.02, 0.01])
    node_a = ((1.0, 2.0, 0.5), geometry.quaternion_of(np.eye(3)))
    node_b = ((1.4, 2.1, 0.4), (0.9, 0.1, 0.3, -0.2))
    refined_a = geometry.world_to_camera(*rigid(r, t, *node_a))
    q, tv = local.corrected(node_b, refined_a, node_a)
    want_q, want_t = geometry.world_to_camera(*rigid(r, t, *node_b))
    assert np.allclose(geometry.rotation_of(q), geometry.rotation_of(want_q), atol=1e-12)
    assert np.allclose(tv, want_t, atol=1e-12)
    # no correction: the node pose
    q, tv = local.corrected(node_b, geometry.world_to_camera(*node_a), node_a)
    assert np.allclose(tv, geometry.world_to_camera(*node_b)[1], atol=1e-12)


class _Work:
    def __init__(self):
        self.model, self.fed_poses = None, {}
        self.pose_of = None


class _Refinement:
    def __init__(self):
        self.options, self.tool, self.log = None, None, lambda level, text: None


def keyframe(i, x):
    return Keyframe(i, "%d.png" % i, i, (x, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (500, 500, 320, 240), 640, 480)


def test_pose_of_gives_the_refined_pose_until_the_node_moves_the_keyframe():
    lr = local.LocalRefinement(_Refinement())
    work = _Work()
    lr.attach(work)
    assert work.pose_of == lr.pose_of
    k1, k2, k3 = keyframe(1, 0.0), keyframe(2, 1.0), keyframe(3, 2.0)
    assert np.allclose(lr.pose_of(k2, 2)[1], geometry.world_to_camera(k2.position, k2.orientation)[1])
    shifted = geometry.world_to_camera((1.1, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    lr._take(2, shifted[0], shifted[1], (k2.position, k2.orientation))
    assert np.allclose(lr.pose_of(k2, 2)[1], shifted[1])
    # after it: moved by its correction (+0.1 in x); before it (the first ones): too
    assert np.allclose(geometry.centre_of(*lr.pose_of(k3, 3)), (2.1, 0.0, 0.0))
    assert np.allclose(geometry.centre_of(*lr.pose_of(k1, 1)), (0.1, 0.0, 0.0))
    # the node corrects keyframe 2 (a loop closure): it is not refined any more
    moved = Keyframe(2, "2.png", 2, (1.05, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (500, 500, 320, 240), 640, 480)
    assert np.allclose(geometry.centre_of(*lr.pose_of(moved, 2)), (1.05, 0.0, 0.0))
    assert 2 not in lr.refined and lr.refined_ids == []


def test_the_model_at_the_node_poses_carries_each_point_with_its_first_image():
    points, poses, kps = scene(n_images=4, n_points=60)
    m = build(points, poses, kps)
    refined = m.to_model()
    # the node's poses: the refined ones moved rigidly (the whole model shifted and turned)
    r = geometry.rotation_of((0.99, 0.05, -0.08, 0.03))
    t = np.array([0.2, -0.1, 0.3])
    node = {}
    for iid, im in refined.images.items():
        centre, q = geometry.camera_to_world(im.qvec, im.tvec)
        node[iid] = geometry.world_to_camera(*rigid(r, t, centre, q))
    out = local.at_node_poses(refined, node)
    assert len(out.points) == len(refined.points)
    for pid, p in out.points.items():
        assert np.allclose(p.xyz, r @ refined.points[pid].xyz + t, atol=1e-9)
        assert p.error < 1e-6
    # a node pose that disagrees with the others: its observations go, the points stay
    c, q = geometry.camera_to_world(*node[4])
    node[4] = geometry.world_to_camera(np.asarray(c) + (0.0, 0.3, 0.0), q)
    out = local.at_node_poses(refined, node)
    assert all(4 not in p.image_ids.tolist() or int(p.image_ids[0]) == 4 for p in out.points.values())
    assert sum(4 in p.image_ids.tolist() for p in out.points.values()) < len(out.points) / 2
    cm_images = out.images[4]
    assert (cm_images.point3D_ids >= 0).sum() == sum(4 in p.image_ids.tolist() for p in out.points.values())


def test_a_verified_partner_is_held_even_when_it_shares_no_point_and_the_cap_is_reached():
    order = list(range(1, 31))
    shared = {5: 40, 6: 30, 7: 20}
    free, fixed = local.choose_window(order, order, refined=range(1, 27), covisible=lambda f: shared, kind="local",
                                      size=4, max_fixed=2, partners=lambda f: {2, 28})  # 2: a revisit's pair
    assert free == [27, 28, 29, 30]
    assert fixed == [2, 5, 6, 26]  # 28 is free itself; 7 beyond the cap


def test_a_run_that_outlives_its_timeout_is_killed_and_counted(tmp_path):
    # A refine_model that hangs (here: sleep) is killed at the options' timeout by the next
    # step, not left to hold every later run back until the finish.
    import subprocess
    import types
    proc = subprocess.Popen(["sleep", "60"], start_new_session=True)
    lr = local.LocalRefinement(None)
    lr.work = types.SimpleNamespace(model=object())
    folder = tmp_path / "run"
    folder.mkdir()
    lr.running = local._Run("local", [1], [], str(folder), proc, {}, set(), 0.0, 3.0, timeout=0.0)
    assert lr.step() is False
    assert lr.running is None and lr.failures == 1
    assert proc.poll() is not None and not folder.exists()

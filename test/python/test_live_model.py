"""The live model: tracks from verified matches, points at the poses, filtering, and the COLMAP
model it writes. Exact synthetic scenes; no ROS, no COLMAP."""
import numpy as np

from view_selection import geometry
from view_selection.colmap import model as cm
from view_selection.live.model import LiveModel

PARAMS = (500.0, 500.0, 320.5, 240.5)
CAMERA = ("PINHOLE", 640, 480, PARAMS)


def scene(n_images=4, n_points=300, seed=0):
    rng = np.random.default_rng(seed)
    points = rng.uniform([-1.5, -1, 4], [1.5, 1, 6], (n_points, 3))
    poses, keypoints = [], []
    for i in range(n_images):
        centre = np.array([0.3 * i, 0.02 * i, 0.0])
        q, t = geometry.world_to_camera(centre, (1.0, 0.0, 0.0, 0.0))
        r = geometry.rotation_of(q)
        pc = points @ r.T + t
        uv = np.stack([PARAMS[0] * pc[:, 0] / pc[:, 2] + PARAMS[2], PARAMS[1] * pc[:, 1] / pc[:, 2] + PARAMS[3]], 1)
        order = rng.permutation(n_points)  # keypoint j of image i is point order[j]
        poses.append((q, t))
        keypoints.append((uv[order], order))
    return points, poses, keypoints


def build(points, poses, keypoints, pairs=None):
    m = LiveModel()
    for i, ((q, t), (uv, _)) in enumerate(zip(poses, keypoints)):
        m.add_image(i + 1, "%d.png" % i, 1, CAMERA, q, t, np.hstack([uv, np.zeros((len(uv), 2))]))
    n = len(poses)
    for a, b in pairs or [(a, b) for a in range(n) for b in range(a + 1, n)]:
        kp_of_point_b = np.argsort(keypoints[b][1])
        matches = np.stack([np.arange(len(points)), kp_of_point_b[keypoints[a][1]]], 1)
        m.add_matches(a + 1, b + 1, matches)
    m.update()
    return m


def test_exact_poses_give_the_points_back():
    points, poses, kps = scene()
    m = build(points, poses, kps)
    model = m.to_model()
    assert len(model.points) == len(points)
    for p in model.points.values():
        im = model.images[int(p.image_ids[0])]
        truth = points[kps[im.id - 1][1][int(p.point2D_idxs[0])]]
        assert np.linalg.norm(p.xyz - truth) < 1e-6
        assert p.error < 1e-6
        assert len(p.image_ids) == 4  # the pairs joined into one track per point


def test_the_model_is_consistent_and_readable(tmp_path):
    points, poses, kps = scene(n_images=3, n_points=50)
    model = build(points, poses, kps).to_model()
    cm.write_model(model, str(tmp_path))
    back = cm.read_model(str(tmp_path))
    for p in back.points.values():
        for iid, idx in zip(p.image_ids, p.point2D_idxs):
            assert back.images[int(iid)].point3D_ids[int(idx)] == p.id
    assert sum(int((im.point3D_ids >= 0).sum()) for im in back.images.values()) == back.statistics()["observations"]


def test_a_wrong_observation_is_dropped_not_the_point():
    points, poses, kps = scene(n_images=4, n_points=40)
    uv, order = kps[3]
    uv = uv.copy()
    uv[:, 1] += np.where(order == 7, 25.0, 0.0)  # point 7 seen 25 px off in image 4, across the baseline
    kps[3] = (uv, order)
    model = build(points, poses, kps).to_model()
    assert len(model.points) == 40
    seven = [p for p in model.points.values()
             if any(kps[int(i) - 1][1][int(k)] == 7 for i, k in zip(p.image_ids, p.point2D_idxs))][0]
    assert sorted(seven.image_ids.tolist()) == [1, 2, 3]
    assert seven.error < 1e-6


def test_a_match_that_would_give_a_track_two_keypoints_of_one_image_is_left_out():
    m = LiveModel()
    for i in range(3):
        m.add_image(i + 1, "%d" % i, 1, CAMERA, (1, 0, 0, 0), (-0.3 * i, 0, 0), np.zeros((5, 4)))
    m.add_matches(1, 2, [[0, 0]])
    m.add_matches(2, 3, [[0, 0]])
    m.add_matches(1, 3, [[1, 0]])  # keypoint 1 of image 1 to the track that holds keypoint 0 of image 1
    assert m.conflicts == 1
    assert len(m.members) == 1 and list(m.members.values())[0] == {1: 0, 2: 0, 3: 0}


def test_a_moved_pose_triangulates_its_tracks_again():
    points, poses, kps = scene(n_images=3, n_points=30)
    m = build(points, poses, kps)
    assert m.update() == 0  # nothing changed
    q, t = poses[2]
    m.set_pose(3, q, np.asarray(t) + [0.0, 0.05, 0.0])
    assert m.update() == 30
    m.set_pose(3, q, t)
    m.update()
    assert all(p[1] < 1e-6 for p in m.points.values())


def test_points_without_parallax_or_behind_a_camera_are_not_kept():
    m = LiveModel()
    for i in range(2):  # 1 mm apart: no parallax for points 5 m away
        m.add_image(i + 1, "%d" % i, 1, CAMERA, (1, 0, 0, 0), (-0.001 * i, 0, 0), np.array([[320.5, 240.5, 1, 0]]))
    m.add_matches(1, 2, [[0, 0]])
    m.update()
    assert m.to_model().points == {}


def add_pair(m, keypoints, a, b, n_points):
    """The matches of images a and b (0-based) of a scene, every point."""
    kp_of_point_b = np.argsort(keypoints[b][1])
    m.add_matches(a + 1, b + 1, np.stack([np.arange(n_points), kp_of_point_b[keypoints[a][1]]], 1))


def test_a_track_that_grows_is_extended_not_triangulated_again():
    """Each new keyframe adds one observation to tracks of many: the update handles those new
    observations, not whole tracks (a full re-triangulation of every track would handle 5 each)."""
    n = 40
    points, poses, kps = scene(n_images=6, n_points=n)
    m = build(points, poses[:4], kps[:4])  # tracks of 4 observations, triangulated
    before = m.observations_triangulated
    q, t = poses[4]
    uv, _ = kps[4]
    m.add_image(5, "4.png", 1, CAMERA, q, t, np.hstack([uv, np.zeros((len(uv), 2))]))
    add_pair(m, kps, 3, 4, n)
    assert m.update() == n
    assert m.observations_triangulated - before == n  # one new observation a track
    model = m.to_model()
    assert len(model.points) == n and all(len(p.image_ids) == 5 for p in model.points.values())
    for p in model.points.values():
        im = model.images[int(p.image_ids[0])]
        assert np.linalg.norm(p.xyz - points[kps[im.id - 1][1][int(p.point2D_idxs[0])]]) < 1e-6


def test_a_new_observation_off_the_point_does_not_join_it():
    n = 30
    points, poses, kps = scene(n_images=5, n_points=n)
    m = build(points, poses[:4], kps[:4])
    uv, order = kps[4]
    uv = uv.copy()
    uv[:, 1] += np.where(order == 3, 12.0, 0.0)  # point 3 seen 12 px off in the new image
    q, t = poses[4]
    m.add_image(5, "4.png", 1, CAMERA, q, t, np.hstack([uv, np.zeros((len(uv), 2))]))
    add_pair(m, [kps[0], kps[1], kps[2], kps[3], (uv, order)], 3, 4, n)
    m.update()
    model = m.to_model()
    assert len(model.points) == n  # the point stays, without the wrong observation
    lengths = sorted(len(p.image_ids) for p in model.points.values())
    assert lengths == [4] + [5] * (n - 1)
    assert max(p.error for p in model.points.values()) < 1e-6


def test_two_points_that_merge_are_triangulated_from_scratch():
    """Two tracks of the same 3D point, each with its own point, joined by a later match: the
    one point is triangulated from all observations, not extended from either."""
    n = 20
    points, poses, kps = scene(n_images=6, n_points=n)
    m = build(points, poses, kps, pairs=[(0, 1), (1, 2), (0, 2), (3, 4), (4, 5), (3, 5)])
    assert len(m.points) == 2 * n
    before = m.observations_triangulated
    add_pair(m, kps, 2, 3, n)
    m.update()
    assert m.observations_triangulated - before == 6 * n  # every observation of each merged track
    model = m.to_model()
    assert len(model.points) == n and all(len(p.image_ids) == 6 for p in model.points.values())


def test_a_short_track_that_merges_into_a_long_one_joins_its_point():
    """A revisit joins a short track with a point (2 observations) to a long one of the same 3D
    point (6): the short one's observations join the long one's point, as a growing track's do,
    and only they are looked at (a triangulation from scratch would handle all 8)."""
    n = 20
    points, poses, kps = scene(n_images=8, n_points=n)
    m = build(points, poses, kps, pairs=[(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (6, 7)])
    assert len(m.points) == 2 * n
    before = m.observations_triangulated
    add_pair(m, kps, 5, 6, n)
    m.update()
    assert m.observations_triangulated - before == 2 * n  # the short tracks' observations only
    model = m.to_model()
    assert len(model.points) == n and all(len(p.image_ids) == 8 for p in model.points.values())
    for p in model.points.values():
        im = model.images[int(p.image_ids[0])]
        assert np.linalg.norm(p.xyz - points[kps[im.id - 1][1][int(p.point2D_idxs[0])]]) < 1e-6


def views_along_x(xs, n, seed):
    """A live model with one image at each x (looking down z), n random points seen by all,
    keypoint j being point j in every image; and the matches of a pair (every point)."""
    points = np.random.default_rng(seed).uniform([-1, -1, 4], [1, 1, 6], (n, 3))
    m = LiveModel()
    for i, x in enumerate(xs):
        q, t = geometry.world_to_camera(np.array([x, 0.0, 0.0]), (1.0, 0.0, 0.0, 0.0))
        pc = points @ geometry.rotation_of(q).T + t
        uv = np.stack([PARAMS[0] * pc[:, 0] / pc[:, 2] + PARAMS[2], PARAMS[1] * pc[:, 1] / pc[:, 2] + PARAMS[3]], 1)
        m.add_image(i + 1, "%d.png" % i, 1, CAMERA, q, t, np.hstack([uv, np.zeros((n, 2))]))
    return m, np.stack([np.arange(n), np.arange(n)], 1)


def test_a_track_without_a_point_waits_until_it_grew_by_half():
    """Tracks seen without parallax give no point; touched again with one more view without
    parallax they are not triangulated again; once a view with parallax has joined, they are."""
    n = 25
    m, same = views_along_x([0.0, 0.0005, 0.001, 0.0015, 0.8], n, seed=5)  # four views 0.5 mm apart, one 0.8 m away
    m.add_matches(1, 2, same)
    m.update()
    assert m.points == {} and m.observations_triangulated == 2 * n
    m.add_matches(2, 3, same)  # 3 observations: not half as many again as 2
    m.update()
    assert m.points == {} and m.observations_triangulated == 2 * n
    m.add_matches(3, 4, same)  # 4: tried again, still no parallax
    m.update()
    assert m.points == {} and m.observations_triangulated == 2 * n + 4 * n
    m.add_matches(4, 5, same)  # 5 < 6: waits, even with parallax now
    m.update()
    assert m.points == {}
    m.add_matches(1, 5, same)  # the same tracks touched again: still 5 observations, still waiting
    m.update()
    assert m.points == {}
    m.set_pose(5, *geometry.world_to_camera(np.array([0.8001, 0.0, 0.0]), (1.0, 0.0, 0.0, 0.0)))
    m.update()  # a moved pose triangulates its tracks from scratch: now with parallax
    assert len(m.points) == n


def test_the_final_update_tries_every_track_that_grew_since_it_gave_no_point():
    n = 20
    m, same = views_along_x([0.0, 0.0005, 0.8], n, seed=6)
    m.add_matches(1, 2, same)  # no parallax: no point
    m.update()
    m.add_matches(2, 3, same)  # 3 observations, 2 when it failed: waits in a live update ...
    m.update()
    assert m.points == {}
    m.update(final=True)  # ... not in the finish's
    assert len(m.points) == n


def test_the_final_update_leaves_a_long_track_that_grew_little_to_wait():
    # A track of more than FINAL_RETRY_MAX_OBSERVATIONS that gave no point and grew by one is not
    # tried again in the finish (its one-by-one triangulation costs the square of its length);
    # grown by half, it is, as in a live update.
    from view_selection.live import model as live_model
    n, long = 10, live_model.FINAL_RETRY_MAX_OBSERVATIONS + 1
    xs = [0.0005 * i for i in range(long)] + [0.8] + [0.8 + 0.0005 * i for i in range(long // 2 + 1)]
    m, same = views_along_x(xs, n, seed=7)
    for i in range(1, long):  # long views without parallax: no point
        m.add_matches(i, i + 1, same)
    m.update()
    assert m.points == {} and all(len(t) == long for t in m.members.values())
    m.add_matches(long, long + 1, same)  # one more view, with parallax
    m.update(final=True)
    assert m.points == {}  # long: waits until it grew by half
    for i in range(long + 1, len(xs)):
        m.add_matches(i, i + 1, same)
    m.update(final=True)
    assert len(m.points) == n


def test_every_image_of_a_track_knows_it():
    """A moved pose re-triangulates every track the image is in, whichever side of the first
    match it was on (a track begun by a match of two lone observations included)."""
    points, poses, kps = scene(n_images=3, n_points=30)
    m = build(points, poses, kps)
    for iid in (1, 2, 3):
        assert len(m.by_image[iid]) == 30, iid
    q, t = poses[0]
    m.set_pose(1, q, np.asarray(t) + [0.0, 0.05, 0.0])
    assert m.update() == 30

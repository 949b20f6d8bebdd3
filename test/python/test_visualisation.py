"""What colmap_bridge shows of its model (live/visualisation.py): the cloud follows the live model
point for point as it grows, moves and loses points, each point coloured from its keyframe image
at its keypoint; the finished model replaces it; the frusta sit at the cameras' poses. Exact
synthetic scenes (test_live_model's); no ROS."""
import cv2
import numpy as np

from view_selection import geometry
from view_selection.colmap import model as cm
from view_selection.live.visualisation import CloudBuffer, ModelView, frustum_lines, pack_rgb

from test_live_model import CAMERA, PARAMS, scene

COLOURS = [(200, 30, 10), (20, 180, 40), (10, 20, 220), (250, 250, 0)]  # image i is all COLOURS[i] (r, g, b)


def write_images(folder, n):
    for i in range(n):
        r, g, b = COLOURS[i]
        cv2.imwrite(str(folder / ("%d.png" % i)), np.full((480, 640, 3), (b, g, r), np.uint8))


def add(m, kps, poses, i):
    (q, t), (uv, _) = poses[i], kps[i]
    m.add_image(i + 1, "%d.png" % i, 1, CAMERA, q, t, np.hstack([uv, np.zeros((len(uv), 2))]))


def match(m, kps, n_points, a, b):
    kp_of_point_b = np.argsort(kps[b][1])
    m.add_matches(a + 1, b + 1, np.stack([np.arange(n_points), kp_of_point_b[kps[a][1]]], 1))


def cloud_of(view):
    """{rounded xyz: rgb} of what the payload holds."""
    rows = np.frombuffer(view.cloud().payload(), np.float32).reshape(-1, 4)
    rgb = rows.view(np.uint32)[:, 3]
    return rows[:, :3].astype(np.float64), rgb


def assert_cloud_is_the_model(view, m):
    xyz, rgb = cloud_of(view)
    want = np.array([m.points[r][0] for r in sorted(m.points)]).reshape(-1, 3)
    assert len(xyz) == len(want)
    order = np.lexsort(xyz.T)
    np.testing.assert_allclose(xyz[order], want[np.lexsort(want.T)], atol=1e-5)
    for root, (x, _, obs) in m.points.items():  # each point's colour: an image's that sees it, read once
        q = int(np.argmin(np.linalg.norm(xyz - x, axis=1)))
        assert rgb[q] in {int(pack_rgb(*COLOURS[i - 1])) for i in obs}, (root, hex(rgb[q]))


def first_pair(tmp_path, n_images, n_points):
    """A scene's images written, a live model with its first two images matched and updated,
    and a view of it: (points, poses, keypoints, model, view)."""
    from view_selection.live.model import LiveModel
    points, poses, kps = scene(n_images=n_images, n_points=n_points)
    write_images(tmp_path, n_images)
    m = LiveModel()
    view = ModelView(str(tmp_path))
    add(m, kps, poses, 0)
    add(m, kps, poses, 1)
    match(m, kps, len(points), 0, 1)
    m.update()
    return points, poses, kps, m, view


def first_three(tmp_path, n_images, n_points):
    """A scene's images written, a live model with its first three images matched in a chain
    (0-1, 1-2) and updated, and a view that took it: (points, poses, keypoints, model, view)."""
    from view_selection.live.model import LiveModel
    points, poses, kps = scene(n_images=n_images, n_points=n_points)
    write_images(tmp_path, n_images)
    m = LiveModel()
    view = ModelView(str(tmp_path))
    for i in range(3):
        add(m, kps, poses, i)
    match(m, kps, len(points), 0, 1)
    match(m, kps, len(points), 1, 2)
    m.update()
    view.live(m)
    return points, poses, kps, m, view


def test_the_cloud_follows_the_live_model(tmp_path):
    points, poses, kps, m, view = first_pair(tmp_path, 4, 120)
    assert view.live(m) == 120  # the first call takes every point the model has
    assert_cloud_is_the_model(view, m)
    version = view.cloud_version
    assert view.live(m) == 0 and view.cloud_version == version  # nothing changed: nothing to send

    add(m, kps, poses, 2)
    add(m, kps, poses, 3)
    match(m, kps, len(points), 1, 2)
    match(m, kps, len(points), 2, 3)
    m.update()
    assert view.live(m) > 0 and view.cloud_version > version
    assert_cloud_is_the_model(view, m)
    assert [f.id for f in view.frusta()] == [1, 2, 3, 4]
    assert view.colours.decoded <= 4  # every image read once, however many updates

    # A pose moves (a loop closure): the tracks that see it are triangulated again and move.
    q, t = poses[3]
    centre = -geometry.rotation_of(q).T @ np.asarray(t) + np.array([0.0, 0.0, 0.01])
    q2, t2 = geometry.world_to_camera(centre, (1.0, 0.0, 0.0, 0.0))
    m.set_pose(4, q2, t2)
    m.update()
    assert view.live(m) > 0
    assert_cloud_is_the_model(view, m)
    moved = [f for f in view.frusta() if f.id == 4][0]
    np.testing.assert_allclose(moved.centre, centre, atol=1e-12)


def test_only_the_frusta_of_new_images_and_moved_poses_are_made_again(tmp_path):
    # Each new keyframe made every frustum again: CPU that grew with the session. A frustum is
    # made for an image that came or whose pose moved; the others are the same objects.
    from view_selection.live.visualisation import frustum_of
    points, poses, kps, m, view = first_pair(tmp_path, 4, 60)
    view.live(m)
    before = {f.id: f for f in view.frusta()}
    version = view.cameras_version
    add(m, kps, poses, 2)
    view.live(m)
    after = {f.id: f for f in view.frusta()}
    assert sorted(after) == [1, 2, 3] and view.cameras_version > version
    assert after[1] is before[1] and after[2] is before[2]
    q, t = poses[0]
    m.set_pose(1, q, np.asarray(t) + [0.0, 0.02, 0.0])
    m.update()
    view.live(m)
    again = {f.id: f for f in view.frusta()}
    assert again[1] is not after[1] and again[2] is after[2] and again[3] is after[3]
    # The same frusta as made from scratch, in image order.
    fresh = [frustum_of(i, im.name, geometry.quaternion_of(im.r), im.t, m.cameras[im.camera_id], view.frustum_depth)
             for i, im in sorted(m.images.items())]
    assert view.frusta() == fresh
    version = view.cameras_version
    view.live(m)
    assert view.cameras_version == version  # nothing came, nothing moved


def test_points_that_are_lost_leave_the_cloud(tmp_path):
    """Image 2 moved onto image 1's centre: no triangulation angle left, every point goes."""
    points, poses, kps, m, view = first_pair(tmp_path, 2, 60)
    view.live(m)
    assert len(view.cloud()) == 60
    q, t = poses[0]
    m.set_pose(2, q, np.asarray(t) + 1e-4)
    m.update()
    assert len(m.points) == 0
    view.live(m)
    assert len(view.cloud()) == 0


def test_the_finished_model_replaces_the_live_one_until_the_model_changes(tmp_path):
    points, poses, kps, m, view = first_three(tmp_path, 3, 80)
    folder = tmp_path / "sparse"
    folder.mkdir()
    written = m.to_model()
    for p in written.points.values():  # the refinement moved the points a little
        p.xyz = p.xyz + 0.01
    cm.write_model(written, str(folder))
    finished = cm.read_model(str(folder))
    view.finished(finished)
    assert view.showing_finished
    xyz, rgb = cloud_of(view)
    want = np.array([p.xyz for p in finished.points.values()])
    np.testing.assert_allclose(xyz[np.lexsort(xyz.T)], want[np.lexsort(want.T)], atol=1e-5)
    first_image = {int(p.image_ids[0]) for p in finished.points.values()}
    assert set(rgb.tolist()) == {int(pack_rgb(*COLOURS[i - 1])) for i in first_image}
    for f in view.frusta():
        im = finished.images[f.id]
        centre, orientation = geometry.camera_to_world(im.qvec, im.tvec)
        np.testing.assert_allclose(f.centre, centre, atol=1e-12)
        np.testing.assert_allclose(f.orientation, orientation, atol=1e-12)
    assert view.live(m) == 0 and view.showing_finished  # nothing new: the finished model stays

    q, t = poses[2]
    m.set_pose(3, q, np.asarray(t) + np.array([0.0, 0.0, 0.02]))  # the recording went on
    m.update()
    view.live(m)
    assert not view.showing_finished
    assert_cloud_is_the_model(view, m)


def test_a_finished_model_older_than_the_live_one_is_not_shown(tmp_path):
    """The bridge's sending thread reads the finished model after the finish: when the live model
    changed meanwhile (the recording went on), the finished one is older and the live one stays."""
    points, poses, kps, m, view = first_three(tmp_path, 4, 80)
    at_finish = view.cloud_version
    folder = tmp_path / "sparse"
    folder.mkdir()
    cm.write_model(m.to_model(), str(folder))
    finished = cm.read_model(str(folder))
    add(m, kps, poses, 3)  # a keyframe came before the finished model was read
    match(m, kps, len(points), 2, 3)
    m.update()
    view.live(m)
    assert view.cloud_version != at_finish
    assert not view.finished(finished, at_finish)
    assert not view.showing_finished
    assert len(view.frusta()) == 4  # the live model's, with the new keyframe
    assert_cloud_is_the_model(view, m)
    assert view.finished(finished, view.cloud_version)  # nothing changed since: it is shown
    assert view.showing_finished and len(view.frusta()) == 3

def test_the_frustum_reaches_the_image_corners():
    fx, fy, cx, cy = PARAMS
    lines = np.array(frustum_lines(fx, fy, cx, cy, 640, 480, 0.5))
    assert lines.shape == (16, 3)
    far = lines[lines[:, 2] > 0]
    uv = np.stack([fx * far[:, 0] / far[:, 2] + cx, fy * far[:, 1] / far[:, 2] + cy], 1)
    assert {(round(u, 9), round(v, 9)) for u, v in uv} == {(0, 0), (640, 0), (640, 480), (0, 480)}
    np.testing.assert_allclose(far[:, 2], 0.5)


def test_the_buffer_stays_compact():
    b = CloudBuffer(capacity=2)
    b.put(["a", "b", "c"], np.arange(9.0).reshape(3, 3), np.array([1, 2, 3], np.uint32))
    b.remove(["a", "zzz"])
    b.put(["c", "d"], np.array([[9.0, 9, 9], [7, 7, 7]]), np.array([5, 4], np.uint32))
    assert len(b) == 3
    got = {k: (tuple(b.xyz()[b.slot[k]]), int(b.rgb()[b.slot[k]])) for k in b.keys}
    assert got == {"b": ((3.0, 4.0, 5.0), 2), "c": ((9.0, 9.0, 9.0), 3), "d": ((7.0, 7.0, 7.0), 4)}
    assert len(b.payload()) == 3 * 16

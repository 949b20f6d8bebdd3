import sqlite3

import numpy as np
import pytest

from view_selection.colmap import database as db

# The columns of COLMAP 3.8's tables, as `colmap database_creator` makes them.
COLMAP_COLUMNS = {
    "cameras": ["camera_id", "model", "width", "height", "params", "prior_focal_length"],
    "images": ["image_id", "name", "camera_id", "prior_qw", "prior_qx", "prior_qy", "prior_qz", "prior_tx",
               "prior_ty", "prior_tz"],
    "keypoints": ["image_id", "rows", "cols", "data"],
    "descriptors": ["image_id", "rows", "cols", "data"],
    "matches": ["pair_id", "rows", "cols", "data"],
    "two_view_geometries": ["pair_id", "rows", "cols", "data", "config", "F", "E", "H", "qvec", "tvec"],
}


@pytest.fixture
def path(tmp_path):
    return str(tmp_path / "database.db")


def test_schema_is_colmaps(path):
    with db.Database(path, create=True) as d:
        for table, columns in COLMAP_COLUMNS.items():
            assert [r[1] for r in d.con.execute("PRAGMA table_info(%s)" % table)] == columns


def test_pair_id_is_order_free_and_inverts():
    assert db.pair_id(3, 7) == db.pair_id(7, 3) == 3 * 2147483647 + 7
    assert db.ids_of_pair(db.pair_id(7, 3)) == (3, 7)


def test_cameras_are_shared_by_equal_intrinsics(path):
    with db.Database(path, create=True) as d:
        a = d.camera_id(640, 480, (525.0, 525.0, 319.5, 239.5))
        b = d.camera_id(640, 480, (525.0, 525.0, 319.5, 239.5))
        c = d.camera_id(640, 480, (525.0, 525.0, 320.0, 239.5))
        assert a == b != c
        assert d.cameras()[c] == (db.PINHOLE, 640, 480, (525.0, 525.0, 320.0, 239.5))


def test_images_get_ids_in_order_and_names_are_unique(path):
    with db.Database(path, create=True) as d:
        cam = d.camera_id(64, 48, (50, 50, 32, 24))
        ids = [d.add_image("%d.png" % i, cam) for i in range(3)]
        assert ids == [1, 2, 3]
        with pytest.raises(db.DatabaseError):
            d.add_image("1.png", cam)
    with db.Database(path) as d:  # committed, visible to a new connection
        assert d.image_ids() == {"0.png": 1, "1.png": 2, "2.png": 3}


def test_features_round_trip(path):
    rng = np.random.default_rng(1)
    kp = rng.uniform(0, 100, (50, 6)).astype(np.float32)
    desc = rng.integers(0, 255, (50, 128)).astype(np.uint8)
    with db.Database(path, create=True) as d:
        iid = d.add_image("a.png", d.camera_id(64, 48, (50, 50, 32, 24)))
        d.write_features(iid, kp, desc)
        d.add_image("b.png", 1)
    with db.Database(path) as d:
        assert np.array_equal(d.keypoints(1), kp)
        assert np.array_equal(d.descriptors(1), desc)
        assert d.images_with_features() == {"a.png"}
        assert d.keypoints(2).shape == (0, 2)


def test_features_of_wrong_shape_are_refused(path):
    with db.Database(path, create=True) as d:
        iid = d.add_image("a.png", d.camera_id(64, 48, (50, 50, 32, 24)))
        with pytest.raises(db.DatabaseError):
            d.write_features(iid, np.zeros((5, 3)), np.zeros((5, 128)))
        with pytest.raises(db.DatabaseError):
            d.write_features(iid, np.zeros((5, 2)), np.zeros((4, 128)))


def test_matches_are_stored_in_colmaps_direction(path):
    """COLMAP keys a pair by (smaller id, larger id) and its columns follow that order: matches
    written from the larger id are swapped, and read back in the order asked."""
    m = np.array([[0, 5], [1, 6], [2, 7]])
    with db.Database(path, create=True) as d:
        cam = d.camera_id(64, 48, (50, 50, 32, 24))
        a, b = d.add_image("a", cam), d.add_image("b", cam)
        d.write_matches(b, a, m)  # b's points first
        raw = d.con.execute("SELECT data FROM matches WHERE pair_id = ?", (db.pair_id(a, b),)).fetchone()[0]
        assert np.array_equal(np.frombuffer(raw, np.uint32).reshape(-1, 2), m[:, ::-1])
        assert np.array_equal(d.matches(b, a), m)
        assert np.array_equal(d.matches(a, b), m[:, ::-1])


def test_two_view_geometry_written_backwards_is_inverted(path):
    from view_selection import geometry
    r = geometry.rotation_of((0.9, 0.1, -0.2, 0.3))
    t = np.array([0.5, -0.1, 0.2])
    with db.Database(path, create=True) as d:
        cam = d.camera_id(64, 48, (50, 50, 32, 24))
        a, b = d.add_image("a", cam), d.add_image("b", cam)
        # the pose of a relative to b (x_a = r x_b + t), written from b's side
        d.write_two_view_geometry(b, a, [[0, 1], [2, 3]], db.CALIBRATED, qvec=geometry.quaternion_of(r), tvec=t)
        g = d.two_view_geometry(a, b)
        assert g["rows"] == 2 and g["config"] == db.CALIBRATED
        r_ab = geometry.rotation_of(g["qvec"])  # x_b = r_ab x_a + t_ab
        assert np.allclose(r_ab, r.T, atol=1e-12)
        assert np.allclose(g["tvec"], -r.T @ t, atol=1e-12)
        assert d.geometry_pairs(verified_only=True) == {(a, b)}
        assert d.counts()["pairs_verified"] == 1


def test_unverified_pairs_count_as_matched_not_verified(path):
    with db.Database(path, create=True) as d:
        cam = d.camera_id(64, 48, (50, 50, 32, 24))
        a, b, c = (d.add_image(n, cam) for n in "abc")
        d.write_two_view_geometry(a, b, np.zeros((0, 2)), db.UNDEFINED)
        d.write_two_view_geometry(a, c, [[1, 1]], db.CALIBRATED)
        assert d.geometry_pairs() == {(a, b), (a, c)}
        assert d.geometry_pairs(verified_only=True) == {(a, c)}
        assert d.inlier_counts() == {(a, b): 0, (a, c): 1}


def test_a_failed_block_writes_nothing(path):
    with db.Database(path, create=True) as d:
        d.camera_id(64, 48, (50, 50, 32, 24))
    with pytest.raises(RuntimeError):
        with db.Database(path) as d:
            d.add_image("a", 1)
            raise RuntimeError("interrupted")
    with db.Database(path) as d:
        assert d.image_ids() == {}


def test_not_a_database_is_a_clear_error(tmp_path):
    bad = tmp_path / "garbage.db"
    bad.write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(db.DatabaseError, match="not a COLMAP database"):
        db.Database(str(bad))
    other = tmp_path / "other.db"
    sqlite3.connect(str(other)).execute("CREATE TABLE x (a INTEGER)")
    with pytest.raises(db.DatabaseError, match="no table"):
        db.Database(str(other))


def test_verified_matches_are_every_pairs_inliers_in_one_read(path):
    """verified_matches() is what matches(a, b, "two_view_geometries") gives pair by pair, in
    COLMAP's direction, without the pairs whose geometry has no inliers; the matches file the
    finish writes from it is the one written pair by pair (a cropped refinement's path)."""
    from view_selection.refinement import refiner
    rng = np.random.default_rng(3)
    with db.Database(path, create=True) as d:
        cam = d.camera_id(64, 48, (50, 50, 32, 24))
        ids = [d.add_image("im%d" % i, cam) for i in range(5)]
        written = {}
        for a, b, n in ((ids[3], ids[0], 7), (ids[1], ids[2], 4), (ids[4], ids[1], 0), (ids[0], ids[4], 2)):
            m = rng.integers(0, 1000, (n, 2))
            d.write_two_view_geometry(a, b, m)
            written[(min(a, b), max(a, b))] = m if a < b else m[:, ::-1]
    with db.Database(path) as d:
        pairs, matches = d.verified_matches()
    assert [tuple(p) for p in pairs] == [(a, b, len(m)) for (a, b), m in sorted(written.items()) if len(m)]
    assert np.array_equal(matches, np.concatenate([m for _, m in sorted(written.items())]))
    one_read, by_pair = path + ".all.bin", path + ".pairs.bin"
    assert refiner.write_matches(path, one_read) == 13
    assert refiner.write_matches(path, by_pair, pairs=list(written)) == 13
    with open(one_read, "rb") as f, open(by_pair, "rb") as g:
        assert f.read() == g.read()

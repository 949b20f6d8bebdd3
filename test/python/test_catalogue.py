"""The project's in-memory catalogue of its database (colmap/catalogue.py): kept current by the
steps that write, it must always equal a catalogue read anew from the database."""
import numpy as np
import pytest

from view_selection.colmap import database as db
from view_selection.colmap.catalogue import Catalogue


def snapshot(c):
    return (c.ids, c.image_cameras, c.with_features, c.inliers)


@pytest.fixture
def path(tmp_path):
    p = str(tmp_path / "database.db")
    with db.Database(p, create=True) as d:
        cam = d.camera_id(640, 480, (525.0, 525.0, 320.0, 240.0))
        for i in range(6):
            d.add_image("%d.png" % i, cam)
    return p


def features(n):
    return np.zeros((n, 4), np.float32), np.zeros((n, 128), np.uint8)


def test_reads_back_only_what_a_step_wrote_and_equals_a_fresh_read(path):
    with db.Database(path) as d:
        cat = Catalogue(d)
    assert cat.with_features == set() and cat.inliers == {} and cat.take_new_verified() == []
    with db.Database(path) as d:  # a step (COLMAP's, say) writes; the catalogue is told what it worked on
        for i in (0, 1, 2):
            d.write_features(cat.ids["%d.png" % i], *features(5))
        d.write_two_view_geometry(cat.ids["0.png"], cat.ids["1.png"], [[0, 0], [1, 1]])
        d.write_two_view_geometry(cat.ids["2.png"], cat.ids["1.png"], np.zeros((0, 2)), config=0)
    with db.Database(path) as d:
        cat.read_features(d, ["0.png", "1.png", "2.png", "3.png"])
        cat.read_pairs(d, [("0.png", "1.png"), ("1.png", "2.png"), ("3.png", "4.png")])
    with db.Database(path) as d:
        assert snapshot(cat) == snapshot(Catalogue(d))
    assert cat.inliers == {("0.png", "1.png"): 2, ("1.png", "2.png"): 0}
    assert cat.take_new_verified() == [(cat.ids["0.png"], cat.ids["1.png"])]  # the verified one, once
    assert cat.take_new_verified() == []


def test_a_fresh_catalogue_hands_every_verified_pair_to_the_live_model_once(path):
    # A restarted bridge: its live model has nothing yet, so every verified pair is new to it.
    with db.Database(path) as d:
        ids = d.image_ids()
        d.write_two_view_geometry(ids["4.png"], ids["3.png"], [[0, 0]])
        d.write_two_view_geometry(ids["0.png"], ids["5.png"], [[0, 0], [2, 3]])
        d.write_two_view_geometry(ids["1.png"], ids["2.png"], np.zeros((0, 2)), config=0)
        cat = Catalogue(d)
    assert sorted(cat.take_new_verified()) == sorted([(ids["3.png"], ids["4.png"]), (ids["0.png"], ids["5.png"])])
    cat.geometry_written(("5.png", "0.png"), 7)  # matched again: not new
    cat.geometry_written(("2.png", "1.png"), 4)  # verified now
    assert cat.take_new_verified() == [(ids["1.png"], ids["2.png"])]

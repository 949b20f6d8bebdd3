import os

import numpy as np
import pytest

from view_selection.colmap import model as cm


def sample_model():
    m = cm.Model()
    m.cameras[1] = cm.Camera(1, "PINHOLE", 640, 480, (525.0, 526.0, 319.5, 239.5))
    m.cameras[2] = cm.Camera(2, "SIMPLE_RADIAL", 320, 240, (300.0, 160.0, 120.0, 0.01))
    m.images[1] = cm.Image(1, (1, 0, 0, 0), (0, 0, 0), 1, "rgb/1.png", [[10.25, 20.5], [30, 40]], [7, -1])
    m.images[3] = cm.Image(3, (0.9, 0.1, -0.2, 0.3), (0.5, -0.25, 2.0), 2, "rgb/3 with space.png",
                           [[1, 2]], [7])
    m.images[4] = cm.Image(4, (1, 0, 0, 0), (1, 0, 0), 1, "rgb/4.png")  # no points
    m.points[7] = cm.Point3D(7, (0.1, 0.2, 3.0), (255, 0, 10), 0.75, [1, 3], [0, 0])
    m.points[9] = cm.Point3D(9, (1, 2, 3), (0, 0, 0), 1.25, [1, 3, 4], [1, 0, 0])
    return m


def same(a, b):
    assert sorted(a.cameras) == sorted(b.cameras)
    for k in a.cameras:
        ca, cb = a.cameras[k], b.cameras[k]
        assert (ca.model, ca.width, ca.height, ca.params) == (cb.model, cb.width, cb.height, cb.params)
    assert sorted(a.images) == sorted(b.images)
    for k in a.images:
        ia, ib = a.images[k], b.images[k]
        assert (ia.name, ia.camera_id, ia.qvec, ia.tvec) == (ib.name, ib.camera_id, ib.qvec, ib.tvec)
        assert np.array_equal(ia.xys, ib.xys) and np.array_equal(ia.point3D_ids, ib.point3D_ids)
    assert sorted(a.points) == sorted(b.points)
    for k in a.points:
        pa, pb = a.points[k], b.points[k]
        assert np.array_equal(pa.xyz, pb.xyz) and pa.rgb == pb.rgb and pa.error == pb.error
        assert np.array_equal(pa.image_ids, pb.image_ids) and np.array_equal(pa.point2D_idxs, pb.point2D_idxs)


@pytest.mark.parametrize("binary", [True, False])
def test_round_trip(tmp_path, binary):
    m = sample_model()
    cm.write_model(m, str(tmp_path), binary=binary)
    assert sorted(os.listdir(str(tmp_path))) == sorted(n + (".bin" if binary else ".txt")
                                                       for n in ("cameras", "images", "points3D"))
    same(m, cm.read_model(str(tmp_path)))


def test_binary_and_text_agree(tmp_path):
    m = sample_model()
    cm.write_model(m, str(tmp_path / "b"), binary=True)
    cm.write_model(cm.read_model(str(tmp_path / "b")), str(tmp_path / "t"), binary=False)
    same(m, cm.read_model(str(tmp_path / "t")))


def test_invalid_point_ids_are_colmaps_in_binary(tmp_path):
    cm.write_model(sample_model(), str(tmp_path), binary=True)
    data = (tmp_path / "images.bin").read_bytes()
    assert (2 ** 64 - 1).to_bytes(8, "little") in data  # kInvalidPoint3DId, not -1 as a signed value
    assert cm.read_model(str(tmp_path)).images[1].point3D_ids.tolist() == [7, -1]


def test_statistics_are_model_analyzers():
    s = sample_model().statistics()
    assert s["registered"] == 3 and s["points"] == 2 and s["observations"] == 5
    assert s["track_length"] == pytest.approx(2.5)
    assert s["obs_per_image"] == pytest.approx(5 / 3)
    assert s["reprojection_error"] == pytest.approx(1.0)


def test_truncated_file_is_a_clear_error(tmp_path):
    cm.write_model(sample_model(), str(tmp_path), binary=True)
    data = (tmp_path / "images.bin").read_bytes()
    (tmp_path / "images.bin").write_bytes(data[:len(data) // 2])
    with pytest.raises(cm.ModelError, match="ends early"):
        cm.read_model(str(tmp_path))


def test_empty_folder_is_a_clear_error(tmp_path):
    with pytest.raises(cm.ModelError, match="no COLMAP model"):
        cm.read_model(str(tmp_path))


def as_table(m):
    """sample_model's points as a PointTable (what LiveModel.to_model hands the writer)."""
    points = [m.points[k] for k in sorted(m.points)]
    t = cm.Model(m.cameras, m.images)
    t.points = cm.PointTable([p.id for p in points], [p.xyz for p in points], [p.rgb for p in points],
                             [p.error for p in points],
                             np.concatenate([[0], np.cumsum([len(p.image_ids) for p in points])]),
                             np.concatenate([p.image_ids for p in points]),
                             np.concatenate([p.point2D_idxs for p in points]))
    return t


@pytest.mark.parametrize("binary", [True, False])
def test_a_point_table_is_its_points(tmp_path, binary):
    """A model whose points are a PointTable reads as its Point3Ds, has their statistics and is
    written byte for byte as the model with the Point3Ds."""
    m, t = sample_model(), as_table(sample_model())
    same(m, t)
    assert dict(t.points.items()).keys() == m.points.keys() and len(list(t.points.values())) == 2
    assert t.statistics() == m.statistics()
    cm.write_model(m, str(tmp_path / "points"), binary=binary)
    cm.write_model(t, str(tmp_path / "table"), binary=binary)
    for name in os.listdir(str(tmp_path / "points")):
        assert (tmp_path / "points" / name).read_bytes() == (tmp_path / "table" / name).read_bytes()
    with pytest.raises(cm.ModelError):
        cm.PointTable([1], [[0, 0, 1]], (0, 0, 0), [0.5], [0, 3], [1, 2], [0, 0])  # 3 said, 2 held

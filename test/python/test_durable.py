"""Writes that survive a crash (issue 35): a file is the old one or the new one, and DIR/sparse/0
is a complete model at every moment of its replacement, also when the replacement stops half
way."""
import os

import pytest

from view_selection.colmap import durable
from view_selection.colmap import model as cm
from view_selection.colmap.project import write_json_atomically


def small_model(n):
    m = cm.Model()
    m.cameras[1] = cm.Camera(1, "PINHOLE", 640, 480, [500.0, 500.0, 320.0, 240.0])
    for i in range(1, n + 1):
        m.images[i] = cm.Image(i, [1.0, 0.0, 0.0, 0.0], [float(i), 0.0, 0.0], 1, "%03d.png" % i)
    return m


def names(folder):
    return sorted(im.name for im in cm.read_model(folder).images.values())


def test_exchange_swaps_two_folders_in_one_step(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    (a / "x").write_text("a")
    (b / "x").write_text("b")
    durable.exchange(str(a), str(b))  # ext4, tmpfs, xfs, btrfs have it; the tests' folders are one of them
    assert (a / "x").read_text() == "b" and (b / "x").read_text() == "a"


def test_a_model_replaced_is_complete_at_every_step(tmp_path, monkeypatch):
    """Each step of replace_folder (every fsync of a folder and the removal of the old model) is
    a moment a crash could stop it at: sparse/0 is then a complete model, old or new, and the
    swap is the exchange, not two renames."""
    output = str(tmp_path / "sparse" / "0")
    cm.write_model(small_model(3), output)
    made = str(tmp_path / "sparse" / ".write_x" / "made")
    cm.write_model(small_model(5), made)
    seen, exchanged = [], []
    real_fsync, real_exchange = durable.fsync_folder, durable.exchange

    def checked_fsync(path):
        seen.append(names(output))
        real_fsync(path)

    def recorded_exchange(a, b):
        exchanged.append((a, b))
        real_exchange(a, b)

    def no_rename(a, b):
        raise AssertionError("sparse/0 renamed away: it would be absent until the next rename")

    monkeypatch.setattr(durable, "fsync_folder", checked_fsync)
    monkeypatch.setattr(durable, "exchange", recorded_exchange)
    monkeypatch.setattr(durable.os, "rename", no_rename)
    durable.replace_folder(made, output)
    assert exchanged == [(made, output)]
    assert len(seen) >= 3 and all(s in (names_of(3), names_of(5)) for s in seen)
    assert names(output) == names_of(5)
    assert not os.path.exists(made)  # the old model, removed after the swap


def names_of(n):
    return ["%03d.png" % i for i in range(1, n + 1)]


def test_a_replacement_that_stops_after_the_swap_leaves_a_complete_model(tmp_path, monkeypatch):
    output = str(tmp_path / "sparse" / "0")
    cm.write_model(small_model(3), output)
    made = str(tmp_path / "sparse" / ".write_x" / "made")
    cm.write_model(small_model(4), made)

    def crash(path):
        raise OSError("the machine stops here")

    monkeypatch.setattr(durable, "fsync_folder", crash)
    with pytest.raises(OSError):
        durable.replace_folder(made, output)
    assert names(output) in (names_of(3), names_of(4))


def test_a_replacement_that_fails_before_the_swap_leaves_the_old_model(tmp_path, monkeypatch):
    output = str(tmp_path / "sparse" / "0")
    cm.write_model(small_model(3), output)
    made = str(tmp_path / "sparse" / ".write_x" / "made")
    cm.write_model(small_model(4), made)

    def fail(a, b):
        raise OSError(5, "I/O error")  # not "unsupported": no fallback to two renames

    monkeypatch.setattr(durable, "exchange", fail)
    with pytest.raises(OSError):
        durable.replace_folder(made, output)
    assert names(output) == names_of(3)


def test_the_fallback_where_the_exchange_is_not_supported(tmp_path, monkeypatch):
    output = str(tmp_path / "0")
    cm.write_model(small_model(2), output)
    made = str(tmp_path / "made")
    cm.write_model(small_model(6), made)

    def unsupported(a, b):
        raise OSError(22, "Invalid argument")

    monkeypatch.setattr(durable, "exchange", unsupported)
    durable.replace_folder(made, output)
    assert names(output) == names_of(6)
    assert sorted(os.listdir(str(tmp_path))) == ["0"]


def test_a_first_model_is_renamed_into_place(tmp_path):
    made = str(tmp_path / "made")
    cm.write_model(small_model(2), made)
    durable.replace_folder(made, str(tmp_path / "sparse" / "0"))
    assert names(str(tmp_path / "sparse" / "0")) == names_of(2)


def test_files_are_written_whole_and_fsynced(tmp_path, monkeypatch):
    synced = []
    real = os.fsync
    monkeypatch.setattr(durable.os, "fsync", lambda fd: (synced.append(fd), real(fd)))
    path = str(tmp_path / "report.json")
    write_json_atomically(path, {"a": 1})
    assert len(synced) == 2  # the file, then its folder
    write_json_atomically(path, {"a": 2})
    assert open(path).read() == '{\n  "a": 2\n}\n'
    assert sorted(os.listdir(str(tmp_path))) == ["report.json"]  # no temporary left
    assert oct(os.stat(path).st_mode & 0o777) == oct(0o644)


def test_a_write_that_fails_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    path = str(tmp_path / "report.json")
    write_json_atomically(path, {"a": 1})

    def full(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(durable.os, "fsync", full)
    with pytest.raises(OSError):
        write_json_atomically(path, {"a": 2})
    assert open(path).read() == '{\n  "a": 1\n}\n'
    assert sorted(os.listdir(str(tmp_path))) == ["report.json"]


def test_the_ledger_is_appended_and_fsynced(tmp_path, monkeypatch):
    synced = []
    real = os.fsync
    monkeypatch.setattr(durable.os, "fsync", lambda fd: (synced.append(fd), real(fd)))
    path = str(tmp_path / "ledger.txt")
    durable.append_durably(path, "1 extracted a.png\n")
    durable.append_durably(path, "2 extracted b.png\n")
    assert open(path).read() == "1 extracted a.png\n2 extracted b.png\n"
    assert len(synced) == 3  # each append, and the folder once when the file was made

"""A finish that runs out of time (the bridge's shutdown budget, project.deadline) still writes a
model: the live model as it stands, unrefined, with report.json saying it is not complete and
why; nothing is charged for it, and the next finish completes (issue 35)."""
import json
import os
import shutil
import time

from conftest import tool, walk_selection
from view_selection.colmap.model import read_model
from view_selection.colmap.project import ColmapProject
from view_selection.export_folder import ExportFolder
from view_selection.keyframes import pair_of
from view_selection.live.work import LiveWork
from view_selection.matching.backend import PoseGuidedBackend
from view_selection.refinement.refiner import ModelRefinement, RefinementOptions


def test_a_finish_out_of_time_writes_the_live_model_as_it_stands(tmp_path):
    _, selection = walk_selection(tmp_path, 90)
    export = ExportFolder(str(selection))
    images = export.image_root(None)
    project = ColmapProject(str(tmp_path / "project"), threads=2)
    for k in export.keyframes:
        os.makedirs(os.path.dirname(os.path.join(project.images, k.name)), exist_ok=True)
        shutil.copyfile(os.path.join(images, k.name), os.path.join(project.images, k.name))
    project.open()
    refinement = ModelRefinement(RefinementOptions(threads=2), tool=tool("refine_model"))
    work = LiveWork(project, backend=PoseGuidedBackend(project), refinement=refinement)
    # The recording so far: the first 10 keyframes extracted, matched and in the live model.
    first = export.keyframes[:10]
    names = {k.name for k in first}
    work.extract(first)
    work.match(first, [p for p in export.pairs if set(p) <= names], limit=1000)
    work.feed_model(first)

    project.deadline = time.monotonic() - 0.1  # the shutdown's budget is spent
    out = work.build_model(export.keyframes, export.pairs)
    assert out["complete"] is False and "out of time" in out["incomplete"], out.get("incomplete")
    assert "refinement" not in out
    model = read_model(out["model_path"])
    assert sorted(im.name for im in model.images.values()) == sorted(names)
    assert out["points"] > 100
    assert work.skipped(all_failed=True) == {"images": [], "pairs": []}  # no item's fault

    project.deadline = None  # the next finish (a restart's) completes
    out = work.build_model(export.keyframes, export.pairs)
    assert out["complete"] is True and "incomplete" not in out
    assert out["registered"] == len(export.keyframes)
    assert out["refinement"]["refined"], out["refinement"]
    wanted = {pair_of(*p) for p in export.pairs}
    assert not [x for x in out["pairs_lost"] if tuple(x["pair"].split()) in wanted]
    json.dumps(out, default=str)  # what the bridge writes as report.json

    # A finish whose refinement budget pays for nothing (a 30-minute session's 5 s; here 1 ms):
    # refine_model is not started (a stand-in that would say so), the model is the live model as
    # written, and the section is refine_model's for such a budget, with the live model's
    # matched observations (issue 34).
    started = tmp_path / "started"
    stand_in = tmp_path / "refine_model"
    stand_in.write_text("#!/bin/sh\ntouch %s\nexit 1\n" % started)
    stand_in.chmod(0o755)
    work.refinement = ModelRefinement(RefinementOptions(max_seconds=1e-3), tool=str(stand_in))
    out = work.build_model(export.keyframes, export.pairs)
    assert not started.exists()
    section = out["refinement"]
    assert section["status"] == "out_of_time" and not section["refined"], section
    assert "refine_model not started" in section["message"]
    assert "%d in its matches" % len(work.model.parent) in section["message"]
    assert out["registered"] == len(export.keyframes) and section["observations"] == [out["observations"]] * 2
    unrefined = read_model(os.path.join(os.path.dirname(out["model_path"]), "unrefined"))
    assert sorted(im.name for im in unrefined.images.values()) == sorted(k.name for k in export.keyframes)
    assert len(read_model(out["model_path"]).points) == out["points"] == len(unrefined.points)

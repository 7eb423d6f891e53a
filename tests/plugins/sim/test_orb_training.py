"""Learning ORB keypoints from rendered views (plugins/sim/orb_training.py, D175) on a small view grid: the
command writes the views file the model names, the same bytes each run, and each learnt keypoint sits in
the print where the flat texture has the corner its descriptor describes (the skin's inverse mapping is
right: a mirrored or shifted placement would put them elsewhere)."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from ckm_lab.scenes import USECASE_MODEL

from plugins.processing.textures import build_model, read_model
from plugins.processing.views import read_views
from plugins.sim import orb_training
from tests.conftest import CONFIGS


def test_views_learnt_on_a_small_grid_agree_with_the_flat_prints(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(orb_training, "DISTANCES", (0.5,))
    monkeypatch.setattr(orb_training, "AZIMUTHS", 3)
    monkeypatch.setattr(orb_training, "HEIGHTS", (0.05,))
    monkeypatch.setattr(orb_training, "STABLE", 1)
    model = tmp_path / "m.yml"
    text = USECASE_MODEL.read_text(encoding="utf-8")
    model.write_text(text.replace("views: lab_objects_orb_views.txt", "views: v.txt"), encoding="utf-8")
    args = ["--model", str(model), "--system", str(CONFIGS / "usecase" / "lab.xml"), "--focal", "577.3"]
    assert orb_training.main(args) == 0
    first = (tmp_path / "v.txt").read_bytes()
    assert orb_training.main(args) == 0
    assert (tmp_path / "v.txt").read_bytes() == first  # reproducible
    spec = read_model(model)
    names = [o.name for o in spec.objects]
    descriptors, points, labels = read_views(tmp_path / "v.txt", names)
    assert set(labels.tolist()) == set(range(len(names)))  # every textured object learnt
    model.write_text(re.sub(r"(?m)^views:.*\n", "", text), encoding="utf-8")
    plain = build_model(model)  # the flat prints' keypoints only
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    for index, obj in enumerate(spec.objects):
        mine = labels == index
        theirs = plain.labels == index
        assert np.all((points[mine] >= -1) & (points[mine] <= [obj.width + 1, obj.height + 1]))
        pairs = [m for m in matcher.match(descriptors[mine], plain.descriptors[theirs]) if m.distance < 50]
        assert len(pairs) >= 8, obj.name
        gap = np.array([points[mine][m.queryIdx] - plain.points[theirs][m.trainIdx] for m in pairs])
        if obj.wrap:
            gap[:, 0] = (gap[:, 0] + obj.width / 2) % obj.width - obj.width / 2
        agree = float(np.mean(np.hypot(gap[:, 0], gap[:, 1]) < 0.04 * max(obj.width, obj.height)))
        assert agree > 0.4, (obj.name, agree, len(pairs))  # by chance: under 1 %

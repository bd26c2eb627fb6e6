"""The diff view draws each robot in its own scene's frame: the arm's wrist axis stands over the
pad."""

from __future__ import annotations

import numpy as np
import pytest

from twin.model.config import TwinConfig
from twin.model.profiles import PROFILES
from twin.verify.check import record_task
from twin.verify.diff_view import arm_points


@pytest.mark.parametrize("robot", sorted(PROFILES))
def test_the_drawn_arm_reaches_the_recorded_pad_on_every_robot(robot):
    rec = record_task(TwinConfig(profile=PROFILES[robot]), "pick_place", {"cycles": 1})
    points = arm_points(rec)  # floor, shoulder, elbow, wrist axis, pad tip
    assert np.abs(points[:, 3, :2] - points[:, 4, :2]).max() < 1e-9
    elbow_m = np.linalg.norm(points[:, 2, :2], axis=1)
    assert np.allclose(elbow_m, PROFILES[robot].link1_m)

"""The Rerun writer's columns, built straight as Arrow, against the SDK's own archetype columns: the
same descriptors, in the same order, and the same arrays, value for value."""

import numpy as np
import pyarrow as pa
import pytest
import rerun as rr

from twin.record.rerun import scene
from twin.record.rerun.columns import ColumnMaker

CAPACITY = 64


def _same(ours, sdk) -> None:
    sdk = list(sdk)
    assert [c.component_descriptor() for c in ours] == [c.component_descriptor() for c in sdk]
    for mine, theirs in zip(ours, sdk, strict=True):
        expected = theirs.as_arrow_array()
        assert mine.as_arrow_array().type == expected.type
        assert mine.as_arrow_array().equals(expected), mine.component_descriptor()


@pytest.fixture
def make():
    return ColumnMaker(CAPACITY, scene.PAD_RGBS)


@pytest.mark.parametrize("n", [1, 37, CAPACITY])
def test_transforms_are_the_sdks(make, n):
    rng = np.random.default_rng(n)
    # float64 values that round to float32 both ways, and ones that need rounding
    translations, quaternions = rng.normal(size=(n, 3)), rng.normal(size=(n, 4))
    _same(
        make.transforms(translations, quaternions),
        rr.Transform3D.columns(translation=translations, quaternion=quaternions),
    )
    parents = pa.array([f"parent_{i}" for i in range(CAPACITY)])
    children = pa.array([f"child_{i}" for i in range(CAPACITY)])
    _same(
        make.transforms(translations, quaternions, (parents, children)),
        rr.Transform3D.columns(
            translation=translations,
            quaternion=quaternions,
            parent_frame=parents.slice(0, n),
            child_frame=children.slice(0, n),
        ),
    )


def test_strided_views_are_read_as_their_values(make):
    """The writer's columns are slices of wider arrays (a pose's first three numbers)."""
    poses = np.random.default_rng(7).normal(size=(20, 7))
    _same(
        make.transforms(poses[:, :3], poses[:, 3:]),
        rr.Transform3D.columns(translation=poses[:, :3].copy(), quaternion=poses[:, 3:].copy()),
    )


def test_pad_cylinders_take_the_colour_of_each_frames_state(make):
    suction_on = np.array([False, True, True, False, True])
    held_body = np.array([-1, -1, 2, -1, 0])
    index = scene.pad_color_index(suction_on, held_body)
    assert index.tolist() == [0, 1, 2, 0, 2]  # holding shows over sucking
    centres = np.arange(15.0).reshape(5, 3) / 7
    rgb = np.array(scene.PAD_RGBS, dtype=np.uint8)[index]
    _same(make.cylinders(centres, index), rr.Cylinders3D.columns(centers=centres, colors=rgb))


@pytest.mark.parametrize(
    "values",
    [np.linspace(-1, 1, 9), np.array([True, False, True]), np.array([3, -1, 0]) >= 0],
)
def test_scalars_are_the_sdks(make, values):
    _same(make.scalars(values), rr.Scalars.columns(scalars=values.astype(np.float64)))

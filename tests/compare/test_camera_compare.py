"""twin diff compares camera pictures: mean absolute pixel difference per picture under exact and
tight (the first differing picture named), not at all under physical and outcome; a replay of a
camera run matches exactly, its pictures included."""

from __future__ import annotations

import copy

import twin
from twin.cli.main import main
from twin.compare.engine import compare
from twin.compare.report import render_markdown
from twin.compare.tolerances import Tolerances
from twin.pictures import encode, track_rgb


def _with_darkened_picture(rec, camera: str, index: int):
    """A copy of rec whose picture `index` of `camera` has a 20x20 black square."""
    out = copy.deepcopy(rec)
    track = out.cameras[camera]
    pixels = track_rgb(track, index).copy()
    pixels[10:30, 10:30] = 0
    track.data[index] = encode(pixels)
    return out


def test_identical_pictures_match_under_every_preset(camera_run):
    rec = twin.load(camera_run["mcap"])
    for preset in ("exact", "tight", "physical", "outcome"):
        assert compare(rec, twin.load(camera_run["mcap"]), Tolerances.from_preset(preset)).match, (
            preset
        )


def test_a_changed_picture_is_the_first_divergence_under_exact_and_tight(camera_run):
    golden = twin.load(camera_run["mcap"])
    candidate = _with_darkened_picture(golden, "wrist", 20)
    for preset in ("exact", "tight"):
        result = compare(golden, candidate, Tolerances.from_preset(preset))
        first = result.first
        assert not result.match and (first.channel, first.field) == ("images", "pixels"), preset
        assert first.element == "wrist #20" and first.step == 20 * 16
        stat = next(f for f in result.fields if f.name == "images.pixels")
        assert stat.steps_over == 1 and 0.5 < stat.worst < 50 and stat.unit == "levels"
    assert "wrist #20" in render_markdown(result)


def test_pictures_are_ignored_under_physical_and_outcome(camera_run):
    golden = twin.load(camera_run["mcap"])
    candidate = _with_darkened_picture(golden, "overhead", 5)
    for preset in ("physical", "outcome"):
        result = compare(golden, candidate, Tolerances.from_preset(preset))
        assert result.match, preset
        assert any("not compared" in note for note in result.notes)


def test_a_missing_picture_differs(camera_run):
    golden = twin.load(camera_run["mcap"])
    candidate = copy.deepcopy(golden)
    track = candidate.cameras["overhead"]
    track.step, track.t_ns, track.data = track.step[:-1], track.t_ns[:-1], track.data[:-1]
    first = compare(golden, candidate, Tolerances.from_preset("exact")).first
    assert first.element == f"overhead #{len(track.data)}" and first.actual == ["missing"]
    assert first.expected == ["picture"]
    # the picture only the candidate has
    first = compare(candidate, golden, Tolerances.from_preset("exact")).first
    assert first.expected == ["missing"] and first.actual == ["picture"]


def test_replay_of_a_camera_run_matches_exactly(camera_run, capsys):
    assert main(["replay", str(camera_run["mcap"])]) == 0
    out = capsys.readouterr().out
    assert "MATCH (tolerance noise" in out and "  bit-identical\n" in out and "images.pixels" in out

"""The pictures people read: configuration panels, captioned camera frames with the detected markers, the GIF,
and the benchmark plots with every run (timeouts too). Small inline inputs, no simulator."""
from __future__ import annotations

import csv

import cv2
import numpy as np
import pytest
from PIL import Image

from planhrc.bench.plots import PlotError, main as plots_main, plot_times, run_from
from planhrc.robot_sim.markers import aruco_dictionary
from planhrc.robot_sim.pictures import (PictureStep, actor_between, caption_frame, describe_action, detect_markers,
                                        draw_configurations, step_caption, write_movie)


def frame_with_markers(ids=(0, 3)) -> np.ndarray:
    frame = np.full((240, 320, 3), 220, np.uint8)
    for i, marker_id in enumerate(ids):
        marker = cv2.aruco.generateImageMarker(aruco_dictionary(), marker_id, 40)
        frame[40:80, 40 + 120 * i:80 + 120 * i] = marker[..., None]
    return frame


def test_actor_and_action_in_words():
    assert actor_between("succeeded", []) == "robot"
    assert actor_between("partial", ["human turned l5 by -45 deg"]) == "robot and human"
    assert actor_between("failed", ["human turned l2"]) == "human"  # a failed action moved nothing
    assert actor_between(None, []) == "nobody"
    action = {"step": 2, "last_step": 3, "joint_index": 3, "turned_link_index": 4, "held_link_index": 3, "delta_deg": -90}
    assert describe_action(action) == "a_2..a_3 j3: turn l4 -90°, hold l3"
    assert describe_action({**action, "last_step": 2, "held_link_index": 0}).endswith("hold the table")
    assert describe_action(None) is None
    hands = {"step": 4, "joint_index": 2, "turned_link_index": 3, "held_link_index": 2, "delta_deg": 0}
    assert describe_action({**hands, "name": "movetocentre"}) == "a_4 j2: centre the hands on j2 (l2 and l3)"
    assert describe_action({**hands, "name": "grasplinks"}) == "a_4 j2: grasp l2 and l3 at j2"
    assert describe_action({**hands, "name": "releaselinks"}) == "a_4 j2: release l2 and l3 at j2"
    assert describe_action({**hands, "name": "rotateclockwise45", "delta_deg": 45}) == "a_4 j2: turn l3 +45°, hold l2"


def test_frames_show_the_detected_markers_and_a_caption(tmp_path):
    frame = frame_with_markers()
    markers = detect_markers(frame)
    assert sorted(markers) == [0, 3]
    assert np.allclose(markers[0].min(axis=0), (40, 40), atol=2)
    step = PictureStep(2, "continue", (90.0, 45.0), (0.6, 0.0), "robot",
                       "a_2 j1: turn l2 +45°, hold l1", "partial", markers_seen=len(markers))
    lines = step_caption(step, 2)
    assert lines[0] == "step 2   decision: continue   markers outlined: 2/2"
    assert lines[2] == "next: a_2 j1: turn l2 +45°, hold l1 -> partial"
    captioned = caption_frame(frame, lines, markers=markers)
    assert captioned.shape[1] == 320 and captioned.shape[0] > 240 + 3 * 15
    assert not np.array_equal(captioned[:240], frame)  # the outlines are drawn on the frame
    assert (captioned[240:] < 128).any()  # text in the band
    small = caption_frame(frame, lines, width=160)
    assert small.shape[1] == 160
    gif = write_movie(tmp_path / "run.gif", [captioned, small[:, :160]])
    assert Image.open(gif).n_frames == 2
    assert write_movie(tmp_path / "none.gif", []) is None


def test_configuration_panels_one_per_decision(tmp_path):
    steps = [PictureStep(1, "replan", (90.0, 90.0, 90.0), (0.6, 0.0), "start", "a_1 j1: turn l2 +90°, hold l1",
                         "succeeded"),
             PictureStep(2, "resume", (90.0, 180.0, 180.0), (0.6, 0.0), "robot and human", None, None,
                         ("human turned l3 by +90 deg",)),
             PictureStep(3, "goal_reached", (90.0, 180.0, 270.0), (0.6, 0.0), "human")]
    path = draw_configurations(tmp_path / "configurations.png", steps, 0.155, goal_deg=(90, 180, 270), title="t")
    one = draw_configurations(tmp_path / "one.png", steps[:1], 0.155)
    assert Image.open(path).width > Image.open(one).width  # a panel per decision, side by side


def _rows(statuses):
    return [{"formulation": f, "planner": "p", "links": 4 + i, "orientations": 4, "status": st,
             "seconds": 10.0 if st != "solved" else 0.01 * (i + 1)}
            for f in ("relative", "absolute") for i, st in enumerate(statuses[f])]


def test_plots_draw_runs_that_did_not_solve(tmp_path):
    paths = plot_times(_rows({"relative": ["solved", "solved"], "absolute": ["timeout", "timeout"]}), tmp_path)
    # a formulation whose every run timed out still gets its figure (the old box plots dropped it)
    assert sorted(p.name for p in paths) == ["times-absolute-p.png", "times-relative-p.png"]


def test_plots_refuse_a_bad_record_naming_the_field(tmp_path, capsys):
    with pytest.raises(PlotError, match="^seconds: "):
        run_from({"formulation": "relative", "planner": "p", "links": 4, "orientations": 4, "status": "solved",
                  "seconds": "nan"})
    with pytest.raises(PlotError, match="^links: "):
        run_from({"formulation": "relative", "planner": "p", "links": "four", "orientations": 4,
                  "status": "solved", "seconds": 1})
    good = tmp_path / "bench.csv"
    rows = _rows({"relative": ["solved"], "absolute": ["timeout"]})
    with good.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    assert plots_main([str(good), "--timeout", "10"]) == 0
    assert (tmp_path / "times-absolute-p.png").exists()
    bad = tmp_path / "bad.csv"
    bad.write_text("formulation,planner\nrelative,p\n")
    assert plots_main([str(bad)]) == 2
    assert "links: expected int, got None" in capsys.readouterr().err

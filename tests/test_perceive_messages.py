"""What `planhrc perceive-node` reads and writes, without ROS 2: Image and CameraInfo fields, the objects it is
configured for, the bridge's JointState from a reading, and when a perception is published."""
from __future__ import annotations

import math

import numpy as np
import pytest

from planhrc.robot_sim.vision import LinkSighting, MarkerMeasure, ObjectMarkers, ObjectReading
from planhrc.ros2.errors import Ros2Error
from planhrc.ros2.perceive_messages import (PublishPolicy, grey_from_image, intrinsics_from_camera_info,
                                            parse_object, perceived_state)


def test_images_in_every_encoding_give_the_same_grey_and_bad_ones_name_the_field():
    rgb = np.zeros((2, 3, 3), np.uint8)
    rgb[0, 0] = (255, 0, 0)
    padded = np.zeros((2, 12), np.uint8)  # rows padded to 12 bytes (step > width * 3)
    padded[:, :9] = rgb.reshape(2, 9)
    from_rgb = grey_from_image("rgb8", 3, 2, 12, padded.tobytes())
    from_bgr = grey_from_image("bgr8", 3, 2, 9, rgb[:, :, ::-1].tobytes())
    assert from_rgb.shape == (2, 3) and np.array_equal(from_rgb, from_bgr) and from_rgb[0, 0] == 76
    assert np.array_equal(grey_from_image("mono8", 3, 2, 3, bytes(range(6))), [[0, 1, 2], [3, 4, 5]])
    with pytest.raises(Ros2Error, match=r"^image.encoding: '16UC1' is not read"):
        grey_from_image("16UC1", 3, 2, 6, bytes(12))
    with pytest.raises(Ros2Error, match=r"^image.data: 5 bytes, 6 expected"):
        grey_from_image("mono8", 3, 2, 3, bytes(5))
    with pytest.raises(Ros2Error, match=r"^image.step"):
        grey_from_image("rgb8", 3, 2, 3, bytes(18))


def test_camera_info_becomes_intrinsics_and_a_bad_one_names_the_field():
    camera = intrinsics_from_camera_info(640, 480, [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1], [0.1, 0, 0, 0, 0],
                                         "plumb_bob")
    assert camera.distorted and camera.matrix[0, 2] == 319.5
    with pytest.raises(Ros2Error, match="^camera_info.distortion_model: 'equidistant'"):
        intrinsics_from_camera_info(640, 480, [500, 0, 320, 0, 500, 240, 0, 0, 1], [0] * 4, "equidistant")
    with pytest.raises(Ros2Error, match="^camera_info.k: expected 9"):
        intrinsics_from_camera_info(640, 480, [0] * 9 + [1], [], "")


def test_objects_name_their_links_markers():
    assert parse_object("obj1=0-4") == ("obj1", (0, 1, 2, 3, 4))
    assert parse_object("rod=7,3,5") == ("rod", (7, 3, 5))
    for bad in ("obj1", "obj1=4-2", "obj1=1,1", "obj1=0-50", "o b=1"):
        with pytest.raises(ValueError):
            parse_object(bad)


def reading(*values: float | None, base: tuple[float, float] | None = (0.6, 0.1)) -> ObjectReading:
    sightings = tuple(LinkSighting(k, k - 1, None if v is None else MarkerMeasure(v, (0.6, 0.1), 0.3, 0.4, 22.0),
                                   None if v is not None else "marker not found") for k, v in enumerate(values, 1))
    return ObjectReading("obj1", tuple(values), base if values[0] is not None else None, sightings)


def test_a_reading_becomes_the_bridges_joint_state_with_its_detail():
    markers = ObjectMarkers("obj1", (0, 1, 2), 0.155, 0.03, -0.164)
    state = perceived_state(reading(90.0, None, 0.0), markers, (7, 5), True, "first", 12.3)
    assert state.names == ["l1", "l2", "l3", "base_x", "base_y"]
    assert state.positions[0] == pytest.approx(-math.pi / 2) and math.isnan(state.positions[1])
    assert state.positions[3:] == [0.6, 0.1]
    assert state.detail["unseen"] == ["l2"] and state.detail["links"][1]["problem"] == "marker not found"
    assert state.detail["links"][0]["reprojection_px"] == 0.3 and state.detail["stamp"] == [7, 5]
    unseen_first = perceived_state(reading(None, 10.0, 0.0), markers, (7, 6), True, "first")
    assert "base_x" not in unseen_first.names


def test_perceptions_are_published_when_new_and_held_while_the_robot_acts():
    policy = PublishPolicy(period_s=1.0, change_deg=3.0)
    assert policy.decide(0.0, reading(90.0, 0.0)) == (True, "first")
    assert policy.decide(0.5, reading(100.0, 0.0)) == (False, "held: period")
    assert policy.decide(2.0, reading(91.0, 0.0)) == (False, "held: unchanged")
    assert policy.decide(3.0, reading(90.0, None)) == (True, "changed")  # a link lost
    policy.on_next_action(3.5, empty=False)
    assert policy.decide(5.0, reading(45.0, None)) == (False, "held: an action is under way")
    policy.on_feedback()
    assert policy.decide(5.1, reading(45.0, None)) == (True, "after feedback")
    policy.on_next_action(6.0, empty=True)  # hold still: nothing under way
    assert policy.decide(6.5, reading(80.0, None)) == (True, "changed")
    every = PublishPolicy(every_image=True)
    assert [every.decide(t, reading(90.0))[0] for t in (0.0, 0.01, 0.02)] == [True, True, True]

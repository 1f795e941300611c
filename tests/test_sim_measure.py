"""`planhrc sim-bench` reports marker error and timings from real renders and skill executions."""
import pytest

from planhrc.robot_sim.measure import measure

pytestmark = pytest.mark.sim


def test_measure_reports_small_marker_error_and_successful_rotations():
    result = measure(configurations=3, rotations=3, seed=1)
    err = result["marker_error_deg"]
    assert err["links"] + err["missed_markers"] == 15
    assert 0 < err["mean"] <= err["max"] < 3.0
    assert result["rotation_action_s"]["succeeded"] == 3
    assert result["perception_s"]["median"] > 0

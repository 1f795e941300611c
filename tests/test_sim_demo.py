"""`planhrc demo`: a real KB service process and the Baxter worker run the paper's scenarios to the goal."""
import json

import pytest

from planhrc.robot_sim.demo import DEMO_SCENARIOS, run_demo

pytestmark = [pytest.mark.sim, pytest.mark.integration, pytest.mark.slow]


@pytest.mark.parametrize("name", sorted(DEMO_SCENARIOS))
def test_paper_scenarios_reach_the_goal(name, tmp_path):
    summary = run_demo(name, tmp_path)
    assert summary["reached_goal"] == 1
    result = summary["results"][0]
    assert result["decisions"][-1]["kind"] == "goal_reached"
    assert result["actions"], "the robot executed no action"
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    assert on_disk["results"][0]["object_id"] == result["object_id"]
    episode = tmp_path / "episode-001"  # the worker's per-step records are kept beside the demo's summary
    worker = json.loads((episode / "summary.json").read_text())
    assert len(worker["steps"]) == len(result["decisions"]) and worker["perception"] == "camera"
    assert (episode / "run.gif").stat().st_size > 0
    assert (episode / "configurations.png").stat().st_size > 0
    assert list(episode.glob("frame_*.png"))
    # camera perception with nothing filled in: every link seen, the marker error small, nothing off the table
    assert result["unseen_links"] == 0 and max(result["marker_error_deg"]) < 3.0
    assert summary["states_off_table"] == 0
    if name == "fig13":  # the human's move reaches the goal early; the later disturbance is repaired
        kinds = [d["kind"] for d in result["decisions"]]
        assert kinds.count("goal_reached") == 2 and "replan" in kinds[kinds.index("goal_reached"):]
    if name == "fig14":  # the robot's gripper let go half-way: reported as partial, with its reason
        assert "partial" in result["outcomes"] and result["failure_reasons"].get("grasp_lost") == 1
    if name == "bimanual":
        # grasps and releases are steps of their own, each with its own feedback; every kind was done
        names = [a["name"] for a in result["actions"]]
        assert names[0] == "grasplinks" and "releaselinks" in names and "movetocentre" in names
        kinds = result["action_kinds"]
        assert set(kinds) == {"centre", "grasp", "turn", "release"} and sum(kinds.values()) == len(names)
        assert result["action_kinds_succeeded"] == kinds  # every step succeeded
        grasp = names.index("grasplinks")
        assert names[grasp + 1].startswith("rotate")  # the turn came after the grasp, as a step of its own
        assert all(a["delta_deg"] == 0 for a in result["actions"] if not a["name"].startswith("rotate"))
        # the human turned the last link while the robot held two: the service planned anew from that state
        assert result["human_moves_performed"] == 1
        assert any("human" in h for s in worker["steps"] for h in s["human_before"])
        assert {"replan", "continue", "goal_reached"} <= {d["kind"] for d in result["decisions"]}
        assert result["replans"] >= 2  # the first plan, and the one after the human's move


def test_unknown_scenario_is_refused(tmp_path):
    from planhrc.robot_sim.errors import SimError

    with pytest.raises(SimError, match="scenario"):
        run_demo("fig99", tmp_path)

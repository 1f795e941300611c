"""`python -m planhrc.bench.large`: its refusals, and one small object through a real `planhrc serve`."""
import json

import pytest

from planhrc.bench.large import CPU_STAGES, main


def test_a_size_that_is_not_links_x_k_is_refused_in_one_line(capsys, tmp_path):
    with pytest.raises(SystemExit) as exit_info:
        main(["--sizes", "20x7", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip()
    assert exit_info.value.code == 2 and len(err.splitlines()) == 1 and "20x7" in err
    assert not list(tmp_path.iterdir())  # nothing written


@pytest.mark.integration
def test_a_small_absolute_object_is_answered_with_its_validated_first_motion(tmp_path):
    assert main(["--sizes", "6x8", "--runs", "2", "--deadline", "600", "--stage-cpu", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "large.json").read_text())
    cpu = report["stage_cpu"][0]
    assert cpu["steps"] > 0 and set(cpu["cpu_s"]) == set(CPU_STAGES) and all(v >= 0 for v in cpu["cpu_s"].values())
    rows = report["sizes"][0]["rows"]
    assert report["deadline_s"] == 600
    assert [r["status"] for r in rows] == [200, 200] and rows[0]["decision"] == "replan"
    assert 1 <= rows[0]["accepted_before_answer"] <= rows[0]["plan_steps"]
    assert rows[0]["first_validated_action_s"] == rows[0]["seconds"]  # the answer names a validated first motion
    assert set(rows[0]["stages_s"]) >= {"translate", "plan", "expected_states"}
    # the service's own CPU, to the answer (it planned and checked the plan) and behind it
    assert all(r["service_cpu_s"]["to_answer"] > 0 and r["service_cpu_s"]["behind"] >= 0 for r in rows)
    assert "| 6 x 8 absolute | 1 | 200 |" in (tmp_path / "large.md").read_text()

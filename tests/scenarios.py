"""Named scenarios shared by the tests, with their expected optimal plan lengths.

Each scenario is one change of configuration of an object's links (absolute orientations, degrees).
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Scenario:
    name: str
    links: int
    orientations: int
    init_links_deg: tuple[int, ...]
    goal_links_deg: tuple[int, ...]
    optimal_relative: int  # steps with the relative formulation (l1's placement not tracked)
    optimal_absolute: int  # steps with the absolute formulation (turning lK moves lK..lN)


SCENARIOS = {
    # The paper's 3-4 example: 3 links, 90 degree resolution.
    "paper-3-4": Scenario("paper-3-4", 3, 4, (0, 0, 0), (0, 90, 0), optimal_relative=2, optimal_absolute=2),
    # Rotating the whole object: nothing changes relatively, one step of j1 absolutely.
    "whole-turn": Scenario("whole-turn", 4, 4, (0, 90, 180, 90), (90, 180, 270, 180), 0, 1),
    # Opposite directions are cheaper anticlockwise.
    "wrap-around": Scenario("wrap-around", 3, 12, (0, 0, 0), (0, 330, 300), 2, 2),
    "five-links-8": Scenario("five-links-8", 5, 8, (0, 45, 90, 135, 180), (0, 0, 0, 0, 0), 4, 4),
}

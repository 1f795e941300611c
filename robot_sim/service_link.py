"""The calls the worker makes on the KB service, as a protocol: `planhrc.client.KBClient` makes them over HTTP;
another transport (the ROS 2 layer's link through the bridge's topics) makes the same calls over its own wire."""
from __future__ import annotations

from typing import Any, Protocol, Sequence

from planhrc.client import Decision
from planhrc.vocabulary import ActionOutcome, FailureReason


class ServiceLink(Protocol):
    def read_object(self, object_id: str) -> dict[str, Any]: ...

    def read_state(self, state_id: str) -> dict[str, Any]: ...

    def read_plan(self, plan_id: str) -> dict[str, Any]: ...

    def set_goal(self, object_id: str, link_orientations_deg: Sequence[float] | None = None,
                 joint_angles_deg: Sequence[float | None] | None = None,
                 allow_infeasible: bool = False) -> dict[str, Any]: ...

    def post_perception(self, object_id: str, link_orientations_deg: Sequence[float | None],
                        base_point_xy: Sequence[float] | None = None) -> Decision: ...

    def next_action(self, object_id: str) -> dict[str, Any] | None: ...

    def post_feedback(self, object_id: str, action_id: str, outcome: ActionOutcome | str, message: str = "",
                      reason: FailureReason | str | None = None,
                      measured_deg: float | None = None, refusal: dict[str, Any] | None = None,
                      hands_open: bool = False) -> dict[str, Any]: ...

    def give_up(self, object_id: str, reason: str, message: str) -> dict[str, Any]: ...

"""What records an episode as it happens, as a protocol (the ROS 2 layer writes it as a rosbag2 bag:
`planhrc.ros2.bag`). The worker hands the recorder its link to the service and its perceiver and works through what
it gets back, so every call and every look is recorded when it happens; it closes the recorder with the summary
(None when the run failed: what was recorded is kept)."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Protocol, Sequence

from planhrc.robot_sim.service_link import ServiceLink

if TYPE_CHECKING:
    from planhrc.robot_sim.episode import WorkerSummary
    from planhrc.robot_sim.perception import CameraPerception, Perception, Perceiver


class EpisodeRecorder(Protocol):
    def link(self, kb: ServiceLink) -> ServiceLink: ...

    def perceiver(self, perceiver: "Perceiver", camera: "CameraPerception") -> "Perceiver": ...

    def look(self, seen: "Perception", camera: "CameraPerception") -> None:
        """Record a look taken past the recorded perceiver, when it is used as a perception (the look that ended a
        bimanual step: `BothHands.take_look`)."""
        ...

    def close(self, summary: "WorkerSummary | None") -> None: ...


# (episode folder, the object as the service describes it, the goal's link orientations when given) -> its recorder
Recording = Callable[[Path, Mapping[str, Any], "Sequence[float] | None"], EpisodeRecorder]

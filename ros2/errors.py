"""The root of the ROS 2 layer's errors."""
from __future__ import annotations

from planhrc.errors import PlanhrcError


class Ros2Error(PlanhrcError):
    """A message on a ROS 2 topic the bridge cannot turn into a request (the message names the topic and field),
    or a ROS 2 peer that did not answer in time."""

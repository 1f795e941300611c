"""planhrc on a ROS 2 graph: a bridge between a running KB service (over HTTP) and ROS 2 topics (through rclpy),
and the Baxter worker's link to the service over those topics.

The top layer: it reaches the service only through `planhrc.client` and the worker through `planhrc.robot_sim`'s
public functions; nothing below imports it. `topics`, `convert` and `markers` are pure (no rclpy) and run in any
environment; `node`, `link` and `bench` import rclpy, which lives in `.venv-ros2` only (see docs/ros2.md).
"""

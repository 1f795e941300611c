"""PyBullet simulation of the Baxter work cell and the robot worker.

scene (Baxter, table, kinematic articulated object) -> markers (ArUco quads) -> perception (camera or noisy
ground truth) -> skills (rotation action -> command of primitives -> execution) -> human (scenarios as data)
-> `planhrc.client` (the only HTTP client of the KB service) -> worker (the perceive / decide / act loop).
Nothing here imports `kb_service`; nothing is built at import time.
"""

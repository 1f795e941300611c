"""The arms' grip on the object, shared by the skills (a turn, a slide): grasps fixed to the gripper once a finger
touches the link, and an arm driven through its joint motors on the physics clock."""
from __future__ import annotations

import time
from typing import Protocol, Sequence

import numpy as np
import pybullet

from planhrc.robot_sim.scene import Scene, arm_joints, drive_gripper, hold_arm


class Robot(Protocol):
    """What the grip needs of the robot the skills describe: its hands' links and its pace."""

    hand_links: dict[str, tuple[int, ...]]
    realtime_s: float


class Hands:
    """The grasps an execution holds: arm -> (constraint id, link, grasp point in the link's frame)."""

    def __init__(self, scene: Scene, robot: Robot) -> None:
        self.scene, self.robot = scene, robot
        self.held: dict[str, tuple[int, int]] = {}

    def grasp(self, arm: str, link: int, steps: int = 8) -> bool:
        """Close the fingers; once a finger touches the link, fix the link to the gripper. False: it closed
        on nothing."""
        s, c = self.scene, self.scene.client
        drive_gripper(s, arm, close=True)
        target = s.object_link_index(link)
        for _ in range(steps):
            s.step()
            if any(s.near(s.robot, f, s.body, target, 0.006) for f in self.robot.hand_links[arm]):
                break
        else:
            return False
        # a constraint's frames are given in each body's centre-of-mass frame
        ee = s.arms[arm].end_effector
        ee_state = c.getLinkState(s.robot, ee, computeForwardKinematics=True)
        link_pos, link_quat = s.link_pose(link)
        inv_pos, inv_quat = c.invertTransform(link_pos.tolist(), link_quat)
        rel_pos, rel_quat = c.multiplyTransforms(inv_pos, inv_quat, ee_state[0], ee_state[1])
        cid = c.createConstraint(s.robot, ee, s.body, target, pybullet.JOINT_PRISMATIC, [0, 0, 1],
                                 parentFramePosition=[0, 0, 0], childFramePosition=rel_pos,
                                 parentFrameOrientation=[0, 0, 0, 1], childFrameOrientation=rel_quat)
        c.changeConstraint(cid, maxForce=200.0)
        self.held[arm] = (cid, link)
        s.gripped.add(link)
        return True

    def offset(self, arm: str) -> float:
        """How far the grasped link has slid from the gripper (metres)."""
        cid, link = self.held[arm]
        c = self.scene.client
        info = c.getConstraintInfo(cid)
        ee_pos = np.asarray(c.getLinkState(self.scene.robot, info[1], computeForwardKinematics=True)[0])
        link_pos, link_quat = self.scene.link_pose(link)
        grip_pos, _ = c.multiplyTransforms(link_pos.tolist(), link_quat, info[7], info[9])
        return float(np.linalg.norm(np.asarray(grip_pos) - ee_pos))

    def release(self, arm: str) -> None:
        if arm in self.held:
            cid, link = self.held.pop(arm)
            self.scene.client.removeConstraint(cid)
            self.scene.gripped.discard(link)
        drive_gripper(self.scene, arm, close=False)

    def release_all(self) -> None:
        for arm in tuple(self.held):
            self.release(arm)


def drive_arm(scene: Scene, robot: Robot, arm: str, target: Sequence[float], max_steps: int = 60,
           tolerance_rad: float = 0.004) -> bool:
    """Drive `arm`'s joint motors to `target`, stepping the physics until the arm is there (True) or
    `max_steps` have passed (False: the arm stalls)."""
    goal = np.asarray(target, dtype=float)
    hold_arm(scene, arm, target)
    for _ in range(max_steps):
        scene.step()
        if robot.realtime_s:
            time.sleep(robot.realtime_s)
        if float(np.max(np.abs(np.asarray(arm_joints(scene, arm)) - goal))) < tolerance_rad:
            return True
    return False

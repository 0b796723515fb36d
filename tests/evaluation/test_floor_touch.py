"""The planner's touch leaves out the floor: open fingers that brush or press the floor below a low
handle do not feel like a grip on it (a press there would keep a lost grip "held" for the rest of
a pull). The touch observation agents read is unchanged."""

from __future__ import annotations

import numpy as np


def test_fingers_pressed_on_the_floor_are_no_grip(drawer_job):
    from opend_mj.evaluation.runner import make_episode_env
    from opend_mj.policy.planner import Robot
    from opend_mj.policy.planner.approach import Approach
    from opend_mj.policy.planner.config import PlannerConfig
    from opend_mj.policy.planner.stage import StageContext
    from opend_mj.sim.hands import HandTouch, get_hand
    from opend_mj.transforms import mat_to_quat

    env = make_episode_env(drawer_job("allegro"))
    try:
        env.reset()
        robot = Robot(env)
        spec = robot.spec
        # the open hand, fingers pointing down (site +y) and palm toward the cabinet (site +z along
        # +x), lowered in front of the cabinet until its fingertips press 2 cm into the floor's way
        quat = mat_to_quat(np.column_stack([(0, -1, 0), (0, 0, -1), (1, 0, 0)]).astype(float))
        fingers = spec.pregrasp_profile("horizontal")
        start = robot.site_pos()
        for z in np.linspace(0.35, 0.0, 120):
            robot.step(np.array([start[0], start[1], z]), quat, fingers)
        for _ in range(20):
            robot.step(np.array([start[0], start[1], 0.0]), quat, fingers)
        felt = HandTouch(env.task.hand, env.physics).read()  # what the touch observation reports
        assert sum(felt.values()) > 5.0, felt  # the fingers do press on the floor
        assert robot.contact_touch() == {}
        ctx = StageContext(config=PlannerConfig(), spec=spec, hand=get_hand("allegro").planner)
        assert not Approach(ctx).holding(robot)[0]
    finally:
        env.close()

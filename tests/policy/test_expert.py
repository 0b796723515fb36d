"""The planner as an interactive expert: started from states another agent reached, it still opens
the part (a hand on a half-pulled drawer pulls on, a door left ajar is approached where it is)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest


def _first(where) -> tuple[str, int]:
    from opend_mj.assets.procedural import GeneratorConfig, find_cabinets

    cabinet = find_cabinets(where, config=GeneratorConfig(flap_share=0.0))[0]
    return cabinet.id, cabinet.index


#: generated cabinets (seed 0): a single drawer, a single side-hinged door
DRAWER = _first(lambda c: len(c.targets) == 1 and c.targets[0].kind == "drawer")
DOOR = _first(lambda c: len(c.targets) == 1 and c.targets[0].kind == "door" and not c.targets[0].double)


@pytest.fixture(scope="module")
def expert_cabinets(tmp_path_factory) -> dict[str, Path]:
    from opend_mj.assets.compiler import compile_cabinet
    from opend_mj.assets.procedural import GeneratorConfig, generate_source

    root = tmp_path_factory.mktemp("expert_cabinets")
    out = {}
    for cid, index in (DRAWER, DOOR):
        src = generate_source(index, 0, root / "src", config=GeneratorConfig(flap_share=0.0))
        compile_cabinet(src, root / "built", cache_dir=root / "cache")
        assert (root / "built" / cid / "cabinet.json").is_file()
        out[cid] = root / "built" / cid
    return out


def _job(cabinets, which, hand="allegro"):
    from opend_mj.evaluation.episode import EpisodeJob

    cid = which[0]
    return EpisodeJob(cabinet=cid, cabinet_dir=str(cabinets[cid]), joint="joint_0", split="test", hand=hand,
                      solver="oracle")


def test_part_motion_moves_a_grasp_with_its_door():
    """A door turned 30 degrees about a hinge at y = 0.4: a point on it moves on the hinge's circle,
    and an orientation fixed to it turns by 30 degrees about z."""
    from opend_mj.policy.planner import PartMotion
    from opend_mj.transforms import axis_angle_quat, quat_to_mat

    rot = quat_to_mat(axis_angle_quat(np.array([0.0, 0.0, 1.0]), math.radians(30)))
    motion = PartMotion(rot=rot, pivot=np.array([0.0, 0.4, 0.5]))
    p = motion.point([0.0, 0.0, 0.7])
    assert np.linalg.norm(p[:2] - [0.0, 0.4]) == pytest.approx(0.4)
    assert p[2] == pytest.approx(0.7)
    assert motion.angle_deg == pytest.approx(30.0)
    q = motion.orientation([1.0, 0.0, 0.0, 0.0])
    assert quat_to_mat(q) == pytest.approx(rot)
    slide = PartMotion(shift=np.array([-0.12, 0.0, 0.0]))
    assert slide.distance == pytest.approx(0.12) and slide.angle_deg == pytest.approx(0.0)


@pytest.mark.slow
@pytest.mark.parametrize("which", [DRAWER, DOOR], ids=["drawer", "door"])
def test_expert_takes_over_the_planners_pull(expert_cabinets, which):
    """The planner's own episode, taken over by a fresh expert in the middle of its pull: the hand
    holds a part already on its way, and the expert pulls on without letting go."""
    from opend_mj.evaluation.takeover import PLANNER_LEAD, takeover_episode

    rec = takeover_episode(_job(expert_cabinets, which), PLANNER_LEAD, switch=6.0)
    assert rec["lead_stage"] == "pull", rec
    assert rec["switch_range_ratio"] > 0.02, rec  # the part was moving
    assert rec["taken_over"]["held"], rec
    assert rec["success"] and rec["range_ratio"] >= 0.75, rec


def _scene(job):
    """(env reset for ``job``, its camera, the first observation); close the camera after use."""
    from opend_mj.evaluation.runner import make_episode_env
    from opend_mj.policy.planner import Observation
    from opend_mj.sim.camera import RGBDCamera

    env = make_episode_env(job)
    env.reset()
    task, physics = env.task, env.physics
    size = task.config.image_size
    cam = RGBDCamera(physics, "front", size, size)
    rgb, depth = cam.render()
    first = Observation(rgb=rgb, depth=depth, instruction=task.instruction, camera_view=task.camera_view(physics))
    return env, cam, first


def _act(env, expert, until: float) -> None:
    """Step ``expert``'s actions until ``until`` seconds of simulated time (or it has none)."""
    while env.physics.data.time < until - 1e-9 and (action := expert.action()) is not None:
        env.step(action)


@pytest.mark.slow
def test_expert_opens_a_door_another_agent_left_ajar(expert_cabinets):
    """An agent pulls the door partly open, opens its fingers and backs away: a fresh expert
    approaches the handle where it now is (the door turned), grasps it again and opens the door."""
    from opend_mj.policy.expert import PlannerExpert

    env, cam, first = _scene(_job(expert_cabinets, DOOR))
    task, physics = env.task, env.physics
    try:
        lead = PlannerExpert(env, first, cam)
        _act(env, lead, 5.5)
        lead.close()
        ajar = task.outcome(physics).range_ratio
        assert 0.03 < ajar < 0.6
        mocap = task.mocap.mocap_id(physics)
        pos, quat = physics.data.mocap_pos[mocap].copy(), physics.data.mocap_quat[mocap].copy()
        for i in range(60):  # fingers open, then 8 cm straight back, in 1 s
            back = pos - np.array([0.08 * min(1.0, max(0, i - 20) / 40), 0.0, 0.0])
            env.step(task.make_action(back, quat, task.hand.spec.open_pose))
        assert task.outcome(physics).range_ratio < ajar + 0.05
        expert = PlannerExpert(env, first, cam)
        _act(env, expert, 15.0)
        expert.close()
    finally:
        cam.close()
    assert expert.taken_over is not None and not expert.taken_over["held"]
    assert expert.taken_over["turned_deg"] > 3.0
    assert task.outcome(physics).success and task.outcome(physics).range_ratio >= 0.75


@pytest.mark.slow
def test_expert_takes_over_from_a_learned_policy(expert_cabinets):
    """The shipped behaviour-cloning policy acts for 3 s; the expert then opens the drawer from
    wherever the policy's hand is."""
    from opend_mj.evaluation.agents import load_agent
    from opend_mj.evaluation.takeover import takeover_episode

    rec = takeover_episode(_job(expert_cabinets, DRAWER), load_agent("bc"), switch=3.0)
    assert rec["lead"].startswith("bc"), rec
    assert rec["success"] and rec["range_ratio"] >= 0.75, rec


def test_expert_says_when_it_has_nothing_to_label(expert_cabinets):
    """Acting alone from the start, the expert is the planner: it never leaves its own plan, opens
    the drawer, and once its plan has finished gives no label and says why."""
    from opend_mj.policy.expert import PlannerExpert

    env, cam, first = _scene(_job(expert_cabinets, DRAWER))
    try:
        expert = PlannerExpert(env, first, cam)
        _act(env, expert, 30.0)
        expert.close()
    finally:
        cam.close()
    assert expert.why == "finished" and expert.action() is None
    assert expert.restarts == 0 and expert.taken_over is None
    assert env.task.outcome(env.physics).success

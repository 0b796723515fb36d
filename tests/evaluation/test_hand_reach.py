"""Failure stages read where the hand's gripping surfaces got, not only its grasp site: a hand whose
fingers reached the handle is never graded as failing the approach."""

from __future__ import annotations

import pytest

from opend_mj.evaluation.grading import failure_stage


def test_the_hand_far_from_the_handle_reads_the_cap(drawer_job):
    from opend_mj.evaluation.probes import HandReach
    from opend_mj.evaluation.runner import make_episode_env

    env = make_episode_env(drawer_job("allegro"))
    env.reset()
    reach = HandReach(env.task, env.physics)
    assert reach() == reach.cap  # the start pose is well away from the cabinet
    assert 0.1 < reach.span < 0.4  # the Allegro's fingers reach about 11 cm past its grasp site


@pytest.mark.parametrize("hand", ["allegro", "franka"])
def test_a_held_handle_is_recorded_as_reached(drawer_job, hand):
    from opend_mj.evaluation.runner import run_episode

    record = run_episode(drawer_job(hand))
    assert record["success"]
    assert record["hand_to_handle"] < 0.002  # fingers on the handle when the pull started


def test_fingers_on_the_handle_are_not_an_approach_failure():
    # a hook that holds the bar in its fingers' far segments: site 4 cm off, fingers touching
    assert failure_stage(False, 0.0, min(0.04, 0.0), check_locate=False) == "grasp"
    assert failure_stage(False, 0.0, min(0.04, 0.03), check_locate=False) == "approach"

"""The behaviour-cloning policy's inputs and outputs (`policy.learned.bc_model`)."""

from __future__ import annotations

import numpy as np

from opend_mj.policy.learned.bc_model import (
    BCConfig,
    decode_action,
    encode_actions,
    lag_index,
    quat_from_rot6,
    rot6,
)
from opend_mj.transforms import quat_to_mat


def _unit_quats(n, seed=0):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_rot6_is_the_matrix_first_two_columns_and_inverts():
    q = _unit_quats(20)
    r = rot6(q)
    for qi, ri in zip(q, r):
        assert np.allclose(ri, quat_to_mat(qi)[:, :2].T.ravel())
        back = quat_from_rot6(ri)
        assert min(np.abs(back - qi).max(), np.abs(back + qi).max()) < 1e-9  # q and -q: one rotation
    assert np.allclose(rot6(q), rot6(-q))  # continuous where a quaternion flips sign


def test_actions_encode_and_decode_back():
    rng = np.random.default_rng(1)
    low, high = -np.ones(4) * 0.3, np.ones(4) * 1.2
    q = _unit_quats(5, 2)
    actions = np.concatenate([rng.normal(size=(5, 3)), q, rng.uniform(low, high, size=(5, 4))], axis=1)
    centre = np.array([0.5, -0.2, 0.9])
    enc = encode_actions(actions, centre, low, high)
    assert enc.shape == (5, 3 + 6 + 4) and np.abs(enc[:, 9:]).max() <= 1.0 + 1e-6
    for a, e in zip(actions, enc):
        back = decode_action(e, centre, low, high)
        assert np.allclose(back[:3], a[:3], atol=1e-6) and np.allclose(back[7:], a[7:], atol=1e-5)
        assert min(np.abs(back[3:7] - a[3:7]).max(), np.abs(back[3:7] + a[3:7]).max()) < 1e-5


def test_lags_start_at_the_first_step():
    idx = lag_index(np.array([0, 3, 40]), (0, 4, 12))
    assert idx.tolist() == [[0, 0, 0], [3, 0, 0], [40, 36, 28]]


def test_config_round_trips():
    c = BCConfig(chunk=7, lags=(0, 2))
    assert BCConfig.from_dict(c.to_dict()) == c


def test_percept_gives_a_doors_hinge_line_relative_to_the_handle():
    """The last three percept numbers: the hinge line (x, y) relative to the handle centre and a
    flag; zeros for a handle with none (a drawer), the first 22 numbers unchanged by it (what the
    checkpoints of before the hinge line read)."""
    from opend_mj.policy.learned.bc_model import PERCEPT_DIM, HandlePercept, percept_vector
    from opend_mj.policy.perception.handle import HandleEstimate, HandleShape

    handle = HandleEstimate(centre=np.array([-0.3, 0.1, 0.8]), orientation="vertical", kind="bar",
                            size=(0.02, 0.12), front_x=-0.33, panel_x=-0.28)
    shape = HandleShape(thickness=0.015, length=0.12, gap=0.02, protrusion=0.035,
                        clear={"up": 0.1, "down": 0.1, "left": 0.15, "right": 0.05})
    drawer = percept_vector(HandlePercept(box=None, handle=handle, shape=shape, hinge=None))
    door = percept_vector(HandlePercept(box=None, handle=handle, shape=shape, hinge="left",
                                        hinge_point=np.array([-0.28, 0.45])))
    assert drawer.shape == door.shape == (PERCEPT_DIM,)
    assert drawer[-3:].tolist() == [0.0, 0.0, 0.0]
    assert np.allclose(door[-3:], [0.02, 0.35, 1.0])
    assert np.allclose(door[:3], handle.centre)
    assert np.array_equal(door[:11], drawer[:11]) and np.array_equal(door[14:22], drawer[14:22])  # but the side


def test_the_agents_step_by_step_actions_are_the_models_own():
    """The agent's one-sample forward pass (a TorchScript trace of the model, `step_actions`) gives
    exactly the module's actions, with and without the grasp-style token, for inputs other than
    those it was traced on; a batch of two goes through the module."""
    import torch

    from opend_mj.policy.learned.bc_model import build_model, step_actions

    for modes in (0, 3):
        model = build_model(30, 12, 9, BCConfig(modes=modes)).eval()
        lags = len(BCConfig().lags)
        g = torch.Generator().manual_seed(modes)
        for _ in range(3):
            ctx, steps = torch.randn(1, 30, generator=g), torch.randn(1, lags, 12, generator=g)
            with torch.no_grad():
                assert torch.equal(step_actions(model, ctx, steps), model.actions(ctx, steps))
        ctx, steps = torch.randn(2, 30, generator=g), torch.randn(2, lags, 12, generator=g)
        with torch.no_grad():
            assert torch.equal(step_actions(model, ctx, steps), model.actions(ctx, steps))

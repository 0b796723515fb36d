"""The compiled control step (`opend_mj.sim.fast`, step.c) against the Python step, bit for bit, and
its fallback to the Python step."""

from __future__ import annotations

import json
import warnings

import mujoco
import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

import opend_mj.sim.gym_env  # noqa: E402,F401  (registers the ids)
from opend_mj.sim import fast  # noqa: E402
from opend_mj.sim.fast import FastStepWarning  # noqa: E402
from opend_mj.sim.scripted import reach_grasp_pull  # noqa: E402

ENV_ID = "opend/OpenCabinet-v0"


def _require_compiled():
    if fast.library() is None:
        pytest.skip(f"the compiled step is not available here: {fast.status()}")


#: the sparse constraint Jacobian's index arrays: with a dense Jacobian MuJoCo never writes them
#: (uninitialised arena memory, different in every MjData)
_SPARSE_INDEX = {"efc_J_colind", "efc_J_rowadr", "efc_J_rownnz", "efc_J_rowsuper"}


def _mjdata(data, model) -> dict:
    """Every array of an MjData (state, derived quantities, contacts, constraint rows) and its
    scalars, as bytes."""
    unused = set() if mujoco.mj_isSparse(model) else _SPARSE_INDEX
    out = {name: value.tobytes() for name in dir(data) if not name.startswith("_") and name not in unused
           for value in [getattr(data, name)] if isinstance(value, np.ndarray)}
    contact = data.contact
    out.update({f"contact.{name}": getattr(contact, name).tobytes()
                for name in ("dist", "pos", "frame", "geom1", "geom2", "efc_address", "dim", "solref", "friction")})
    out.update(time=data.time, ncon=data.ncon, nefc=data.nefc, warnings=data.warning.number.tobytes())
    return out


def _same_obs(x: dict, y: dict, where: str) -> None:
    assert list(x) == list(y), where
    for key in x:
        assert x[key].dtype == y[key].dtype and x[key].tobytes() == y[key].tobytes(), f"{where}/{key}"


def _absolute_script(obs: dict, t: int, env, rng) -> np.ndarray:
    """The task's own action: toward the handle (within and beyond the top speed, sometimes far
    outside the workspace), turning about z and x, fingers open then closed; some steps not turning."""
    low, high = env.action_space.low, env.action_space.high
    n = len(low) - 7
    step = obs["handle_pos"] - obs["grasp_site_pos"]
    pos = obs["mocap_pos"].astype(float) + np.clip(step, -0.004 * (1 + t % 5), 0.004 * (1 + t % 5))
    if t % 17 == 16:
        pos = pos + np.array([0.0, 9.0, 0.0])  # beyond the workspace: clipped
    angle = 0.0 if t % 4 == 3 else 0.05 * np.sin(0.07 * t)
    turn = np.array([np.cos(angle), 0.3 * np.sin(angle), 0.0, np.sin(angle)])
    w1, x1, y1, z1 = turn / np.linalg.norm(turn)
    w2, x2, y2, z2 = obs["mocap_quat"].astype(float)
    quat = np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2]) * 1.7
    fingers = low[7:] if t < 120 else high[7:]
    if t % 13 == 12:
        fingers = rng.uniform(low[7:] - 0.2, high[7:] + 0.2, n)  # beyond the control ranges: clipped
    return np.concatenate([pos, quat, fingers])


@pytest.mark.parametrize("hand,control", [("allegro", "delta"), ("shadow", "delta"), ("franka", "absolute"),
                                          ("skeleton", "absolute")])
def test_compiled_env_step_gives_the_python_steps_numbers_and_mjdata_to_the_bit(small_dataset, hand, control):
    _require_compiled()
    kwargs = dict(cabinets=str(small_dataset), split="all", hand=hand, privileged=True, control=control,
                  time_limit=4.0)
    compiled = gym.make(ENV_ID, **kwargs).unwrapped
    python = gym.make(ENV_ID, compiled_step=False, **kwargs).unwrapped
    rng = np.random.default_rng(5)
    touched = contact = opened = truncations = 0
    try:
        for seed in (0, 3):
            obs, info = compiled.reset(seed=seed)
            ref_obs, ref_info = python.reset(seed=seed)
            assert compiled.core._fast is not None and python.core._fast is None
            _same_obs(obs, ref_obs, "reset")
            for t in range(260):
                if control == "delta":
                    action = reach_grasp_pull(obs, t, compiled.action_space.shape, rng)
                else:
                    action = _absolute_script(obs, t, compiled, rng)
                if t % 7 == 0:
                    action = np.asarray(action, np.float64).tolist()  # lists and float64 as well as float32
                obs, reward, terminated, truncated, info = compiled.step(action)
                ref = python.step(action)
                _same_obs(obs, ref[0], f"seed {seed} step {t}")
                assert (reward, terminated, truncated) == ref[1:4]
                assert json.dumps(info, sort_keys=True) == json.dumps(ref[4], sort_keys=True)
                a, b = compiled.core.scene._data, python.core.scene._data
                for field in ("qpos", "qvel", "ctrl", "mocap_pos", "mocap_quat", "qacc_warmstart"):
                    assert getattr(a, field).tobytes() == getattr(b, field).tobytes(), (seed, t, field)
                touched += bool(obs["touch"].any())
                contact += info["reward_terms"]["contact"]
                opened += info["open_ratio"] > 0.0
                if terminated or truncated:
                    truncations += truncated
                    break
            assert (_mjdata(compiled.core.scene._data, compiled.core.scene.physics.model.ptr)
                    == _mjdata(python.core.scene._data, python.core.scene.physics.model.ptr))
    finally:
        compiled.close()
        python.close()
    assert touched > 10  # touch
    if control == "delta":
        assert opened > 10  # a moving handle (its box recomputed) and the open terms
    if hand == "allegro":
        assert contact > 10  # the handle contact term
    assert truncations >= 1  # the time limit


def test_compiled_step_refuses_bad_actions_as_the_python_step_does(small_dataset):
    _require_compiled()
    for control, size in (("delta", 22), ("absolute", 23)):
        env = gym.make(ENV_ID, cabinets=str(small_dataset), split="all", hand="allegro", control=control).unwrapped
        try:
            env.reset(seed=1)
            assert env.core._fast is not None
            data = env.core.scene._data
            model = env.core.scene.task._model
            before = _mjdata(data, model)
            bad = np.zeros(size)
            bad[3] = 1.0
            bad[1] = np.nan
            with pytest.raises(ValueError, match="non-finite"):
                env.step(bad)
            with pytest.raises(ValueError, match="shape"):
                env.step(np.zeros(size + 1))
            if control == "absolute":
                with pytest.raises(ValueError, match="zero norm"):
                    env.step(np.zeros(size))
            assert _mjdata(data, model) == before  # nothing stepped, nothing written
        finally:
            env.close()


def test_compiled_task_step_gives_the_python_task_steps_planner_records(small_dataset):
    """`opend run`'s episodes (the planner on the Task) give the same record with either step."""
    _require_compiled()
    from opend_mj.assets.layout import load_manifest
    from opend_mj.evaluation.episode import EpisodeJob
    from opend_mj.evaluation.runner import run_episode

    manifest = load_manifest(small_dataset)
    cab, tgt = next(iter(manifest.targets("all")))
    job = EpisodeJob(cabinet=cab["id"], cabinet_dir=str(small_dataset / cab.get("path", cab["id"])),
                     joint=tgt["joint"], split=cab["split"], hand="franka", solver="oracle", use_grasp_file=False)
    records = []
    with pytest.MonkeyPatch.context() as patch:
        for flag in ("1", "0"):
            patch.setenv(fast.ENV_VAR, flag)
            record = run_episode(job)
            record.pop("wall_seconds")
            records.append(record)
    assert "error" not in records[0]
    assert json.dumps(records[0], sort_keys=True) == json.dumps(records[1], sort_keys=True)


def test_switched_off_by_the_environment_variable_without_a_warning(small_dataset, monkeypatch):
    monkeypatch.setenv(fast.ENV_VAR, "0")
    with warnings.catch_warnings():
        warnings.simplefilter("error", FastStepWarning)
        assert fast.library() is None
        assert fast.ENV_VAR in fast.status()
        env = gym.make(ENV_ID, cabinets=str(small_dataset), split="all", hand="franka")
        try:
            env.reset(seed=0)
            assert env.unwrapped.core._fast is None and env.unwrapped.core.scene.task._fast is None
            env.step(env.action_space.sample())
        finally:
            env.close()


@pytest.mark.parametrize("compiler", ["missing", "failing"])
def test_no_compiler_or_a_failed_compile_warns_once_and_the_python_step_runs(small_dataset, monkeypatch, tmp_path,
                                                                             compiler):
    if compiler == "missing":
        monkeypatch.setenv("CC", "no-such-c-compiler-for-opend")
        reason = "no C compiler"
    else:
        script = tmp_path / "bad-cc"
        script.write_text("#!/bin/sh\necho 'step.c: error: this compiler refuses' >&2\nexit 1\n")
        script.chmod(0o755)
        monkeypatch.setenv("CC", str(script))
        reason = "this compiler refuses"
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))  # nothing built there yet
    monkeypatch.delenv(fast.ENV_VAR, raising=False)
    fast._reset_for_tests()
    try:
        with pytest.warns(FastStepWarning, match=reason):
            assert fast.library() is None
        with warnings.catch_warnings():
            warnings.simplefilter("error", FastStepWarning)  # once per process
            assert fast.library() is None
            env = gym.make(ENV_ID, cabinets=str(small_dataset), split="all", hand="franka")
            try:
                env.reset(seed=0)
                assert env.unwrapped.core._fast is None
                for _ in range(5):
                    env.step(env.action_space.sample())
            finally:
                env.close()
        assert reason in fast.status()
    finally:
        fast._reset_for_tests()


def test_the_c_source_ships_with_the_package():
    from importlib import resources

    assert resources.files("opend_mj.sim.fast").joinpath("step.c").is_file()
    assert fast.SOURCE.read_text().count("ofs_env_step") >= 1


def test_compiled_step_reports_instabilities_as_the_python_step_does(small_dataset):
    """A state that blows up: the same warnings, termination, zero reward and observations."""
    _require_compiled()
    kwargs = dict(cabinets=str(small_dataset), split="all", hand="allegro")
    compiled = gym.make(ENV_ID, **kwargs).unwrapped
    python = gym.make(ENV_ID, compiled_step=False, **kwargs).unwrapped
    try:
        for env in (compiled, python):
            env.reset(seed=2)
            env.core.scene._data.qvel[:] = 1e12  # far beyond anything MuJoCo accepts
        action = np.zeros(compiled.action_space.shape)
        out, ref = compiled.step(action), python.step(action)
        _same_obs(out[0], ref[0], "unstable step")
        assert out[1:4] == ref[1:4] and out[2] and out[1] == 0.0
        assert out[4]["physics_warnings"] and json.dumps(out[4], sort_keys=True) == json.dumps(ref[4], sort_keys=True)
    finally:
        compiled.close()
        python.close()

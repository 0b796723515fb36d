"""`opend demos` (the planner's episodes as demonstrations), `opend train-policy` and `opend run --policy bc`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from opend_mj.cli import main


@pytest.fixture(scope="module")
def demos_file(small_dataset, tmp_path_factory):
    """Two franka demos of the small dataset, recorded through the command line."""
    out = tmp_path_factory.mktemp("demos") / "franka.hdf5"
    args = ["demos", "--cabinets", str(small_dataset), "--split", "all", "--hand", "franka", "--limit", "2",
            "--out", str(out), "--no-progress"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    return out, args


def test_demos_read_back_with_the_documented_keys(demos_file):
    from opend_mj.apps.demos import read_demos
    from opend_mj.apps.planner_demos import DEMO_OBS_KEYS
    from opend_mj.policy.learned.bc_model import PERCEPT_DIM
    from opend_mj.sim.hands import load_spec

    out, _ = demos_file
    attrs, demos = read_demos(out)
    assert attrs["format"] == "opend-mj-demos" and json.loads(attrs["env_args"])["env_name"] == "OpenCabinet"
    assert len(demos) == 2 and attrs["total"] == sum(d.num_samples for d in demos)
    n_fingers = len(load_spec("franka").actuator_names)
    for d in demos:
        t = d.num_samples
        assert t > 60  # over a second at 60 Hz
        assert set(DEMO_OBS_KEYS) <= set(d.obs) and "open_ratio" not in d.obs  # no ground truth
        assert d.actions.shape == (t, 7 + n_fingers) and d.extra["actions_delta"].shape == (t, 6 + n_fingers)
        assert np.abs(d.extra["actions_delta"]).max() <= 1.0
        for key in DEMO_OBS_KEYS:
            assert len(d.obs[key]) == t, key
        assert np.allclose(np.diff(d.obs["time"][:, 0]), 1 / 60, atol=1e-5)  # stored as float32
        assert d.obs["handle_features"].shape == (t, PERCEPT_DIM) and np.isfinite(d.obs["handle_features"]).all()
        assert d.obs["instruction"].shape == (t, 14) and (d.obs["instruction"].sum(axis=1) == 3).all()
        for key in ("instruction", "cabinet", "target_joint", "target_type", "hand", "solver", "split", "seed",
                    "success", "failed_stage", "open_ratio", "joint_value", "episode", "job_key"):
            assert key in d.attrs, key
        assert d.attrs["success"] and d.attrs["solver"] == "oracle" and d.attrs["open_ratio"] > 0.2


def test_demos_watch_the_front_they_open(demos_file):
    """Every step stores the front as a learner watches it (a depth image every 12 steps): it is not
    seen before the first look, and a demo that opened its target ends with the front seen moved,
    the grasp site near the handle as that motion carries it (the hand held it to the end or let go
    within a hand's width)."""
    from opend_mj.apps.demos import read_demos
    from opend_mj.policy.perception import WATCH_DIM, WATCH_NAMES

    out, _ = demos_file
    _, demos = read_demos(out)
    name = {k: i for i, k in enumerate(WATCH_NAMES)}
    for d in demos:
        w = d.obs["front_watch"]
        assert w.shape == (d.num_samples, WATCH_DIM) and np.isfinite(w).all() and d.attrs["watch_every"] == 12
        assert (w[:12, name["looked"]] == 0).all() and (w[12:, name["looked"]] == 1).all()
        assert w[:, name["age"]].max() < 12 / 60 + 1e-4  # s since the latest look, a look every 12 steps
        assert w[-1, name["seen"]] == 1
        # a drawer's front is seen out by its travel, a door's turned (its handle carried toward the camera)
        assert -w[-1, name["handle_dx"]] > 0.05, w[-1]


def test_delta_actions_are_the_absolute_ones_in_the_gym_action_space(demos_file):
    """Applied to the commanded pose before each step, the delta action gives the absolute one (to the
    float32 the file stores both in)."""
    from opend_mj.apps.demos import read_demos, task_config_from_args
    from opend_mj.sim.envs import ActionAdapter

    out, _ = demos_file
    attrs, demos = read_demos(out)
    adapter = ActionAdapter("franka", task_config_from_args(attrs["env_args"]))
    d = demos[0]
    delta = d.extra["actions_delta"]
    inside = np.abs(delta[:, :6]).max(axis=1) < 0.999  # steps whose root motion was not clipped
    assert inside.mean() > 0.5
    for t in np.flatnonzero(inside)[::25]:
        back = adapter.from_delta(delta[t], d.obs["mocap_pos"][t], d.obs["mocap_quat"][t])
        a = d.actions[t]
        assert np.allclose(back[:3], a[:3], atol=1e-5)
        assert min(np.abs(back[3:7] - a[3:7]).max(), np.abs(back[3:7] + a[3:7]).max()) < 1e-5
        assert np.allclose(back[7:], np.clip(a[7:], adapter.finger_low, adapter.finger_high), atol=1e-5)


def test_replaying_a_demo_reproduces_its_open_ratio(demos_file):
    from opend_mj.apps.demos import read_demos, replay_demo

    out, _ = demos_file
    attrs, demos = read_demos(out)
    for d in demos:
        r = replay_demo(d, attrs["env_args"])
        assert r.error <= 1e-9 and r.success
    # and through the command line
    result = CliRunner().invoke(main, ["replay", str(out), "--demo", "1"])
    assert result.exit_code == 0 and "OK" in result.output, result.output


def test_demos_under_hand_start_approach_from_farther_out_and_open(small_dataset, tmp_path):
    """`opend demos --perturb hand_start=strong`: training data whose approaches start back, out and up
    or down from the benchmark's start (the scene's own draw); the planner still opens the part from
    there. A bad axis is refused before any episode runs."""
    from opend_mj.apps.demos import read_demos

    out = tmp_path / "start.hdf5"
    args = ["demos", "--cabinets", str(small_dataset), "--split", "all", "--hand", "franka", "--limit", "1",
            "--out", str(out), "--no-progress"]
    res = CliRunner().invoke(main, args + ["--perturb", "hand_start=strong"])
    assert res.exit_code == 0, res.output
    nominal = tmp_path / "nominal.hdf5"
    assert CliRunner().invoke(main, args[:-3] + ["--out", str(nominal), "--no-progress"]).exit_code == 0
    (moved,), (plain,) = read_demos(out)[1], read_demos(nominal)[1]
    assert moved.attrs["success"] and plain.attrs["success"] and moved.attrs["open_ratio"] > 0.2
    assert "hand_start=strong" in moved.attrs["job_key"] and "hand_start" not in plain.attrs["job_key"]
    start, start0 = moved.obs["mocap_pos"][0], plain.obs["mocap_pos"][0]
    assert np.linalg.norm(start - start0) > 0.01 and start[1] >= start0[1]
    bad = CliRunner().invoke(main, args[:-3] + ["--out", str(tmp_path / "bad.hdf5"), "--perturb", "fog=mild"])
    assert bad.exit_code == 2 and "fog" in bad.output and not (tmp_path / "bad.hdf5").exists()


def test_demos_resume_and_refuse_bad_output(demos_file, tmp_path):
    out, args = demos_file
    again = CliRunner().invoke(main, args)
    assert again.exit_code == 0 and "0 episodes recorded, 2 already tried" in again.output
    bad = CliRunner().invoke(main, args[:-3] + ["--out", str(tmp_path / "x.json")])
    assert bad.exit_code != 0 and "HDF5" in bad.output


def test_a_killed_recording_resumes_without_losing_or_repeating_episodes(demos_file, tmp_path):
    """A kill after the first demo reached the file, while the log held the second episode as kept
    (its demo never written) and a torn line: the resumed run records the second episode only, and
    the file ends with the uninterrupted run's episodes, each once."""
    from opend_mj.apps.demos import append_demos, read_demos
    from opend_mj.apps.planner_demos import log_path

    full, args = demos_file
    attrs, demos = read_demos(full)
    keys = [d.attrs["job_key"] for d in demos]
    out = tmp_path / "killed.hdf5"
    demos[0].env_args = json.loads(attrs["env_args"])
    append_demos(out, demos[:1])
    lines = log_path(full).read_text().splitlines()
    log_path(out).write_text(lines[1] + "\n" + lines[0][:25])
    result = CliRunner().invoke(main, args[:-3] + ["--out", str(out), "--no-progress"])
    assert result.exit_code == 0 and "1 episodes recorded, 1 already tried" in result.output, result.output
    resumed = [d.attrs["job_key"] for d in read_demos(out)[1]]
    assert resumed == keys  # the same episodes, none repeated, in the uninterrupted order
    assert all(json.loads(line) for line in log_path(out).read_text().splitlines())


def test_train_policy_and_run_it_as_an_agent(demos_file, small_dataset, tmp_path):
    """A tiny policy trains from the demos (deterministically) and `opend run --policy bc` scores it."""
    import torch

    from opend_mj.evaluation.results import load_results

    out, _ = demos_file
    ckpts = []
    for name in ("a", "b"):
        ckpt = tmp_path / f"bc_{name}.pt"
        result = CliRunner().invoke(main, ["train-policy", "--demos", str(out), "--hand", "franka", "--out", str(ckpt),
                                           "--steps", "20", "--batch-size", "16", "--d-model", "16", "--no-progress"])
        assert result.exit_code == 0, result.output
        ckpts.append(torch.load(ckpt, weights_only=True))
    summary = json.loads((tmp_path / "bc_a.json").read_text())
    assert summary["demos"] == 2 and summary["hand"] == "franka" and summary["history"][-1]["step"] == 20
    for key, value in ckpts[0]["model"].items():
        assert torch.equal(value, ckpts[1]["model"][key]), key  # same seed, same weights
    wrong = CliRunner().invoke(main, ["train-policy", "--demos", str(out), "--hand", "allegro",
                                      "--out", str(tmp_path / "x.pt"), "--steps", "1"])
    assert wrong.exit_code != 0 and "franka" in wrong.output

    results = tmp_path / "bc.jsonl"
    args = ["run", "--cabinets", str(small_dataset), "--split", "all", "--hand", "franka", "--limit", "1",
            "--out", str(results), "--policy", "bc", "--policy-arg", f"checkpoint={tmp_path / 'bc_a.pt'}"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    (record,) = load_results(results)
    assert "error" not in record, record.get("error_reason")
    assert record["solver"] == "bc-fasterrcnn" and record["agent_stopped"]
    assert record["agent_stop"] in ("done", "locate") and isinstance(record["success"], bool)
    assert summary["stop_time"] <= summary["max_time"]
    assert record["sim_seconds"] <= summary["stop_time"] + 1 / 60 + 1e-6
    score = CliRunner().invoke(main, ["score", str(results)])
    assert score.exit_code == 0 and "bc-fasterrcnn" in score.output, score.output
    again = CliRunner().invoke(main, args)
    assert again.exit_code == 0 and "0 episodes run, 1 already done" in again.output


def test_seed_ensemble_averages_its_members_and_bundles_to_one_file(demos_file, small_dataset, tmp_path):
    """Checkpoints of two seeds run as one agent (``checkpoint=a.pt,b.pt``), which averages the two
    models' chunks; `opend bundle-policy` writes the same ensemble as one file (same episode, same
    record), with its ensemble_decay as the default; members that predict different chunks are refused.
    A bundle's routes (and the agent's drawer= / door= checkpoints) give a target kind its own members."""
    import torch

    from opend_mj.evaluation.results import load_results
    from opend_mj.policy.learned.bc_model import load_policies

    out, _ = demos_file
    ckpts = {}
    for name, extra in (("s0", ["--seed", "0"]), ("s1", ["--seed", "1"]), ("c5", ["--chunk", "5"])):
        ckpts[name] = tmp_path / f"bc_{name}.pt"
        result = CliRunner().invoke(main, ["train-policy", "--demos", str(out), "--hand", "franka", "--out",
                                           str(ckpts[name]), "--steps", "20", "--batch-size", "16", "--d-model", "16",
                                           "--watch", "0", "--no-progress", *extra])
        assert result.exit_code == 0, result.output
    pair = f"{ckpts['s0']},{ckpts['s1']}"
    bundle = tmp_path / "bundle.pt"
    result = CliRunner().invoke(main, ["bundle-policy", str(ckpts["s0"]), str(ckpts["s1"]), "--out", str(bundle),
                                       "--ensemble-decay", "0.1"])
    assert result.exit_code == 0 and "2 members" in result.output, result.output
    members = load_policies([bundle])
    assert len(members) == 2 and all(c.ensemble_decay == 0.1 for _, c, _ in members)
    side = json.loads(bundle.with_suffix(".json").read_text())  # the first member's summary, and the bundle's
    assert side["config"]["seed"] == 0 and side["bundle"]["members"] == 2
    assert [m["config"]["seed"] for m in side["bundle"]["member_summaries"]] == [0, 1]
    # the ensemble's prediction is the mean of its members' (the agent averages exactly these)
    ctx, steps = torch.randn(1, members[0][2]["dims"]["ctx"]), torch.randn(1, 4, members[0][2]["dims"]["step"])
    a, b = (m.actions(ctx, steps) for m, _, _ in members)
    assert not torch.allclose(a, b)
    wrong = CliRunner().invoke(main, ["bundle-policy", str(ckpts["s0"]), str(ckpts["c5"]), "--out",
                                      str(tmp_path / "bad.pt")])
    assert wrong.exit_code != 0 and "bc_c5.pt" in wrong.output and "chunk" in wrong.output
    assert not (tmp_path / "bad.pt").exists()

    def run(name, *policy_args):
        results = tmp_path / f"{name}.jsonl"
        args = ["run", "--cabinets", str(small_dataset), "--split", "all", "--hand", "franka", "--limit", "1",
                "--out", str(results), "--policy", "bc"]
        for arg in policy_args:
            args += ["--policy-arg", arg]
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 0, result.output
        (record,) = load_results(results)
        assert "error" not in record, record.get("error_reason")
        return {k: record[k] for k in ("success", "open_ratio", "joint_value", "steps", "agent_stop")}

    listed = run("listed", f"checkpoint={pair}", "ensemble_decay=0.1")
    assert run("bundled", f"checkpoint={bundle}") == listed

    # the first action of a demo's first step: the decoded mean of the two members' chunks
    from types import SimpleNamespace

    from opend_mj.apps.demos import read_demos
    from opend_mj.policy.bc_agent import BCAgent
    from opend_mj.policy.learned.bc_model import STEP_KEYS, context_features, decode_action, step_features

    demo = read_demos(out)[1][0]
    feats, instruction = np.asarray(demo.obs["handle_features"][0], float), demo.attrs["instruction"]
    obs = {k: np.asarray(demo.obs[k][0]) for k in STEP_KEYS}
    episode = SimpleNamespace(hand="franka", instruction=instruction, time_limit=15.0, camera_view=None)

    def first_action(checkpoint, text=instruction, **kinds):
        agent = BCAgent(checkpoint=checkpoint, **kinds)
        agent.reset(SimpleNamespace(**{**vars(episode), "instruction": text}))
        ctx = torch.from_numpy(context_features(feats, text))[None]
        agent._centre, agent._ctx = feats[:3], [ctx] * len(agent.models)
        return agent.act(obs), agent

    action, agent = first_action(pair)
    assert len(agent.models) == 2
    steps = torch.from_numpy(np.repeat(step_features({k: v[None] for k, v in obs.items()}, feats[:3]), 4, axis=0))[None]
    with torch.no_grad():
        mean = np.mean([m.actions(agent._ctx[0], steps)[0].numpy() for m in agent.models], axis=0)
    np.testing.assert_allclose(action, decode_action(mean[0], feats[:3], agent._low, agent._high), atol=1e-6)
    single, _ = first_action(str(ckpts["s0"]))
    assert not np.allclose(single, action)

    # a bundle's routes give a target kind its own members, chosen by the kind the instruction names
    routed = tmp_path / "routed.pt"
    result = CliRunner().invoke(main, ["bundle-policy", str(ckpts["s0"]), str(ckpts["s1"]), "--out", str(routed),
                                       "--route", "drawer=1"])
    assert result.exit_code == 0 and "drawer: members [1]" in result.output, result.output
    assert len(load_policies([routed], kind="drawer")) == 1 and len(load_policies([routed], kind="door")) == 2
    # a bundle re-bundled (here: to route doors too) keeps its members' own files as its sources
    rerouted = tmp_path / "rerouted.pt"
    result = CliRunner().invoke(main, ["bundle-policy", str(routed), "--out", str(rerouted), "--route", "drawer=1",
                                       "--route", "door=0"])
    assert result.exit_code == 0, result.output
    assert torch.load(rerouted, weights_only=True)["summary"]["sources"] == [str(ckpts["s0"]), str(ckpts["s1"])]
    assert len(load_policies([rerouted], kind="door")) == 1
    drawer_action, agent = first_action(str(routed), "drawer")
    assert len(agent.models) == 1
    np.testing.assert_allclose(drawer_action, first_action(str(ckpts["s1"]), "drawer")[0], atol=1e-6)
    door_action, agent = first_action(str(routed), "top left door")
    assert len(agent.models) == 2
    np.testing.assert_allclose(door_action, first_action(pair, "top left door")[0], atol=1e-6)
    # a kind's own checkpoints given to the agent (drawer= / door=) replace checkpoint= for that kind
    assert len(first_action(pair, "drawer", drawer=str(ckpts["s1"]))[1].models) == 1
    assert len(first_action(pair, "top left door", drawer=str(ckpts["s1"]))[1].models) == 2
    for bad, words in (("kitchen=0", "kind"), ("door=2", "0..1"), ("door", "KIND=I,J"), ("door=a", "whole numbers")):
        wrong = CliRunner().invoke(main, ["bundle-policy", str(ckpts["s0"]), str(ckpts["s1"]), "--out",
                                          str(tmp_path / "bad.pt"), "--route", bad])
        assert wrong.exit_code != 0 and words in wrong.output, (bad, wrong.output)
    assert not (tmp_path / "bad.pt").exists()


def test_dart_noise_labels_are_the_planners_clean_actions(small_dataset, tmp_path):
    """With action noise (DART) the scene is stepped with the planner's action plus a smooth offset,
    the stored labels are the planner's own clean actions, and replay (of the sent actions)
    reproduces the open ratio; the same job gives the same noise."""
    from opend_mj.apps.demos import read_demos, replay_demo
    from opend_mj.apps.planner_demos import ActionNoise, NoiseProcess, RecordConfig, record_episode
    from opend_mj.sim.envs import ActionAdapter
    from opend_mj.sim.task import TaskConfig

    out = tmp_path / "dart.hdf5"
    args = ["demos", "--cabinets", str(small_dataset), "--split", "all", "--hand", "franka", "--limit", "2",
            "--keep-failures", "--noise-pos", "0.004", "--noise-rot", "0.03", "--noise-fingers", "0.05",
            "--out", str(out), "--no-progress"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    attrs, demos = read_demos(out)
    assert len(demos) == 2
    for d in demos:
        sent = d.extra["actions_executed"]
        assert sent.shape == d.actions.shape
        gap = np.linalg.norm(sent[:, :3] - d.actions[:, :3], axis=1)
        assert gap.max() > 0.002 and gap[len(gap) // 2:].mean() > 0.001  # the hand was pushed off the plan
        noise = json.loads(d.attrs["action_noise"])
        assert noise["pos"] == 0.004 and noise["tau"] == 0.3
        # the label of a step is the planner's reply to the (perturbed) state it saw: the commanded
        # pose before a step is the previous step's *sent* action (where the mocap speed limit did
        # not cut it short), not its label (to the float32 the file stores mocap_pos in)
        def matches(actions):
            return float(np.mean(np.abs(d.obs["mocap_pos"][1:] - actions[:-1, :3]).max(axis=1) < 1e-6))

        assert matches(sent) > 0.8 and matches(d.actions) < 0.05
        r = replay_demo(d, attrs["env_args"])
        assert r.error <= 1e-9
    # the process: stationary spread as configured, zero offset before the first step, reproducible
    adapter = ActionAdapter("franka", TaskConfig())
    a = np.concatenate([[0.1, 0.2, 1.0, 1.0, 0.0, 0.0, 0.0], (adapter.finger_low + adapter.finger_high) / 2])
    offsets = []
    for seed in (1, 1, 2):
        proc = NoiseProcess(ActionNoise(pos=0.01, tau=0.1), adapter.finger_low, adapter.finger_high, 1 / 60, seed)
        offsets.append(np.array([proc.perturb(a)[:3] - a[:3] for _ in range(3000)]))
    assert np.array_equal(offsets[0], offsets[1]) and not np.array_equal(offsets[0], offsets[2])
    assert 0.008 < offsets[0][300:].std() < 0.012
    assert np.array_equal(proc.perturb(a)[7:], a[7:])  # no finger noise asked for
    with pytest.raises(ValueError, match="tau"):
        ActionNoise(pos=0.01, tau=0.0)
    assert RecordConfig().noise.active is False
    line, demo = record_episode(_first_job(small_dataset), None, RecordConfig())
    assert "actions_executed" not in demo.extra and demo.attrs["action_noise"] == ""


def _first_job(cabinets):
    from opend_mj.apps.planner_demos import demo_jobs

    return demo_jobs(cabinets, ["franka"], split="all", limit=1)[0]


def test_training_demos_of_one_kind(demos_file):
    """`opend train-policy --kind` reads only the demos whose instruction names that kind of target
    (the members a bundle routes a kind to); both kinds together are every demo."""
    from opend_mj.apps.planner_demos import load_training_demos
    from opend_mj.language import target_kind

    out, _ = demos_file
    every = load_training_demos(out)
    by_kind = {k: load_training_demos(out, kind=k) for k in ("drawer", "door")}
    assert sum(map(len, by_kind.values())) == len(every) == 2
    for kind, demos in by_kind.items():
        assert all(target_kind(d.attrs["instruction"]) == kind for d in demos)
    # the small dataset's first two targets are of one kind (its first cabinet's): no demo of the other
    # kind to train on is a clear error, no checkpoint
    missing = [k for k, demos in by_kind.items() if not demos]
    assert len(missing) == 1, {k: len(d) for k, d in by_kind.items()}
    result = CliRunner().invoke(main, ["train-policy", "--demos", str(out), "--hand", "franka", "--kind", missing[0],
                                       "--out", "never.pt", "--steps", "1", "--no-progress"])
    assert result.exit_code != 0 and "no usable demonstrations" in result.output
    assert not Path("never.pt").exists()


def test_dagger_rounds_label_the_policys_own_states_are_kept_and_resume(demos_file, small_dataset, tmp_path):
    """`opend train-policy --dagger 1`: round 0 trains on the demos; round 1 rolls that policy out at
    its own episode seed, the planner as expert labels every state it reaches (the rollouts are
    training data whether or not they opened their part), trains again from round 0's weights, and
    each round is validated on cabinets kept apart and kept (float16 policy and figures) in
    --keep-rounds; the final policy trains on every training cabinet from the best round, as two
    members of seeds 0 and 1 (`--final-members 2`) that the agent loads as one ensemble. A second
    run runs no episode and trains nothing again; a run with the build folder gone records the
    rollouts again from the kept policies, the same episodes, and trains no kept round again."""
    import torch

    from opend_mj.apps.dagger import split_cabinets
    from opend_mj.apps.demos import read_demos
    from opend_mj.evaluation.jobs import make_jobs

    out, _ = demos_file
    folder, keep = tmp_path / "dagger", tmp_path / "kept"
    args = ["train-policy", "--demos", str(out), "--hand", "franka", "--out", str(tmp_path / "bc.pt"), "--steps", "20",
            "--batch-size", "16", "--d-model", "16", "--dagger", "1", "--cabinets", str(small_dataset), "--dagger-dir",
            str(folder), "--keep-rounds", str(keep), "--dagger-targets", "2", "--val-targets", "1",
            "--final-steps", "30", "--final-members", "2", "--no-progress"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "bc.json").read_text())["dagger"]
    from opend_mj.policy.learned.bc_model import load_policies

    members = load_policies([tmp_path / "bc.pt"])
    assert [m["seed"] for m in summary["final"]["members"]] == [0, 1] == [c.seed for _, c, _ in members]
    assert json.loads((tmp_path / "bc.json").read_text())["bundle"]["seeds"] == [0, 1]
    a, b = (m.state_dict() for m, _, _ in members)
    assert any(not torch.equal(a[k], b[k]) for k in a)  # other seeds, other weights
    assert [r["round"] for r in summary["rounds"]] == [0, 1]
    assert all(r["val_episodes"] == 1 and 0.0 <= r["val_success"] <= 100.0 for r in summary["rounds"])
    assert summary["rounds"][1]["rollouts"] >= 1 and summary["rounds"][1]["beta"] == 0.5
    kept = [json.loads((keep / f"round_{i}.json").read_text()) for i in (0, 1)]
    assert [k["steps"] for k in kept] == [20, 20] and kept[0]["init"] is None
    assert kept[1]["init"] == str(keep / "round_0.pt") and kept[1]["rollout_seed"] == 11
    assert all({"training", "validation"} <= set(k["seconds"]) for k in kept) and "rollouts" in kept[1]["seconds"]
    for i in (0, 1):
        ckpt = torch.load(keep / f"round_{i}.pt", weights_only=True)
        assert all(v.dtype == torch.float16 for v in ckpt["model"].values() if v.is_floating_point())
    final = summary["final"]
    assert final["steps"] == 30 and final["from_round"] == summary["chosen"]
    assert final["demos"] == 2  # the validation cabinets' demonstrations too
    _, rollouts = read_demos(folder / "round_1.hdf5")
    _, val = split_cabinets(make_jobs(small_dataset, ["franka"], "oracle", split="train"), 0.15, 0)
    assert rollouts and all(d.attrs["labels"] == "expert" and d.attrs["cabinet"] not in val for d in rollouts)
    assert all(d.attrs["seed"] == 11 and d.obs["front_watch"].shape[1] == 11 for d in rollouts)
    for d in rollouts:  # labels are the expert's absolute actions; what was stepped is kept beside them
        assert d.actions.shape == d.extra["actions_executed"].shape and np.isfinite(d.actions).all()
    log = (folder / "round_1.hdf5.episodes.jsonl").read_text()
    kept_bytes = [(keep / f"round_{i}.pt").read_bytes() for i in (0, 1)]
    final_time = (folder / "final.pt").stat().st_mtime_ns
    again = CliRunner().invoke(main, args)
    assert again.exit_code == 0, again.output
    assert (folder / "round_1.hdf5.episodes.jsonl").read_text() == log
    assert (folder / "final.pt").stat().st_mtime_ns == final_time
    assert again.output.count("already trained for these rounds") == 2
    import shutil

    shutil.rmtree(folder)  # a fresh checkout: only the kept rounds
    fresh = CliRunner().invoke(main, args)
    assert fresh.exit_code == 0, fresh.output
    assert [(keep / f"round_{i}.pt").read_bytes() for i in (0, 1)] == kept_bytes
    def outcomes(text):
        return sorted((r["key"], r["success"], r["open_ratio"]) for r in map(json.loads, text.splitlines()))
    assert outcomes((folder / "round_1.hdf5.episodes.jsonl").read_text()) == outcomes(log)
    # kept rounds replaced (another run's round 0, round 1 gone): the work folder's rollouts were made
    # by the old round 0, so they are made again, never mixed in; the final policy is trained again
    from opend_mj.apps.dagger import file_sha256

    other = torch.load(keep / "round_0.pt", weights_only=True)
    other["model"] = {k: (v * 0.5 if v.is_floating_point() else v) for k, v in other["model"].items()}
    torch.save(other, keep / "round_0.pt")
    for f in keep.glob("round_1.*"):
        f.unlink()
    final_time = (folder / "final.pt").stat().st_mtime_ns
    replaced = CliRunner().invoke(main, args)
    assert replaced.exit_code == 0, replaced.output
    assert "made by another policy or recipe: made again" in replaced.output
    maker = json.loads((folder / "round_1.maker.json").read_text())
    assert maker["policy_sha256"] == file_sha256(keep / "round_0.pt")
    assert len((folder / "round_1.hdf5.episodes.jsonl").read_text().splitlines()) == len(log.splitlines())
    assert (folder / "final.pt").stat().st_mtime_ns != final_time


@pytest.fixture(scope="module")
def long_door_dataset(tmp_path_factory):
    """One compiled cabinet of the long_door family (`opend generate --family`), id proc_2000."""
    from opend_mj.assets.dataset import build_dataset
    from opend_mj.commands.assets import generate

    root = tmp_path_factory.mktemp("long")
    res = CliRunner().invoke(generate, ["--count", "1", "--start", "2000", "--family", "long_door",
                                        "--out", str(root / "src")])
    assert res.exit_code == 0, res.output
    build_dataset(sorted((root / "src").iterdir()), root / "cabinets", workers=1, progress=False,
                  log=lambda *a: None)
    return root / "cabinets"


def test_dagger_revisits_the_targets_its_rollouts_failed(demos_file, small_dataset, long_door_dataset, tmp_path):
    """`--revisit 1`: after a round's rollouts, the training targets whose rollout did not open their
    part are rolled out once more at an episode seed of their own, by the same policy, and labelled by
    the expert; the round trains on both and says how many it revisited. `--extra-cabinets`: every
    target of another dataset is rolled out too (validation stays on --cabinets). A later run with
    another --revisit makes a kept round's rollouts again as that round made them."""
    from opend_mj.apps.dagger import DaggerConfig, failed_targets
    from opend_mj.apps.demos import read_demos

    out, _ = demos_file
    folder, keep = tmp_path / "dagger", tmp_path / "kept"
    args = ["train-policy", "--demos", str(out), "--hand", "franka", "--out", str(tmp_path / "bc.pt"), "--steps", "5",
            "--batch-size", "16", "--d-model", "16", "--dagger", "1", "--cabinets", str(small_dataset), "--dagger-dir",
            str(folder), "--keep-rounds", str(keep), "--dagger-targets", "2", "--val-targets", "1",
            "--final-steps", "5", "--revisit", "1", "--extra-cabinets", str(long_door_dataset), "--no-progress"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    failed = failed_targets(folder / "round_1.hdf5.episodes.jsonl")
    entry = json.loads((keep / "round_1.json").read_text())
    assert entry["revisit"] == 1 and entry["revisited"] == len(failed)
    assert entry["extra_cabinets"] == [str(long_door_dataset)]
    rolled = [json.loads(x) for x in (folder / "round_1.hdf5.episodes.jsonl").read_text().splitlines()]
    assert len(rolled) == 3 and sum(r["cabinet"] == "proc_2000" for r in rolled) == 1
    validated = [json.loads(x)["cabinet"] for x in (folder / "val_1.jsonl").read_text().splitlines()]
    assert validated and "proc_2000" not in validated
    seed = DaggerConfig().revisit_seed(1, 0)
    assert seed not in (11, 100)
    extra = folder / "round_1_revisit_0.hdf5"
    if failed:  # a policy trained for 5 steps opens little; whatever failed is rolled out again
        lines = [json.loads(x) for x in (folder / "round_1_revisit_0.hdf5.episodes.jsonl").read_text().splitlines()]
        assert {(x["cabinet"], x["joint"]) for x in lines} == failed and {x["seed"] for x in lines} == {seed}
        _, revisits = read_demos(extra)
        assert all(d.attrs["labels"] == "expert" and d.attrs["seed"] == seed for d in revisits)
        _, firsts = read_demos(folder / "round_1.hdf5")
        assert entry["rollouts"] == len(firsts) + len(revisits)
    else:
        assert not extra.exists()
    again = CliRunner().invoke(main, [a if a != "1" or i != args.index("--revisit") + 1 else "2"
                                      for i, a in enumerate(args)])
    assert again.exit_code == 0, again.output
    assert not (folder / "round_1_revisit_1.hdf5").exists()  # round 1 was kept with one revisit


def test_rollouts_hold_after_the_plan_opened_the_part(demos_file, small_dataset, tmp_path):
    """`Rollout.hold`: where the expert's plan has ended with the part open, the rollout goes on to the
    policy's stop, each later state labelled with the plan's last action (the hand stays where the
    planner left it); without it the rollout ends with the plan."""
    from opend_mj.apps.dagger import Rollout, rollout_episode
    from opend_mj.apps.planner_demos import RecordConfig
    from opend_mj.evaluation.runner import make_episode_env

    out, _ = demos_file
    ckpt = tmp_path / "bc.pt"
    result = CliRunner().invoke(main, ["train-policy", "--demos", str(out), "--hand", "franka", "--out", str(ckpt),
                                       "--steps", "5", "--batch-size", "16", "--d-model", "16", "--no-progress"])
    assert result.exit_code == 0, result.output
    job = _first_job(small_dataset)
    runs = {}
    for hold in (False, True):  # beta 1: the expert's actions are stepped, the policy only decides when to stop
        rollout = Rollout(policy="bc", policy_args=(("checkpoint", str(ckpt)), ("stop_time", "12.0")), beta=1.0,
                          hold=hold)
        runs[hold] = rollout_episode(job, make_episode_env(job), RecordConfig(keep_failures=True, rollout=rollout))
    (line, demo), (held_line, held) = runs[False], runs[True]
    assert line["success"] and line["ended"] == "expert_finished" and line["held"] == 0
    assert held_line["ended"] == "policy_stopped" and held_line["success"]
    n = demo.num_samples
    assert held_line["held"] == held.num_samples - n > 0 and held.attrs["held_steps"] == held_line["held"]
    np.testing.assert_allclose(held.actions[:n], demo.actions)  # the same episode up to the plan's end
    assert (held.actions[n:] == demo.actions[-1]).all()  # then the plan's last action
    assert (held.num_samples - 1) / 60.0 <= 12.0 + 1e-6  # to the policy's stop (its stop_time, s)


def test_rounds_warm_start_from_the_previous_policy_and_the_final_policy_from_the_best_round(tmp_path):
    from opend_mj.apps.dagger import DaggerConfig

    warm = DaggerConfig(rounds=3, round_steps=500, final_steps=9000, init=tmp_path / "start.pt")
    plans = [warm.round_training(r, 3000, tmp_path / f"round_{r - 1}.pt") for r in range(4)]
    assert plans == [(3000, tmp_path / "start.pt"), (500, tmp_path / "round_0.pt"), (500, tmp_path / "round_1.pt"),
                     (500, tmp_path / "round_2.pt")]
    assert warm.final_training(3000, tmp_path / "round_2.pt") == (9000, tmp_path / "round_2.pt")
    cold = DaggerConfig(rounds=2, warm_start=False)
    assert [cold.round_training(r, 3000, tmp_path / "p.pt") for r in range(3)] == [(3000, None)] * 3
    assert cold.final_training(3000, tmp_path / "p.pt") == (3000, None)


def test_best_round_is_the_best_on_validation_and_the_later_on_a_tie():
    from opend_mj.apps.dagger import best_round

    rounds = [{"round": 0, "val_success": 40.0}, {"round": 1, "val_success": 70.0}, {"round": 2, "val_success": 65.0}]
    assert best_round({"rounds": rounds})["round"] == 1
    assert best_round({"rounds": rounds + [{"round": 3, "val_success": 70.0}]})["round"] == 3


def test_grasp_style_token_trains_and_acts(demos_file, small_dataset, tmp_path):
    """Demos record the planner's grasp style at every step; `--grasp-token` trains a policy whose
    style head predicts it (cross-entropy beside the actions' L1), and the policy acts as an agent."""
    import torch

    from opend_mj.apps.demos import read_demos
    from opend_mj.policy.learned.bc_model import GRASP_STYLES, load_policy

    out, _ = demos_file
    _, demos = read_demos(out)
    for d in demos:
        styles = d.extra["grasp_style"]
        assert styles.shape == (d.num_samples,) and styles.min() >= -1 and styles.max() < len(GRASP_STYLES)
        assert (styles >= 0).mean() > 0.9  # a style from the first approach on
    ckpt = tmp_path / "token.pt"
    result = CliRunner().invoke(main, ["train-policy", "--demos", str(out), "--hand", "franka", "--out", str(ckpt),
                                       "--steps", "20", "--batch-size", "16", "--d-model", "16", "--grasp-token",
                                       "--no-progress"])
    assert result.exit_code == 0, result.output
    model, config, _ = load_policy(ckpt)
    assert config.modes == len(GRASP_STYLES)
    ctx = torch.zeros(2, model.ctx_mean.numel())
    steps = torch.zeros(2, len(config.lags), model.step_mean.numel())
    actions, logits = model.predict(ctx, steps)
    assert logits.shape == (2, len(GRASP_STYLES)) and actions.shape[:2] == (2, config.chunk)
    results = tmp_path / "token.jsonl"
    run = CliRunner().invoke(main, ["run", "--cabinets", str(small_dataset), "--split", "all", "--hand", "franka",
                                    "--limit", "1", "--out", str(results), "--policy", "bc", "--policy-arg",
                                    f"checkpoint={ckpt}"])
    assert run.exit_code == 0, run.output
    assert "error" not in results.read_text()


def test_a_warm_start_trains_on_from_a_checkpoint_and_refuses_one_that_does_not_fit(demos_file, tmp_path):
    """`opend train-policy --init CKPT` starts from the checkpoint's weights and standardisation, with
    its architecture (a 16-wide model stays 16 wide whatever --d-model says): at a learning rate of
    zero the weights are the checkpoint's. A checkpoint of another hand, or a file that is none, is
    refused in one line naming it."""
    import torch

    out, _ = demos_file
    base = tmp_path / "base.pt"
    common = ["--demos", str(out), "--hand", "franka", "--batch-size", "16", "--no-progress"]
    result = CliRunner().invoke(main, ["train-policy", *common, "--out", str(base), "--steps", "20", "--d-model", "16"])
    assert result.exit_code == 0, result.output
    warm = tmp_path / "warm.pt"
    result = CliRunner().invoke(main, ["train-policy", *common, "--out", str(warm), "--steps", "5", "--lr", "0",
                                       "--init", str(base)])
    assert result.exit_code == 0, result.output
    a, b = torch.load(base, weights_only=True), torch.load(warm, weights_only=True)
    assert b["config"]["d_model"] == 16 and b["summary"]["init"] == str(base)
    for key, value in a["model"].items():
        assert torch.equal(value, b["model"][key]), key
    trained = tmp_path / "trained.pt"
    result = CliRunner().invoke(main, ["train-policy", *common, "--out", str(trained), "--steps", "5", "--init", str(base)])
    assert result.exit_code == 0, result.output
    moved = torch.load(trained, weights_only=True)["model"]
    assert any(not torch.equal(a["model"][k], moved[k]) for k in a["model"] if not k.endswith(("_mean", "_std")))
    assert all(torch.equal(a["model"][k], moved[k]) for k in a["model"] if k.endswith(("_mean", "_std")))

    other = dict(a, hand="allegro")
    torch.save(other, tmp_path / "allegro.pt")
    refused = CliRunner().invoke(main, ["train-policy", *common, "--out", str(tmp_path / "x.pt"), "--steps", "1",
                                        "--init", str(tmp_path / "allegro.pt")])
    assert refused.exit_code != 0 and "allegro.pt" in refused.output and "allegro hand" in refused.output
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    junk = CliRunner().invoke(main, ["train-policy", *common, "--out", str(tmp_path / "y.pt"), "--steps", "1",
                                     "--init", str(tmp_path / "junk.pt")])
    assert junk.exit_code != 0 and "junk.pt" in junk.output and "Traceback" not in junk.output

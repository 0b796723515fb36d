"""`opend run --instruction-file`: a user's own phrasings per target or per template, and the
episodes whose instruction the parser refuses (failed at stage "language", the robot still)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from opend_mj.evaluation.episode import EpisodeJob, episode_key, strip_wall_clock
from opend_mj.evaluation.phrasings import (
    InstructionFileError,
    assign_phrasings,
    load_instruction_file,
    reading_summary,
)

CORPUS = Path(__file__).parents[1] / "data" / "instruction_corpus.csv"


def _job(cabinet, joint, instruction, hand="franka", **kw):
    return EpisodeJob(cabinet=cabinet, cabinet_dir=f"/x/{cabinet}", joint=joint, split="test", hand=hand,
                      solver="oracle", instruction=instruction, **kw)


def test_json_targets_win_over_templates_and_templates_are_handed_out_in_turn(tmp_path):
    path = tmp_path / "mine.json"
    path.write_text(json.dumps({"targets": {"c1": {"j0": "the drawer at the very top"}},
                                "templates": {"top drawer": ["uppermost drawer", "highest drawer"],
                                              "door": "open the cupboard"}}))
    spec = load_instruction_file(path)
    jobs = [_job("c1", "j0", "top drawer"), _job("c2", "j0", "top drawer"), _job("c3", "j1", "top drawer"),
            _job("c4", "j0", "top drawer"), _job("c5", "j2", "door"),
            _job("c2", "j0", "top drawer", hand="shadow")]
    out = assign_phrasings(jobs, spec)
    assert [j.phrasing for j in out] == ["the drawer at the very top", "uppermost drawer", "highest drawer",
                                         "uppermost drawer", "open the cupboard", "uppermost drawer"]
    assert len({j.key() for j in out}) == len(out) and out[1].key() != jobs[1].key()
    assert reading_summary(out) == {"targets": 5, "as_template": 5, "refused": 0, "misread": 0, "misreadings": []}


def test_csv_per_target_and_the_corpus_as_a_template_file(tmp_path):
    path = tmp_path / "mine.csv"
    path.write_text("cabinet,joint,instruction\nc1,j0,\"second from the left, the door\"\n")
    spec = load_instruction_file(path)
    assert spec.targets == {("c1", "j0"): "second from the left, the door"}
    corpus = load_instruction_file(CORPUS)  # rows to be refused name no template: skipped
    assert not corpus.targets and len(corpus.templates["top drawer"]) >= 5
    jobs = assign_phrasings([_job("c1", "j0", "second left door"), _job("c2", "j0", "door")], corpus)
    assert reading_summary(jobs)["misread"] == 0


@pytest.mark.parametrize("name, text, message", [
    ("a.json", '{"templates": {"top-left drawer": "x"}}', "not Algorithm 1 templates"),
    ("a.json", '{"targets": {"c1": "x"}}', "must map joint names"),
    ("a.json", '{"phrasings": {}}', "'targets' and/or 'templates'"),
    ("a.json", "{not json", "not valid JSON"),
    ("a.csv", "text,template\nx,door\n", "header needs 'instruction'"),
    ("a.csv", "instruction,template\n,door\n", "line 2"),
    ("a.txt", "x", ".json or .csv"),
])
def test_bad_instruction_files_name_the_file_and_the_problem(tmp_path, name, text, message):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(InstructionFileError, match=message) as info:
        load_instruction_file(path)
    assert str(path) in str(info.value)


def test_a_target_without_a_phrasing_is_an_error(tmp_path):
    path = tmp_path / "a.json"
    path.write_text('{"templates": {"door": "the cupboard"}}')
    with pytest.raises(InstructionFileError, match=r"no phrasing for 1 target.*c2/j0 \('top drawer'\)"):
        assign_phrasings([_job("c1", "j0", "door"), _job("c2", "j0", "top drawer")], load_instruction_file(path))


def test_refused_and_reworded_episodes(drawer_cabinet):
    """A phrasing the parser reads as the template gives the template's episode (same motion and
    outcome); a refused one fails at stage "language" with the hand never moving the cabinet."""
    from opend_mj.evaluation.runner import run_episode

    target = json.loads((drawer_cabinet / "cabinet.json").read_text())["targets"][0]
    assert target["instruction"] == "top drawer"
    base = EpisodeJob(cabinet=drawer_cabinet.name, cabinet_dir=str(drawer_cabinet), joint=target["joint"],
                      split="train", hand="franka", solver="oracle", use_grasp_file=False,
                      target_type="drawer", instruction=target["instruction"])
    plain = run_episode(base)
    words = "could you pull out the uppermost drawer, please?"
    worded = run_episode(EpisodeJob(**{**base.__dict__, "phrasing": words}))
    refused = run_episode(EpisodeJob(**{**base.__dict__, "phrasing": "open the second drawer"}))
    assert plain["success"] and plain["understood_as"] == "top drawer"
    differ = {k for k in strip_wall_clock(plain) if strip_wall_clock(plain)[k] != worded.get(k)}
    assert differ == {"instruction"} and worded["phrasing"] == worded["instruction"]
    assert worded["understood_as"] == "top drawer"
    assert not refused["success"] and refused["failed_stage"] == refused["planner_failed_stage"] == "language"
    assert refused["understood_as"] is None and "counted from which side" in refused["language_refusal"]
    assert refused["open_ratio"] < 0.01 and refused["box"] is None
    assert refused["sim_seconds"] >= 5.0  # an episode lasts its minimum time even when the robot waits
    assert episode_key(refused) != episode_key(plain)


def test_opend_run_with_an_instruction_file(small_dataset, tmp_path):
    """`opend run --instruction-file` (the hand-written corpus): says how the parser reads the
    phrasings, records each episode's phrasing; `--paraphrase` with it is a usage error."""
    from click.testing import CliRunner

    from opend_mj.cli import main
    from opend_mj.evaluation.results import load_results

    out = tmp_path / "r.jsonl"
    args = ["run", "--cabinets", str(small_dataset), "--split", "all", "--hand", "franka", "--limit", "2",
            "--instruction-file", str(CORPUS), "--out", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "2 targets reworded; the parser reads 2 as their template, refuses 0, misreads 0" in result.output
    records = load_results(out)
    assert len(records) == 2 and all(r["phrasing"] and r["understood_as"] for r in records)
    bad = CliRunner().invoke(main, args + ["--paraphrase", "2"])
    assert bad.exit_code == 2 and "exclude each other" in bad.output


def test_opend_reword_writes_one_grammar_rewording_per_target(small_dataset, tmp_path):
    """`opend reword`: an instruction file (JSON targets) whose phrasings all read back to their
    target's template; another seed words them otherwise."""
    from click.testing import CliRunner

    from opend_mj.assets.layout import load_manifest
    from opend_mj.cli import main
    from opend_mj.evaluation.jobs import make_jobs
    from opend_mj.language import canonical_instruction

    out = tmp_path / "reworded.json"
    result = CliRunner().invoke(main, ["reword", "--cabinets", str(small_dataset), "--split", "all", "--out", str(out)])
    assert result.exit_code == 0, result.output
    spec = load_instruction_file(out)
    templates = {(c["id"], t["joint"]): t["instruction"] for c, t in load_manifest(small_dataset).targets("all")}
    assert set(spec.targets) == set(templates)
    assert all(canonical_instruction(text) == templates[key] for key, text in spec.targets.items())
    jobs = assign_phrasings(make_jobs(small_dataset, ["franka"], "oracle", split="all"), spec)
    assert reading_summary(jobs)["as_template"] == len(templates)
    other = tmp_path / "other.json"
    CliRunner().invoke(main, ["reword", "--cabinets", str(small_dataset), "--split", "all", "--seed", "1",
                              "--out", str(other)])
    assert load_instruction_file(other).targets != spec.targets

"""`opend score` over files that hold different episodes: a warning per pair, and `--common`."""

from __future__ import annotations

import json

from click.testing import CliRunner

from opend_mj.cli import main


def _write(path, solver, joints, hand="allegro", success=True):
    lines = [json.dumps(dict(cabinet="c", joint=j, hand=hand, solver=solver, split="test", seed=0, light_scale=1.0,
                             pull="arc", target_type="drawer", success=success,
                             open_ratio=0.5 if success else 0.0, range_ratio=0.8 if success else 0.0,
                             failed_stage=None if success else "approach"))
             for j in joints]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def _ranking_row(output: str, solver: str) -> str:
    return next(line for line in output.splitlines() if line.startswith("| ") and f"| {solver} |" in line)


def test_unequal_files_are_named_and_common_scores_the_shared_episodes(tmp_path):
    small = _write(tmp_path / "small.jsonl", "agent", ["j0", "j1"])
    big = _write(tmp_path / "big.jsonl", "oracle", ["j0", "j1", "j2", "j3"], success=False)
    same = _write(tmp_path / "same.jsonl", "other", ["j0", "j1"])
    runner = CliRunner()

    plain = runner.invoke(main, ["score", small, big, same])
    assert plain.exit_code == 0, plain.output
    warnings = [line for line in plain.stderr.splitlines() if line.startswith("warning:")]
    # small and same hold the same episodes: two pairs differ
    assert len(warnings) == 2
    assert f"{small} holds 2 episodes and {big} 4, 2 of them in both" in warnings[0]
    assert f"{big} holds 4 episodes and {same} 2, 2 of them in both" in warnings[1]
    assert "| oracle | allegro | 0.0 (0/4)" in _ranking_row(plain.stdout, "oracle")

    common = runner.invoke(main, ["score", "--common", small, big, same])
    assert common.exit_code == 0, common.output
    assert "| oracle | allegro | 0.0 (0/2)" in _ranking_row(common.stdout, "oracle")
    assert "| agent | allegro | 100.0 (2/2)" in _ranking_row(common.stdout, "agent")
    assert "# Results (6 episodes)" in common.stdout


def test_equal_files_give_no_warning(tmp_path):
    a = _write(tmp_path / "a.jsonl", "agent", ["j0", "j1"])
    b = _write(tmp_path / "b.jsonl", "oracle", ["j1", "j0"])
    result = CliRunner().invoke(main, ["score", a, b])
    assert result.exit_code == 0 and "warning" not in result.stderr


def test_common_with_nothing_in_common_is_an_error(tmp_path):
    a = _write(tmp_path / "a.jsonl", "agent", ["j0"], hand="allegro")
    b = _write(tmp_path / "b.jsonl", "oracle", ["j0"], hand="franka")  # another hand: another episode
    result = CliRunner().invoke(main, ["score", "--common", a, b])
    assert result.exit_code == 1 and "no episode is in every file" in result.output

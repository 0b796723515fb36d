"""results/ holds what `make results`, `make eval-real`, `opend robustness`, `opend expert-check` and `opend report`
write or read, nothing else."""

from __future__ import annotations

import fnmatch
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def unexplained_results(results: Path, makefile_text: str) -> list[str]:
    """Files under ``results`` that `opend report` does not read and whose name the Makefile does not
    write (a plot counts as written where its records are); hidden files and the git-ignored
    `results/quickstart/` are left out."""
    from opend_mj.evaluation.report import CONDITIONS, EXPERT_RESULTS, RESULT_SETS, ROBUSTNESS_RESULTS

    read = [rs.generated for rs in RESULT_SETS] + [f"real/{rs.real}" for rs in RESULT_SETS]
    read += [name for name, _ in CONDITIONS] + list(ROBUSTNESS_RESULTS) + list(EXPERT_RESULTS)
    out = []
    for path in sorted(results.rglob("*")):
        rel = path.relative_to(results).as_posix()
        if not path.is_file() or rel.startswith("quickstart/") or any(p.startswith(".") for p in path.parts):
            continue
        if any(fnmatch.fnmatch(rel, pattern) for pattern in read):
            continue
        stem = rel.rsplit(".", 1)[0]
        if "/" not in stem and stem in makefile_text:  # e.g. results/oracle_test_corpus.jsonl and .png
            continue
        out.append(rel)
    return out


def test_every_results_file_is_written_or_read_by_a_command():
    assert unexplained_results(ROOT / "results", (ROOT / "Makefile").read_text()) == []


def test_an_experiment_file_is_found(tmp_path):
    for rel in ("oracle_test.jsonl", "real/oracle_all.json", "bc/allegro_shipped_test.jsonl",
                "oracle_test_corpus.jsonl", "bc/allegro_n50_test.jsonl", "sweep.jsonl", ".x.lock"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("")
    makefile = "results/oracle_test_corpus.jsonl"
    assert unexplained_results(tmp_path, makefile) == ["bc/allegro_n50_test.jsonl", "sweep.jsonl"]

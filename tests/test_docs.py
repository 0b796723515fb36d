"""The user pages stay true to the code: every relative link resolves, and docs/cli.md is current."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", ROOT / "CHANGELOG.md", *(ROOT / "docs").rglob("*.md"),
                *(ROOT / "checkpoints").glob("*.md")])
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def anchors(page: Path) -> set[str]:
    """GitHub's anchors of a page's headings: lower case, punctuation dropped, spaces to hyphens."""
    out = set()
    for line in FENCE.sub("", page.read_text()).splitlines():
        if line.startswith("#"):
            title = line.lstrip("#").strip().lower()
            out.add(re.sub(r"[^\w\- ]", "", title).replace(" ", "-"))
    return out


def broken_links(page: Path) -> list[str]:
    """The relative links of ``page`` whose file, or whose anchor in that file, does not exist."""
    bad = []
    for target in LINK.findall(FENCE.sub("", page.read_text())):
        if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            bad.append(f"{target} (no such file)")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target} (no such heading)")
    return bad


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_every_relative_link_resolves(page):
    assert broken_links(page) == [], f"{page.relative_to(ROOT)}: broken links"


def test_a_broken_link_is_found(tmp_path):
    (tmp_path / "b.md").write_text("# Some heading\n")
    page = tmp_path / "a.md"
    page.write_text("[ok](b.md) [ok](b.md#some-heading) [bad](c.md) [bad](b.md#other)\n"
                    "```\n[in a code block](d.md)\n```\n")
    assert broken_links(page) == ["c.md (no such file)", "b.md#other (no such heading)"]


def test_the_command_reference_is_current():
    """docs/cli.md is `python tools/cli_reference.py`'s output for the commands as they are now."""
    proc = subprocess.run([sys.executable, str(ROOT / "tools" / "cli_reference.py"), "--check"],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def test_the_command_reference_names_every_command():
    from opend_mj.cli import COMMANDS

    page = (ROOT / "docs" / "cli.md").read_text()
    named = set(re.findall(r"^## `opend ([\w-]+)`", page, re.M))
    assert named == set(COMMANDS)


def test_no_user_page_is_over_300_lines():
    long = {str(p.relative_to(ROOT)): n for p in PAGES if p.parent.name == "docs" and p.name != "cli.md"
            and (n := len(p.read_text().splitlines())) > 300}
    assert long == {}


def test_the_shipped_policies_model_cards_are_current(load_tool):
    """Each checkpoints/bc_<hand>.md is `python tools/bc_model_card.py`'s output for the shipped policy's
    summary, kept rounds and results as they are now: a retrained policy cannot ship with an old card."""
    model_card = load_tool("bc_model_card").model_card
    hands = sorted(p.stem[3:] for p in (ROOT / "checkpoints").glob("bc_*.pt"))
    assert hands, "no shipped behaviour-cloning checkpoint"
    stale = [h for h in hands if (ROOT / "checkpoints" / f"bc_{h}.md").read_text() != model_card(h)]
    assert stale == [], f"regenerate with python tools/bc_model_card.py --hand {' --hand '.join(stale)}"


def test_a_shipped_ensemble_is_the_bundle_of_its_kept_runs_final_policies():
    """A shipped checkpoint that bundles several DAgger runs (`ENSEMBLE_<hand>` in the Makefile) holds
    exactly the final policies kept in checkpoints/bc_rounds/<hand>[-<variant>]/final.pt, in the
    Makefile's order: what `make train-bc` bundles is what ships, and each member's run can continue."""
    import torch

    from opend_mj.policy.learned.checkpoint_io import read_checkpoint

    make = (ROOT / "Makefile").read_text()
    for path in sorted((ROOT / "checkpoints").glob("bc_*.pt")):
        hand = path.stem[3:]
        ckpt = read_checkpoint(path, "behaviour-cloning policy checkpoint")
        line = next((ln for ln in make.splitlines() if ln.startswith(f"ENSEMBLE_{hand} =")), None)
        if "members" not in ckpt:
            assert line is None, f"{path}: one policy, but the Makefile bundles {hand} runs"
            continue
        runs = [hand] + [f"{hand}-{v}" for v in line.partition("=")[2].split()]
        kept = [read_checkpoint(ROOT / "checkpoints" / "bc_rounds" / run / "final.pt", "final") for run in runs]
        assert len(ckpt["members"]) == len(kept)
        for member, final in zip(ckpt["members"], kept):
            assert all(torch.equal(member["model"][k], final["model"][k]) for k in final["model"])

"""Instruction files: the benchmark's episodes run with a user's own phrasings (`opend run
--instruction-file FILE`).

A file gives phrasings for targets (one cabinet's joint) or for templates (Algorithm 1's
instruction, e.g. "top left drawer"); a target's own phrasing wins over its template's. Every
episode of a target (each hand, seed) gets the same phrasing. A template's phrasings are handed
out in turn to the targets that read so, in the manifest's order, so a run has as many episodes as
with the templates and each phrasing is used about equally often. The phrasings are not checked
against the parser here: reading them is part of the episode (a refused one is an episode failed
at stage ``language``; one read as another template opens what it was read as).

JSON::

    {"targets":   {"<cabinet id>": {"<joint>": "open the drawer on the far left", ...}, ...},
     "templates": {"top left drawer": ["the upper-left drawer", "open the top drawer on the left"],
                   "door": "could you open the door?"}}

CSV (a header row; other columns, such as a note, are ignored)::

    cabinet,joint,instruction            or        instruction,template
    proc_0011,joint_1,open the lowest drawer       the upper-left drawer,top left drawer

A CSV row with an empty template and no cabinet names no target (a phrasing that must be refused,
as in the parser's test corpus) and is skipped, so that corpus is itself an instruction file.
"""

from __future__ import annotations

import csv
import json
import random
from dataclasses import dataclass, replace
from pathlib import Path

from opend_mj.evaluation.episode import EpisodeJob


class InstructionFileError(ValueError):
    """An instruction file that cannot be read or does not cover the run's targets."""


@dataclass(frozen=True)
class InstructionFile:
    path: str
    #: (cabinet id, joint) -> phrasing
    targets: dict
    #: Algorithm 1 template -> phrasings (a tuple, handed out in turn)
    templates: dict


def _text(value, where: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise InstructionFileError(f"{where}: a phrasing must be a non-empty string, got {value!r}")
    return value.strip()


def load_instruction_file(path: Path | str) -> InstructionFile:
    """Read a JSON or CSV instruction file (see the module doc); errors name the file and the entry."""
    from opend_mj.language import all_templates

    path = Path(path)
    try:
        raw = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InstructionFileError(f"{path}: cannot read: {exc}") from None
    targets: dict = {}
    templates: dict = {}
    if path.suffix.lower() == ".json":
        try:
            data = json.loads(raw)
        except json.JSONDecodeError as exc:
            raise InstructionFileError(f"{path}: not valid JSON: {exc}") from None
        if not isinstance(data, dict) or not set(data) <= {"targets", "templates"} or not data:
            raise InstructionFileError(f"{path}: expected an object with 'targets' and/or 'templates'")
        for cabinet, joints in (data.get("targets") or {}).items():
            if not isinstance(joints, dict):
                raise InstructionFileError(f"{path}: targets[{cabinet!r}] must map joint names to phrasings")
            for joint, text in joints.items():
                targets[(str(cabinet), str(joint))] = _text(text, f"{path}: targets[{cabinet!r}][{joint!r}]")
        for template, texts in (data.get("templates") or {}).items():
            texts = [texts] if isinstance(texts, str) else texts
            if not isinstance(texts, list) or not texts:
                raise InstructionFileError(f"{path}: templates[{template!r}] must be a phrasing or a list of them")
            templates[template] = tuple(_text(t, f"{path}: templates[{template!r}]") for t in texts)
    elif path.suffix.lower() == ".csv":
        rows = list(csv.DictReader(raw.splitlines()))
        fields = set(rows[0]) if rows else set()
        if "instruction" not in fields or not ({"cabinet", "joint"} <= fields or "template" in fields):
            raise InstructionFileError(f"{path}: the header needs 'instruction' and either 'cabinet' and 'joint' "
                                       f"or 'template' (found {sorted(fields)})")
        for i, row in enumerate(rows, start=2):
            text = _text(row.get("instruction"), f"{path}: line {i}")
            if (row.get("cabinet") or "").strip():
                targets[(row["cabinet"].strip(), (row.get("joint") or "").strip())] = text
            elif (row.get("template") or "").strip():
                templates.setdefault(row["template"].strip(), []).append(text)
        templates = {k: tuple(v) for k, v in templates.items()}
    else:
        raise InstructionFileError(f"{path}: an instruction file is .json or .csv")
    unknown = sorted(set(templates) - set(all_templates()))
    if unknown:
        raise InstructionFileError(f"{path}: not Algorithm 1 templates: {unknown} (e.g. 'top left drawer', 'door')")
    if not targets and not templates:
        raise InstructionFileError(f"{path}: no phrasings")
    return InstructionFile(str(path), targets, templates)


def assign_phrasings(jobs: list[EpisodeJob], spec: InstructionFile) -> list[EpisodeJob]:
    """``jobs`` with their ``phrasing`` set from ``spec``; raises InstructionFileError naming the
    targets that neither their own entry nor their template's covers."""
    chosen: dict[tuple[str, str], str] = {}
    turn: dict[str, int] = {}
    missing = []
    for job in jobs:
        key = (job.cabinet, job.joint)
        if key in chosen:
            continue
        if key in spec.targets:
            chosen[key] = spec.targets[key]
        elif job.instruction in spec.templates:
            options = spec.templates[job.instruction]
            chosen[key] = options[turn.get(job.instruction, 0) % len(options)]
            turn[job.instruction] = turn.get(job.instruction, 0) + 1
        else:
            missing.append(f"{job.cabinet}/{job.joint} ({job.instruction!r})")
    if missing:
        raise InstructionFileError(f"{spec.path}: no phrasing for {len(missing)} target(s): "
                                   + ", ".join(missing[:8]) + (" ..." if len(missing) > 8 else ""))
    return [replace(job, phrasing=chosen[(job.cabinet, job.joint)]) for job in jobs]


def reading_summary(jobs: list[EpisodeJob]) -> dict:
    """How the parser reads the phrasings of ``jobs`` (one count per target): ``as_template`` (its
    own template), ``refused``, ``misread`` (another template) and the misread ones listed."""
    from opend_mj.language import InstructionNotUnderstood, canonical_instruction

    out = {"targets": 0, "as_template": 0, "refused": 0, "misread": 0, "misreadings": []}
    for job in {(j.cabinet, j.joint): j for j in jobs if j.phrasing is not None}.values():
        out["targets"] += 1
        try:
            read = canonical_instruction(job.phrasing)
        except InstructionNotUnderstood:
            out["refused"] += 1
            continue
        if read == job.instruction:
            out["as_template"] += 1
        else:
            out["misread"] += 1
            out["misreadings"].append((job.phrasing, job.instruction, read))
    return out


def generated_instruction_file(cabinets_dir: Path | str, split: str = "test", seed: int = 0) -> dict:
    """An instruction file (the JSON form) with one grammar rewording per target of ``split``
    (:func:`opend_mj.language.rewordings`), drawn with ``seed`` and the target's identity."""
    from opend_mj.assets.layout import load_manifest
    from opend_mj.language import Description, rewordings

    targets: dict = {}
    for cab, tgt in load_manifest(Path(cabinets_dir)).targets(split):
        d = Description(tgt.get("vertical", ""), tgt.get("horizontal", ""), tgt["type"])
        if d.instruction != tgt.get("instruction", d.instruction):
            raise InstructionFileError(f"{cabinets_dir}: {cab['id']}/{tgt['joint']}: labels {d} do not read "
                                       f"{tgt.get('instruction')!r}")
        options = rewordings(d, 30, seed)
        pick = random.Random(f"{seed}/{cab['id']}/{tgt['joint']}").choice(options)
        targets.setdefault(cab["id"], {})[tgt["joint"]] = pick
    return {"targets": targets}

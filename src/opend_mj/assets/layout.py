"""The compiled dataset's file contract: what `opend build-assets` writes and the runtime reads.

    <out>/manifest.json          every cabinet (id, path, split, targets) and every rejected source
    <out>/<id>/cabinet.xml       the cabinet's MJCF (meshes beside it)
    <out>/<id>/cabinet.json      its targets: joint, door or drawer, range, handle box, instruction

The task, the evaluation and the training renders import this module only, never the compiler, so
loading a cabinet does not load trimesh, CoACD or the mesh pipeline.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

CABINET_XML = "cabinet.xml"
CABINET_JSON = "cabinet.json"

#: Uniform scale from PartNet-Mobility's normalised units to metres (the OpenD paper used 0.7). The
#: compiler's default (`CompilerConfig.scale`) and the procedural generator's units both use it.
PARTNET_SCALE = 0.7


MANIFEST = "manifest.json"


@dataclass
class Manifest:
    cabinets: list[dict] = field(default_factory=list)
    rejected: list[dict] = field(default_factory=list)
    info: dict = field(default_factory=dict)
    #: Targets of built cabinets that the feasibility check excluded: id, joint, type, reason, message.
    excluded_targets: list[dict] = field(default_factory=list)

    def to_json(self) -> dict:
        return {"info": self.info, "cabinets": self.cabinets, "rejected": self.rejected,
                "excluded_targets": self.excluded_targets, "summary": split_table(self.cabinets)}

    def targets(self, split: str = "all") -> list[tuple[dict, dict]]:
        """(cabinet, target) pairs of a split ("train", "test" or "all"), in a stable order."""
        return [(c, t) for c in self.cabinets if split in ("all", c["split"]) for t in c["targets"]]

    def save(self, out_root: Path) -> Path:
        path = Path(out_root) / MANIFEST
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.to_json(), indent=1) + "\n")
        tmp.replace(path)
        return path


def load_manifest(cabinets_dir: Path) -> Manifest:
    path = Path(cabinets_dir) / MANIFEST
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no manifest; run `opend build-assets --out {cabinets_dir}` first")
    data = json.loads(path.read_text())
    return Manifest(cabinets=data["cabinets"], rejected=data["rejected"], info=data.get("info", {}),
                    excluded_targets=data.get("excluded_targets", []))


def split_table(cabinets: list[dict]) -> dict[str, dict[str, int]]:
    """Counts of drawers, doors and cabinets per split (the paper's Table 1 layout)."""
    table = {row: {"train": 0, "test": 0, "total": 0} for row in ("drawers", "doors", "targets", "cabinets")}
    for cab in cabinets:
        split = cab["split"]
        for col in (split, "total"):
            table["cabinets"][col] += 1
            for t in cab["targets"]:
                table["drawers" if t["type"] == "drawer" else "doors"][col] += 1
                table["targets"][col] += 1
    return table

"""The package's shape: imports flow one way (bottom to top), no cycle, and light imports stay light."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

import opend_mj

PACKAGE_DIR = Path(opend_mj.__file__).resolve().parent

#: Layers, bottom to top: a module may import its own layer's modules and those below, never above.
LAYERS = {
    "opend_mj": 0, "opend_mj.transforms": 0, "opend_mj.language": 0, "opend_mj.backends": 0,
    "opend_mj.assets": 1, "opend_mj.sim": 2, "opend_mj.policy": 3, "opend_mj.evaluation": 4,
    "opend_mj.apps": 5, "opend_mj.commands": 6, "opend_mj.cli": 7,
}
_LAZY_TARGET = re.compile(r"^(opend_mj(?:\.\w+)+):\w+$")  # "module:attribute" registries (CLI, solvers)


def _module_names() -> dict[str, Path]:
    out = {}
    for path in PACKAGE_DIR.rglob("*.py"):
        rel = path.relative_to(PACKAGE_DIR.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _module_names()


def _resolve(name: str) -> str | None:
    """The package module that importing ``name`` runs last (an attribute resolves to its module)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def imports_of(module: str) -> set[str]:
    """Every package module that ``module`` imports, at module level or inside functions, including
    "module:attribute" strings that are imported lazily by name."""
    path = MODULES[module]
    tree = ast.parse(path.read_text(), filename=str(path))
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")
                base = base if is_package else base[:-1]
                base = base[: len(base) - (node.level - 1)]
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ""
            names = [f"{prefix}.{a.name}" for a in node.names] + [prefix]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and _LAZY_TARGET.match(node.value):
            names = [node.value.split(":")[0]]
        for name in names:
            if name == "opend_mj" or name.startswith("opend_mj."):
                target = _resolve(name)
                if target and target != module:
                    found.add(target)
    return found


def _layer(module: str) -> int:
    best = max((k for k in LAYERS if module == k or module.startswith(k + ".")), key=len)
    return LAYERS[best]


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of the graph, or None (depth-first search)."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_cycle_finder_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_no_import_cycle_in_the_package():
    graph = {m: imports_of(m) for m in MODULES}
    assert sum(len(v) for v in graph.values()) > 50  # the walk really sees the imports
    assert "opend_mj.policy.learned.detector" in graph["opend_mj.policy.solvers"]  # lazy "module:attr"
    cycle = _cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_imports_flow_from_the_bottom_up():
    upward = [f"{m} -> {t}" for m in MODULES for t in imports_of(m) if _layer(t) > _layer(m)]
    assert not upward, "imports of a higher layer:\n" + "\n".join(sorted(upward))


def _modules_after_import(module: str) -> set[str]:
    code = f"import sys, {module}; print('\\n'.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return set(out.stdout.split())


def test_the_task_does_not_load_the_compiler():
    loaded = _modules_after_import("opend_mj.sim.task")
    assert "opend_mj.sim.task" in loaded
    heavy = {"trimesh", "coacd", "yourdfpy", "opend_mj.assets.compiler", "opend_mj.assets.meshes",
             "opend_mj.assets.sources", "torch"}
    assert not heavy & loaded, f"importing the task loaded {sorted(heavy & loaded)}"


def test_a_broken_command_module_is_reported_as_what_it_is(monkeypatch):
    from click.testing import CliRunner

    from opend_mj import cli

    monkeypatch.setitem(cli.COMMANDS, "broken", "opend_mj.commands.no_such_module:command")
    result = CliRunner().invoke(cli.main, ["broken"])
    assert result.exit_code == 1
    assert "cannot be loaded" in result.output and "ModuleNotFoundError" in result.output
    unknown = CliRunner().invoke(cli.main, ["no-such-command"])
    assert unknown.exit_code == 2 and "No such command" in unknown.output


def test_every_shipped_hand_scene_includes_its_hand():
    import mujoco

    from opend_mj.sim.hands import HANDS_DIR, builtin_hands
    from opend_mj.sim.physics import PHYSICS

    assert len(builtin_hands()) >= 4
    for hand in builtin_hands():
        scene = HANDS_DIR / hand / "scene.xml"
        assert '<include file="hand.xml"/>' in scene.read_text()
        hand_model = mujoco.MjModel.from_xml_path(str(HANDS_DIR / hand / "hand.xml"))
        scene_model = mujoco.MjModel.from_xml_path(str(scene))
        assert scene_model.nu == hand_model.nu and scene_model.njnt == hand_model.njnt, hand
        assert scene_model.opt.timestep == pytest.approx(PHYSICS.timestep)
        assert (HANDS_DIR / hand / "README.md").is_file()


#: Largest module (lines) in the package: a longer one holds more than one job and is split.
MAX_MODULE_LINES = 600


def test_no_module_is_longer_than_the_limit():
    lengths = {m: len(p.read_text().splitlines()) for m, p in MODULES.items()}
    assert len(lengths) > 50 and sum(lengths.values()) > 10000  # the walk really reads the package
    over = {m: n for m, n in lengths.items() if n > MAX_MODULE_LINES}
    assert not over, f"modules over {MAX_MODULE_LINES} lines (split them along their jobs): {over}"


def test_partnet_scale_has_one_definition():
    from opend_mj.assets import procedural
    from opend_mj.assets.config import CompilerConfig
    from opend_mj.assets.layout import PARTNET_SCALE

    assert CompilerConfig().scale == PARTNET_SCALE == procedural.GeneratorConfig().scale


def test_episode_identity_derives_key_record_and_video_name():
    from opend_mj.evaluation.episode import EPISODE_FIELDS, EpisodeJob, episode_key, record_fields, scene_key

    job = EpisodeJob(cabinet="c", cabinet_dir="d", joint="j", split="test", hand="allegro", solver="oracle")
    variants = [EpisodeJob(**{**job.__dict__, **change}) for change in
                ({"seed": 1}, {"light_scale": 0.7}, {"pull": "straight"}, {"paraphrase": 2},
                 {"physics_timestep": 1 / 120}, {"hand": "shadow"}, {"solver": "cliport"})]
    keys = {job.key()} | {v.key() for v in variants}
    names = {job.video_name()} | {v.video_name() for v in variants}
    assert len(keys) == len(names) == len(variants) + 1  # every identity field tells episodes apart
    assert job.video_name() == "c_j_allegro_oracle_s0_l1_arc.mp4"
    record = {**record_fields(job), "success": True}
    assert episode_key(record) == job.key()
    assert list(record_fields(job)) == [f.name for f in EPISODE_FIELDS if f.always]
    # episodes of one cabinet that differ only in target, solver or wording share a scene
    assert scene_key(job) == scene_key(EpisodeJob(**{**job.__dict__, "joint": "k", "paraphrase": 1}))
    assert scene_key(job) != scene_key(EpisodeJob(**{**job.__dict__, "light_scale": 0.7}))


def test_the_package_version_is_the_one_pyproject_declares():
    """`opend --version` and `opend_mj.__version__` name the release in pyproject.toml (the
    CHANGELOG's headings follow it)."""
    import re

    from click.testing import CliRunner

    import opend_mj
    from opend_mj.cli import main

    declared = re.search(r'^version = "([^"]+)"', (PACKAGE_DIR.parents[1] / "pyproject.toml").read_text(), re.M).group(1)
    assert opend_mj.__version__ == declared
    assert declared in CliRunner().invoke(main, ["--version"]).output
    assert f"## {declared}" in (PACKAGE_DIR.parents[1] / "CHANGELOG.md").read_text()

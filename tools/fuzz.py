"""Fuzz the inputs a user hands to opend: cabinet sources and results files (`make fuzz`).

A seeded mutator breaks copies of small real-format sources (two procedural cabinets, a door and a
drawer; with ``--real DIR`` also a PartNet-Mobility folder such as ../shared/partnet-sample/45780):
URDF numbers, attributes, names and elements, missing and extra files, OBJ and MTL bytes. Each case
is compiled as `opend build-assets` does; a cabinet that builds is loaded in MuJoCo and pushed open
in its room (the feasibility check). Results files (copies of committed records) are mutated the
same way and scored with `opend score`.

Every case must end in one of these, within ``--case-seconds``:
- built: the cabinet compiled, loads, and the feasibility check gave every target a verdict
  (``built`` when all open, ``built, excluded <reason>`` when the check excluded some);
- refused: a one-line message with its reason, naming a file of the source (or the results file);
- scored: `opend score` read the (still valid) results file.
Anything else fails the run: an exception that escaped, a ``compiler_error``, a message on several
lines or naming no file, a library warning that leaked, a case past its time limit (the process is
ended with the stack of where it hung), a built cabinet that MuJoCo cannot load.

    python tools/fuzz.py --cases 300 --seed 0      # prints the outcome table; exit 1 if any case failed
"""

from __future__ import annotations

import argparse
import faulthandler
import json
import os
import random
import re
import shutil
import sys
import tempfile
import time
import warnings
from collections import Counter
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

ROOT = Path(__file__).resolve().parents[1]

HOSTILE_NUMBERS = ["nan", "NaN", "inf", "-inf", "1e400", "1e9", "-1e9", "1e-9", "0", "-0", "1000", "-1", "0.001",
                   "abc", "", "1,2", "0x10", "1e-320", "3.0e38", "7"]
HOSTILE_NAMES = ["a/b", "world", "carcass", "", "x y", "j\u00fcrgen", "x" * 300, "<&>", "joint_0", "link_0",
                 "base", "a.b-c", "tab\tname", "..", "1"]
NUMERIC_ATTRS = {"origin": ("xyz", "rpy"), "axis": ("xyz",), "limit": ("lower", "upper", "effort", "velocity"),
                 "mesh": ("scale",), "mass": ("value",), "inertia": ("ixx", "iyy", "izz", "ixy")}


# --------------------------------------------------------------------------------------------------
# source mutators: each takes (source folder, rng) and returns a short description


def _urdf(src: Path):
    from lxml import etree

    return etree.parse(str(src / "mobility.urdf"))


def _save(src: Path, tree) -> None:
    tree.write(str(src / "mobility.urdf"))


def _elements(tree, tags=None):
    return [el for el in tree.getroot().iter() if isinstance(el.tag, str) and (tags is None or el.tag in tags)]


def m_number(src: Path, rng: random.Random) -> str:
    """A numeric attribute (present or added) gets a hostile value in one of its components."""
    tree = _urdf(src)
    tag = rng.choice(sorted(NUMERIC_ATTRS))
    from lxml import etree

    els = _elements(tree, {tag})
    if tag in ("mesh", "mass", "inertia") and (not els or rng.random() < 0.3):
        if tag == "mesh":
            els = _elements(tree, {"mesh"})
        else:  # add an inertial to a link
            link = rng.choice(_elements(tree, {"link"}))
            inertial = etree.SubElement(link, "inertial")
            etree.SubElement(inertial, "mass", value="1")
            etree.SubElement(inertial, "inertia", ixx="1", iyy="1", izz="1", ixy="0", ixz="0", iyz="0")
            els = _elements(tree, {tag})
    if not els:
        return f"no <{tag}>"
    el = rng.choice(els)
    attr = rng.choice(NUMERIC_ATTRS[tag])
    values = (el.get(attr) or ("1 1 1" if attr in ("xyz", "rpy", "scale") else "1")).split() or ["1"]
    k = rng.randrange(len(values))
    if rng.random() < 0.3:  # a plausible but wrong magnitude
        try:
            values[k] = repr(float(values[k] or 1) * rng.choice([1000.0, -1.0, 1e-4, 3.0, 0.0]))
        except ValueError:
            values[k] = rng.choice(HOSTILE_NUMBERS)
    else:
        values[k] = rng.choice(HOSTILE_NUMBERS)
    el.set(attr, " ".join(values))
    _save(src, tree)
    return f"<{tag} {attr}={el.get(attr)!r}>"


def m_remove(src: Path, rng: random.Random) -> str:
    tree = _urdf(src)
    els = [el for el in _elements(tree) if el.getparent() is not None]
    el = rng.choice(els)
    el.getparent().remove(el)
    _save(src, tree)
    return f"removed <{el.tag}>"


def m_duplicate(src: Path, rng: random.Random) -> str:
    import copy

    tree = _urdf(src)
    els = [el for el in _elements(tree) if el.getparent() is not None]
    el = rng.choice(els)
    el.addnext(copy.deepcopy(el))
    _save(src, tree)
    return f"duplicated <{el.tag}>"


def m_rename(src: Path, rng: random.Random) -> str:
    tree = _urdf(src)
    el = rng.choice(_elements(tree, {"link", "joint"}))
    old, new = el.get("name"), rng.choice(HOSTILE_NAMES)
    el.set("name", new)
    if el.tag == "link" and rng.random() < 0.7:  # keep the references consistent, mostly
        for ref in _elements(tree, {"parent", "child"}):
            if ref.get("link") == old:
                ref.set("link", new)
    _save(src, tree)
    return f"{el.tag} {old!r} -> {new!r}"


def m_joint_type(src: Path, rng: random.Random) -> str:
    tree = _urdf(src)
    el = rng.choice(_elements(tree, {"joint"}))
    el.set("type", rng.choice(["floating", "planar", "continuous", "fixed", "revolute", "prismatic", "weird", ""]))
    _save(src, tree)
    return f"joint {el.get('name')} type {el.get('type')!r}"


def m_extra(src: Path, rng: random.Random) -> str:
    from lxml import etree

    tree = _urdf(src)
    root = tree.getroot()
    kind = rng.choice(["unknown", "joint", "link", "visual"])
    if kind == "unknown":
        rng.choice(_elements(tree)).append(etree.Element("foo", bar="1"))
    elif kind == "joint":
        j = etree.SubElement(root, "joint", name="extra_joint", type=rng.choice(["revolute", "prismatic", "fixed"]))
        etree.SubElement(j, "parent", link=rng.choice(["base", "link_0", "nowhere"]))
        etree.SubElement(j, "child", link=rng.choice(["extra_link", "link_0", "base"]))
        etree.SubElement(j, "limit", lower="0", upper="1")
    elif kind == "link":
        etree.SubElement(root, "link", name=rng.choice(["extra_link", "link_0"]))
    else:
        link = rng.choice(_elements(tree, {"link"}))
        vis = etree.SubElement(link, "visual", name="extra")
        geo = etree.SubElement(vis, "geometry")
        if rng.random() < 0.5:
            etree.SubElement(geo, "box", size="0.1 0.1 0.1")
        else:
            etree.SubElement(geo, "mesh", filename=rng.choice(
                ["textured_objs/original-0.obj", "textured_objs/none.obj", "../x.obj", "textured_objs"]))
    _save(src, tree)
    return f"extra {kind}"


def m_mesh_path(src: Path, rng: random.Random) -> str:
    tree = _urdf(src)
    els = _elements(tree, {"mesh"})
    el = rng.choice(els)
    el.set("filename", rng.choice(["textured_objs/missing.obj", "../../etc/passwd", "/dev/zero", "textured_objs",
                                   "mobility.urdf", "", "textured_objs/original-0.obj", "package://x.obj",
                                   "textured_objs/junk.bin"]))
    _save(src, tree)
    return f"mesh filename {el.get('filename')!r}"


def m_urdf_bytes(src: Path, rng: random.Random) -> str:
    return _bytes(src / "mobility.urdf", rng)


def _bytes(path: Path, rng: random.Random) -> str:
    data = bytearray(path.read_bytes()) if path.is_file() else bytearray()
    how = rng.choice(["truncate", "flip", "insert", "delete_span", "empty", "nul"])
    if how == "truncate" and data:
        data = data[: rng.randrange(len(data))]
    elif how == "flip" and data:
        for _ in range(rng.randint(1, 8)):
            data[rng.randrange(len(data))] = rng.randrange(256)
    elif how == "insert":
        at = rng.randrange(len(data) + 1)
        data[at:at] = rng.choice([b"\xff\xfe\x00", b"\nv nan nan nan\n", b"\nf 1 2 999999\n", b"<<<", b"\nf 0 0 0\n",
                                  b"\nv 1e300 1e300 1e300\n", b"\nusemtl nothing\n", b"\nmtllib ../../x.mtl\n"])
    elif how == "delete_span" and data:
        a = rng.randrange(len(data))
        del data[a: a + rng.randint(1, 200)]
    elif how == "empty":
        data = bytearray()
    else:
        data = bytearray(b"\x00" * rng.randint(1, 64))
    path.write_bytes(bytes(data))
    return f"{path.name}: {how}"


def _objs(src: Path) -> list[Path]:
    return sorted((src / "textured_objs").glob("*.obj"))


def m_obj_bytes(src: Path, rng: random.Random) -> str:
    return _bytes(rng.choice(_objs(src)), rng)


def m_obj_numbers(src: Path, rng: random.Random) -> str:
    """Vertices scaled, pushed to NaN, inf or huge values; faces pointing nowhere."""
    path = rng.choice(_objs(src))
    lines = path.read_text(errors="replace").splitlines()
    vs = [i for i, ln in enumerate(lines) if ln.startswith("v ")]
    how = rng.choice(["scale", "one_vertex", "bad_face", "no_faces"])
    if how == "scale" and vs:
        factor = rng.choice([1000.0, 1e-6, -1.0, 0.0, 50.0])
        for i in vs:
            lines[i] = "v " + " ".join(repr(float(x) * factor) for x in lines[i].split()[1:4])
        how = f"scale x{factor:g}"
    elif how == "one_vertex" and vs:
        i = rng.choice(vs)
        lines[i] = "v " + " ".join(rng.choice(["nan", "inf", "1e30", "-1e30", "0"]) for _ in range(3))
    elif how == "bad_face":
        lines.append(rng.choice(["f 1 2 999999", "f 0 1 2", "f -99999 1 2", "f a b c", "f 1 1"]))
    else:
        lines = [ln for ln in lines if not ln.startswith("f ")]
    path.write_text("\n".join(lines) + "\n")
    return f"{path.name}: {how}"


def m_delete_file(src: Path, rng: random.Random) -> str:
    files = [p for p in src.rglob("*") if p.is_file()]
    f = rng.choice(files)
    f.unlink()
    return f"deleted {f.relative_to(src)}"


def m_extra_file(src: Path, rng: random.Random) -> str:
    how = rng.choice(["junk_obj", "dir_obj", "huge_name", "symlink"])
    objs = src / "textured_objs"
    if how == "junk_obj":
        (objs / "junk.obj").write_bytes(bytes(rng.randrange(256) for _ in range(200)))
    elif how == "dir_obj":
        (objs / "dir.obj").mkdir(exist_ok=True)
    elif how == "huge_name":
        (objs / ("n" * 200 + ".obj")).write_text("v 0 0 0\n")
    else:
        try:
            (objs / "loop.obj").symlink_to(objs / "loop.obj")
        except OSError:
            pass
    return f"extra file {how}"


def m_mtl(src: Path, rng: random.Random) -> str:
    mtls = sorted((src / "textured_objs").glob("*.mtl"))
    if not mtls:
        return "no mtl"
    path = rng.choice(mtls)
    text = path.read_text(errors="replace")
    how = rng.choice(["kd_nan", "map_missing", "bytes"])
    if how == "kd_nan":
        text = re.sub(r"Kd [^\n]*", "Kd nan inf -1", text)
        path.write_text(text)
    elif how == "map_missing":
        path.write_text(text + "\nnewmtl extra\nmap_Kd ../images/nothing.png\n")
    else:
        return _bytes(path, rng)
    return f"{path.name}: {how}"


SOURCE_MUTATORS = {f.__name__[2:]: f for f in (m_number, m_remove, m_duplicate, m_rename, m_joint_type, m_extra,
                                                m_mesh_path, m_urdf_bytes, m_obj_bytes, m_obj_numbers, m_delete_file,
                                                m_extra_file, m_mtl)}


# --------------------------------------------------------------------------------------------------
# results-file mutators


def r_mutate(path: Path, rng: random.Random) -> str:
    lines = path.read_bytes().split(b"\n")
    how = rng.choice(["bytes", "field", "drop_field", "not_object", "garbage_line", "duplicate", "crlf", "bom"])
    if how == "bytes":
        return _bytes(path, rng)
    k = rng.randrange(max(1, len(lines) - 1))
    if how in ("field", "drop_field") and lines[k].strip():
        rec = json.loads(lines[k])
        key = rng.choice(sorted(rec))
        if how == "field":
            rec[key] = rng.choice([None, "abc", [], {}, float("nan"), -1, 1e308, True, "1"])
        else:
            del rec[key]
        lines[k] = json.dumps(rec).encode()
        how = f"{how} {key}"
    elif how == "not_object":
        lines[k] = rng.choice([b"[]", b"3", b"null", b'"x"', b"true"])
    elif how == "garbage_line":
        lines.insert(k, rng.choice([b"{", b"not json", b"\xff\xfe", b"{}", b'{"cabinet": 1}']))
    elif how == "duplicate":
        lines.insert(k, lines[k])
    elif how == "crlf":
        lines = [ln + b"\r" for ln in lines]
    else:
        lines[0] = b"\xef\xbb\xbf" + lines[0]
    path.write_bytes(b"\n".join(lines))
    return how


# --------------------------------------------------------------------------------------------------
# running cases


class CaseFailed(Exception):
    pass


def one_line_naming(message: str | None, names: list[str]) -> None:
    if not message:
        raise CaseFailed("no message")
    if "\n" in message or "Traceback" in message:
        raise CaseFailed(f"message is not one line: {message[:200]!r}")
    if not any(n in message for n in names):
        raise CaseFailed(f"message names no file: {message[:200]!r}")


def source_case(base: Path, work: Path, rng: random.Random, check) -> tuple[str, str]:
    """(outcome, what was done) of one mutated source."""
    from opend_mj.assets.compiler import compile_cabinet
    from opend_mj.assets.dataset import excluded_targets

    src = work / "src" / base.name
    shutil.copytree(base, src, symlinks=True)
    done = []
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        name = rng.choice(sorted(SOURCE_MUTATORS))
        try:
            done.append(f"{name}: {SOURCE_MUTATORS[name](src, rng)}")
        except Exception as exc:  # the mutator found nothing to break (e.g. the file is already gone)
            done.append(f"{name}: skipped ({type(exc).__name__})")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = compile_cabinet(src, work / "out", cache_dir=work.parent / "cache")  # unmutated pieces hit it
        if result.status == "rejected":
            if result.reason == "compiler_error":
                raise CaseFailed(f"compiler_error: {result.message}")
            one_line_naming(result.message, [str(src)])
            outcome = f"refused: {result.reason}"
        else:
            import mujoco

            cabinet = work / "out" / result.id
            mujoco.MjModel.from_xml_path(str(cabinet / "cabinet.xml"))
            try:
                report = check(cabinet)
            except Exception as exc:  # noqa: BLE001 (what build-assets records as physics_error)
                message = f"{cabinet}: feasibility check failed ({type(exc).__name__}: {exc})"
                one_line_naming(" ".join(message.split()), [str(cabinet)])
                raise CaseFailed(f"the feasibility check raised on a built cabinet: {message[:300]}") from exc
            out = excluded_targets({"feasibility": report})
            outcome = "built" if not out else "built, excluded " + "/".join(sorted({t["reason"] for t in out.values()}))
    leaked = [w for w in caught if not issubclass(w.category, (DeprecationWarning, PendingDeprecationWarning))]
    if leaked:
        w = leaked[0]
        raise CaseFailed(f"a warning leaked: {w.category.__name__}: {w.message} ({w.filename}:{w.lineno})")
    return outcome, "; ".join(done)


def results_case(base: Path, work: Path, rng: random.Random) -> tuple[str, str]:
    from click.testing import CliRunner

    from opend_mj.cli import main

    path = work / "results.jsonl"
    shutil.copy(base, path)
    steps = []
    for _ in range(rng.choice([1, 1, 2])):
        try:
            steps.append(r_mutate(path, rng))
        except Exception as exc:  # noqa: BLE001 (a line the first mutation already broke: nothing to edit)
            steps.append(f"skipped ({type(exc).__name__})")
    done = "; ".join(steps)
    result = CliRunner().invoke(main, ["score", str(path)])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise CaseFailed(f"opend score raised {type(result.exception).__name__}: {result.exception}")
    if "Traceback" in result.output:
        raise CaseFailed("a traceback in the output")
    if result.exit_code == 0:
        return "scored", done
    if result.exit_code != 1:
        raise CaseFailed(f"exit status {result.exit_code}")
    errors = [ln for ln in result.output.splitlines() if ln.startswith("Error:")]
    if len(errors) != 1:
        raise CaseFailed(f"not one error line: {result.output[-300:]!r}")
    one_line_naming(errors[0], [str(path)])
    return "refused: " + _reason(errors[0]), done


def _reason(line: str) -> str:
    for word in ("corrupt line", "not an episode record", "is not valid", "cannot read"):
        if word in line:
            return word
    return "other"


def base_sources(root: Path, real: Path | None, real_only: bool = False) -> list[Path]:
    from opend_mj.assets.procedural import find_cabinets, write_source

    def single(kind: str):  # the first describable generated cabinet with one target of this kind
        return find_cabinets(lambda c: len(c.targets) == 1 and c.targets[0].kind == kind
                             and c.targets[0].hinge in ("", "left", "right"))[0]

    bases = [] if real_only else [write_source(single("door"), root), write_source(single("drawer"), root)]
    if real is not None:
        bases.append(Path(shutil.copytree(real, root / real.name)))
    return bases


def base_results(root: Path) -> Path:
    lines = (ROOT / "results" / "oracle_test.jsonl").read_text().splitlines()[:24]
    path = root / "base.jsonl"
    path.write_text("\n".join(lines) + "\n")
    return path


def run(cases: int, seed: int, results_cases: int, case_seconds: float, real: Path | None,
        real_only: bool = False, log=print, only: int | None = None) -> tuple[Counter, list[str]]:
    """Run the cases; returns the outcome counts and the failures (one line each)."""
    from opend_mj.sim.feasibility import RoomCheck

    check = RoomCheck()
    outcomes: Counter = Counter()
    failures: list[str] = []
    with tempfile.TemporaryDirectory(prefix="opend-fuzz-") as tmp:
        tmp = Path(tmp)
        bases = base_sources(tmp / "bases", real, real_only)
        base_res = base_results(tmp)
        total = cases + results_cases
        for k in range(total) if only is None else [only]:
            rng = random.Random(f"{seed}:{k}")
            work = tmp / f"case{k}"
            work.mkdir()
            kind = "source" if k < cases else "results"
            faulthandler.dump_traceback_later(case_seconds, exit=True)  # a hang ends the run, with its stack
            start = time.perf_counter()
            try:
                if kind == "source":
                    outcome, done = source_case(rng.choice(bases), work, rng, check)
                else:
                    outcome, done = results_case(base_res, work, rng)
            except CaseFailed as exc:
                outcome, done = "FAILED", str(exc)
            except Exception as exc:  # noqa: BLE001 (an exception that escaped: the worst outcome)
                import traceback

                frames = None if only is not None else -3  # the whole stack when one case is rerun
                outcome, done = "FAILED", f"escaped {type(exc).__name__}: {exc} | {traceback.format_exc(limit=frames)}"
            finally:
                faulthandler.cancel_dump_traceback_later()
            seconds = time.perf_counter() - start
            outcomes[f"{kind} {outcome}"] += 1
            if outcome == "FAILED":
                failures.append(f"case {k} (seed {seed}, {kind}): {' '.join(done.split())}")
                log(f"FAILED {failures[-1]}")
            elif os.environ.get("FUZZ_VERBOSE") or only is not None:
                log(f"case {k} {kind} {outcome} ({seconds:.1f} s): {done}")
            shutil.rmtree(work, ignore_errors=True)
    return outcomes, failures


def table(outcomes: Counter, failures: list[str]) -> str:
    total = sum(outcomes.values())
    lines = [f"fuzz: {total} cases tried, {len(failures)} failed", "", "| input | outcome | cases |",
             "|---|---|---:|"]
    for key, n in sorted(outcomes.items()):
        kind, outcome = key.split(" ", 1)
        lines.append(f"| {kind} | {outcome} | {n} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=int(os.environ.get("FUZZ_CASES", 200)),
                        help="mutated sources (default $FUZZ_CASES or 200)")
    parser.add_argument("--results-cases", type=int, default=None,
                        help="mutated results files (default: a third of --cases)")
    parser.add_argument("--seed", type=int, default=int(os.environ.get("FUZZ_SEED", 0)))
    parser.add_argument("--case-seconds", type=float, default=60.0,
                        help="wall-clock limit of one case: past it the run ends with the stack of the hang")
    parser.add_argument("--real", type=Path, default=None,
                        help="also mutate this PartNet-Mobility folder (e.g. ../shared/partnet-sample/45780)")
    parser.add_argument("--real-only", action="store_true", help="with --real: mutate that folder only")
    parser.add_argument("--only", type=int, default=None, metavar="K",
                        help="rerun case K alone (of the same --cases, --seed, --real), with its whole stack if it fails")
    args = parser.parse_args(argv)
    results_cases = args.results_cases if args.results_cases is not None else max(1, args.cases // 3)
    start = time.perf_counter()
    outcomes, failures = run(args.cases, args.seed, results_cases, args.case_seconds, args.real, args.real_only,
                             only=args.only)
    print(table(outcomes, failures))
    print(f"\n{time.perf_counter() - start:.1f} s")
    for f in failures:
        print(f"FAILED {f}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())

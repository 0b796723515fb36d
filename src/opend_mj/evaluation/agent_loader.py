"""Naming and loading an agent of `opend run --policy` (``module:Class``, ``file.py[:Class]``, ``bc``).

Light on imports: the agent process (`evaluation.agent_process`) loads its agent with it and holds no
simulator module beyond what the agent interface (`opend_mj.policy.agents`) needs.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import sys
import zlib
from pathlib import Path

from opend_mj.policy.agents import agent_control, agent_images

#: Agents shipped with the package, by short name (``opend run --policy bc``).
BUILTIN_POLICIES = {"bc": "opend_mj.policy.bc_agent:BCAgent"}

_LOADED: dict[tuple, object] = {}


def parse_policy_args(items) -> tuple[tuple[str, object], ...]:
    """``("k=v", ...)`` -> ``(("k", v), ...)``; a value is JSON where it parses (numbers, true, lists)."""
    out = []
    for item in items or ():
        key, sep, value = str(item).partition("=")
        if not sep or not key.strip():
            raise ValueError(f"policy argument {item!r} is not key=value")
        try:
            parsed = json.loads(value)
        except json.JSONDecodeError:
            parsed = value
        out.append((key.strip(), parsed))
    return tuple(out)


def resolve_policy(spec: str) -> tuple[str, str]:
    """``(module or absolute file path, attribute)`` of a policy spec; raises ValueError if not found."""
    spec = BUILTIN_POLICIES.get(spec, spec)
    target, sep, attr = spec.rpartition(":")
    if not sep:
        target, attr = spec, ""
    if target.endswith(".py") or Path(target).is_file():
        path = Path(target).expanduser().resolve()
        if not path.is_file():
            raise ValueError(f"policy file {target} not found")
        return str(path), attr or "Agent"
    if not attr:
        raise ValueError(f"policy {spec!r}: name a class, as module:Class or path/to/file.py:Class")
    return target, attr


def _import(target: str):
    if target.endswith(".py"):
        name = f"opend_policy_{zlib.crc32(target.encode()):08x}"
        if name in sys.modules:
            return sys.modules[name]
        spec = importlib.util.spec_from_file_location(name, target)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
        return module
    return importlib.import_module(target)


def load_agent(spec: str, args: tuple = ()):
    """The agent a spec names, made with ``args``, in this process (cached per process)."""
    key = (spec, args)
    agent = _LOADED.get(key)
    if agent is None:
        target, attr = resolve_policy(spec)
        try:
            module = _import(target)
        except ImportError as exc:
            raise ValueError(f"policy {spec!r}: cannot import {target} ({exc})") from exc
        factory = getattr(module, attr, None)
        if factory is None:
            raise ValueError(f"policy {spec!r}: {target} has no {attr!r}")
        # a class or a factory function is called with the arguments; an instance is used as it is
        is_factory = isinstance(factory, type) or (callable(factory) and not hasattr(factory, "act"))
        agent = factory(**dict(args)) if is_factory else factory
        if not callable(getattr(agent, "act", None)):
            raise ValueError(f"policy {spec!r}: {attr} has no act(obs) method")
        agent_control(agent)
        agent_images(agent)
        _LOADED[key] = agent
    return agent

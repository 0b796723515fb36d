"""The agent channel's cost per step beside the physics step (`make bench-agents`; also in `make bench`).

`opend run --policy` runs the agent in a process of its own (`evaluation.agent_process`): every
control step the observation goes over a pipe and the action comes back. Measured here, on the scene
`opend run` builds for the first test target (``--hand``, default allegro), in interleaved chunks of
``--chunk`` steps (a chunk of each contestant in turn, round after round, so that all see the same
load on a shared machine), each in wall-clock time and in the simulator process's CPU time:

- physics: ``env.step`` of the episode's scene with a holding action (state mode: no rendering),
  what the agent loop calls once per step;
- channel: one round trip of a step's observation (the hand's state, camera, instruction; no image,
  as after the first step of an ``images = "first"`` agent) to an agent process whose ``act`` returns
  a constant action at once, and the action back: the channel's whole cost per step;
- BC: the shipped BC policy's ``act`` per step (after its first, which runs the handle solver) in
  this process and across the channel, on the same observations; their difference is the channel's
  cost for that policy (``--no-bc`` skips it).

Prints a Markdown section; ``--write FILE`` also puts it into FILE (BENCHMARKS.md) in place of its
"## Agent channel" section (added at the end where there is none).

    python tools/bench_agent_channel.py [--cabinets cabinets] [--hand allegro] [--steps 2000] [--chunk 100]
                                        [--no-bc] [--write BENCHMARKS.md]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

from bench_sections import write_section  # tools/, beside this script

ROOT = Path(__file__).resolve().parents[1]
TITLE = "## Agent channel"


class HoldAgent:
    """An agent that returns the same action at once: the channel's cost alone."""

    name = "hold"
    control = "absolute"
    images = "first"

    def __init__(self, dim: int = 23):
        import numpy as np

        self.action = np.zeros(int(dim))

    def reset(self, episode) -> None:
        pass

    def act(self, obs):
        return self.action

    def episode_info(self) -> dict:
        """This (agent) process's CPU seconds so far: its side of the channel's cost."""
        return {"cpu": time.process_time()}


def _process_cpu(pid: int) -> float:
    """CPU seconds (user + system) of process ``pid`` so far, from /proc (clock-tick resolution)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _timed(fn, n: int) -> tuple[float, float]:
    """(wall, CPU of this process) seconds per call of ``fn`` over ``n`` calls."""
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(n):
        fn()
    return (time.perf_counter() - wall) / n, (time.process_time() - cpu) / n


def section(cabinets: Path, hand: str, steps: int, chunk: int, bc: bool) -> str:
    import numpy as np

    from opend_mj.evaluation.agent_process import AgentProcess
    from opend_mj.evaluation.agents import PROTOCOL_TIME_LIMIT, episode_seed, load_agent
    from opend_mj.evaluation.jobs import make_jobs
    from opend_mj.evaluation.runner import make_episode_env
    from opend_mj.policy.agents import EpisodeInfo
    from opend_mj.sim.envs import ActionAdapter, SceneReader

    job = make_jobs(cabinets, [hand], "bench", split="test", limit=1)[0]
    env = make_episode_env(job)
    env.reset()
    task = env.task
    reader = SceneReader(env, task.config.image_size)
    adapter = ActionAdapter(hand, task.config)
    d = reader._data
    hold = adapter.from_delta(np.zeros(adapter.delta_dim), d.mocap_pos[reader._mocap].copy(),
                              d.mocap_quat[reader._mocap].copy())
    spec = env.action_spec()
    info = EpisodeInfo(instruction=task.instruction, hand=hand, hand_spec=task.hand.spec,
                       camera_view=reader.camera_view(), control_dt=task.control_timestep,
                       time_limit=PROTOCOL_TIME_LIMIT, action_names=tuple(spec.name.split("\t")),
                       action_low=spec.minimum, action_high=spec.maximum, seed=episode_seed(job))
    camera = reader.camera_arrays()

    def observe(images: bool = False) -> dict:
        obs = {**reader.proprio(), "instruction": task.instruction, **camera}
        if images:
            obs["rgb"], obs["depth"] = reader.render(task.config.depth_frames)
        return obs

    first = observe(images=bc)
    obs = observe()
    channel = AgentProcess(f"{Path(__file__).resolve()}:HoldAgent", (("dim", len(hold)),), None)
    channel.reset(info)
    contestants = {"physics": lambda: env.step(hold), "channel": lambda: channel.act(obs)}
    agents = []
    if bc:
        local = load_agent("opend_mj.policy.bc_agent:BCAgent", ())
        remote = AgentProcess("opend_mj.policy.bc_agent:BCAgent", (), None)
        for agent in (local, remote):
            agent.reset(info)
            agent.act(first)  # the handle solver runs on the first observation
        agents = [local, remote]
        contestants.update({"bc_local": lambda: local.act(obs), "bc_channel": lambda: remote.act(obs)})
    figures: dict[str, list[tuple[float, float]]] = {k: [] for k in contestants}
    agent_cpu = {k: 0.0 for k in contestants}  # the agent process's CPU seconds in each contestant's chunks
    load_before = os.getloadavg()[0]
    for _ in range(max(1, steps // chunk)):
        for name, fn in contestants.items():
            if name == "channel":
                before = channel.episode_info()["cpu"]
            elif name == "bc_channel":
                before = _process_cpu(agents[1].pid)
            figures[name].append(_timed(fn, chunk))
            if name == "channel":
                agent_cpu[name] += channel.episode_info()["cpu"] - before
            elif name == "bc_channel":
                agent_cpu[name] += _process_cpu(agents[1].pid) - before
    load_after = os.getloadavg()[0]
    n_steps = len(figures["physics"]) * chunk
    channel.close()
    if bc:
        agents[1].close()
    reader.close()
    env.close()

    def med(name: str, which: int) -> float:
        return statistics.median(f[which] for f in figures[name]) * 1e6

    physics, physics_cpu = med("physics", 0), med("physics", 1)
    sim_cpu, hold_cpu = med("channel", 1), agent_cpu["channel"] / n_steps * 1e6
    rows = [f"| state-mode physics step (`env.step` of `opend run`'s scene, 8 substeps) | {physics:.0f} "
            f"| {physics_cpu:.0f} | | 1 |",
            f"| channel round trip (observation out, action back; an agent that answers at once) "
            f"| {med('channel', 0):.0f} | {sim_cpu:.0f} | {hold_cpu:.0f} | wall {med('channel', 0) / physics:.0%}, "
            f"simulator CPU {sim_cpu / physics_cpu:.0%}, both CPU {(sim_cpu + hold_cpu) / physics_cpu:.0%} |"]
    if bc:
        local, remote = med("bc_local", 0), med("bc_channel", 0)
        local_cpu, remote_cpu = med("bc_local", 1), med("bc_channel", 1) + agent_cpu["bc_channel"] / n_steps * 1e6
        rows += [f"| BC policy's `act` in this process (debugging, `--agent-in-process`) | {local:.0f} "
                 f"| {local_cpu:.0f} | | {local / physics:.2f}x |",
                 f"| BC policy's `act` across the channel (the default; CPU of both processes) | {remote:.0f} | "
                 f"{med('bc_channel', 1):.0f} | {remote_cpu - med('bc_channel', 1):.0f} | {remote / physics:.2f}x |",
                 f"| difference: the channel's cost for the BC policy | {remote - local:.0f} | "
                 f"{remote_cpu - local_cpu:.0f} (both) | | wall {(remote - local) / physics:.0%}, "
                 f"CPU {(remote_cpu - local_cpu) / physics_cpu:.0%} |"]
    return "\n".join([
        TITLE, "",
        f"`make bench-agents` (`python tools/bench_agent_channel.py`): {hand}, the first test target, "
        f"{len(figures['physics'])} interleaved chunks of {chunk} steps per contestant, medians of the chunks. "
        "An agent of `opend run --policy` runs in a process of its own; each step its observation (the hand's "
        "state, camera, instruction: about 0.5 kB) crosses a pipe as raw bytes and the action comes back. "
        "CPU: each process's own (the agent process's from its own clock, the BC process's from /proc at "
        "clock-tick resolution, over all chunks); on a loaded machine the wall figures add the time the agent "
        "process waits for a core. "
        f"Load average (1 min) before / after: {load_before:.2f} / {load_after:.2f} on {os.cpu_count()} cores.",
        "", "| per control step | wall µs | simulator process CPU µs | agent process CPU µs | / physics step |",
        "|---|---:|---:|---:|---|", *rows, ""])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cabinets", type=Path, default=ROOT / "cabinets")
    parser.add_argument("--hand", default="allegro")
    parser.add_argument("--steps", type=int, default=2000, help="steps per contestant")
    parser.add_argument("--chunk", type=int, default=100)
    parser.add_argument("--no-bc", dest="bc", action="store_false", help="skip the BC policy's figures")
    parser.add_argument("--write", type=Path, default=None, help="also write the section into this file")
    args = parser.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    text = section(args.cabinets, args.hand, args.steps, args.chunk, args.bc)
    print(text)
    if args.write is not None:
        write_section(args.write, TITLE, text)


if __name__ == "__main__":
    main()

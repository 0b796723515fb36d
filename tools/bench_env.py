"""Environment steps per second against what MuJoCo itself allows, in one run (`make bench-env`).

    python tools/bench_env.py [--cabinets cabinets] [--hand allegro] [--steps 1500] [--chunk 50]
                              [--image-steps 300] [--sizes 128,256] [--state-only]
                              [--layouts vec1,vec2,main2,...]

Made for a shared machine: every figure that is compared with another is measured in interleaved
chunks of ``--chunk`` steps in one run (a chunk of each contestant in turn, round after round), so
that all of them see the same load, and each is given both in wall-clock time and in CPU time
(``time.process_time`` of the process; the vector environments' workers report theirs), which
waiting for a core does not inflate. The load average is printed before and after.

Figures (`opend/OpenCabinet-v0`, random delta actions drawn before timing; a time limit longer than
the run, so that no reset falls inside a timed chunk):

- raw mj_step: ``mj_step(model, data, n)`` in one C call on a copy of the environment's own MjData
  as it is at that chunk (the same model and scene, hand where the environment left it, controls
  held); / substeps per control step = the ceiling in control steps/s.
- state: ``env.step`` of ``gym.make(...)`` (with gymnasium's order-enforcing and passive-checker
  wrappers) and of ``env.unwrapped``, in one process; their ratio to the ceiling. The default step
  is the compiled one (`opend_mj.sim.fast`) where it loads; the Python step (``compiled_step=False``,
  the same numbers) is timed beside it, in the same interleaved chunks.
- vector: `OpenDVectorEnv` (``gym.make_vec``'s default for these ids: shared memory) in the layouts
  of `LAYOUTS`: an environment per process (1 and 2 worker processes; 2 environments in 2
  processes with ``step_in_main=True``: environment 0 in the main process, 1 worker), and K
  environments per process (``envs_per_worker=K``: 2 in 1 worker; 4 as 2 workers x 2; 4 as the
  main process x 2 + 1 worker x 2; 8 as 2 workers x 4 and as main x 4 + 1 worker x 4), and
  gymnasium's ``AsyncVectorEnv`` with 2 (pickled dict observations and info). Wall: steps of all
  environments per second; CPU: the main process's CPU per vector step, a worker's CPU per step of
  one of its environments, steps per CPU second of all processes together, and the speed-up over
  one process that the layout would give if every process had a core of its own: N x (CPU per step
  in one process) / (the lock-step critical path: a worker's K steps + the main process's
  hand-over; with ``step_in_main`` the longer of the main process's steps-and-hand-over and a
  worker's steps). An estimate from CPU times: wake-up latencies are not in it.
- reference: two processes with an environment each stepping the same chunk at the same time with
  no hand-over between steps: what two processes give on this machine at this moment (shared
  caches and memory bandwidth, and other work on the cores, included), the bound for any lock-step
  vector environment of two processes.
- RGB-D at each image size: environment steps/s, the scene's own renderer alone (rgb + depth of
  the current state), and the ceiling of physics and rendering alone
  (1 / (1 / control-step ceiling + 1 / render rate)), interleaved in the same way.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import opend_mj.sim.gym_env  # noqa: E402,F401  (registers the ids)

ENV_ID = "opend/OpenCabinet-v0"
#: vector layouts: key -> (num_envs, envs_per_worker, step_in_main, label); "async2" is gymnasium's
LAYOUTS = {
    "vec1": (1, 1, False, "vector env, 1 worker process"),
    "vec2": (2, 1, False, "vector env, 2 worker processes"),
    "main2": (2, 1, True, "**vector env, 2 processes: `step_in_main=True` + 1 worker**"),
    "w1x2": (2, 2, False, "vector env, 2 environments in 1 worker (`envs_per_worker=2`)"),
    "w2x2": (4, 2, False, "vector env, 4 environments: 2 workers x 2 (`envs_per_worker=2`)"),
    "main2x2": (4, 2, True, "**vector env, 4 environments: main x 2 + 1 worker x 2** (`envs_per_worker=2, "
                            "step_in_main=True`)"),
    "w2x4": (8, 4, False, "vector env, 8 environments: 2 workers x 4 (`envs_per_worker=4`)"),
    "main4x4": (8, 4, True, "**vector env, 8 environments: main x 4 + 1 worker x 4** (`envs_per_worker=4, "
                            "step_in_main=True`)"),
    "async2": (2, 1, False, "gymnasium AsyncVectorEnv, 2 processes"),
}
_CLOCK_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


class Tally:
    """Steps, wall seconds and CPU seconds (this process / worker processes) of one contestant."""

    def __init__(self):
        self.steps = 0
        self.wall = self.cpu = self.worker_cpu = 0.0

    def add(self, steps: int, wall: float, cpu: float, worker_cpu: float = 0.0) -> None:
        self.steps += steps
        self.wall += wall
        self.cpu += cpu
        self.worker_cpu += worker_cpu

    @property
    def rate(self) -> float:
        return self.steps / self.wall

    @property
    def cpu_rate(self) -> float:
        return self.steps / self.cpu


def _timed(fn) -> tuple[float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - wall, time.process_time() - cpu


def _proc_cpu(pids) -> float | None:
    """CPU seconds (user + system) of processes from /proc (Linux; None elsewhere)."""
    try:
        total = 0
        for pid in pids:
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            total += int(fields[11]) + int(fields[12])
        return total / _CLOCK_TICKS
    except OSError:
        return None


class Single:
    """One environment in this process: env steps (wrapped and unwrapped) and raw mj_step chunks."""

    def __init__(self, base: dict, steps: int, obs_mode: str = "state", size: int = 256):
        self.env = gym.make(ENV_ID, obs_mode=obs_mode, image_size=size, **base)
        self.env.reset(seed=0)
        self.substeps = self.env.unwrapped.core.scene.task._substeps
        self.env.action_space.seed(0)
        self.actions = [self.env.action_space.sample() for _ in range(steps)]
        self.at = 0
        self.ended = 0

    def chunk(self, env, k: int, tally: Tally) -> None:
        actions = self.actions[self.at:self.at + k]
        self.at += k
        out = []

        def run():
            for a in actions:
                out.append(env.step(a))

        wall, cpu = _timed(run)
        tally.add(len(actions), wall, cpu)
        if any(o[2] or o[3] for o in out):  # an episode ended (should not within the time limit)
            self.ended += 1
            self.env.reset()

    def raw_chunk(self, k: int, tally: Tally) -> None:
        physics = self.env.unwrapped.core.scene.physics
        model = physics.model.ptr
        data = mujoco.MjData(model)
        mujoco.mj_copyData(data, model, physics.data.ptr)
        wall, cpu = _timed(lambda: mujoco.mj_step(model, data, k * self.substeps))
        tally.add(k, wall, cpu)  # counted in control steps

    def render_chunk(self, k: int, tally: Tally) -> None:
        scene = self.env.unwrapped.core.scene

        def run():
            for _ in range(k):
                scene.render()

        wall, cpu = _timed(run)
        tally.add(k, wall, cpu)

    def close(self) -> None:
        self.env.close()


class Vector:
    """A vector environment stepped in chunks, with its workers' CPU time."""

    def __init__(self, base: dict, steps: int, n: int, mode: str | None = None, **extra):
        kwargs = {"vectorization_mode": mode, "vector_kwargs": {"context": "spawn"}} if mode else extra
        # only the arguments that differ from the defaults: older OpenDVectorEnvs lack the newer ones
        kwargs = {k: v for k, v in kwargs.items() if (k, v) not in (("step_in_main", False), ("envs_per_worker", 1))}
        self.envs = gym.make_vec(ENV_ID, num_envs=n, obs_mode="state", **kwargs, **base)
        self.n = n
        self.envs.reset(seed=list(range(n)))
        self.envs.action_space.seed(0)
        self.actions = [self.envs.action_space.sample() for _ in range(steps)]
        self.at = 0

    def worker_cpu(self) -> float | None:
        envs = self.envs.unwrapped
        if hasattr(envs, "worker_cpu_seconds"):
            return sum(envs.worker_cpu_seconds())
        processes = getattr(envs, "processes", None) or getattr(envs, "_processes", [])
        return _proc_cpu([p.pid for p in processes])

    def chunk(self, k: int, tally: Tally) -> None:
        actions = self.actions[self.at:self.at + k]
        self.at += k
        before = self.worker_cpu()

        def run():
            for a in actions:
                self.envs.step(a)

        wall, cpu = _timed(run)
        after = self.worker_cpu()
        worker = after - before if before is not None and after is not None else float("nan")
        tally.add(len(actions) * self.n, wall, cpu, worker)

    def close(self) -> None:
        self.envs.close()


def _free_runner(base: dict, steps: int, connection) -> None:
    """A process with its own environment: runs ``k`` steps when told, answers (wall, CPU) seconds."""
    single = Single(base, steps)
    connection.send("ready")
    while True:
        k = connection.recv()
        if k is None:
            break
        tally = Tally()
        single.chunk(single.env, k, tally)
        connection.send((tally.wall, tally.cpu))
    single.close()


class FreePair:
    """Two processes with an environment each, stepping a chunk at the same time without any
    hand-over between steps: the most two processes can give on this machine at this moment (the
    reference for the vector environments' lock-step scaling)."""

    def __init__(self, base: dict, steps: int):
        import multiprocessing as mp

        context = mp.get_context("spawn")
        self.connections, self.processes = [], []
        for _ in range(2):
            here, there = context.Pipe()
            proc = context.Process(target=_free_runner, args=(base, steps, there), daemon=True)
            proc.start()
            self.connections.append(here)
            self.processes.append(proc)
        for c in self.connections:
            c.recv()

    def chunk(self, k: int, tally: Tally) -> None:
        start = time.perf_counter()
        for c in self.connections:
            c.send(k)
        answers = [c.recv() for c in self.connections]
        tally.add(2 * k, time.perf_counter() - start, 0.0, sum(cpu for _, cpu in answers))

    def close(self) -> None:
        for c, proc in zip(self.connections, self.processes):
            c.send(None)
            proc.join(timeout=10)


def state_and_vector(base: dict, steps: int, k: int, layouts=tuple(LAYOUTS)) -> dict:
    """Interleaved chunks: gym.make env (compiled and Python step), the unwrapped env, raw mj_step,
    the vector envs of ``layouts`` (keys of `LAYOUTS`) and two free processes (with any layout)."""
    single = Single(base, 2 * steps + 2 * k)
    python = Single({**base, "compiled_step": False}, steps + k)  # the same episode and actions
    vectors = {}
    for key in layouts:
        n, per_worker, in_main, _ = LAYOUTS[key]
        if key == "async2":
            vectors[key] = Vector(base, steps + k, n, mode="async")
            continue
        try:
            vectors[key] = Vector(base, steps + k, n, step_in_main=in_main, envs_per_worker=per_worker)
        except TypeError:  # an OpenDVectorEnv without step_in_main / envs_per_worker (older code)
            print(f"(layout {key} not supported by this code: skipped)", flush=True)
    if vectors:
        vectors["free2"] = FreePair(base, steps + k)
    tallies = {key: Tally() for key in ("env", "python", "unwrapped", "raw", *vectors)}
    try:
        single.chunk(single.env, k, Tally())  # warm-up
        python.chunk(python.env, k, Tally())
        for v in vectors.values():
            v.chunk(k, Tally())
        for _ in range(steps // k):
            single.chunk(single.env, k, tallies["env"])
            single.raw_chunk(k, tallies["raw"])
            python.chunk(python.env, k, tallies["python"])
            single.chunk(single.env.unwrapped, k, tallies["unwrapped"])
            for key, v in vectors.items():
                v.chunk(k, tallies[key])
    finally:
        single.close()
        python.close()
        for v in vectors.values():
            v.close()
    return {"tallies": tallies, "substeps": single.substeps, "ended": single.ended}


def image_figures(base: dict, steps: int, k: int, size: int) -> dict:
    single = Single(base, steps + k, obs_mode="rgbd", size=size)
    env, render, raw = Tally(), Tally(), Tally()
    try:
        single.chunk(single.env, k, Tally())
        for _ in range(steps // k):
            single.chunk(single.env, k, env)
            single.render_chunk(k, render)
            single.raw_chunk(k, raw)
    finally:
        single.close()
    return {"env": env, "render": render, "raw": raw}


def _row(label: str, value: str, against: str = "") -> str:
    return f"| {label} | {value} | {against} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cabinets", default="cabinets")
    parser.add_argument("--hand", default="allegro")
    parser.add_argument("--split", default="train")
    parser.add_argument("--steps", type=int, default=1500, help="timed state steps per contestant")
    parser.add_argument("--chunk", type=int, default=50, help="steps per chunk (contestants take turns)")
    parser.add_argument("--image-steps", type=int, default=300, help="RGB-D steps per image size")
    parser.add_argument("--sizes", default="128,256", help="RGB-D image sizes (square), comma-separated")
    parser.add_argument("--state-only", action="store_true", help="only the single-process state figures")
    parser.add_argument("--layouts", default=",".join(LAYOUTS),
                        help=f"vector layouts, comma-separated, of: {', '.join(LAYOUTS)}")
    args = parser.parse_args()
    from opend_mj.sim import fast

    step_kind = fast.status()
    # a time limit beyond the run: no reset inside a timed chunk (60 control steps per second)
    limit = (2 * args.steps + 4 * args.chunk) / 60.0 + 10.0
    base = {"cabinets": args.cabinets, "hand": args.hand, "split": args.split, "time_limit": limit}
    load = os.getloadavg()
    cpus = os.cpu_count()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {cpus} CPUs", flush=True)

    print(f"the environments' step: {step_kind}", flush=True)
    layouts = [] if args.state_only else [x for x in args.layouts.split(",") if x]
    unknown = [x for x in layouts if x not in LAYOUTS]
    if unknown:
        parser.error(f"unknown layouts {unknown}: choose from {', '.join(LAYOUTS)}")
    s = state_and_vector(base, args.steps, args.chunk, layouts)
    t, sub = s["tallies"], s["substeps"]
    raw, env, unwrapped, python = t["raw"], t["env"], t["unwrapped"], t["python"]
    ceiling, cpu_ceiling = raw.rate, raw.cpu_rate  # control steps (of `sub` mj_steps) per second
    us = 1e6
    for label, tally in (("state env", env), ("Python step", python)):
        print(f"{label}: {tally.rate:.0f} steps/s ({tally.rate / ceiling:.2f} of the ceiling {ceiling:.0f}; CPU time "
              f"{tally.cpu_rate / cpu_ceiling:.2f}, {(1 / tally.cpu_rate - 1 / cpu_ceiling) * us:.0f} us around "
              f"{us / cpu_ceiling:.0f} us of physics)", flush=True)
    images = []
    for size in (int(x) for x in args.sizes.split(",") if x) if not args.state_only else ():
        f = image_figures(base, args.image_steps, args.chunk, size)
        physics = f["raw"].rate
        both = 1.0 / (1.0 / physics + 1.0 / f["render"].rate)
        images.append((size, f, both))
        print(f"rgbd {size}: env {f['env'].rate:.0f} steps/s, renderer alone {f['render'].rate:.0f} frames/s, "
              f"physics + rendering ceiling {both:.0f}", flush=True)
    load_after = os.getloadavg()

    print(f"\n## Environment benchmark (`{ENV_ID}`, {args.hand}, {args.split} split, random delta actions, "
          f"60 Hz control, {sub} physics substeps)\n")
    print(f"(Load average {load[0]:.1f} when the run started and {load_after[0]:.1f} when it ended, on {cpus} CPUs: "
          "above about 1 other work shared the cores. Compared figures ran in interleaved chunks of "
          f"{args.chunk} steps, {args.steps} steps each; CPU figures do not count time spent waiting for a core.)\n")
    print("| figure | value | against |")
    print("|---|---:|---:|")
    print(_row(f"raw `mj_step`/s on the env's own model and state (CPU time: {raw.cpu_rate * sub:.0f})",
               f"{raw.rate * sub:.0f}"))
    print(_row(f"ceiling: control steps/s (raw / {sub}; CPU time: {cpu_ceiling:.0f})", f"{ceiling:.0f}"))
    print(_row(f"**state steps/s, 1 process** (`gym.make`; {step_kind})", f"**{env.rate:.0f}**",
               f"**{env.rate / ceiling:.2f} of the ceiling**"))
    print(_row("the same in CPU time of the process (steps per CPU second)", f"{env.cpu_rate:.0f}",
               f"{env.cpu_rate / cpu_ceiling:.2f} of the ceiling"))
    print(_row("state steps/s, `env.unwrapped` (no gymnasium wrappers; CPU time)",
               f"{unwrapped.rate:.0f} ({unwrapped.cpu_rate:.0f})",
               f"{unwrapped.rate / ceiling:.2f} ({unwrapped.cpu_rate / cpu_ceiling:.2f}) of the ceiling"))
    print(_row("Python around the physics per step (CPU time)", f"{(1 / env.cpu_rate - 1 / cpu_ceiling) * us:.0f} us",
               f"physics {us / cpu_ceiling:.0f} us"))
    print(_row("state steps/s, 1 process, the Python step (`compiled_step=False`; CPU time)",
               f"{python.rate:.0f} ({python.cpu_rate:.0f})",
               f"{python.rate / ceiling:.2f} ({python.cpu_rate / cpu_ceiling:.2f}) of the ceiling"))
    print(_row("&nbsp;&nbsp;its Python around the physics per step (CPU time)",
               f"{(1 / python.cpu_rate - 1 / cpu_ceiling) * us:.0f} us", f"physics {us / cpu_ceiling:.0f} us"))
    one_cpu = 1.0 / env.cpu_rate  # CPU seconds per step in one process
    if "free2" not in t:
        return
    free = t["free2"]
    print(_row("reference: 2 independent processes, an environment each, stepping at the same time "
               "(no hand-over; CPU per step)", f"{free.rate:.0f} ({free.worker_cpu / free.steps * us:.0f} us)",
               f"{free.rate / env.rate:.2f}x 1 process (CPU per step {free.worker_cpu / free.steps / one_cpu:.2f}x)"))
    for key in LAYOUTS:
        if key not in t:
            continue
        v = t[key]
        n, per_worker, in_main, label = LAYOUTS[key]
        workers = (n - per_worker if in_main else n) // per_worker
        main_cpu = v.cpu / (v.steps / n)  # per vector step (with step_in_main: its environments' steps too)
        worker = v.worker_cpu / (v.steps / n * workers)  # a worker's CPU per vector step (its K steps)
        all_cpu = v.steps / (v.cpu + v.worker_cpu)
        # lock-step critical path per vector step on a core per process: the main process's own work
        # (with step_in_main, its environments' steps and the hand-over) against the slowest worker
        critical = max(main_cpu, worker) if in_main else worker + main_cpu
        bold = "**" if label.startswith("**") else ""
        print(_row(f"state steps/s, {label}", f"{bold}{v.rate:.0f}{bold}",
                   f"{bold}{v.rate / env.rate:.2f}x 1 process{bold}"
                   + (f", {v.rate / t['vec1'].rate:.2f}x 1 worker" if n > 1 and "vec1" in t else "")))
        print(_row("&nbsp;&nbsp;CPU: main process per vector step / a worker per step of an environment / steps per "
                   "CPU second of all processes",
                   f"{main_cpu * us:.0f} us / {worker / per_worker * us:.0f} us / {all_cpu:.0f}",
                   f"{all_cpu * one_cpu:.2f} of 1 process's; a core each: {n * one_cpu / critical:.2f}x 1 process"))
    for size, f, both in images:
        print(_row(f"RGB-D {size}x{size} steps/s, 1 process", f"{f['env'].rate:.0f}",
                   f"{f['env'].rate / both:.2f} of physics + rendering ({both:.0f})"))
        print(_row(f"the scene's renderer alone, RGB-D {size}x{size} frames/s", f"{f['render'].rate:.0f}"))
    if s["ended"]:
        print(f"\n({s['ended']} chunks of the single environment ended an episode early and reset.)")


if __name__ == "__main__":
    main()

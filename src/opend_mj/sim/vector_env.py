"""A vector environment over the dataset whose workers write observations into shared memory.

``gym.make_vec("opend/OpenCabinet-v0", num_envs=N, cabinets=...)`` builds `OpenDVectorEnv`: worker
processes (``spawn``: a GL context does not survive ``fork``) running ``envs_per_worker`` `OpenDCore`
environments each (1 by default). Per step the main process writes the actions into a shared array
and writes one byte into each worker's command pipe; the worker steps its environments one after
the other, each writing its float observation vector (float32), images, reward, flags and the
numeric info into its row of the shared arrays, and answers with one byte on its answer pipe
(plain ``os.write`` / ``os.read`` of a byte: no message framing, no pickling, no Python object per
step). Only at an episode's start (its instruction, cabinet, target, room, seed), on a
physics warning and on an error does the answer byte say that a pickled message waits on the
worker's control connection. gymnasium's ``AsyncVectorEnv`` instead pickles every step's info dict
and merges it key by key in the main process (about four times the main process's CPU per step).

Semantics are gymnasium's defaults: ``reset(seed=s)`` seeds environment i with ``s + i`` (the
episode ``gym.make(...).reset(seed=s + i)`` gives); an environment whose episode ended is reset on
the next ``step`` (autoreset "next step"), which returns its first observation with reward 0.
Observations and the step's info arrays are fresh copies; the info's episode columns
(instruction, cabinet, target, ...) and its masks are read-only arrays shared between steps. Text
instructions (``instruction="text"``) cannot live in shared memory: use the one-hot code, or
``vectorization_mode="async"``.

``gym.make_vec(..., step_in_main=True)`` steps the first ``envs_per_worker`` environments in the
main process while the workers step the others (see `OpenDVectorEnv`).
`OpenDVectorEnv.worker_cpu_seconds` reports each worker's CPU time (for benchmarks).
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import pickle
import time
import traceback

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

#: Numeric info per step: floats and flags (each in a shared array of its dtype), and the reward
#: terms' fields split the same way.
_INFO_FLOATS, _INFO_FLAGS = ("open_ratio", "sim_time"), ("success", "others_moved")
_INFO_KEYS = ("success", "open_ratio", "others_moved", "sim_time")  # the info dict's order
_TERM_KEYS = ("distance", "start_distance", "contact", "open_ratio", "others_range", "success", "others_moved",
              "reach", "open", "others", "range_ratio")
_TERM_FLAGS = ("contact", "success", "others_moved")
_TERM_FLOATS = tuple(k for k in _TERM_KEYS if k not in _TERM_FLAGS)
#: (key, its mask's key, whether a flag, column) per info key and per reward term, in dict order
_INFO_PLAN = [(k, "_" + k, k in _INFO_FLAGS, (_INFO_FLAGS if k in _INFO_FLAGS else _INFO_FLOATS).index(k))
              for k in _INFO_KEYS]
_TERM_PLAN = [(k, "_" + k, k in _TERM_FLAGS, (_TERM_FLAGS if k in _TERM_FLAGS else _TERM_FLOATS).index(k))
              for k in _TERM_KEYS]
#: Strings and integers that change only when an episode starts (sent through the pipe then).
_EPISODE_KEYS = ("instruction", "cabinet", "target", "target_type", "room", "episode_seed")
#: Command bytes (main -> worker) and answer bytes (worker -> main).
_STEP, _RESET, _CPU, _CLOSE = b"s", b"r", b"t", b"c"
_DONE, _MESSAGE, _ERROR = b".", b"m", b"E"


def env_groups(num_envs: int, envs_per_worker: int, step_in_main: bool) -> tuple[range | None, list[range]]:
    """Which environments each process steps: (the main process's, or None; each worker's).
    Consecutive groups of ``envs_per_worker`` environments, the main process's first (with
    ``step_in_main``); the last group takes what is left when ``num_envs`` is not a multiple."""
    if num_envs < 1:
        raise ValueError(f"num_envs must be >= 1, not {num_envs}")
    if isinstance(envs_per_worker, bool) or not isinstance(envs_per_worker, int) or envs_per_worker < 1:
        raise ValueError(f"envs_per_worker must be an integer >= 1, not {envs_per_worker!r}")
    groups = [range(start, min(start + envs_per_worker, num_envs)) for start in range(0, num_envs, envs_per_worker)]
    return (groups[0], groups[1:]) if step_in_main else (None, groups)


def _span(group: range) -> str:
    return f"environment {group[0]}" if len(group) == 1 else f"environments {group[0]}-{group[-1]}"


class _Shared:
    """Shared arrays, (num_envs, ...) each: ``multiprocessing`` raw arrays (handed to spawned
    workers as process arguments, freed with the last process that holds them) viewed as numpy."""

    def __init__(self, specs: dict[str, tuple[tuple[int, ...], np.dtype]], context=None, raw: dict | None = None):
        self.specs = specs
        self.raw = raw if raw is not None else {
            key: context.RawArray("b", max(1, int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize))
            for key, (shape, dtype) in specs.items()}
        self.arrays = {key: np.frombuffer(self.raw[key], dtype=dtype, count=int(np.prod(shape, dtype=np.int64)))
                       .reshape(shape) for key, (shape, dtype) in specs.items()}

    def close(self) -> None:
        self.arrays.clear()


class _Runner:
    """One environment writing its results into row ``index`` of the shared arrays (in a worker
    process, or for ``step_in_main`` in the main process)."""

    def __init__(self, index: int, kwargs: dict, arrays: dict):
        from gymnasium.utils import seeding

        from opend_mj.sim.envs import OpenDCore, make_config

        self._seeding = seeding
        self.index = index
        self.core = OpenDCore(make_config(**kwargs))
        self.rng, _ = seeding.np_random(None)
        self.done = True
        a = arrays
        # this environment's rows of the shared arrays
        self.flat, self.actions = a["flat"][index], a["actions"][index]
        self.reward, self.terminated = a["reward"][index:index + 1], a["terminated"][index:index + 1]
        self.truncated = a["truncated"][index:index + 1]
        self.info_floats, self.info_flags = a["info_floats"][index], a["info_flags"][index]
        self.term_floats, self.term_flags = a["term_floats"][index], a["term_flags"][index]
        self.images = {key: a[key][index] for key in ("rgb", "depth") if key in a}

    def _write(self, images: dict, reward: float, terminated: bool, truncated: bool, info: dict) -> None:
        np.copyto(self.flat, self.core.flat, casting="same_kind")
        for key, image in images.items():
            self.images[key][...] = image
        self.reward[0], self.terminated[0], self.truncated[0] = reward, terminated, truncated
        self.info_floats[:] = [info[k] for k in _INFO_FLOATS]
        self.info_flags[:] = [info[k] for k in _INFO_FLAGS]
        terms = info["reward_terms"]
        self.term_floats[:] = [terms[k] for k in _TERM_FLOATS]
        self.term_flags[:] = [terms[k] for k in _TERM_FLAGS]

    def reset(self, seed, options) -> bytes:
        """Start an episode (seeded, or the next of this environment's seed sequence); returns the
        pickled episode message."""
        if seed is not None:
            self.rng, _ = self._seeding.np_random(int(seed))
            episode_seed = int(seed)
        else:
            episode_seed = int(self.rng.integers(2**31 - 1))
        obs, info = self.core.reset(episode_seed, options)
        self._write({k: obs[k] for k in ("rgb", "depth") if k in obs}, 0.0, False, False, info)
        self.done = False
        return pickle.dumps({k: info[k] for k in _EPISODE_KEYS})

    def step(self) -> bytes | None:
        """Step with the shared actions row (or reset an ended episode); None, or the pickled
        message (an episode start or physics warnings)."""
        if self.done:
            return self.reset(None, None)
        _, reward, terminated, truncated, info = self.core.step(self.actions, observe=False)
        self._write(self.core.images(), reward, terminated, truncated, info)
        self.done = terminated or truncated
        warnings = info.get("physics_warnings")
        return pickle.dumps({"physics_warnings": warnings}) if warnings else None

    def close(self) -> None:
        self.core.close()


@contextlib.contextmanager
def _in_environment(index: int):
    """An error raised inside names the environment it came from (a note on the exception)."""
    try:
        yield
    except Exception as error:
        error.add_note(f"(in environment {index})")
        raise


def _step_all(runners: list[_Runner]) -> bytes | None:
    """Step each runner in turn; None when none has a message, else the pickled list of their
    messages (None or bytes, one per runner)."""
    messages = None
    for k, runner in enumerate(runners):
        with _in_environment(runner.index):
            message = runner.step()
        if message is not None:
            if messages is None:
                messages = [None] * len(runners)
            messages[k] = message
    return None if messages is None else pickle.dumps(messages)


def _reset(runner: _Runner, seed, options) -> bytes:
    with _in_environment(runner.index):
        return runner.reset(seed, options)


def _worker(indices: range, kwargs: dict, specs: dict, raw: dict, commands, answers, control) -> None:
    """Environments ``indices`` in a worker process: each command byte steps them all in turn, and
    one answer byte says they are done."""
    shared = _Shared(specs, raw=raw)
    command_fd, answer_fd = commands.fileno(), answers.fileno()
    runners = []

    def answer(message: bytes | None = None) -> None:
        if message is None:
            os.write(answer_fd, _DONE)
        else:  # the message first: the main process reads it when the answer byte says so
            control.send_bytes(message)
            os.write(answer_fd, _MESSAGE)

    try:
        for index in indices:
            with _in_environment(index):
                runners.append(_Runner(index, kwargs, shared.arrays))
        answer()  # ready
        while True:
            command = os.read(command_fd, 1)
            if command == _STEP:
                answer(_step_all(runners))
            elif command == _RESET:
                resets = pickle.loads(control.recv_bytes())  # (seed, options) per environment
                answer(pickle.dumps([_reset(r, *args) for r, args in zip(runners, resets)]))
            elif command == _CPU:
                answer(pickle.dumps({"cpu_seconds": time.process_time()}))
            else:  # _CLOSE, or b"" when the main process is gone
                break
    except Exception:  # noqa: BLE001 (reported to the main process, which raises it)
        try:
            control.send_bytes(traceback.format_exc().encode())
            os.write(answer_fd, _ERROR)
        except (BrokenPipeError, OSError):
            pass
    finally:
        for runner in runners:
            runner.close()
        shared.close()
        for connection in (commands, answers, control):
            connection.close()


class OpenDVectorEnv(VectorEnv):
    """``num_envs`` environments over the dataset in worker processes with shared-memory results.

    Keyword arguments: those of ``gym.make("opend/OpenCabinet-v0", ...)`` (`EnvConfig`'s fields),
    and:

    - ``envs_per_worker`` (K, default 1): each worker process steps K consecutive environments in
      turn per hand-over (``ceil(num_envs / K)`` processes; the last takes what is left), so that
      one command byte and one answer byte serve K steps.
    - ``step_in_main``: True runs the first group (environments 0 to K - 1) in this process,
      between handing the step to the workers and collecting their answers: the main process steps
      environments instead of sleeping, and waits for one fewer answer. Where there are no more
      free cores than processes (e.g. 2 processes on 2 cores) this is the faster choice; where a
      learner in the main process needs its core, leave it False.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 2, step_in_main: bool = False, envs_per_worker: int = 1, **kwargs):
        from opend_mj.sim.envs import OpenDCore, make_config
        from opend_mj.sim.spaces import action_space, observation_space

        local, groups = env_groups(int(num_envs), envs_per_worker, step_in_main)
        if kwargs.get("instruction", "onehot") == "text":
            raise ValueError("text instructions cannot be shared-memory observations: use instruction='onehot' "
                             "or gym.make_vec(..., vectorization_mode='async')")
        if kwargs.get("lean_step") is False:
            raise ValueError("the shared-memory vector environment reads the lean step's observation vector: "
                             "lean_step=False is for single environments")
        core = OpenDCore(make_config(**kwargs))  # spaces and layout, in this process (builds no scene)
        try:
            self.single_observation_space = observation_space(core)
            self.single_action_space = action_space(core)
            layout = core.flat_layout()
            flat_size = core.flat_size
            images = {k: self.single_observation_space[k] for k in ("rgb", "depth")
                      if k in self.single_observation_space.spaces}
        finally:
            core.close()
        self.num_envs = n = int(num_envs)
        self.observation_space = batch_space(self.single_observation_space, n)
        self.action_space = batch_space(self.single_action_space, n)
        floats = {key: (sl, shape) for key, sl, shape in layout}
        #: (key, columns of the float vector, batched shape or None where the columns are it)
        self._obs_plan = [(key, floats[key][0], None if len(floats[key][1]) == 1 else (n, *floats[key][1]))
                          if key in floats else (key, None, None) for key in self.single_observation_space.spaces]
        specs = {"flat": ((n, flat_size), np.float32), "actions": ((n, *self.single_action_space.shape), np.float64),
                 "reward": ((n,), np.float64), "terminated": ((n,), np.bool_), "truncated": ((n,), np.bool_),
                 "info_floats": ((n, len(_INFO_FLOATS)), np.float64), "info_flags": ((n, len(_INFO_FLAGS)), np.bool_),
                 "term_floats": ((n, len(_TERM_FLOATS)), np.float64), "term_flags": ((n, len(_TERM_FLAGS)), np.bool_)}
        for key, space in images.items():
            specs[key] = ((n, *space.shape), space.dtype)
        context = mp.get_context("spawn")
        self._shared = _Shared(specs, context)
        self._arrays = self._shared.arrays
        self._episode = [dict.fromkeys(_EPISODE_KEYS) for _ in range(n)]
        self._episode_columns: dict | None = None
        self._all = np.ones(n, dtype=bool)  # the info masks: every environment reports every key
        self._all.flags.writeable = False
        self._closed_workers = False
        self._controls, self._processes, self._command_fds, self._answer_fds, self._ends = [], [], [], [], []
        self._local: list[_Runner] = []
        #: the environments of this process (``step_in_main``) and of each worker
        self._local_group, self._groups = local or range(0), groups
        try:
            for i, group in enumerate(groups):
                command_r, command_w = context.Pipe(duplex=False)
                answer_r, answer_w = context.Pipe(duplex=False)
                control, child_control = context.Pipe()
                proc = context.Process(target=_worker, name=f"opend-vector-{i}", daemon=True,
                                       args=(group, dict(kwargs), specs, self._shared.raw, command_r, answer_w,
                                             child_control))
                proc.start()
                for child_end in (command_r, answer_w, child_control):
                    child_end.close()
                self._ends += [command_w, answer_r]
                self._command_fds.append(command_w.fileno())
                self._answer_fds.append(answer_r.fileno())
                self._controls.append(control)
                self._processes.append(proc)
            for i in self._local_group:
                self._local.append(_Runner(i, dict(kwargs), self._arrays))
            for j in range(len(self._processes)):
                self._answer(j)
        except BaseException:
            self.close_extras()
            raise

    # ------------------------------------------------------------------ plumbing
    def _answer(self, j: int) -> bytes | None:
        """Worker j's answer: None for a plain step, else its message (raises on a worker's error)."""
        try:
            byte = os.read(self._answer_fds[j], 1)
        except OSError:
            byte = b""
        if byte == _DONE:
            return None
        if byte == _MESSAGE:
            return self._controls[j].recv_bytes()
        where = f"worker {j} ({_span(self._groups[j])}) of the vector environment"
        if byte == _ERROR:
            raise RuntimeError(f"{where} failed:\n{self._controls[j].recv_bytes().decode()}")
        raise RuntimeError(f"{where} died")

    def _apply(self, i: int, message: bytes | None, warnings: dict[int, list]) -> None:
        """Apply environment i's message (an episode start or physics warnings, into ``warnings``)."""
        if message is None:
            return
        data = pickle.loads(message)
        if "physics_warnings" in data:
            warnings[i] = data["physics_warnings"]
            return
        self._episode[i] = data
        self._episode_columns = None

    def _apply_worker(self, j: int, answer: bytes | None, warnings: dict[int, list]) -> None:
        """Apply worker j's answer: None, or the pickled list of its environments' messages."""
        if answer is not None:
            for i, message in zip(self._groups[j], pickle.loads(answer)):
                self._apply(i, message, warnings)

    def _observations(self) -> dict:
        a = self._arrays
        flat = a["flat"].copy()
        obs = {}
        for key, columns, shape in self._obs_plan:
            if columns is None:
                obs[key] = a[key].copy()
            elif shape is None:
                obs[key] = flat[:, columns]
            else:
                obs[key] = flat[:, columns].reshape(shape)
        return obs

    def _infos(self, warnings: dict[int, list]) -> dict:
        a, n = self._arrays, self.num_envs
        mask = self._all  # read-only, the same array every step
        # one copy per shared array, transposed: each key is then a contiguous row of it
        columns = ((a["info_floats"].T.copy(), a["info_flags"].T.copy()),
                   (a["term_floats"].T.copy(), a["term_flags"].T.copy()))
        info, terms = {}, {}
        for out, plan, (floats, flags) in ((info, _INFO_PLAN, columns[0]), (terms, _TERM_PLAN, columns[1])):
            for key, mask_key, flag, j in plan:
                out[key], out[mask_key] = (flags if flag else floats)[j], mask
        info["reward_terms"], info["_reward_terms"] = terms, mask
        if self._episode_columns is None:  # an episode started: its strings and integers as columns
            self._episode_columns = {}
            for key in _EPISODE_KEYS:
                column = np.array([e[key] for e in self._episode],
                                  dtype=np.int64 if key in ("room", "episode_seed") else object)
                column.flags.writeable = False  # handed out until the next episode starts
                self._episode_columns[key] = column
        for key, column in self._episode_columns.items():
            info[key], info["_" + key] = column, mask
        if warnings:
            column = np.empty(n, dtype=object)
            for i, w in warnings.items():
                column[i] = w
            info["physics_warnings"] = column
            info["_physics_warnings"] = np.array([i in warnings for i in range(n)])
        return info

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        if seed is None or isinstance(seed, int):
            seeds = [None if seed is None else seed + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"{len(seeds)} seeds for {self.num_envs} environments")
        for j, group in enumerate(self._groups):
            self._controls[j].send_bytes(pickle.dumps([(seeds[i], options) for i in group]))
            os.write(self._command_fds[j], _RESET)
        unused: dict[int, list] = {}
        for i, runner in zip(self._local_group, self._local):
            self._apply(i, runner.reset(seeds[i], options), unused)
        for j in range(len(self._processes)):
            self._apply_worker(j, self._answer(j), unused)
        return self._observations(), self._infos({})

    def step(self, actions):
        a = self._arrays
        target = a["actions"]
        actions = np.asarray(actions)
        target[...] = actions if actions.shape == target.shape else actions.reshape(target.shape)
        for fd in self._command_fds:
            os.write(fd, _STEP)
        warnings: dict[int, list] = {}
        for i, runner in zip(self._local_group, self._local):  # stepped here while the workers step theirs
            self._apply(i, runner.step(), warnings)
        for j in range(len(self._processes)):
            self._apply_worker(j, self._answer(j), warnings)
        return (self._observations(), a["reward"].copy(), a["terminated"].copy(), a["truncated"].copy(),
                self._infos(warnings))

    def worker_cpu_seconds(self) -> list[float]:
        """CPU seconds (user + system) each worker process has used so far (not this process's:
        with ``step_in_main`` the first group's steps are in ``time.process_time()`` here)."""
        for fd in self._command_fds:
            os.write(fd, _CPU)
        return [pickle.loads(self._answer(j))["cpu_seconds"] for j in range(len(self._processes))]

    def close_extras(self, **kwargs) -> None:
        if self._closed_workers:
            return
        self._closed_workers = True
        for fd, proc in zip(self._command_fds, self._processes):
            try:
                if proc.is_alive():
                    os.write(fd, _CLOSE)
            except OSError:
                pass
        for proc in self._processes:
            proc.join(timeout=10)
            if proc.is_alive():
                proc.terminate()
        for connection in self._ends + self._controls:
            connection.close()
        for runner in self._local:
            runner.close()
        self._local = []
        self._shared.close()

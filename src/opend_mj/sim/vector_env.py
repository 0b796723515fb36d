"""A vector environment over the dataset whose workers write observations into shared memory.

``gym.make_vec("opend/OpenCabinet-v0", num_envs=N, cabinets=...)`` builds `OpenDVectorEnv`: one
worker process per environment (``spawn``: a GL context does not survive ``fork``), each running an
`OpenDCore`. Per step the main process writes the actions into a shared array and sends each worker
one byte; the worker steps, writes its float observation vector (float32), images, reward, flags
and the numeric info into shared arrays, and answers with an empty message. Nothing is pickled per
step: only at an episode's start (its instruction, cabinet, target, room, seed) and on a physics
warning. gymnasium's ``AsyncVectorEnv`` instead pickles every step's info dict and merges it key by
key in the main process, which made two processes slower than one.

Semantics are gymnasium's defaults: ``reset(seed=s)`` seeds environment i with ``s + i`` (the
episode ``gym.make(...).reset(seed=s + i)`` gives); an environment whose episode ended is reset on
the next ``step`` (autoreset "next step"), which returns its first observation with reward 0.
Observations are fresh copies. Text instructions (``instruction="text"``) cannot live in shared
memory: use the one-hot code, or ``vectorization_mode="async"``.
"""

from __future__ import annotations

import multiprocessing as mp
import pickle
import traceback

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

#: Numeric info per step (float64 in shared memory) and the reward terms' fields.
_INFO_KEYS = ("success", "open_ratio", "others_moved", "sim_time")
_TERM_KEYS = ("distance", "start_distance", "contact", "open_ratio", "others_range", "success", "others_moved",
              "reach", "open", "others", "range_ratio")
_BOOL_KEYS = {"success", "others_moved", "contact"}
#: Strings and integers that change only when an episode starts (sent through the pipe then).
_EPISODE_KEYS = ("instruction", "cabinet", "target", "target_type", "room", "episode_seed")
_STEP, _RESET, _CLOSE = b"s", b"r", b"c"


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


def _worker(index: int, kwargs: dict, specs: dict, raw: dict, pipe) -> None:
    """One environment: steps on a one-byte command, writes its results into row ``index``."""
    from gymnasium.utils import seeding

    from opend_mj.sim.envs import OpenDCore, make_config

    shared = _Shared(specs, raw=raw)
    a = shared.arrays
    try:
        core = OpenDCore(make_config(**kwargs))
        rng, _ = seeding.np_random(None)
        done = True

        def write(obs_images: dict, reward: float, terminated: bool, truncated: bool, info: dict) -> None:
            np.copyto(a["flat"][index], core.flat, casting="same_kind")
            for key, image in obs_images.items():
                a[key][index] = image
            a["reward"][index] = reward
            a["terminated"][index] = terminated
            a["truncated"][index] = truncated
            a["info"][index] = [float(info[k]) for k in _INFO_KEYS]
            terms = info["reward_terms"]
            a["terms"][index] = [float(terms[k]) for k in _TERM_KEYS]

        def reset(seed, options) -> bytes:
            nonlocal rng, done
            if seed is not None:
                rng, _ = seeding.np_random(int(seed))
                episode_seed = int(seed)
            else:
                episode_seed = int(rng.integers(2**31 - 1))
            obs, info = core.reset(episode_seed, options)
            write({k: obs[k] for k in ("rgb", "depth") if k in obs}, 0.0, False, False, info)
            done = False
            return pickle.dumps({k: info[k] for k in _EPISODE_KEYS})

        pipe.send_bytes(b"ok")
        while True:
            message = pipe.recv_bytes()
            command = message[:1]
            if command == _STEP:
                if done:
                    pipe.send_bytes(reset(None, None))
                    continue
                _, reward, terminated, truncated, info = core.step(a["actions"][index], observe=False)
                write(core.images(), reward, terminated, truncated, info)
                done = terminated or truncated
                warnings = info.get("physics_warnings")
                pipe.send_bytes(pickle.dumps({"physics_warnings": warnings}) if warnings else b"")
            elif command == _RESET:
                seed, options = pickle.loads(message[1:])
                pipe.send_bytes(reset(seed, options))
            elif command == _CLOSE:
                break
    except Exception:  # noqa: BLE001 (reported to the main process, which raises it)
        try:
            pipe.send_bytes(b"E" + traceback.format_exc().encode())
        except (BrokenPipeError, OSError):
            pass
    finally:
        if "core" in locals():
            core.close()
        shared.close()
        pipe.close()


class OpenDVectorEnv(VectorEnv):
    """``num_envs`` environments over the dataset in worker processes with shared-memory results.

    Keyword arguments: those of ``gym.make("opend/OpenCabinet-v0", ...)`` (`EnvConfig`'s fields).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 2, **kwargs):
        from opend_mj.sim.envs import OpenDCore, make_config
        from opend_mj.sim.spaces import action_space, observation_space

        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, not {num_envs}")
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
        self.num_envs = int(num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._layout = layout
        n = self.num_envs
        specs = {"flat": ((n, flat_size), np.float32), "actions": ((n, *self.single_action_space.shape), np.float64),
                 "reward": ((n,), np.float64), "terminated": ((n,), np.bool_), "truncated": ((n,), np.bool_),
                 "info": ((n, len(_INFO_KEYS)), np.float64), "terms": ((n, len(_TERM_KEYS)), np.float64)}
        for key, space in images.items():
            specs[key] = ((n, *space.shape), space.dtype)
        self._images = tuple(images)
        context = mp.get_context("spawn")
        self._shared = _Shared(specs, context)
        self._episode = [dict.fromkeys(_EPISODE_KEYS) for _ in range(n)]
        self._closed_workers = False
        self._pipes, self._processes = [], []
        try:
            for i in range(n):
                parent, child = context.Pipe()
                proc = context.Process(target=_worker, args=(i, dict(kwargs), specs, self._shared.raw, child),
                                       name=f"opend-vector-{i}", daemon=True)
                proc.start()
                child.close()
                self._pipes.append(parent)
                self._processes.append(proc)
            for i in range(n):
                self._receive(i)
        except BaseException:
            self.close_extras()
            raise

    # ------------------------------------------------------------------ plumbing
    def _receive(self, i: int) -> bytes:
        try:
            message = self._pipes[i].recv_bytes()
        except EOFError:
            raise RuntimeError(f"worker {i} of the vector environment died") from None
        if message[:1] == b"E":
            raise RuntimeError(f"worker {i} of the vector environment failed:\n{message[1:].decode()}")
        return message

    def _episode_message(self, i: int, message: bytes) -> list | None:
        """Apply a worker's message (episode start or physics warnings); return the warnings."""
        if not message or message == b"ok":
            return None
        data = pickle.loads(message)
        if "physics_warnings" in data:
            return data["physics_warnings"]
        self._episode[i] = data
        return None

    def _observations(self) -> dict:
        a = self._shared.arrays
        flat = a["flat"].copy()
        n = self.num_envs
        obs = {key: flat[:, sl].reshape(n, *shape) for key, sl, shape in self._layout}
        for key in self._images:
            obs[key] = a[key].copy()
        return {key: obs[key] for key in self.single_observation_space.spaces}

    def _infos(self, warnings: dict[int, list]) -> dict:
        a, n = self._shared.arrays, self.num_envs
        mask = np.ones(n, dtype=bool)
        info = {}
        values = a["info"].copy()
        for j, key in enumerate(_INFO_KEYS):
            info[key] = values[:, j].astype(bool) if key in _BOOL_KEYS else values[:, j]
            info[f"_{key}"] = mask
        terms = a["terms"].copy()
        info["reward_terms"] = {}
        for j, key in enumerate(_TERM_KEYS):
            info["reward_terms"][key] = terms[:, j].astype(bool) if key in _BOOL_KEYS else terms[:, j]
            info["reward_terms"][f"_{key}"] = mask
        info["_reward_terms"] = mask
        for key in _EPISODE_KEYS:
            column = np.array([e[key] for e in self._episode], dtype=object if key not in ("room", "episode_seed")
                              else np.int64)
            info[key], info[f"_{key}"] = column, mask
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
        for i, s in enumerate(seeds):
            self._pipes[i].send_bytes(_RESET + pickle.dumps((s, options)))
        for i in range(self.num_envs):
            self._episode_message(i, self._receive(i))
        return self._observations(), self._infos({})

    def step(self, actions):
        a = self._shared.arrays
        a["actions"][:] = np.asarray(actions, dtype=np.float64).reshape(a["actions"].shape)
        for pipe in self._pipes:
            pipe.send_bytes(_STEP)
        warnings = {}
        for i in range(self.num_envs):
            w = self._episode_message(i, self._receive(i))
            if w:
                warnings[i] = w
        return (self._observations(), a["reward"].copy(), a["terminated"].copy(), a["truncated"].copy(),
                self._infos(warnings))

    def close_extras(self, **kwargs) -> None:
        if self._closed_workers:
            return
        self._closed_workers = True
        for pipe, proc in zip(self._pipes, self._processes):
            try:
                if proc.is_alive():
                    pipe.send_bytes(_CLOSE)
            except (BrokenPipeError, OSError):
                pass
        for pipe, proc in zip(self._pipes, self._processes):
            proc.join(timeout=10)
            if proc.is_alive():
                proc.terminate()
            pipe.close()
        self._shared.close()

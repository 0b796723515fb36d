"""The behaviour-cloning agent: `opend run --policy bc` (a checkpoint of `opend train-policy`).

On the first step a shipped handle solver (``fasterrcnn`` by default, or ``cliport``) finds the
instructed handle in the RGB-D image, and the planner's perception back-projects it
(`policy.learned.bc_model.perceive_handle`); from then on, every control step, the transformer reads that
handle, the instruction, the hand's own state and, for a checkpoint that watches (``watch``), the
instructed front as the latest depth image shows it (`policy.perception.watch`: a new image every
``watch`` control steps, ``image_every``) (`policy.learned.bc_model`) and predicts the next
``chunk`` actions; the action sent blends every prediction made for this step, oldest weighted most
(ACT's temporal ensemble, weight ``exp(-ensemble_decay * i)`` for the i-th oldest). Several
checkpoints (``checkpoint=a.pt,b.pt,c.pt``, or one bundle file of `opend bundle-policy`) form a seed
ensemble: every step, each model predicts its chunk from the same inputs and the agent averages
them before the temporal blend (models trained from different seeds err differently; their mean
errs less). A target kind may have its own members: ``drawer=`` / ``door=`` checkpoints, or a
bundle's routes (`opend bundle-policy --route`), chosen by the kind the instruction names (the
instruction is the agent's input; `language.target_kind`). The agent stops
(returns None) where the solver finds no handle, and at ``stop_time`` (default: the checkpoint's,
the time by which 95 % of its training demonstrations had ended, holding the opened part; the
protocol's 15 s limit applies in any case).

Ground truth is never read: the observation is the protocol's (`opend_mj.policy.agents`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from opend_mj import resources
from opend_mj.policy.learned.bc_model import (STEP_KEYS, WATCH_KEY, checkpoint_paths, context_features,
                                              decode_action, load_policies, step_actions, step_features)
from opend_mj.policy.perception.watch import FrontWatcher, WatchConfig


def default_checkpoint(hand: str) -> Path:
    """``checkpoints/bc_<hand>.pt`` here, else the shipped one (`opend_mj.resources`)."""
    return resources.default_checkpoint(f"bc_{hand}.pt")


class BCAgent:
    """A behaviour-cloning policy behind the agent interface (`opend_mj.policy.agents`).

    ``checkpoint``: a file of `opend train-policy` or `opend bundle-policy` (default
    ``checkpoints/bc_<hand>.pt``), or several separated by commas: their predictions are averaged;
    ``solver``: the handle solver that reads the first image (never one that needs ground truth);
    ``threads``: torch CPU threads (1 keeps parallel episodes from competing); ``stop_time``: s of
    simulated time after which the agent stops (default: the checkpoint's ``stop_time``);
    ``ensemble_decay``: the temporal ensemble's weight decay (default: the checkpoint's; negative
    values weight the newest predictions most); ``drawer`` / ``door``: the checkpoints (same
    form as ``checkpoint``) that act on that kind of target instead. Over several checkpoints, the
    defaults of ``stop_time`` and ``ensemble_decay`` are the mean of theirs. The checkpoints named
    here are loaded when the agent is made (read as plain data, `checkpoint_io.read_checkpoint`), so
    that one missing or refused stops `opend run` before its first episode."""

    control = "absolute"
    #: RGB-D every ``image_every`` steps: the front watched (set at reset from the checkpoint's ``watch``)
    images = "every_step"

    def __init__(self, checkpoint: str | None = None, solver: str = "fasterrcnn", threads: int = 1,
                 name: str | None = None, stop_time: float | None = None, ensemble_decay: float | None = None,
                 drawer: str | None = None, door: str | None = None, **solver_options):
        from opend_mj.policy.factory import agent_solver

        self._factory = agent_solver(solver, **solver_options)
        self._solver_name = solver
        self._solver = None
        self.checkpoint = checkpoint
        self.kind_checkpoints = {"drawer": drawer, "door": door}
        self.threads = int(threads)
        self.stop_time = stop_time
        self.ensemble_decay = ensemble_decay
        self.name = name or f"bc-{solver}"
        self._episode = None
        self.image_every = WatchConfig().every
        self.watcher = None
        self.last_watch = None  # the watched front's numbers of the latest step (`perception.watch`)
        for spec in (checkpoint, drawer, door):  # cached: reset() finds them loaded
            if spec:
                load_policies(checkpoint_paths(spec))

    @property
    def solver(self):
        if self._solver is None:
            self._solver = self._factory()
        return self._solver

    def reset(self, episode) -> None:
        import torch

        from opend_mj.language import InstructionNotUnderstood, target_kind

        torch.set_num_threads(self.threads)
        try:
            kind = target_kind(episode.instruction)
        except InstructionNotUnderstood:
            kind = None  # every member acts
        spec = self.kind_checkpoints.get(kind) or self.checkpoint
        paths = checkpoint_paths(spec) if spec else [default_checkpoint(episode.hand)]
        members = load_policies(paths, kind=kind)
        self.models = [m for m, _, _ in members]
        _, self.config, ckpt = members[0]
        if ckpt.get("hand") not in (None, episode.hand):
            raise ValueError(f"{paths[0]}: trained for the {ckpt['hand']} hand, not {episode.hand}")
        self._low, self._high = np.asarray(ckpt["finger_low"]), np.asarray(ckpt["finger_high"])
        from opend_mj.language import instruction_onehot

        # the percept numbers each checkpoint was trained with (older ones: the first 22 of today's)
        codes = len(instruction_onehot(episode.instruction))
        self._percept_dims = [int(k["dims"]["ctx"]) - codes for _, _, k in members]
        default = np.mean([k.get("stop_time", k.get("max_time", episode.time_limit)) for _, _, k in members])
        self._max_time = float(self.stop_time if self.stop_time is not None else default)
        self._decay = float(self.ensemble_decay if self.ensemble_decay is not None
                            else np.mean([c.ensemble_decay for _, c, _ in members]))
        self._watch = WatchConfig(every=self.config.watch) if self.config.watch else None
        # a blind checkpoint gets the images it ignores at the default rate, as one that watches
        self.image_every = self._watch.every if self._watch else WatchConfig().every
        self.watcher = None
        self.last_watch = None
        self._episode = episode
        self._ctx = None  # one context per member
        self._centre = None
        self._steps: list[np.ndarray] = []
        self._preds: list[np.ndarray] = []  # prediction made at step i (chunk, A), kept while it covers a step
        self.percept = None
        self.stopped = None

    def act(self, obs: dict) -> np.ndarray | None:
        import torch

        if self._ctx is None:
            if self.stopped:
                return None
            from opend_mj.policy.learned.bc_model import perceive_handle

            self.percept = perceive_handle(self.solver, obs["rgb"], obs["depth"], obs["instruction"],
                                           self._episode.camera_view)
            if self.percept is None:
                self.stopped = "locate"
                return None
            vec = self.percept.vector()
            self._centre = vec[:3]
            self._ctx = [torch.from_numpy(context_features(vec[:n], obs["instruction"]))[None]
                         for n in self._percept_dims]
            if self._watch is not None:
                self.watcher = FrontWatcher.from_percept(obs["depth"], self._episode.camera_view, self.percept,
                                                         self._watch)
        elif self.watcher is not None and obs.get("depth") is not None:
            self.watcher.look(obs["depth"], obs["grasp_site_pos"], float(obs["time"][0]))
        if float(obs["time"][0]) >= self._max_time:
            self.stopped = "done"
            return None
        one = {k: np.asarray(obs[k], float)[None] for k in STEP_KEYS}
        if self.watcher is not None:
            self.last_watch = self.watcher.vector(obs["grasp_site_pos"], float(obs["time"][0]))
            one[WATCH_KEY] = self.last_watch[None]
        self._steps.append(step_features(one, self._centre, watch=self.watcher is not None)[0])
        t = len(self._steps) - 1
        rows = [max(t - lag, 0) for lag in self.config.lags]
        steps = torch.from_numpy(np.stack([self._steps[r] for r in rows]))[None]
        chunk = np.mean([step_actions(m, c, steps)[0].numpy() for m, c in zip(self.models, self._ctx)], axis=0)
        self._preds.append(chunk)
        k = self.config.chunk
        first = max(0, t - k + 1)
        covering = [self._preds[i][t - i] for i in range(first, t + 1)]  # oldest first
        w = np.exp(-self._decay * np.arange(len(covering)))
        blended = (np.asarray(covering) * w[:, None]).sum(axis=0) / w.sum()
        for i in range(first):  # predictions no longer covering any step
            self._preds[i] = None
        return decode_action(blended, self._centre, self._low, self._high)

    def episode_info(self) -> dict:
        """Extra fields for the episode's record: the located box and why the agent stopped."""
        box = self.percept.box.as_tuple() if self.percept is not None else None
        return {"box": [round(float(x), 2) for x in box] if box else None, "agent_stop": self.stopped,
                "handle_kind": self.percept.handle.kind if self.percept is not None else None}


__all__ = ["BCAgent", "default_checkpoint"]

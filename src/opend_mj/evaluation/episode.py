"""What an episode is: its job description and the one list of fields that identifies it.

`EPISODE_FIELDS` is the single definition: the results-file key (`episode_key`, what resume skips),
the fields a record starts with (`record_fields`), the key of episodes that can share one compiled
scene (`scene_key`) and the video file name (`video_name`) are all derived from it.
"""

from __future__ import annotations

import zlib
from dataclasses import asdict, dataclass
from typing import Any, Callable

_REQUIRED = object()


def _rounded(decimals: int) -> Callable[[Any], float | None]:
    return lambda v: None if v is None else round(float(v), decimals)


@dataclass(frozen=True)
class EpisodeField:
    """One field of an episode's identity."""

    name: str
    default: Any = _REQUIRED
    #: Canonical form in the key (so 1 and 1.0000001 light scales compare as one episode).
    normalise: Callable[[Any], Any] = str
    #: Part of `episode_key` (split is a label of the cabinet, not of the episode).
    in_key: bool = True
    #: Episodes that differ in it need a scene of their own.
    in_scene: bool = False
    #: Written in every record; else only when it differs from its default.
    always: bool = True
    #: Its part of the video file name (None: not in the name).
    tag: Callable[[Any], str] | None = str

    def value(self, record: dict) -> Any:
        return record[self.name] if self.default is _REQUIRED else record.get(self.name, self.default)

    def shown(self, value: Any) -> bool:
        return self.always or value != self.default


EPISODE_FIELDS: tuple[EpisodeField, ...] = (
    EpisodeField("cabinet"),
    EpisodeField("joint"),
    EpisodeField("hand", in_scene=True),
    EpisodeField("solver"),
    EpisodeField("split", in_key=False, tag=None),
    EpisodeField("seed", 0, int, in_scene=True, tag=lambda v: f"s{v}"),
    EpisodeField("light_scale", 1.0, _rounded(6), in_scene=True, tag=lambda v: f"l{v:g}"),
    EpisodeField("pull", "arc"),
    EpisodeField("paraphrase", 0, int, always=False, tag=lambda v: f"p{v}"),
    #: The user's own wording of the instruction (`opend run --instruction-file`); None: the template's.
    EpisodeField("phrasing", None, always=False, tag=lambda v: f"i{zlib.crc32(str(v).encode()):08x}"),
    EpisodeField("physics_timestep", None, _rounded(9), in_scene=True, always=False, tag=lambda v: f"dt{v:.6g}"),
    EpisodeField("policy", None, in_key=False, always=False, tag=None),
    #: A perturbation (`opend run --perturb`, `sim.perturb`): canonical ``AXIS=LEVEL[,...]``; None: nominal.
    EpisodeField("perturb", None, in_scene=True, always=False,
                 tag=lambda v: "x" + str(v).replace("=", "-").replace(",", "+")),
)
#: Fields that depend on the machine and the clock, not on the episode (left out when comparing runs).
WALL_CLOCK_FIELDS = ("wall_seconds",)


@dataclass(frozen=True)
class EpisodeJob:
    cabinet: str
    cabinet_dir: str
    joint: str
    split: str
    hand: str
    solver: str
    seed: int = 0
    light_scale: float = 1.0
    pull: str = "arc"
    video_dir: str | None = None
    room: int | None = None
    #: ((field, value), ...) for grasp search / experiments: ``PlannerConfig.override`` keys
    #: ("pull", "grasp.close_scale", ...)
    planner_overrides: tuple = ()
    use_grasp_file: bool = True
    #: From the manifest, so that even an episode that could not run is scored in its column.
    target_type: str | None = None
    instruction: str | None = None
    #: 0: the Algorithm 1 instruction; k > 0: the k-th paraphrase template (language.PARAPHRASES)
    paraphrase: int = 0
    #: The instruction in the user's words (`opend run --instruction-file`); None: Algorithm 1's
    #: (or the ``paraphrase`` template's). Read by the same parser as every instruction.
    phrasing: str | None = None
    #: Physics timestep in seconds; None: TaskConfig's default.
    physics_timestep: float | None = None
    #: An agent acts instead of the planner (`opend run --policy`): its spec and constructor
    #: arguments ((key, value), ...). Not part of the key: the agent's name is the ``solver``.
    policy: str | None = None
    policy_args: tuple = ()
    #: How the agent runs (`evaluation.agent_process`): "process" (its own, apart from the simulator)
    #: or "in-process" (`opend run --agent-in-process`, for debugging); its address-space limit in
    #: bytes (None: none); the sha256 of its source file (None: computed where the record is made).
    agent_isolation: str = "process"
    agent_memory: int | None = None
    agent_sha256: str | None = None
    #: A perturbation (`sim.perturb`, canonical ``AXIS=LEVEL[,AXIS=LEVEL]``), drawn from the scene's
    #: seed; None: the nominal scene.
    perturb: str | None = None

    def key(self) -> tuple:
        return episode_key(asdict(self))

    def record_fields(self) -> dict:
        """The fields every record of this episode starts with (identity, split, target)."""
        return record_fields(self)

    def video_name(self) -> str:
        return video_name(self)


def episode_key(record: dict) -> tuple:
    """What identifies an episode in a results file (a record or an `EpisodeJob` as a dict)."""
    return tuple(f.normalise(f.value(record)) for f in EPISODE_FIELDS if f.in_key)


def scene_key(job: EpisodeJob) -> tuple:
    """Episodes with the same key share one compiled scene (room, cabinet, hand, physics)."""
    record = asdict(job)
    return (job.cabinet_dir, job.room) + tuple(f.normalise(f.value(record)) for f in EPISODE_FIELDS if f.in_scene)


def scene_seed(job: EpisodeJob) -> int:
    """The seed of a job's scene (which room, its furniture, materials and light): the episode seed
    and the cabinet together, so that a run's cabinets are seen in rooms as varied as the seeds give
    (with the episode seed alone, every cabinet of a run stood in the same room). A cabinet's targets
    and hands share its scene; another ``--seed`` gives every cabinet another one."""
    return zlib.crc32(f"{int(job.seed)}/{job.cabinet}".encode()) & 0x7FFFFFFF


def record_fields(job: EpisodeJob) -> dict:
    """The fields a record of ``job`` starts with: its identity, split, and the target's type and
    instruction from the manifest (so even an episode that could not run is scored in its column);
    for an agent's episode, how the agent was run (`agent_process.CONTAINMENT_FIELDS`)."""
    base = {f.name: getattr(job, f.name) for f in EPISODE_FIELDS if f.shown(getattr(job, f.name))}
    for k in ("target_type", "instruction"):
        if getattr(job, k) is not None:
            base[k] = getattr(job, k)
    if job.policy:  # how the agent was contained, in every record of its episodes (errors too)
        from opend_mj.evaluation.agent_process import containment_fields

        base.update(containment_fields(job))
    return base


def video_name(job: EpisodeJob) -> str:
    """``<cabinet>_<joint>_<hand>_<solver>_s<seed>_l<light>_<pull>[_p<k>][_dt<step>].mp4``: one file per
    episode key, so runs that differ in any identity field never overwrite each other's videos."""
    parts = [f.tag(getattr(job, f.name)) for f in EPISODE_FIELDS
             if f.tag is not None and f.shown(getattr(job, f.name))]
    return "_".join(parts) + ".mp4"


def strip_wall_clock(record: dict) -> dict:
    """A record without its machine- and clock-dependent fields (to compare runs)."""
    return {k: v for k, v in record.items() if k not in WALL_CLOCK_FIELDS}

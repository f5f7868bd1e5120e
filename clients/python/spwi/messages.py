"""spwi's messages as typed dataclasses, field for field as docs/PROTOCOL.md lists them.

The type annotations are the wire format: ``codec`` walks them to write and read the
bytes, so each message is described once. ``U16``/``U32``/``U64`` are variable-length
integers, ``F32`` a 4-byte float, ``Fixed(n)`` an array of exactly n values without a
length, ``RobotId`` a validated id string, ``Optional`` an option and ``list`` a
length-prefixed sequence. A field Python cannot name (``class``) ends in ``_``.

Every message has ``validate()``, the checks a robot applies when it decodes one, so a
frame that a robot would refuse is refused here first, with the field that is wrong.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from enum import Enum, IntEnum
from typing import Annotated, Optional

__all__ = [
    "PROTOCOL_VERSION", "MAX_MESSAGE_BYTES", "FEATURE_DIM", "KEYPOINT_VALUES", "EMBEDDING_DIM",
    "MAX_OBJECTS", "MAX_LANDMARKS", "MAX_STEPS", "MAX_MEMBERS", "MAX_HISTORY_TICKS", "MAX_HUMANS", "TICK_US",
    "Invalid", "Station", "ObjectClass", "DecidedBy", "WorkerPhase",
    "BBox", "FloorPose", "HumanDetection", "ObjectDetection", "DetectionFrame", "WorkerEstimate",
    "StepVote", "VoteMsg", "Landmark", "Verdict", "PersonShare", "EmbeddingMsg", "BallotsMsg", "MapMsg", "Lesson", "HistoryMsg",
    "TeamStep", "DecisionMsg", "RobotPose", "TruthMsg",
]  # fmt: skip

PROTOCOL_VERSION = 11
MAX_MESSAGE_BYTES = 256 * 1024
FEATURE_DIM = 512
KEYPOINT_VALUES = 34
EMBEDDING_DIM = 128
MAX_OBJECTS = 64
MAX_LANDMARKS = 64
MAX_STEPS = 128
MAX_MEMBERS = 1024
MAX_HISTORY_TICKS = 100
MAX_HUMANS = 8
MAX_FLOOR_M = 10_000.0
TICK_US = 100_000
"""A tick is this many microseconds of the fleet's clock: tick = capture_us // TICK_US."""


class Fixed:
    """An array of exactly ``n`` elements, written without a length."""

    def __init__(self, n: int) -> None:
        self.n = n


U16 = Annotated[int, "u16"]
U32 = Annotated[int, "u32"]
U64 = Annotated[int, "u64"]
F32 = Annotated[float, "f32"]
RobotId = Annotated[str, "id"]
Vec2 = Annotated[list[F32], Fixed(2)]

_ID = re.compile(r"[A-Za-z0-9_-]{1,64}")


class Invalid(ValueError):
    """A message that a robot would refuse: the field and what is wrong with it."""

    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"field `{field}`: {problem}")
        self.field = field
        self.problem = problem


def check_id(value: str, field: str = "robot") -> None:
    if not isinstance(value, str) or not _ID.fullmatch(value):
        raise Invalid(field, f"{value!r} is not an id of 1 to 64 characters of [A-Za-z0-9_-]")


class Station(IntEnum):
    """A station class; one byte on the wire, a number in JSON."""

    STORAGE = 0
    WORKSTATION = 1
    ASSEMBLY = 2
    MANUFACTURING = 3


class ObjectClass(Enum):
    """What a detected object is. On the wire, its index in this order; in JSON, its name."""

    CRATE = "Crate"
    BOX = "Box"
    PALLET = "Pallet"
    DESK = "Desk"
    CHAIR = "Chair"
    STORAGE_DRAWER = "StorageDrawer"
    COMPUTER = "Computer"
    WORKBENCH = "Workbench"
    CNC_MACHINE = "CncMachine"
    TABLE = "Table"
    OTHER = "Other"


class DecidedBy(Enum):
    ALL_VOTED = "AllVoted"
    DEADLINE = "Deadline"


class WorkerPhase(Enum):
    MOVING = "Moving"
    TRANSITION = "Transition"
    STATIONARY = "Stationary"


def _finite(field: str, values) -> None:
    for i, x in enumerate(values):
        if not (isinstance(x, (int, float)) and math.isfinite(x)):
            raise Invalid(field, f"value {i} is {x!r} (must be a finite number)")


def _dim(field: str, values, want: int) -> None:
    if len(values) != want:
        raise Invalid(field, f"has {len(values)} values, expected {want}")
    _finite(field, values)


def _unit(field: str, x: float) -> None:
    if not (isinstance(x, (int, float)) and math.isfinite(x) and 0.0 <= x <= 1.0):
        raise Invalid(field, f"{x!r} not in [0, 1]")


def _sorted_ids(field: str, ids: list[str]) -> None:
    if len(ids) > MAX_MEMBERS:
        raise Invalid(field, f"{len(ids)} voters, at most {MAX_MEMBERS}")
    for a, b in zip(ids, ids[1:]):
        if a >= b:
            raise Invalid(field, f"{a} before {b}: must be sorted, each once")


@dataclass
class BBox:
    """A box in image pixels: top-left corner, width, height."""

    x: F32
    y: F32
    w: F32
    h: F32

    def validate(self, field: str) -> None:
        _finite(field, [self.x, self.y, self.w, self.h])
        if self.w < 0 or self.h < 0:
            raise Invalid(field, "negative width or height")


@dataclass
class FloorPose:
    """The camera's pose on the floor: metres, radians counter-clockwise from x."""

    position: Vec2
    heading: F32


@dataclass
class HumanDetection:
    bbox: BBox
    keypoints: list[F32]
    """17 COCO keypoints as x0, y0, x1, y1, … in image pixels (34 values)."""
    feature: list[F32]
    """The appearance feature (512 values)."""
    track: Optional[U32] = None
    """The detector's id of this person across its frames, if it tracks people."""


@dataclass
class ObjectDetection:
    class_: ObjectClass
    bbox: BBox
    score: F32
    feature: list[F32]


@dataclass
class DetectionFrame:
    """One camera frame's detections of one robot; its tick is ``capture_us // TICK_US``."""

    robot: RobotId
    capture_us: U64
    pose: Optional[FloorPose]
    image_size: Vec2
    humans: list[HumanDetection]
    """Every person in view (at most 8), in any order."""
    objects: list[ObjectDetection]
    scene_feature: list[F32]

    @property
    def tick(self) -> int:
        return self.capture_us // TICK_US

    def validate(self) -> None:
        _finite("image_size", self.image_size)
        if any(s < 1 for s in self.image_size):
            raise Invalid("image_size", "width and height must be at least 1 pixel")
        _dim("scene_feature", self.scene_feature, FEATURE_DIM)
        if self.pose is not None:
            _finite("pose", [*self.pose.position, self.pose.heading])
        if len(self.humans) > MAX_HUMANS:
            raise Invalid("humans", f"{len(self.humans)} people, at most {MAX_HUMANS}")
        tracks = [h.track for h in self.humans if h.track is not None]
        if len(set(tracks)) != len(tracks):
            raise Invalid("humans.track", "a track id twice")
        for h in self.humans:
            h.bbox.validate("humans.bbox")
            _dim("humans.keypoints", h.keypoints, KEYPOINT_VALUES)
            _dim("humans.feature", h.feature, FEATURE_DIM)
        if len(self.objects) > MAX_OBJECTS:
            raise Invalid("objects", f"{len(self.objects)} objects, at most {MAX_OBJECTS}")
        for o in self.objects:
            o.bbox.validate("objects.bbox")
            _dim("objects.feature", o.feature, FEATURE_DIM)
            _unit("objects.score", o.score)


@dataclass
class WorkerEstimate:
    """A track of the worker on the floor; covariance per axis: (pos, pos-vel, vel)."""

    position: Vec2
    velocity: Vec2
    covariance: Annotated[list[F32], Fixed(3)]

    def validate(self, prefix: str = "worker") -> None:
        _finite(f"{prefix}.position", self.position)
        _finite(f"{prefix}.velocity", self.velocity)
        _finite(f"{prefix}.covariance", self.covariance)
        pp, pv, vv = self.covariance
        if pp <= 0 or vv <= 0 or pv * pv > pp * vv * (1 + 1e-4):
            raise Invalid(f"{prefix}.covariance", f"{self.covariance} is not a covariance (positive definite)")


@dataclass
class StepVote:
    class_: Station
    confidence: F32


@dataclass
class VoteMsg:
    """A robot's vote for a tick: ``steps[0]`` for t, ``steps[h]`` for t + h."""

    robot: RobotId
    instance: U64
    tick: U64
    steps: list[StepVote]
    visibility: U32
    quality: F32
    worker: Optional[WorkerEstimate]
    signature: bytes = b""

    def validate(self) -> None:
        if not 1 <= len(self.steps) <= MAX_STEPS:
            raise Invalid("steps", f"{len(self.steps)} steps, expected 1..={MAX_STEPS}")
        for s in self.steps:
            _unit("steps.confidence", s.confidence)
        _unit("quality", self.quality)
        if self.worker is not None:
            self.worker.validate()
        if len(self.signature) not in (0, 64):
            raise Invalid("signature", f"{len(self.signature)} bytes, expected 0 or 64")


@dataclass
class Landmark:
    station: Station
    position: Vec2
    sigma: F32


@dataclass
class Verdict:
    tick: U64
    class_: Optional[Station]
    voters: list[RobotId]
    digest: U64


@dataclass
class PersonShare:
    """One person a robot tracks, under the team's id for that person (docs/PROTOCOL.md)."""

    worker: U64
    estimate: WorkerEstimate


@dataclass
class EmbeddingMsg:
    """A robot's share of a tick: its embedding, its vote, what it knows on the floor."""

    robot: RobotId
    instance: U64
    tick: U64
    embedding: Optional[list[F32]]
    visibility: U32
    vote: Optional[VoteMsg]
    worker: Optional[WorkerEstimate]
    facing: Optional[F32]
    landmarks: list[Landmark]
    verdict: Optional[Verdict]
    people: list[PersonShare] = field(default_factory=list)

    def validate(self) -> None:
        if self.embedding is not None:
            _dim("embedding", self.embedding, EMBEDDING_DIM)
        if self.worker is not None:
            self.worker.validate()
        if self.facing is not None:
            _finite("facing", [self.facing])
        if len(self.landmarks) > MAX_LANDMARKS:
            raise Invalid("landmarks", f"{len(self.landmarks)} landmarks, at most {MAX_LANDMARKS}")
        for m in self.landmarks:
            _finite("landmarks.position", m.position)
            if not (math.isfinite(m.sigma) and m.sigma > 0):
                raise Invalid("landmarks.sigma", f"{m.sigma} must be a positive number")
        if self.verdict is not None:
            _sorted_ids("verdict.voters", self.verdict.voters)
        if len(self.people) > MAX_HUMANS:
            raise Invalid("people", f"{len(self.people)} people, at most {MAX_HUMANS}")
        for i, p in enumerate(self.people):
            p.estimate.validate("people.estimate")
            if any(q.worker == p.worker for q in self.people[:i]):
                raise Invalid("people.worker", f"worker {p.worker} named twice")
        if self.vote is not None:
            self.vote.validate()
            if (self.vote.robot, self.vote.instance, self.vote.tick) != (self.robot, self.instance, self.tick):
                raise Invalid("vote", f"{self.vote.robot}'s vote for tick {self.vote.tick} in {self.robot}'s message")


@dataclass
class BallotsMsg:
    """Every vote a robot holds for a tick, relayed; each keeps its origin."""

    robot: RobotId
    instance: U64
    tick: U64
    votes: list[VoteMsg]

    def validate(self) -> None:
        if len(self.votes) > MAX_MEMBERS:
            raise Invalid("votes", f"{len(self.votes)} votes, at most {MAX_MEMBERS}")
        seen = set()
        for v in self.votes:
            v.validate()
            if v.tick != self.tick:
                raise Invalid("votes.tick", f"a vote for tick {v.tick} in the ballots of tick {self.tick}")
            if v.robot in seen:
                raise Invalid("votes.robot", f"two votes from {v.robot}")
            seen.add(v.robot)


@dataclass
class Lesson:
    """Every vote a robot held for one tick it learned from."""

    tick: U64
    votes: list[VoteMsg]


@dataclass
class HistoryMsg:
    """The lessons a robot learned lately, sent when a member joins (oldest first)."""

    robot: RobotId
    instance: U64
    lessons: list[Lesson]

    def validate(self) -> None:
        if len(self.lessons) > MAX_HISTORY_TICKS:
            raise Invalid("lessons", f"{len(self.lessons)} lessons, at most {MAX_HISTORY_TICKS}")
        for a, b in zip(self.lessons, self.lessons[1:]):
            if a.tick >= b.tick:
                raise Invalid("lessons.tick", f"{a.tick} before {b.tick}: oldest first, each once")
        for lesson in self.lessons:
            if len(lesson.votes) > MAX_MEMBERS:
                raise Invalid("lessons.votes", f"{len(lesson.votes)} votes, at most {MAX_MEMBERS}")
            for a, b in zip(lesson.votes, lesson.votes[1:]):
                if a.robot >= b.robot:
                    raise Invalid("lessons.votes.robot", f"{a.robot} before {b.robot}: sorted, each once")
            for v in lesson.votes:
                v.validate()
                if v.tick != lesson.tick:
                    raise Invalid("lessons.votes.tick", f"a vote for tick {v.tick} in the lesson of tick {lesson.tick}")


@dataclass
class MapMsg:
    """Where a robot's team map puts each station (``None``: not mapped)."""

    robot: RobotId
    instance: U64
    stations: Annotated[list[Optional[Vec2]], Fixed(4)]

    def validate(self) -> None:
        for p in self.stations:
            if p is not None:
                _finite("stations", p)
                if any(abs(x) > MAX_FLOOR_M for x in p):
                    raise Invalid("stations", f"{p} lies more than {MAX_FLOOR_M} m out")


@dataclass
class TeamStep:
    class_: Station
    score: F32


@dataclass
class DecisionMsg:
    """The team's answer for a tick as one robot decided it; ``steps`` empty when no
    member saw the worker. Robots that counted the same ballots name the same digest."""

    robot: RobotId
    instance: U64
    tick: U64
    steps: list[TeamStep]
    voters: list[RobotId]
    live_members: U32
    decided_by: DecidedBy
    digest: U64

    @property
    def station(self) -> Optional[Station]:
        """The team's class at t, or None when no member saw the worker."""
        return self.steps[0].class_ if self.steps else None

    def validate(self) -> None:
        if len(self.steps) > MAX_STEPS:
            raise Invalid("steps", f"{len(self.steps)} steps, at most {MAX_STEPS}")
        for s in self.steps:
            _finite("steps.score", [s.score])
        _sorted_ids("voters", self.voters)


@dataclass
class RobotPose:
    robot: RobotId
    position: Vec2
    heading: F32


@dataclass
class TruthMsg:
    """Ground truth for a tick (simulation only)."""

    tick: U64
    intent: Station
    phase: WorkerPhase
    worker_position: Vec2
    worker_heading: F32
    robots: list[RobotPose] = field(default_factory=list)

    def validate(self) -> None:
        _finite("worker_position", self.worker_position)
        _finite("worker_heading", [self.worker_heading])
        if len(self.robots) > MAX_MEMBERS:
            raise Invalid("robots", f"{len(self.robots)} robots, at most {MAX_MEMBERS}")

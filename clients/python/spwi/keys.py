"""spwi's Zenoh key expressions, built and parsed (docs/PROTOCOL.md, "Key expressions").

| key expression                          | payload                              |
|-----------------------------------------|--------------------------------------|
| ``spwi/<fleet>/robot/<robot>/<topic>``  | topic: detections, embedding, vote,  |
|                                         | decision, ballots, map, history      |
| ``spwi/<fleet>/alive/<robot>``          | liveliness token while it runs       |
| ``spwi/<fleet>/world/truth``            | simulation truth                     |
"""

from __future__ import annotations

import re
from typing import NamedTuple, Optional

ROOT = "spwi"
ROBOT_TOPICS = ("detections", "embedding", "vote", "decision", "ballots", "map", "history")
_ID = r"[A-Za-z0-9_-]{1,64}"
_ROBOT_KEY = re.compile(rf"{ROOT}/({_ID})/robot/({_ID})/([a-z]+)")
_TRUTH_KEY = re.compile(rf"{ROOT}/({_ID})/world/truth")
_ALIVE_KEY = re.compile(rf"{ROOT}/({_ID})/alive/({_ID})")


def check_fleet(fleet: str) -> None:
    if not re.fullmatch(_ID, fleet):
        raise ValueError(f"{fleet!r} is not a fleet id of 1 to 64 characters of [A-Za-z0-9_-]")


def robot_topic(fleet: str, robot: str, topic: str) -> str:
    """``spwi/<fleet>/robot/<robot>/<topic>``; ``robot="*"`` for every robot's."""
    if topic not in ROBOT_TOPICS:
        raise ValueError(f"no robot topic {topic!r}; one of {', '.join(ROBOT_TOPICS)}")
    return f"{ROOT}/{fleet}/robot/{robot}/{topic}"


def alive(fleet: str, robot: str = "*") -> str:
    return f"{ROOT}/{fleet}/alive/{robot}"


def truth(fleet: str) -> str:
    return f"{ROOT}/{fleet}/world/truth"


class Key(NamedTuple):
    fleet: str
    robot: Optional[str]
    """The robot a robot topic belongs to; None for the world's truth."""
    topic: str


def parse(key: str) -> Optional[Key]:
    """A key that carries a message, or None."""
    if m := _ROBOT_KEY.fullmatch(key):
        return Key(m[1], m[2], m[3]) if m[3] in ROBOT_TOPICS else None
    if m := _TRUTH_KEY.fullmatch(key):
        return Key(m[1], None, "truth")
    return None


def parse_alive(key: str) -> Optional[tuple[str, str]]:
    """(fleet, robot) of a liveliness key, or None."""
    m = _ALIVE_KEY.fullmatch(key)
    return (m[1], m[2]) if m else None

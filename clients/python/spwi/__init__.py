"""spwi's wire protocol in Python: every message as a typed dataclass, encoded and
decoded byte for byte as the robots do (docs/PROTOCOL.md), and a session on a fleet
to feed a robot's detections and follow the team's decisions.

    import spwi
    payload = spwi.encode(frame)            # bytes, as a robot reads them
    msg = spwi.decode(key, payload)         # the message a key carries
    with spwi.connect("tcp/127.0.0.1:7447") as fleet:
        for d in fleet.decisions(limit=10):
            print(d.robot, d.tick, d.station)
"""

from .bincode import DecodeError
from .codec import TOPICS, decode, decode_as, encode, from_json, to_json
from .fleet import Fleet, connect, fleet_of, now_us, tick_now
from . import keys
from .messages import *  # noqa: F401,F403 (the message types and constants)
from .messages import __all__ as _messages

__all__ = _messages + [
    "DecodeError",
    "TOPICS",
    "decode",
    "decode_as",
    "encode",
    "from_json",
    "to_json",
    "Fleet",
    "connect",
    "fleet_of",
    "now_us",
    "tick_now",
    "keys",
]

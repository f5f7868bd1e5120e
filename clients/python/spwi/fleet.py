"""A Zenoh session on a spwi fleet: publish a robot's detection frames, follow what the
robots publish (decisions, votes, any topic) and who is a member.

An open fleet needs only an endpoint of one of its processes. A secured fleet needs
its fleet directory (``ca.crt``, ``fleet.toml``) and one member's certificate and key
(``members/<name>.crt``, ``.key``): an observer (``spwi-agent fleet add --observer``)
to follow, the world (``--world``) or the robot itself to publish its frames. The
session is mutual TLS then, as the robots' own: ``tcp/`` endpoints are taken as ``tls/``.
"""

from __future__ import annotations

import json
import queue
import time
import tomllib
from pathlib import Path
from typing import Iterator, Optional, Sequence, Union

import zenoh

from . import keys
from .bincode import DecodeError
from .codec import Message, decode, encode
from .messages import TICK_US, DetectionFrame, Invalid


def now_us() -> int:
    """Now on the fleet's clock (this host's clock, synchronised by chrony or PTP), in
    microseconds since the Unix epoch: a frame's ``capture_us``."""
    return time.time_ns() // 1000


def tick_now() -> int:
    """The tick of the fleet's clock now."""
    return now_us() // TICK_US


def _config(endpoints: Sequence[str], mode: str, fleet_dir: Optional[Path], identity: Optional[str]) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", "[]")
    if fleet_dir is not None:
        if identity is None:
            raise ValueError("a secured fleet needs the identity (a member's name) to present")
        member = fleet_dir / "members"
        files = {"ca": fleet_dir / "ca.crt", "cert": member / f"{identity}.crt", "key": member / f"{identity}.key"}
        for what, path in files.items():
            if not path.is_file():
                raise FileNotFoundError(f"{path}: no such file ({what} of {identity} in the fleet directory)")
        tls = {
            "root_ca_certificate": str(files["ca"]),
            "connect_certificate": str(files["cert"]),
            "connect_private_key": str(files["key"]),
            "enable_mtls": True,
            "verify_name_on_connect": False,
        }
        for k, v in tls.items():
            conf.insert_json5(f"transport/link/tls/{k}", json.dumps(v))
        conf.insert_json5("transport/link/protocols", '["tls", "quic"]')
        endpoints = ["tls/" + e[4:] if e.startswith("tcp/") else e for e in endpoints]
    conf.insert_json5("connect/endpoints", json.dumps(list(endpoints)))
    return conf


def fleet_of(fleet_dir: Union[str, Path]) -> str:
    """The fleet id a fleet directory's roster names."""
    path = Path(fleet_dir) / "fleet.toml"
    with open(path, "rb") as f:
        return tomllib.load(f)["fleet"]


class Fleet:
    """One session on one fleet. Use as a context manager, or call ``close()``."""

    def __init__(self, session: zenoh.Session, fleet: str) -> None:
        self.session = session
        self.fleet = fleet
        self.refused = 0
        """Messages followed but refused (malformed, another version, wrong robot)."""
        self.dropped = 0
        """Messages that came faster than they were read and found the inbox full."""

    def __enter__(self) -> "Fleet":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self.session.close()

    def publish(self, frame: DetectionFrame) -> None:
        """Publishes ``frame`` on its robot's detections key (validated first: a frame a
        robot would refuse raises ``Invalid`` here, naming the field)."""
        self.session.put(keys.robot_topic(self.fleet, frame.robot, "detections"), encode(frame))

    def follow(
        self, topic: str, robot: str = "*", seconds: Optional[float] = None, limit: Optional[int] = None
    ) -> Iterator[Message]:
        """Yields the messages robots publish on ``topic`` (every robot's unless
        ``robot``), as they arrive, for ``seconds`` or until ``limit`` came (forever if
        neither). What does not decode is counted in ``refused`` and skipped; what finds
        the inbox (4096 messages) full, in ``dropped``."""
        inbox: "queue.Queue[tuple[str, bytes]]" = queue.Queue(maxsize=4096)

        def arrived(sample: zenoh.Sample) -> None:
            try:
                inbox.put_nowait((str(sample.key_expr), sample.payload.to_bytes()))
            except queue.Full:
                self.dropped += 1

        subscriber = self.session.declare_subscriber(keys.robot_topic(self.fleet, robot, topic), arrived)
        end = None if seconds is None else time.monotonic() + seconds
        got = 0
        try:
            while limit is None or got < limit:
                wait = None if end is None else end - time.monotonic()
                if wait is not None and wait <= 0:
                    return
                try:
                    key, payload = inbox.get(timeout=wait)
                except queue.Empty:
                    return
                try:
                    msg = decode(key, payload)
                except (DecodeError, Invalid):
                    self.refused += 1
                    continue
                got += 1
                yield msg
        finally:
            subscriber.undeclare()

    def decisions(self, **kw) -> Iterator[Message]:
        """The team's decisions as each robot publishes them (``follow("decision")``)."""
        return self.follow("decision", **kw)

    def votes(self, **kw) -> Iterator[Message]:
        return self.follow("vote", **kw)

    def members(self, seconds: float = 1.0) -> set[str]:
        """The robots live now (those holding their liveliness token)."""
        live = set()
        for reply in self.session.liveliness().get(keys.alive(self.fleet), timeout=seconds):
            if reply.ok is not None and (parsed := keys.parse_alive(str(reply.ok.key_expr))):
                live.add(parsed[1])
        return live

    def membership(self, seconds: Optional[float] = None) -> Iterator[tuple[str, bool]]:
        """Yields (robot, joined) as robots join (True) and leave (False), starting
        with those live now, for ``seconds`` (forever if None)."""
        inbox: "queue.Queue[tuple[str, bool]]" = queue.Queue()

        def changed(sample: zenoh.Sample) -> None:
            if parsed := keys.parse_alive(str(sample.key_expr)):
                inbox.put((parsed[1], sample.kind == zenoh.SampleKind.PUT))

        subscriber = self.session.liveliness().declare_subscriber(keys.alive(self.fleet), changed, history=True)
        end = None if seconds is None else time.monotonic() + seconds
        try:
            while True:
                wait = None if end is None else end - time.monotonic()
                if wait is not None and wait <= 0:
                    return
                try:
                    yield inbox.get(timeout=wait)
                except queue.Empty:
                    return
        finally:
            subscriber.undeclare()


def connect(
    endpoints: Union[str, Sequence[str]] = "tcp/127.0.0.1:7447",
    fleet: Optional[str] = None,
    fleet_dir: Union[str, Path, None] = None,
    identity: Optional[str] = None,
    mode: str = "peer",
    wait: float = 5.0,
) -> Fleet:
    """Opens a session on a fleet through ``endpoints`` (any of its processes). Open
    fleets: ``fleet`` names it (``default`` if not given). Secured fleets: ``fleet_dir``
    and ``identity``, a member's name in it; the fleet id comes from its roster.
    Returns once linked to some process of the fleet; raises ``ConnectionError`` if
    none answers within ``wait`` seconds (a wrong address, or a certificate the fleet
    does not accept)."""
    if isinstance(endpoints, str):
        endpoints = [endpoints]
    fleet_dir = None if fleet_dir is None else Path(fleet_dir)
    if fleet_dir is not None:
        named = fleet_of(fleet_dir)
        if fleet is not None and fleet != named:
            raise ValueError(f"fleet {fleet}, but {fleet_dir / 'fleet.toml'} is for fleet {named}")
        fleet = named
    fleet = fleet or "default"
    keys.check_fleet(fleet)
    session = zenoh.open(_config(endpoints, mode, fleet_dir, identity))
    end = time.monotonic() + wait
    while not (list(session.info.peers_zid()) or list(session.info.routers_zid())):
        if time.monotonic() > end:
            session.close()
            raise ConnectionError(
                f"no process of fleet {fleet} answered at {', '.join(endpoints)} within {wait} s"
                + (f" (presenting {identity}'s certificate of {fleet_dir})" if fleet_dir else "")
            )
        time.sleep(0.02)
    return Fleet(session, fleet)

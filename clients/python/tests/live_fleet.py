"""Feeds running spwi-agents their detection frames from Python and writes down the
decisions Python reads back, for the Rust test that compares them with what a Rust
observer read (tests/tests/python_client.rs). Not a unittest: it needs a live fleet.

    live_fleet.py --connect tcp/127.0.0.1:PORT --fleet F --robots r0,r1,r2 --seconds 5 --out decisions.jsonl
    live_fleet.py --connect tls/127.0.0.1:PORT --fleet-dir DIR --feeder world --follower dashboard --forge …

In a secured fleet the frames go out as the feeder (a world or detector member) and
decisions are followed as the follower (an observer); with ``--forge`` the follower
also tries to publish a decision, which the fleet must refuse.
"""

import argparse
import json
import math
import threading
import time

import spwi


def frame(robot: str, index: int, tick: int) -> spwi.DetectionFrame:
    """A scripted frame of ``robot`` (its index in the fleet) for ``tick``: the worker
    walks across the image, seen unless ``tick % 11 == index``."""
    phase = tick % 100_000
    seed = phase * 0.21 + index * 1.7

    def feature(k: float) -> list[float]:
        return [math.sin(i * 0.05 + k + seed) for i in range(spwi.FEATURE_DIM)]

    x = 100.0 + (math.sin(phase * 0.05 + index) + 1.0) * 200.0
    human = None
    if tick % 11 != index:
        box = spwi.BBox(x, 150.0, 40.0, 140.0)
        human = spwi.HumanDetection(box, [x + i for i in range(spwi.KEYPOINT_VALUES)], feature(1.0))
    objects = [
        spwi.ObjectDetection(list(spwi.ObjectClass)[(k + index) % 10], spwi.BBox(60.0 * k, 300.0, 50.0, 50.0), 0.9, feature(2.0 + k))
        for k in range(2 + index % 4)
    ]
    return spwi.DetectionFrame(
        robot=robot,
        capture_us=tick * spwi.TICK_US,
        pose=spwi.FloorPose([3.0 * index, 0.0], 0.1 * index),
        image_size=[640.0, 480.0],
        humans=[] if human is None else [human],
        objects=objects,
        scene_feature=feature(0.0),
    )


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--connect", required=True)
    p.add_argument("--fleet")
    p.add_argument("--fleet-dir")
    p.add_argument("--feeder", help="the member whose certificate publishes frames (secured)")
    p.add_argument("--follower", help="the member whose certificate follows decisions (secured)")
    p.add_argument("--robots", required=True)
    p.add_argument("--seconds", type=float, default=5.0)
    p.add_argument("--forge", action="store_true", help="the follower also tries to publish a decision")
    p.add_argument("--out", required=True)
    a = p.parse_args()
    robots = a.robots.split(",")

    feeder = spwi.connect(a.connect, fleet=a.fleet, fleet_dir=a.fleet_dir, identity=a.feeder)
    follower = spwi.connect(a.connect, fleet=a.fleet, fleet_dir=a.fleet_dir, identity=a.follower)
    read: list[dict] = []
    members: set[str] = set()

    def follow() -> None:
        for d in follower.decisions(seconds=a.seconds + 1.0):
            read.append(
                {
                    "robot": d.robot,
                    "instance": d.instance,
                    "tick": d.tick,
                    "class": None if d.station is None else int(d.station),
                    "digest": d.digest,
                    "voters": d.voters,
                    "live_members": d.live_members,
                }
            )

    reader = threading.Thread(target=follow)
    reader.start()
    time.sleep(0.3)  # the subscription is declared before the first frame
    if a.forge:
        # From a session of its own: a session hears its own puts, whatever the fleet allows.
        with spwi.connect(a.connect, fleet=a.fleet, fleet_dir=a.fleet_dir, identity=a.follower) as forger:
            forged = spwi.DecisionMsg(robots[0], 999, spwi.tick_now(), [], [], 1, spwi.DecidedBy.DEADLINE, 1)
            forger.session.put(spwi.keys.robot_topic(forger.fleet, robots[0], "decision"), spwi.encode(forged))
            time.sleep(0.2)
    # One frame per robot per tick of the fleet's clock, 5 ms into the tick.
    end = time.monotonic() + a.seconds
    tick = spwi.tick_now() + 1
    while time.monotonic() < end:
        time.sleep(max(0.0, tick * spwi.TICK_US / 1e6 + 0.005 - time.time()))
        for i, r in enumerate(robots):
            feeder.publish(frame(r, i, tick))
        tick += 1
    members = follower.members()
    reader.join()
    with open(a.out, "w") as f:
        json.dump({"members": sorted(members), "refused": follower.refused}, f)
        f.write("\n")
        for d in read:
            f.write(json.dumps(d) + "\n")
    feeder.close()
    follower.close()


if __name__ == "__main__":
    main()

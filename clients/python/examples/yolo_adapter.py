"""Turns a YOLO-style detections file into a robot's detection frames.

Each line of the input is one camera image, as a detector pipeline writes it (boxes as
corners, COCO class names, YOLO-pose keypoints as (x, y, confidence) triples), plus the
two things a plain detector does not know — the camera's floor pose from the robot's
localiser, and the 512-number appearance features of each crop and of the whole image
from the appearance backbone (docs/DETECTOR.md says which network and why):

    {"robot": "r1", "capture_us": 1765000000000000, "image_size": [640, 480],
     "pose": {"x": 2.0, "y": 4.5, "heading": 1.5},            # or null
     "scene_feature": [512 numbers],
     "detections": [
       {"name": "person", "box": [x1, y1, x2, y2], "conf": 0.91, "track_id": 4,  # id optional
        "keypoints": [[x, y, c], … 17 in COCO order], "feature": [512 numbers]},
       {"name": "chair", "box": [x1, y1, x2, y2], "conf": 0.74, "feature": [512 numbers]}]}

Every person goes into the frame (the 8 largest, largest first, with the tracker's id if
the line has one): the robot follows the one its track of the worker predicts. Other
classes map onto spwi's object classes (``CLASSES``), anything else is ``Other``. A line that cannot be a frame stops
the adapter with its line number and what is wrong.

    yolo_adapter.py detections.jsonl --check              # convert, print what it made
    yolo_adapter.py detections.jsonl --connect tcp/10.0.0.10:7447 --fleet plant7
    detector | yolo_adapter.py - --connect …              # live: one line per image

From a file, frames are replayed at their recorded pace with capture times moved to
now (a robot refuses frames more than half a second old); from ``-`` (a live
detector's output) they go out as they come, with the times they carry.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Iterable, Iterator

import spwi

CLASSES = {
    "crate": spwi.ObjectClass.CRATE,
    "box": spwi.ObjectClass.BOX,
    "pallet": spwi.ObjectClass.PALLET,
    "desk": spwi.ObjectClass.DESK,
    "chair": spwi.ObjectClass.CHAIR,
    "storage drawer": spwi.ObjectClass.STORAGE_DRAWER,
    "computer": spwi.ObjectClass.COMPUTER,
    "laptop": spwi.ObjectClass.COMPUTER,
    "tv": spwi.ObjectClass.COMPUTER,
    "keyboard": spwi.ObjectClass.COMPUTER,
    "workbench": spwi.ObjectClass.WORKBENCH,
    "cnc machine": spwi.ObjectClass.CNC_MACHINE,
    "table": spwi.ObjectClass.TABLE,
    "dining table": spwi.ObjectClass.TABLE,
}
"""COCO's names where they fit, a factory-trained detector's own names beside them."""


class BadLine(ValueError):
    pass


def _box(corners) -> spwi.BBox:
    x1, y1, x2, y2 = (float(v) for v in corners)
    return spwi.BBox(x1, y1, x2 - x1, y2 - y1)


def frame(line: dict) -> spwi.DetectionFrame:
    """One input line as a frame (``spwi.Invalid`` if a robot would refuse it)."""
    people = [d for d in line["detections"] if d["name"] == "person"]
    humans = []
    # The largest first, and at most the 8 largest: the robot picks whom it follows.
    for p in sorted(people, key=lambda d: -_box(d["box"]).w * _box(d["box"]).h)[: spwi.MAX_HUMANS]:
        if len(p["keypoints"]) != 17:
            raise BadLine(f"a person has {len(p['keypoints'])} keypoints, expected COCO's 17")
        keypoints = [float(v) for kp in p["keypoints"] for v in kp[:2]]
        track = p.get("track_id")
        humans.append(spwi.HumanDetection(_box(p["box"]), keypoints, p["feature"], None if track is None else int(track)))
    objects = [
        spwi.ObjectDetection(CLASSES.get(d["name"], spwi.ObjectClass.OTHER), _box(d["box"]), float(d["conf"]), d["feature"])
        for d in line["detections"]
        if d["name"] != "person"
    ]
    pose = line.get("pose")
    f = spwi.DetectionFrame(
        robot=line["robot"],
        capture_us=int(line["capture_us"]),
        pose=None if pose is None else spwi.FloorPose([pose["x"], pose["y"]], pose["heading"]),
        image_size=[float(v) for v in line["image_size"]],
        humans=humans,
        objects=objects[: spwi.MAX_OBJECTS],
        scene_feature=line["scene_feature"],
    )
    f.validate()
    return f


def frames(lines: Iterable[str]) -> Iterator[spwi.DetectionFrame]:
    """The frames of a detections file's lines; blank lines are skipped."""
    for n, text in enumerate(lines, 1):
        if not text.strip():
            continue
        try:
            yield frame(json.loads(text))
        except (KeyError, TypeError, ValueError) as e:
            what = f"no {e}" if isinstance(e, KeyError) else str(e)
            raise BadLine(f"line {n}: {what}") from None


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("input", help="a detections file (JSON lines), or - for a live detector's output on stdin")
    p.add_argument("--check", action="store_true", help="convert only, and print what each frame holds")
    p.add_argument("--connect", default="tcp/127.0.0.1:7447")
    p.add_argument("--fleet")
    p.add_argument("--fleet-dir", help="a secured fleet's directory")
    p.add_argument("--identity", default="world", help="the member to publish as (secured)")
    a = p.parse_args()
    live = a.input == "-"
    source = sys.stdin if live else open(a.input)
    try:
        if a.check:
            for f in frames(source):
                seen = f"{len(f.humans)} people" if f.humans else "nobody"
                print(f"{f.robot} tick {f.tick}: {seen}, {len(f.objects)} objects, {len(spwi.encode(f))} bytes")
            return
        with spwi.connect(a.connect, fleet=a.fleet, fleet_dir=a.fleet_dir, identity=a.identity) as fleet:
            shift = None
            for f in frames(source):
                if not live:
                    now = spwi.now_us()
                    shift = now - f.capture_us if shift is None else shift
                    time.sleep(max(0.0, (f.capture_us + shift - now) / 1e6))
                    f.capture_us += shift
                fleet.publish(f)
    except BadLine as e:
        sys.exit(f"{a.input}: {e}")


if __name__ == "__main__":
    main()

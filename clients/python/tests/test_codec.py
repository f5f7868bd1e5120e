"""What the client refuses, as a robot refuses it: a clear error naming the problem."""

import struct
import unittest
from pathlib import Path

import spwi

GOLDEN = Path(__file__).resolve().parents[3] / "proto" / "golden"
VOTE_KEY = "spwi/f1/robot/r1/vote"


def vote_bytes():
    return (GOLDEN / "vote.bin").read_bytes()


def frame(**changes):
    values = dict(
        robot="r1",
        capture_us=1_765_000_000_000_000,
        pose=spwi.FloorPose([2.0, 4.5], 1.5),
        image_size=[640.0, 480.0],
        humans=[spwi.HumanDetection(spwi.BBox(300, 200, 40, 120), [320.0] * 34, [0.5] * 512)],
        objects=[spwi.ObjectDetection(spwi.ObjectClass.WORKBENCH, spwi.BBox(10, 20, 30, 40), 0.75, [0.25] * 512)],
        scene_feature=[0.0] * 512,
    )
    values.update(changes)
    return spwi.DetectionFrame(**values)


class Refused(unittest.TestCase):
    def test_a_frame_round_trips_and_its_tick_is_its_capture_time_in_periods(self):
        # (values exact in f32: others come back rounded to the nearest f32)
        f = frame()
        back = spwi.decode("spwi/f1/robot/r1/detections", spwi.encode(f))
        self.assertEqual(back, f)
        self.assertEqual(back.tick, 17_650_000_000)

    def test_trailing_bytes_another_version_and_a_cut_message_are_refused(self):
        with self.assertRaisesRegex(spwi.DecodeError, "1 trailing bytes"):
            spwi.decode(VOTE_KEY, vote_bytes() + b"\x00")
        with self.assertRaisesRegex(spwi.DecodeError, "protocol version 9"):
            spwi.decode(VOTE_KEY, b"\x09" + vote_bytes()[1:])
        with self.assertRaisesRegex(spwi.DecodeError, "more bytes expected"):
            spwi.decode(VOTE_KEY, vote_bytes()[:-3])
        with self.assertRaisesRegex(spwi.DecodeError, "at most 262144"):
            spwi.decode(VOTE_KEY, bytes(262145))

    def test_a_message_naming_another_robot_than_its_key_is_refused(self):
        with self.assertRaisesRegex(spwi.DecodeError, "names robot r1"):
            spwi.decode("spwi/f1/robot/r9/vote", vote_bytes())
        with self.assertRaisesRegex(spwi.DecodeError, "not a spwi key"):
            spwi.decode("spwi/f1/robot/r1/nonsense", vote_bytes())

    def test_a_float_that_is_not_finite_is_refused_on_the_wire(self):
        good = spwi.encode(frame(humans=[], objects=[]))
        # image_size[0] sits after robot (3 bytes), capture_us (9) and the pose (1 + 12).
        at = 1 + 3 + 9 + 13
        self.assertEqual(struct.unpack_from("<f", good, at)[0], 640.0)
        bad = good[:at] + struct.pack("<f", float("nan")) + good[at + 4 :]
        with self.assertRaisesRegex(spwi.DecodeError, "image_size: nan is not finite"):
            spwi.decode("spwi/f1/robot/r1/detections", bad)

    def test_a_frame_a_robot_would_refuse_is_refused_before_it_is_sent_naming_the_field(self):
        cases = [
            (dict(scene_feature=[0.0] * 511), "scene_feature.*511 values, expected 512"),
            (dict(robot="r 1"), "robot.*not an id"),
            (dict(image_size=[0.0, 480.0]), "image_size.*at least 1 pixel"),
            (dict(objects=[spwi.ObjectDetection(spwi.ObjectClass.BOX, spwi.BBox(0, 0, 1, 1), 1.5, [0.0] * 512)]), "objects.score"),
            (dict(pose=spwi.FloorPose([float("inf"), 0.0], 0.0)), "pose"),
            (dict(image_size=[640.0]), "image_size.*expected 2"),
            (dict(capture_us=-1), "capture_us"),
        ]
        for changes, error in cases:
            with self.subTest(error=error), self.assertRaisesRegex(spwi.Invalid, error):
                spwi.encode(frame(**changes))

    def test_people_in_a_share_are_at_most_eight_each_named_once(self):
        share = spwi.decode("spwi/f1/robot/r1/embedding", (GOLDEN / "embedding.bin").read_bytes())
        self.assertEqual([p.worker for p in share.people], [0x0123_4567_89AB_CDEF, 42])
        person = share.people[1]
        cases = [
            ([person] * 2, "people.worker.*named twice"),
            ([spwi.PersonShare(i, person.estimate) for i in range(9)], "people.*9 people, at most 8"),
            ([spwi.PersonShare(1, spwi.WorkerEstimate([0.0, 0.0], [0.0, 0.0], [-1.0, 0.0, 1.0]))], "people.estimate.covariance"),
        ]
        for people, error in cases:
            share.people = people
            with self.subTest(error=error), self.assertRaisesRegex(spwi.Invalid, error):
                spwi.encode(share)


if __name__ == "__main__":
    unittest.main()

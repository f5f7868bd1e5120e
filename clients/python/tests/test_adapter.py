"""The YOLO-style adapter (examples/yolo_adapter.py) on its shipped fixture."""

import subprocess
import sys
import unittest
from pathlib import Path

import spwi

HERE = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(HERE / "examples"))
import yolo_adapter  # noqa: E402

FIXTURE = HERE / "examples" / "fixtures" / "yolo_detections.jsonl"


class Adapter(unittest.TestCase):
    def setUp(self):
        self.frames = list(yolo_adapter.frames(FIXTURE.open()))

    def test_every_line_becomes_a_frame_a_robot_decodes(self):
        self.assertEqual([f.tick for f in self.frames], [17650000000, 17650000001, 17650000002])
        for f in self.frames:
            self.assertEqual(spwi.decode("spwi/plant7/robot/r1/detections", spwi.encode(f)).tick, f.tick)

    def test_every_person_goes_in_the_largest_first_with_keypoints_in_coco_order(self):
        first, second, third = self.frames
        person = first.humans[0]
        self.assertEqual((person.bbox.x, person.bbox.w, person.bbox.h), (300.0, 40.0, 160.0))
        self.assertEqual(person.keypoints[:4], [310.0, 125.0, 313.0, 134.0])  # x0, y0, x1, y1
        self.assertEqual([h.bbox.x for h in second.humans][0], 305.0)  # then the smaller, farther one
        self.assertEqual(len(second.humans), 2)
        self.assertEqual(third.humans, [])
        self.assertIsNone(third.pose)

    def test_classes_map_onto_spwi_objects_and_the_rest_is_other(self):
        self.assertEqual(
            [o.class_ for o in self.frames[0].objects],
            [spwi.ObjectClass.CHAIR, spwi.ObjectClass.TABLE, spwi.ObjectClass.OTHER],
        )
        self.assertEqual(self.frames[1].objects[0].class_, spwi.ObjectClass.WORKBENCH)

    def test_a_bad_line_stops_the_adapter_naming_the_line_and_the_field(self):
        lines = FIXTURE.read_text().splitlines()
        bad = lines[1].replace('"scene_feature":[', '"scene_feature":[1.0,', 1)
        with self.assertRaisesRegex(yolo_adapter.BadLine, r"line 2: field `scene_feature`: has 513 values"):
            list(yolo_adapter.frames([lines[0], bad]))
        with self.assertRaisesRegex(yolo_adapter.BadLine, r"line 1: no 'robot'"):
            list(yolo_adapter.frames([lines[0].replace('"robot"', '"robut"')]))

    def test_the_command_line_checks_the_fixture(self):
        out = subprocess.run(
            [sys.executable, str(HERE / "examples" / "yolo_adapter.py"), str(FIXTURE), "--check"],
            capture_output=True, text=True, check=True, env={"PYTHONPATH": str(HERE)},
        ).stdout
        self.assertIn("r1 tick 17650000000: 1 people, 3 objects", out)
        self.assertIn("r1 tick 17650000001: 2 people, 1 objects", out)
        self.assertIn("r1 tick 17650000002: nobody, 1 objects", out)


if __name__ == "__main__":
    unittest.main()

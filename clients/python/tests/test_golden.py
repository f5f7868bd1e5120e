"""The client against proto/golden: every message's bytes decode to its JSON, and its
JSON encodes to its bytes, exactly as the Rust codec (whose own test holds the same
files) writes and reads them."""

import json
import unittest
from pathlib import Path

import spwi

GOLDEN = Path(__file__).resolve().parents[3] / "proto" / "golden"
KEYS = {topic: f"spwi/f1/robot/{'r2' if topic in ('ballots', 'history') else 'r1'}/{topic}" for topic in spwi.TOPICS}
KEYS["truth"] = "spwi/f1/world/truth"


def golden(topic):
    return (GOLDEN / f"{topic}.bin").read_bytes(), json.loads((GOLDEN / f"{topic}.json").read_text())


class GoldenVectors(unittest.TestCase):
    def test_there_is_a_vector_for_every_topic(self):
        self.assertEqual({p.stem for p in GOLDEN.glob("*.bin")}, set(spwi.TOPICS))

    def test_every_golden_payload_decodes_to_its_json(self):
        for topic in spwi.TOPICS:
            with self.subTest(topic=topic):
                payload, expected = golden(topic)
                msg = spwi.decode(KEYS[topic], payload)
                self.assertIsInstance(msg, spwi.TOPICS[topic])
                self.assertEqual(spwi.to_json(msg), expected)

    def test_every_golden_json_encodes_to_its_bytes(self):
        for topic, cls in spwi.TOPICS.items():
            with self.subTest(topic=topic):
                payload, value = golden(topic)
                self.assertEqual(spwi.encode(spwi.from_json(cls, value)), payload)


if __name__ == "__main__":
    unittest.main()

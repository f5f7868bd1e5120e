"""Connecting: what a user gets when the fleet cannot be reached or a file is missing."""

import tempfile
import unittest
from pathlib import Path

import spwi


class Connect(unittest.TestCase):
    def test_an_endpoint_nobody_answers_on_is_an_error_naming_it(self):
        with self.assertRaisesRegex(ConnectionError, r"no process of fleet plant7 answered at tcp/127.0.0.1:9"):
            spwi.connect("tcp/127.0.0.1:9", fleet="plant7", wait=0.5)

    def test_a_secured_fleet_without_the_members_certificate_is_an_error_naming_the_file(self):
        with tempfile.TemporaryDirectory() as d:
            Path(d, "fleet.toml").write_text('fleet = "plant7"\n')
            Path(d, "ca.crt").write_text("")
            with self.assertRaisesRegex(FileNotFoundError, r"members/dashboard.crt"):
                spwi.connect("tcp/127.0.0.1:9", fleet_dir=d, identity="dashboard", wait=0.5)
            with self.assertRaisesRegex(ValueError, r"fleet other, but .*fleet.toml is for fleet plant7"):
                spwi.connect("tcp/127.0.0.1:9", fleet="other", fleet_dir=d, identity="dashboard")

    def test_a_bad_fleet_id_is_refused(self):
        with self.assertRaisesRegex(ValueError, "not a fleet id"):
            spwi.connect("tcp/127.0.0.1:9", fleet="plant 7")


if __name__ == "__main__":
    unittest.main()

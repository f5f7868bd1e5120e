"""Checks a spwi recording as a viewer reads it (tests/tests/fleet.rs runs it on a
recorded run): with the `mcap` reader, every channel carries a JSON Schema and JSON
messages, every channel the run wrote to has messages, and every message validates
against its channel's schema (the first 50 of each channel).

    python tests/mcap_schemas.py run.mcap
"""

import json
import sys
from collections import Counter

import jsonschema
from mcap.reader import make_reader


def main(path: str) -> None:
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None, "no summary: the recording was not finished"
        for channel in summary.channels.values():
            schema = summary.schemas.get(channel.schema_id)
            assert schema is not None, f"{channel.topic}: no schema"
            assert schema.encoding == "jsonschema", f"{channel.topic}: schema encoding {schema.encoding}"
            assert channel.message_encoding == "json", f"{channel.topic}: message encoding {channel.message_encoding}"
        seen = Counter()
        for schema, channel, message in reader.iter_messages():
            seen[channel.topic] += 1
            if seen[channel.topic] > 50:
                continue
            value = json.loads(message.data)
            try:
                jsonschema.validate(value, json.loads(schema.data))
            except jsonschema.ValidationError as e:
                raise SystemExit(f"{channel.topic} message {seen[channel.topic]} does not match {schema.name}: {e.message}")
    topics = {c.topic for c in summary.channels.values()}
    print(f"{len(topics)} channels, each with a JSON Schema; messages checked: " + ", ".join(f"{t} {n}" for t, n in sorted(seen.items())))
    expected = {"/spwi/config", "/spwi/in/detections", "/spwi/in/embedding", "/spwi/in/membership", "/spwi/out/decision", "/spwi/out/vote", "/spwi/state"}
    missing = expected - set(seen)
    assert not missing, f"no messages on {sorted(missing)}"


if __name__ == "__main__":
    main(sys.argv[1])

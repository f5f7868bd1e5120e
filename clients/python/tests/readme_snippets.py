"""Runs the README's two Python sections against a live fleet: "Feed it from your
detector" in a thread, "Read it from Python" meanwhile, and checks that the reader
printed twenty decisions and the members. The endpoint and fleet in the README are
replaced by the test fleet's. Driven by tests/tests/python_client.rs.

    readme_snippets.py --readme README.md --connect tcp/127.0.0.1:PORT --fleet F
"""

import argparse
import contextlib
import io
import re
import threading


def section(readme: str, heading: str) -> str:
    m = re.search(rf"^## {re.escape(heading)}\n.*?```python\n(.*?)```", readme, re.S | re.M)
    if not m:
        raise SystemExit(f"README has no Python block under '## {heading}'")
    code = m[1]
    lines = code.strip().count("\n") + 1
    assert lines <= 15, f"'{heading}' has {lines} lines of code, at most 15"
    return code


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--readme", required=True)
    p.add_argument("--connect", required=True)
    p.add_argument("--fleet", required=True)
    a = p.parse_args()
    readme = open(a.readme).read()

    def here(code: str) -> str:
        return code.replace('"tcp/127.0.0.1:7447"', repr(a.connect)).replace('fleet="default"', f"fleet={a.fleet!r}")

    feed, read = here(section(readme, "Feed it from your detector")), here(section(readme, "Read it from Python"))
    failed = []

    def feeding() -> None:
        try:
            exec(compile(feed, "README: Feed it from your detector", "exec"), {})
        except Exception as e:  # reported below, from the main thread
            failed.append(e)

    feeder = threading.Thread(target=feeding)
    feeder.start()
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(read, "README: Read it from Python", "exec"), {})
    feeder.join()
    if failed:
        raise failed[0]
    out = printed.getvalue().splitlines()
    print("\n".join(out))
    assert out and out[-1].startswith("members: ['r0', 'r1', 'r2']"), out[-1:]
    decided = [line for line in out[:-1] if re.fullmatch(r"r\d tick \d+: .+, voters .*", line)]
    assert len(decided) == 20, f"the reader printed {len(decided)} decisions, expected 20:\n{out}"


if __name__ == "__main__":
    main()

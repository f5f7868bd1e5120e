#!/usr/bin/env python3
"""A study, not a test: real packet drop on a fresh 6-agent container fleet, with the
end-to-end test's own helpers (tests/compose_e2e.py). 10 s at 10 % of the packets
reaching every agent dropped, then twice 10 s at 30 %; prints how often the agents
decided alike. Needs root (nsenter, iptables) and the image (deploy/build-image.sh).

    python3 tests/compose_drop.py                       # the secured fleet, router up
    SPWI_FLEET_DIR= python3 tests/compose_drop.py       # the open fleet
    STOP_ROUTER=1 python3 tests/compose_drop.py         # the router stopped first, as
                                                        # compose_e2e.py does
"""
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import compose_e2e as e  # noqa: E402 - beside this file


def run():
    e.compose("up", "-d", "--scale", "agent=6")
    ips = [ip for _, ip in e.agents().values()]
    e.wait_until("6 agents counting 6", e.all_count(ips, 6), 90, poll=0.2)
    time.sleep(5)
    if os.environ.get("STOP_ROUTER"):
        e.compose("stop", "--timeout", "1", "router")
        time.sleep(2.0)
        print("router stopped")
    share, ticks = e.agreement(ips)
    print(f"nothing dropped: same decision on {share:.1%} of {ticks} common ticks")
    ag = e.agents()
    try:
        for p in (0.1, 0.3, 0.3):
            e.drop_packets(ag, p)
            e.decisions_advance(ips)
            share, ticks = e.agreement(ips, seconds=10.0)
            print(f"{p:.0%} dropped: same decision on {share:.1%} of {ticks} common ticks", flush=True)
    finally:
        e.drop_packets(ag, 0)


if __name__ == "__main__":
    try:
        run()
    finally:
        subprocess.run([*e.COMPOSE, "down", "-v", "--timeout", "1", "--remove-orphans"], capture_output=True)

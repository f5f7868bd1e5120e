#!/usr/bin/env python3
"""The container fleet end to end (driven by tests/compose-e2e.sh, which builds the image).

Starts deploy/compose.yaml (the secured fleet: certificates, router, world, 4 agents)
as its own compose project and checks, through each agent's /status (read from the
host over the Docker network):

1. all 4 agents are healthy, count 4 members and decide the same class tick by tick;
   once the fleet has settled, over 30 s, the robots' own comparisons of their
   decisions with their peers' agree at least 99.5 % of the time;
   rogues: a container without a certificate (calling itself mallory) and one holding
   a real robot certificate but claiming another robot's id are never counted;
2. `docker kill` one agent: the other 3 count 3 within 1.5 s and keep deciding;
3. `--scale agent=6`: the newcomers (and the killed one, restarted) are counted and vote;
4. `docker network disconnect` one agent: the others drop it within 1.5 s; after
   `docker network connect` it is counted again;
5. the router stops: the connected agents keep deciding, all still counted;
6. real packet loss (as root): 10 % and then 30 % of the packets reaching every agent
   dropped (iptables' statistic match in each container's network namespace): the
   fleet keeps deciding; agreement is measured (at least 97 % at 10 %);
7. a fresh fleet whose world freezes one robot's camera (tests/compose-stuck.yaml):
   that robot reports its feed stale and leaves the vote, the fleet keeps deciding;
8. on that fleet, the operator revokes one robot and admits a new one while it runs
   (`spwi-agent fleet revoke | add` on the shared fleet directory, which every process
   reads again within a second): the others drop the revoked robot within 5 s and it
   leaves; a container started as the newly admitted robot-17 is counted by all.

Prints each measured time. Tears the project down at the end, even on failure.
Only the Python standard library and the docker CLI are needed.
"""
import json
import os
import shutil
import subprocess
import sys
import time
import traceback
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PROJECT = os.environ.get("SPWI_E2E_PROJECT", f"spwi-e2e-{os.getpid()}")
# Docker's compose plugin where installed, else Debian's docker-compose (1.29).
_plugin = subprocess.run(["docker", "compose", "version"], capture_output=True).returncode == 0
COMPOSE = (["docker", "compose"] if _plugin else ["docker-compose"]) + [
    "-p",
    PROJECT,
    "-f",
    os.path.join(ROOT, "deploy", "compose.yaml"),
]
NETWORK = f"{PROJECT}_fleet"
STUCK = os.path.join(ROOT, "tests", "compose-stuck.yaml")
KILL_BUDGET_S = 1.5
# Settled fleet, no fault: the share of peer decisions each robot found equal to its own.
STEADY_S = 30.0
STEADY_AGREEMENT = 0.995
# Real packet loss: drop probability -> least agreement accepted (None: reported only).
# TCP resends what is dropped, so a lost packet is a message late by a retransmission
# timeout (>= 200 ms, past the 60 ms decision deadline), not a message lost; at 30 %
# links stall for longer than the 1 s lease and members come and go, so agreement
# there varies widely from run to run (58-94 % seen): the fleet must keep deciding.
DROPS = {0.1: 0.97, 0.3: None}
figures = {}


def sh(*args, check=True):
    r = subprocess.run(args, capture_output=True, text=True)
    if check and r.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed ({r.returncode}): {r.stderr.strip()}")
    return r.stdout.strip()


def compose(*args):
    return sh(*COMPOSE, *args)


def agents():
    """Running agent containers: id -> (host name, IP on the fleet network). The robot
    id is the identity the container claimed: read it from its /status."""
    out = {}
    for cid in compose("ps", "-q", "agent").split():
        info = json.loads(sh("docker", "inspect", cid))[0]
        if not info["State"]["Running"]:
            continue
        net = info["NetworkSettings"]["Networks"].get(NETWORK)
        out[cid] = (info["Config"]["Hostname"], net["IPAddress"] if net else None)
    return out


def status(ip):
    """One read of an agent's /status, or None when it does not answer within 0.5 s."""
    try:
        with urllib.request.urlopen(f"http://{ip}:9000/status", timeout=0.5) as r:
            return json.load(r)
    except (OSError, ValueError):
        return None


def must_status(ip, wait=5.0):
    """An agent's /status, retried for `wait` seconds: under packet loss or a busy
    machine one read may time out; an agent silent for that long fails the test."""
    s, _ = wait_until(f"/status of the agent at {ip}", lambda: status(ip), wait, poll=0.1)
    return s


def last_tick(s):
    """The latest tick an agent decided (-1 before its first decision)."""
    return s["last_decision"]["tick"] if s["last_decision"] else -1


def fail(msg):
    raise AssertionError(msg)


def wait_until(what, cond, timeout, poll=0.05):
    """Polls cond() until it returns a truthy value; returns (value, seconds taken)."""
    start = time.monotonic()
    while True:
        v = cond()
        if v:
            return v, time.monotonic() - start
        if time.monotonic() - start > timeout:
            fail(f"timed out after {timeout} s waiting for: {what}")
        time.sleep(poll)


def all_count(ips, n):
    """True when every agent at `ips` answers and counts exactly n members."""
    def cond():
        sts = [status(ip) for ip in ips]
        return all(s is not None and len(s["members"]) == n for s in sts) and sts
    return cond


def agreement(ips, seconds=3.0):
    """Share of ticks, decided by every agent, on which all decided the same class."""
    time.sleep(seconds)
    recents = [must_status(ip) for ip in ips]
    by_tick = [{d["tick"]: d["class"] for d in r["recent_decisions"]} for r in recents]
    common = set.intersection(*(set(b) for b in by_tick))
    if len(common) < 10:
        fail(f"only {len(common)} ticks decided by all {len(ips)} agents in the last 10 s")
    split = sorted(t for t in common if len({b[t] for b in by_tick}) > 1)
    if split:
        robots = [r["robot"] for r in recents]
        print(f"  ticks decided differently ({len(split)}), class by robot {robots}:")
        for t in split[:20]:
            print(f"    {t}: {[b[t] for b in by_tick]}")
    return 1 - len(split) / len(common), len(common)


def steady_agreement(ips, seconds):
    """Share of the peer decisions the agents compared with their own over `seconds`
    (their `agreement_compared` / `agreement_same` counters) that were the same."""
    def counters():
        ms = [must_status(ip)["metrics"] for ip in ips]
        return sum(m["agreement_compared"] for m in ms), sum(m["agreement_same"] for m in ms)
    c0, s0 = counters()
    time.sleep(seconds)
    c1, s1 = counters()
    if c1 - c0 < 100:
        fail(f"only {c1 - c0} peer decisions compared in {seconds} s")
    return (s1 - s0) / (c1 - c0), c1 - c0


def keeps_deciding(ips, members):
    """Every agent's latest decided tick advances and counts `members` live members."""
    before = [last_tick(must_status(ip)) for ip in ips]
    time.sleep(1.0)
    after = [must_status(ip) for ip in ips]
    for b, a in zip(before, after):
        if last_tick(a) < b + 5:
            fail(f"{a['robot']} decided only up to tick {last_tick(a)} one second after {b}")
        d = a["last_decision"]
        if d["live_members"] != members:
            fail(f"{a['robot']} decided with {d['live_members']} live members, expected {members}")
    return after


def decisions_advance(ips, seconds=2.0):
    """Every agent decided at least 5 more ticks per second over `seconds`."""
    before = [last_tick(must_status(ip)) for ip in ips]
    time.sleep(seconds)
    for ip, b in zip(ips, before):
        s = must_status(ip)
        if last_tick(s) < b + 5 * seconds:
            fail(f"{s['robot']} decided only up to tick {last_tick(s)} {seconds} s after {b}")


def drop_packets(containers, probability):
    """Drops `probability` of the packets reaching each container (its /status port
    exempt, so the test can still read it); probability 0 removes the rules."""
    for c in containers:
        pid = sh("docker", "inspect", "-f", "{{.State.Pid}}", c)
        ipt = ["nsenter", "-t", pid, "-n", "iptables"]
        sh(*ipt, "-F", "INPUT")
        if probability > 0:
            sh(*ipt, "-A", "INPUT", "-p", "tcp", "--dport", "9000", "-j", "ACCEPT")
            sh(*ipt, "-A", "INPUT", "-m", "statistic", "--mode", "random",
               "--probability", str(probability), "-j", "DROP")


def real_packet_loss():
    if os.geteuid() != 0 or not (shutil.which("nsenter") and shutil.which("iptables")):
        print("!!!!!!!! SKIPPED: real packet loss (needs root, nsenter and iptables) !!!!!!!!")
        return
    ag = agents()
    ips = [ip for _, ip in ag.values()]
    try:
        for p, least in DROPS.items():
            drop_packets(ag, p)
            decisions_advance(ips)
            share, ticks = agreement(ips, seconds=10.0)
            print(f"{p:.0%} of packets dropped at every agent: same decision on {share:.1%} of {ticks} common ticks")
            figures[f"agreement_drop_{int(p * 100)}"] = round(share, 4)
            if least is not None and share < least:
                fail(f"with {p:.0%} packet drop the agents agree on only {share:.1%} of ticks (< {least:.0%})")
    finally:
        drop_packets(ag, 0)


def rogues(ips):
    """Two rogue containers on the fleet's network for 8 s: one without a certificate
    (the open mode) calling itself mallory, and one presenting robot-16's certificate
    while claiming to be robot-15 (an admitted identity no agent uses). Neither may be
    counted by anyone; the members stay the 4 agents."""
    image = os.environ.get("SPWI_IMAGE", "spwi:latest")
    fleet_dir = "/var/lib/spwi/fleet"
    runs = {
        "mallory": ["--robot-id", "mallory"],
        "robot-15": ["--fleet-dir", fleet_dir, "--identity", "robot-16", "--robot-id", "robot-15"],
    }
    started = []
    try:
        for robot, args in runs.items():
            name = f"{PROJECT}-rogue-{robot}"
            sh("docker", "run", "-d", "--name", name, "--network", NETWORK,
               "-v", f"{PROJECT}_fleet:{fleet_dir}", image, *args)
            started.append(name)
        end = time.monotonic() + 8.0
        while time.monotonic() < end:
            for ip in ips:
                s = must_status(ip)
                if set(s["members"]) & set(runs):
                    fail(f"{s['robot']} counts a rogue: members {s['members']}")
                if len(s["members"]) != 4:
                    fail(f"{s['robot']} counts {len(s['members'])} members with the rogues about: {s['members']}")
            time.sleep(0.2)
        running = [n for n in started if sh("docker", "inspect", "-f", "{{.State.Running}}", n) == "true"]
        print(f"rogues: no certificate (mallory) and a stolen id (robot-16 as robot-15) never counted "
              f"over 8 s; still trying at the end: {len(running)} of 2")
        if len(running) < 2:
            logs = {n: sh("docker", "logs", "--tail", "3", n, check=False) for n in started}
            fail(f"a rogue container exited early, so the test proves less than it says: {logs}")
    finally:
        for n in started:
            sh("docker", "rm", "-f", n, check=False)


def roster_changes():
    ag = agents()
    sts = {c: must_status(ip) for c, (_, ip) in ag.items()}
    victim = next(c for c, s in sts.items() if not s["feed_stale"])
    operator = next(c for c in ag if c != victim)  # any container holding the fleet volume
    revoked = sts[victim]["robot"]
    version = sts[operator]["roster_version"]
    rest = [ip for c, (_, ip) in ag.items() if c != victim]
    left_before = {ip: sts[c]["metrics"]["members_left"] for c, (_, ip) in ag.items() if c != victim}
    fleet_dir = "/var/lib/spwi/fleet"
    sh("docker", "exec", operator, "spwi-agent", "fleet", "revoke", "--robot", revoked, "--dir", fleet_dir)
    _, took = wait_until(f"the other 3 dropping the revoked {revoked}", all_count(rest, 3), 10, poll=0.05)
    print(f"revoked while running: the other 3 drop {revoked} {took:.2f} s after `fleet revoke`")
    figures["revoke_s"] = round(took, 2)
    if took > 5.0:
        fail(f"the revoked robot was still counted {took:.2f} s after `fleet revoke` (> 5 s)")
    wait_until(f"{revoked}'s agent to leave",
               lambda: sh("docker", "inspect", "-f", "{{.State.Running}}", victim) == "false", 15, poll=0.2)
    logs = subprocess.run(["docker", "logs", "--tail", "20", victim], capture_output=True, text=True)
    said = logs.stdout + logs.stderr  # the agent logs to stderr
    if "revoked" not in said:
        fail(f"{revoked}'s agent left without saying it was revoked: {said[-500:]}")
    # Every reopen over (0.2-1.7 s after adoption, by name) and a held member's grace:
    # until its own reopen a robot can miss frames and votes from peers that already
    # reopened (their links drop and come back; deploy/README.md), so whether the rest
    # decide is asked after the window, not inside it.
    time.sleep(3.0)
    keeps_deciding(rest, 3)
    for ip in rest:
        s = must_status(ip)
        gone = s["metrics"]["members_left"] - left_before[ip]
        if gone != 1:
            fail(f"{s['robot']} saw {gone} members leave while only {revoked} was revoked "
                 f"(a peer reopening its session taken for gone)")

    newcomer = "robot-17"
    sh("docker", "exec", operator, "spwi-agent", "fleet", "add", "--robot", newcomer, "--dir", fleet_dir)
    wait_until("every agent holding the new roster",
               lambda: all(must_status(ip)["roster_version"] == version + 2 for ip in rest), 10, poll=0.1)
    image = os.environ.get("SPWI_IMAGE", "spwi:latest")
    name = f"{PROJECT}-{newcomer}"
    sh("docker", "run", "-d", "--name", name, "--network", NETWORK, "-v", f"{PROJECT}_fleet:{fleet_dir}",
       image, "--fleet-dir", fleet_dir, "--robot-id", newcomer)
    try:
        _, took = wait_until(f"every agent counting the admitted {newcomer}", all_count(rest, 4), 30, poll=0.1)
        print(f"admitted while running: {newcomer} counted by the other 3 {took:.1f} s after its container started "
              f"(roster version {version} -> {version + 2}, no restart)")
        figures["admit_s"] = round(took, 1)
        decisions_advance(rest)
    finally:
        sh("docker", "rm", "-f", name, check=False)


def stuck_camera():
    compose("down", "-v", "--timeout", "1", "--remove-orphans")
    sh(*COMPOSE, "-f", STUCK, "up", "-d", "--scale", "agent=4")
    ips = [ip for _, ip in agents().values()]
    wait_until("4 agents counting 4 members", all_count(ips, 4), 60)

    def stuck_one():
        sts = [status(ip) for ip in ips]
        return next((s["robot"] for s in sts if s and s["feed_stale"]), None)

    robot, took = wait_until("one agent reporting its camera's feed as stale", stuck_one, 120, poll=0.2)
    print(f"stuck camera: {robot} sets its frozen feed aside ({took:.1f} s after the fleet formed)")
    time.sleep(1.0)
    decisions_advance(ips)
    for ip in ips:
        s = must_status(ip)
        if s["robot"] != robot and robot in (s["last_decision"] or {}).get("voters", []):
            fail(f"{s['robot']} still counts {robot}'s vote after its feed went stale")
    share, ticks = agreement(ips, seconds=5.0)
    print(f"stuck camera: all 4 keep deciding, same decision on {share:.1%} of {ticks} common ticks")
    figures["agreement_stuck_camera"] = round(share, 4)
    if share < 0.95:
        fail(f"with one stuck camera the agents agree on only {share:.1%} of ticks")


def main():
    print(f"compose project {PROJECT}")
    compose("up", "-d", "--scale", "agent=4")

    # 1. four agents, healthy, same decisions
    ag = agents()
    ips = [ip for _, ip in ag.values()]
    wait_until("4 agents counting 4 members", all_count(ips, 4), 60)
    wait_until(
        "every agent healthy (image health check on /healthz)",
        lambda: all(sh("docker", "inspect", "-f", "{{.State.Health.Status}}", c) == "healthy" for c in ag),
        30,
    )
    wait_until("decisions from every agent", lambda: all((status(ip) or {}).get("last_decision") for ip in ips), 10)
    share, ticks = agreement(ips)
    print(f"4 agents: same decision on {share:.1%} of {ticks} common ticks")
    if share < 0.95:
        fail(f"agents agree on only {share:.1%} of ticks")
    figures["agreement_4"] = round(share, 4)
    steady, compared = steady_agreement(ips, STEADY_S)
    print(f"4 agents, settled: {steady:.2%} of {compared} peer decisions the same as their own over {STEADY_S:.0f} s")
    figures["agreement_4_settled"] = round(steady, 4)
    if steady < STEADY_AGREEMENT:
        fail(f"a settled fleet agrees on only {steady:.2%} of compared decisions (< {STEADY_AGREEMENT:.1%})")
    rogues(ips)

    # 2. kill one
    victim = next(iter(ag))
    rest = [ip for c, (_, ip) in ag.items() if c != victim]
    sh("docker", "kill", victim)
    _, took = wait_until("the other 3 counting 3 members after docker kill", all_count(rest, 3), 10, poll=0.02)
    print(f"docker kill: the other 3 count 3 members after {took * 1000:.0f} ms")
    if took > KILL_BUDGET_S:
        fail(f"kill detected after {took:.2f} s > {KILL_BUDGET_S} s")
    figures["kill_detect_ms"] = round(took * 1000)
    keeps_deciding(rest, 3)

    # 3. scale to 6: the killed container restarts (same host name, same robot id) and two are new
    before = set(ag)
    started = time.monotonic()
    compose("up", "-d", "--no-recreate", "--scale", "agent=6")
    ag = agents()
    if len(ag) != 6:
        fail(f"{len(ag)} agent containers running after --scale agent=6")
    ips = [ip for _, ip in ag.values()]
    wait_until("6 agents counting 6 members", all_count(ips, 6), 60, poll=0.1)
    took = time.monotonic() - started
    print(f"scale 4 -> 6: every agent counts 6 members {took:.1f} s after `compose up` (container start included)")
    figures["scale_to_6_s"] = round(took, 1)
    # A robot votes on the ticks it sees the worker: every newcomer that has seen it
    # must be among the voters of the team's decisions.
    newcomers = {must_status(ip)["robot"] for c, (_, ip) in ag.items() if c not in before}
    voted = set()

    def newcomers_voted():
        sts = [status(ip) for ip in ips]
        for s in sts:
            if s and s["last_decision"]:
                voted.update(s["last_decision"]["voters"])
        seen = {s["robot"] for s in sts if s and s["robot"] in newcomers and s["metrics"]["frames_with_worker"] > 0}
        return seen and seen <= voted and seen

    seen, took = wait_until("every newcomer that saw the worker among the voters", newcomers_voted, 60, poll=0.1)
    print(f"newcomers {sorted(newcomers)}: {sorted(seen)} saw the worker and were counted as voters")
    keeps_deciding(ips, 6)
    share, ticks = agreement(ips)
    print(f"6 agents: same decision on {share:.1%} of {ticks} common ticks")
    # What the fresh robots (the two new, the killed one restarted) did while they
    # learned whom the team trusts: ticks withheld, votes of the team's history learned.
    for s in (must_status(ip) for ip in ips):
        m = s["metrics"]
        if m["decisions_withheld"] > 0 or m["history_votes_learned"] > 0:
            print(f"  {s['robot']} caught up with the team: {m['decisions_withheld']} decisions withheld, "
                  f"{m['history_votes_learned']} votes of its history learned, catching up now: {s['catching_up']}")
    if share < 0.95:
        fail(f"agents agree on only {share:.1%} of ticks")

    # 4. cut one off the network, then plug it back
    cut, (_, cut_ip) = next(iter(ag.items()))
    cut_robot = must_status(cut_ip)["robot"]
    rest = [ip for c, (_, ip) in ag.items() if c != cut]
    sh("docker", "network", "disconnect", NETWORK, cut)
    _, took = wait_until("the other 5 counting 5 after network disconnect", all_count(rest, 5), 10, poll=0.02)
    print(f"network disconnect: the other 5 drop {cut_robot} after {took * 1000:.0f} ms")
    if took > KILL_BUDGET_S + 0.5:
        fail(f"disconnect detected after {took:.2f} s")
    figures["disconnect_detect_ms"] = round(took * 1000)
    keeps_deciding(rest, 5)
    sh("docker", "network", "connect", NETWORK, cut)
    _, took = wait_until("the cut agent counted again after reconnect", all_count(rest, 6), 60, poll=0.1)
    print(f"network reconnect: {cut_robot} counted again after {took:.1f} s")
    figures["reconnect_s"] = round(took, 1)

    # 5. the router goes down: the mesh stays
    ips = [ip for _, ip in agents().values()]
    wait_until("all 6 counting 6 before stopping the router", all_count(ips, 6), 30, poll=0.1)
    compose("stop", "--timeout", "1", "router")
    time.sleep(2.0)
    keeps_deciding(ips, 6)
    share, ticks = agreement(ips, seconds=2.0)
    print(f"router stopped: all 6 still decide, same decision on {share:.1%} of {ticks} common ticks")
    figures["agreement_without_router"] = round(share, 4)

    # 6. real packet loss on every agent's interface
    real_packet_loss()

    # 7. a camera stuck on one frame
    stuck_camera()

    # 8. a robot revoked and one admitted while the fleet runs
    roster_changes()
    print("figures: " + json.dumps(figures))


if __name__ == "__main__":
    try:
        main()
        print("compose end-to-end: PASS")
    except Exception as e:  # noqa: BLE001 - report, tear down, fail
        traceback.print_exc()
        print(f"compose end-to-end: FAIL: {e}", file=sys.stderr)
        for svc in ("fleet-setup", "router", "world", "agent"):
            logs = subprocess.run([*COMPOSE, "logs", "--tail", "15", svc], capture_output=True, text=True).stdout
            print(f"--- last logs of {svc}:\n{logs}", file=sys.stderr)
        sys.exit(1)
    finally:
        subprocess.run([*COMPOSE, "down", "-v", "--timeout", "1", "--remove-orphans"], capture_output=True)

//! Admitting and revoking robots while the fleet runs: real Zenoh over mutual TLS,
//! access rules from the roster, agents with the fixture models. Each robot runs on a
//! copy of the fleet directory of its own (its host's, taken before the change); the
//! operator changes the roster in theirs and says it on the fleet with `fleet publish`
//! (`spwi_agent::fleet::cli::publish`). The test's hub (frames and the decision log)
//! holds the newest roster from the start, as the world's host would.
//! Run: `cargo test -p spwi-tests --test roster -- --nocapture` to see the figures.

use spwi_agent::config::AgentConfig;
use spwi_agent::daemon::Options;
use spwi_agent::fleet::authority::{self, Validity};
use spwi_agent::fleet::{cli, FleetDir, Role};
use spwi_proto::keys::{self, Topic};
use spwi_proto::*;
use spwi_tests::*;
use std::collections::BTreeSet;
use std::path::PathBuf;
use std::time::{Duration, Instant};

const TICK: Duration = Duration::from_millis(100);

/// The operator's fleet directory (holding ca.key) and the hosts' copies, removed
/// when dropped.
struct Operator {
    root: PathBuf,
    dir: FleetDir,
}

impl Operator {
    fn make(test: &str, robots: &[&str]) -> Operator {
        let root = std::env::temp_dir().join(format!("spwi-roster-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let dir = FleetDir::new(root.join("operator"));
        let members: Vec<_> =
            std::iter::once(("world", Role::World)).chain(robots.iter().map(|r| (*r, Role::Robot))).collect();
        authority::create(&dir, &FleetId::new(format!("live-{test}")).unwrap(), &members, Validity::days(1)).unwrap();
        Operator { root, dir }
    }

    /// What `name`'s host holds: the roster as it is now, the CA's certificate, its
    /// own certificate and key.
    fn host_copy(&self, name: &str) -> FleetDir {
        self.copy_into(name, &format!("host-{name}"))
    }

    /// The same, into folder `folder`.
    fn copy_into(&self, name: &str, folder: &str) -> FleetDir {
        let host = FleetDir::new(self.root.join(folder));
        std::fs::create_dir_all(host.members()).unwrap();
        let d = &self.dir;
        for (from, to) in [
            (d.roster(), host.roster()),
            (d.ca_cert(), host.ca_cert()),
            (d.member_cert(name), host.member_cert(name)),
            (d.member_key(name), host.member_key(name)),
        ] {
            std::fs::copy(from, to).unwrap();
        }
        host
    }

    /// `fleet publish --dir <operator's> --as world --connect <hub>`.
    async fn publish(&self, hub: &Hub) -> u64 {
        let zenoh = spwi_agent::zenoh_config::loopback_peer(std::slice::from_ref(&hub.locator)).unwrap();
        within!(20, "fleet publish", cli::publish(&self.dir.root, "world", zenoh)).unwrap()
    }
}

impl Drop for Operator {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.root);
    }
}

/// Robot `name` on its host's copy of the fleet directory.
async fn start(hub: &Hub, host: &FleetDir, name: &str) -> InProcessAgent {
    let (zenoh, creds) = secured_peer(&host.root, name, std::slice::from_ref(&hub.locator)).unwrap();
    // With its HTTP server, as in a deployment: a daemon that leaves by itself must
    // end it too.
    let mut config = AgentConfig::default();
    config.http.listen = Some("127.0.0.1:0".parse().unwrap());
    let opts =
        Options { robot: id(name), fleet: hub.fleet.clone(), config, zenoh, record: None, credentials: Some(creds) };
    InProcessAgent::start_with(opts, &models()).await.unwrap()
}

/// The test's fleet running: the hub (holding the operator's roster as it is now),
/// its decision log, frames for `framed`, and `robots` on their hosts' copies, each
/// counting all of them.
struct Running {
    hub: Hub,
    collector: Decisions,
    publisher: Publisher,
    agents: Vec<InProcessAgent>,
}

async fn run_fleet(op: &Operator, hosts: &[FleetDir], robots: &[RobotId], framed: Vec<RobotId>) -> Running {
    let hub = Hub::start_secured(&op.dir.root, "world").await.unwrap();
    let collector = hub.decisions().await.unwrap();
    let publisher = Publisher::start(&hub, framed, TICK);
    let mut agents = Vec::new();
    for (r, host) in robots.iter().zip(hosts) {
        agents.push(start(&hub, host, r.as_str()).await);
    }
    let n = robots.len() as u32;
    collector.wait_members(robots, n, Instant::now(), Duration::from_secs(20)).await.unwrap();
    Running { hub, collector, publisher, agents }
}

fn members(a: &InProcessAgent) -> BTreeSet<RobotId> {
    a.started.status.lock().unwrap().members.iter().cloned().collect()
}

/// Waits until `ok` holds for the members of every agent in `agents`; returns how long.
async fn members_become(agents: &[&InProcessAgent], ok: impl Fn(&BTreeSet<RobotId>) -> bool, what: &str) -> Duration {
    let since = Instant::now();
    within!(15, what, async {
        while !agents.iter().all(|a| ok(&members(a))) {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    });
    since.elapsed()
}

/// The least share of ticks each robot decides while the roster changes. Reopening
/// the session (Zenoh sets access rules only when a session opens) drops its links
/// for about 10 ms: frames and peers' messages of that moment may be lost to it (100 %
/// in each of 18 runs since reopens stopped waiting Zenoh's 500 ms scouting delay;
/// down to 89.8 % in 7 of 16 before); a tick or two of slack for a loaded host.
/// Every tick is decided by some robot: they reopen at different moments.
const LEAST_DECIDED: f64 = 0.95;

/// Checks that every tick of `from..=to` was decided by one of `robots` at least and
/// that each of them decided at least [`LEAST_DECIDED`] of them; prints what each
/// decided.
fn decided_on(collector: &Decisions, robots: &[RobotId], from: u64, to: u64) {
    let by = collector.by_robot();
    let none: Vec<u64> =
        (from..=to).filter(|t| !robots.iter().any(|r| by.get(r).is_some_and(|m| m.contains_key(t)))).collect();
    let shares: Vec<f64> = robots
        .iter()
        .map(|r| by.get(r).map_or(0, |m| m.range(from..=to).count()) as f64 / (to - from + 1) as f64)
        .collect();
    eprintln!(
        "ticks {from}..={to}: decided by {:?}; by none of them: {none:?}",
        robots.iter().zip(&shares).map(|(r, s)| format!("{r} {:.1} %", s * 100.0)).collect::<Vec<_>>()
    );
    assert!(none.is_empty(), "ticks none of {robots:?} decided while the roster changed: {none:?}");
    for (r, s) in robots.iter().zip(shares) {
        assert!(s >= LEAST_DECIDED, "{r} decided {:.1} % of the ticks while the roster changed", s * 100.0);
    }
}

/// Checks that every decision of `robots` heard since `since` counted `members` live
/// members: while the members reopen their sessions with the new roster's rules
/// (their links drop for a moment), none of them is taken for gone.
fn counted_throughout(collector: &Decisions, robots: &[RobotId], since: Instant, members: u32) {
    let seen: Vec<_> = collector.all().into_iter().filter(|d| d.at >= since && robots.contains(&d.msg.robot)).collect();
    assert!(seen.len() > 20, "only {} decisions heard since the members changed", seen.len());
    for d in seen {
        assert_eq!(
            d.msg.live_members, members,
            "{} decided tick {} with {} live members",
            d.msg.robot, d.msg.tick, d.msg.live_members
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_robot_admitted_while_the_fleet_runs_is_counted_by_every_robot() {
    let _serial = serial().await;
    within!(120, "test", async {
        let op = Operator::make("admit", &["r1", "r2", "r3"]);
        let hosts: Vec<_> = ["r1", "r2", "r3"].iter().map(|r| op.host_copy(r)).collect();
        let r4 = RobotId::new("r4").unwrap();
        authority::add(&op.dir, &r4, Role::Robot, Validity::days(1)).unwrap();
        let host4 = op.host_copy("r4");

        let veterans = vec![id("r1"), id("r2"), id("r3")];
        let all = [veterans.clone(), vec![r4.clone()]].concat();
        let Running { hub, collector, publisher, mut agents } = run_fleet(&op, &hosts, &veterans, all.clone()).await;
        let from = publisher.current_tick();

        let version = op.publish(&hub).await;
        let started = Instant::now();
        agents.push(start(&hub, &host4, "r4").await);
        let refs: Vec<_> = agents.iter().collect();
        let took = members_become(&refs, |m| m.contains(&r4) && m.len() == 4, "every robot to count r4").await;
        eprintln!("r4 counted by every robot {:.2} s after it started", took.as_secs_f64());
        let counted = Instant::now();
        for a in &agents[..3] {
            let s = a.started.status.lock().unwrap().clone();
            assert_eq!(s.roster_version, Some(version), "{} holds roster version {:?}", a.robot, s.roster_version);
            assert_eq!(s.transport.rosters_adopted, 1, "{}", a.robot);
        }
        for host in &hosts {
            let kept = spwi_agent::fleet::Roster::load(&host.roster()).unwrap();
            assert_eq!(kept.version, version, "the adopted roster is kept in {}", host.roster().display());
        }
        collector.wait_members(&all, 4, started, Duration::from_secs(10)).await.unwrap();
        tokio::time::sleep(Duration::from_secs(2)).await;
        let to = publisher.current_tick() - 2;
        decided_on(&collector, &veterans, from, to);
        counted_throughout(&collector, &all, counted, 4);
        for a in &agents[..3] {
            let m = a.started.status.lock().unwrap().metrics.clone();
            assert_eq!((m.members_joined, m.members_left), (3, 0), "{}: members joined and left", a.robot);
        }
        for a in agents {
            a.stop().await.unwrap();
        }
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_robot_revoked_while_the_fleet_runs_is_cut_off() {
    let _serial = serial().await;
    within!(120, "test", async {
        let op = Operator::make("revoke", &["r1", "r2", "r3"]);
        let hosts: Vec<_> = ["r1", "r2", "r3"].iter().map(|r| op.host_copy(r)).collect();
        // What r2 still holds when it would go on regardless: its files from before.
        let stale = op.copy_into("r2", "stale-r2");
        let robots = vec![id("r1"), id("r2"), id("r3")];
        let Running { hub, collector, publisher, mut agents } = run_fleet(&op, &hosts, &robots, robots.clone()).await;

        authority::revoke(&op.dir, "r2").unwrap();
        let from = publisher.current_tick();
        let version = op.publish(&hub).await;
        let r2 = agents.remove(1);
        let took = members_become(&[&agents[0], &agents[1]], |m| !m.contains(&id("r2")), "r2 to be no member").await;
        eprintln!("r2 no member of r1 and r3 {:.2} s after the roster was said", took.as_secs_f64());
        let dropped = Instant::now();
        // Nobody speaks to it any more: the publisher's and the peers' rules deny it.
        let cut = members_become(&[&r2], |m| m.len() == 1, "r2 to be alone").await;
        eprintln!("r2 counts no one else {:.2} s later", cut.as_secs_f64());
        // Given the new roster on its host, the revoked daemon leaves, saying why.
        std::fs::copy(op.dir.roster(), hosts[1].roster()).unwrap();
        within!(15, "r2 to leave", async {
            while !r2.finished() {
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        });
        let left = r2.stop().await.unwrap_err().to_string();
        assert!(left.contains("r2 is revoked by roster version"), "{left}");

        // r2's files from before, in hands that ignore the roster: its shares, at
        // confidence 1, reach no one's decisions, and its links carry nothing.
        let (config, _) = secured_peer(&stale.root, "r2", std::slice::from_ref(&hub.locator)).unwrap();
        let session = within!(10, "r2's old session", zenoh::open(config)).unwrap();
        let _token = session.liveliness().declare_token(keys::alive(&hub.fleet, &id("r2"))).await.unwrap();
        let key = keys::robot_topic(&hub.fleet, &id("r2"), Topic::Embedding);
        let since = Instant::now();
        for _ in 0..30 {
            session.put(&key, encode(&lying_share(&id("r2"), clock_tick(), Station::Storage))).await.unwrap();
            tokio::time::sleep(TICK).await;
        }
        let honest = [id("r1"), id("r3")];
        for d in collector.all().iter().filter(|d| d.at >= since && honest.contains(&d.msg.robot)) {
            assert!(!d.msg.voters.contains(&id("r2")), "{} counted r2's vote at tick {}", d.msg.robot, d.msg.tick);
        }
        // Nor r2 (revoked), nor one another while r1 and r3 reopened their sessions.
        counted_throughout(&collector, &honest, dropped, 2);
        for a in &agents {
            let m = a.started.status.lock().unwrap().metrics.clone();
            assert_eq!(
                (m.members_joined, m.members_left),
                (2, 1),
                "{}: members joined and left (only r2 left)",
                a.robot
            );
        }
        for a in &agents {
            let s = a.started.status.lock().unwrap().clone();
            assert_eq!(s.roster_version, Some(version));
            let refused = s.transport.bad_messages.get(&spwi_agent::metrics::DropReason::NotAdmitted).copied();
            eprintln!("{}: r2's messages refused before the reopened session's rules: {refused:?}", a.robot);
        }
        let to = publisher.current_tick() - 2;
        decided_on(&collector, &honest, from, to);
        session.close().await.unwrap();
        for a in agents {
            a.stop().await.unwrap();
        }
    });
}

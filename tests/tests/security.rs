//! A fleet that only its own robots can join: real Zenoh sessions over mutual TLS on
//! loopback, access control generated from the roster, real agents with the fixture
//! models, certificates made by the fleet tool's own functions.
//!
//! Covers: the members decide together while a plain-TCP peer, a TLS peer without a
//! certificate, a peer with another CA's certificate and one with an expired
//! certificate never get a link, never count as members and never reach anyone (nor,
//! on a QUIC listener, a QUIC peer without a certificate or with a wrong one); a
//! member cannot publish a vote, embedding, decision or detections as another robot nor
//! hold its liveliness token (also as a whole daemon started under a stolen id); a
//! revoked robot cannot rejoin with its old files; a router on the path forwards a
//! member's messages and refuses what the member may not say (it runs the same rules).
//! Run: `cargo test -p spwi-tests --test security`.

use spwi_agent::config::AgentConfig;
use spwi_agent::daemon::Options;
use spwi_agent::fleet::authority::{self, Validity};
use spwi_agent::fleet::{Credentials, FleetDir, Role};
use spwi_agent::zenoh_config;
use spwi_proto::keys::{self, Topic};
use spwi_proto::*;
use spwi_tests::*;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const TICK: Duration = Duration::from_millis(100);

/// A fleet directory with members world, router, r1, r2, r3 and r4 (whose certificate expired
/// yesterday), and a second CA of the same fleet name with a robot r9.
struct Dirs {
    root: PathBuf,
    fleet: FleetDir,
    other: FleetDir,
}

impl Dirs {
    fn make(test: &str) -> Dirs {
        let root = std::env::temp_dir().join(format!("spwi-security-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let (fleet, other) = (FleetDir::new(root.join("fleet")), FleetDir::new(root.join("other")));
        let f = FleetId::new(format!("sec-{test}")).unwrap();
        let members = [
            ("world", Role::World),
            ("router", Role::Router),
            ("r1", Role::Robot),
            ("r2", Role::Robot),
            ("r3", Role::Robot),
        ];
        authority::create(&fleet, &f, &members, Validity::days(30)).unwrap();
        let now = time::OffsetDateTime::now_utc();
        let expired = Validity { not_before: now - time::Duration::days(3), not_after: now - time::Duration::days(1) };
        authority::add(&fleet, &id("r4"), Role::Robot, expired).unwrap();
        authority::create(&other, &f, &[("r9", Role::Robot)], Validity::days(30)).unwrap();
        Dirs { root, fleet, other }
    }
}

impl Drop for Dirs {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.root);
    }
}

/// The secured hub (the fleet's world) and what reaches it: every key under the
/// fleet, every decision.
struct Observed {
    hub: Hub,
    keys_seen: Arc<Mutex<Vec<String>>>,
    collector: Decisions,
    _watch: zenoh::pubsub::Subscriber<()>,
}

async fn observe(dirs: &Dirs) -> Observed {
    let hub = Hub::start_secured(&dirs.fleet.root, "world").await.unwrap();
    let keys_seen = Arc::new(Mutex::new(Vec::new()));
    let s = keys_seen.clone();
    let _watch = hub
        .session
        .declare_subscriber(keys::everything(&hub.fleet))
        .callback(move |sample| s.lock().unwrap().push(sample.key_expr().as_str().to_owned()))
        .await
        .unwrap();
    let collector = hub.decisions().await.unwrap();
    Observed { hub, keys_seen, collector, _watch }
}

/// A TLS peer of our own making (not through the fleet's checks): the CA to trust
/// the hub with, and optionally a certificate and key to present.
fn tls_peer(connect: &str, ca: &Path, presented: Option<(PathBuf, PathBuf)>) -> zenoh::Config {
    let mut c = zenoh_config::loopback_peer(&[connect.to_owned()]).unwrap();
    let q = |p: &Path| format!("{:?}", p.display().to_string());
    let mut set = |k: &str, v: String| c.insert_json5(k, &v).unwrap();
    set("transport/link/protocols", r#"["tls"]"#.into());
    set("listen/endpoints", "[]".into());
    set("transport/link/tls/root_ca_certificate", q(ca));
    set("transport/link/tls/verify_name_on_connect", "false".into());
    if let Some((cert, key)) = presented {
        set("transport/link/tls/enable_mtls", "true".into());
        set("transport/link/tls/connect_certificate", q(&cert));
        set("transport/link/tls/connect_private_key", q(&key));
    }
    c
}

async fn open(config: zenoh::Config, who: &str) -> zenoh::Session {
    within!(10, format!("{who}'s session to open"), zenoh::open(config)).unwrap_or_else(|e| panic!("{who}: {e}"))
}

/// Acts as `robot` for `period`: holds its liveliness token and puts a valid embedding
/// message with a vote, the vote alone, a decision and a detection frame under its keys
/// every tick.
async fn impersonate(session: zenoh::Session, fleet: FleetId, robot: RobotId, period: Duration) {
    let (fleet, robot) = (&fleet, &robot);
    let _token = session.liveliness().declare_token(keys::alive(fleet, robot)).await.unwrap();
    let vote = VoteMsg {
        robot: robot.clone(),
        instance: 7,
        tick: 0,
        steps: vec![StepVote { class: Station::Manufacturing, confidence: 1.0 }],
        visibility: 1000,
        worker: None,
        quality: 1.0,
        signature: Vec::new(),
    };
    let end = Instant::now() + period;
    let mut tick = 0;
    while Instant::now() < end {
        tick += 1;
        let frame = scripted_frame(robot, 0, tick);
        let decision = DecisionMsg {
            robot: robot.clone(),
            instance: 7,
            tick,
            steps: vec![],
            voters: vec![robot.clone()],
            live_members: 1,
            decided_by: DecidedBy::AllVoted,
            digest: 0,
        };
        let share = EmbeddingMsg {
            robot: robot.clone(),
            instance: 7,
            tick,
            embedding: None,
            visibility: 1000,
            vote: Some(VoteMsg { tick, ..vote.clone() }),
            worker: None,
            facing: None,
            landmarks: Vec::new(),
            verdict: None,
            people: Vec::new(),
        };
        let messages = [
            (Topic::Embedding, encode(&share)),
            (Topic::Vote, encode(&VoteMsg { tick, ..vote.clone() })),
            (Topic::Decision, encode(&decision)),
            (Topic::Detections, encode(&frame)),
        ];
        for (topic, bytes) in messages {
            session.put(keys::robot_topic(fleet, robot, topic), bytes).await.unwrap();
        }
        tokio::time::sleep(TICK).await;
    }
}

/// A daemon calling itself `robot` with the Zenoh config and credentials given.
fn agent_as(hub: &Hub, robot: &str, zenoh: zenoh::Config, credentials: Option<Arc<Credentials>>) -> Options {
    Options {
        robot: id(robot),
        fleet: hub.fleet.clone(),
        config: AgentConfig::default(),
        zenoh,
        record: None,
        credentials,
    }
}

/// Runs the publisher for `robots` until `ticks` ticks have passed.
async fn run_ticks(hub: &Hub, robots: Vec<RobotId>, ticks: u64) {
    let publisher = Publisher::start(hub, robots, TICK);
    within!(ticks as f64 * 0.1 + 20.0, "ticks to pass", async {
        while publisher.published() < ticks {
            tokio::time::sleep(TICK).await;
        }
    });
}

/// Every decision of `robots` since `since` counted exactly `members` and only them;
/// and each of them decided at least `at_least` times.
fn only_members_counted(collector: &Decisions, robots: &[RobotId], since: Instant, at_least: usize) {
    let seen = collector.all();
    for r in robots {
        let mine: Vec<_> = seen.iter().filter(|s| s.at >= since && &s.msg.robot == r).collect();
        assert!(mine.len() >= at_least, "{r} decided only {} times", mine.len());
        for s in mine {
            assert_eq!(s.msg.live_members as usize, robots.len(), "{r} at tick {} counted {:?}", s.msg.tick, s.msg);
            assert!(s.msg.voters.iter().all(|v| robots.contains(v)), "{r} counted a voter of {:?}", s.msg.voters);
        }
    }
    let strangers: Vec<_> = seen.iter().filter(|s| !robots.contains(&s.msg.robot)).map(|s| &s.msg.robot).collect();
    assert!(strangers.is_empty(), "decisions from outside the fleet reached the hub: {strangers:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn outsiders_get_no_link_and_are_never_counted() {
    let _serial = serial().await;
    within!(90, "the test", async {
        let dirs = Dirs::make("outsiders");
        let Observed { hub, keys_seen, collector, _watch } = observe(&dirs).await;
        assert!(hub.locator.starts_with("tls/"), "the hub listens on {}", hub.locator);
        let models = models();
        let members = vec![id("r1"), id("r2")];
        let mut agents = Vec::new();
        for r in &members {
            agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
        }
        // A control: a member's own raw session does get a link.
        let (member, _) = secured_peer(&dirs.fleet.root, "r3", std::slice::from_ref(&hub.locator)).unwrap();
        let member = open(member, "r3").await;

        let plain = zenoh_config::loopback_peer(&[hub.locator.replacen("tls/", "tcp/", 1)]).unwrap();
        let nocert = tls_peer(&hub.locator, &dirs.fleet.ca_cert(), None);
        let other_ca = tls_peer(
            &hub.locator,
            &dirs.other.ca_cert(),
            Some((dirs.other.member_cert("r9"), dirs.other.member_key("r9"))),
        );
        let expired = tls_peer(
            &hub.locator,
            &dirs.fleet.ca_cert(),
            Some((dirs.fleet.member_cert("r4"), dirs.fleet.member_key("r4"))),
        );
        let outsiders = [(plain, "mallory"), (nocert, "nocert"), (other_ca, "r9"), (expired, "r4")];
        let mut sessions = Vec::new();
        for (config, name) in outsiders {
            sessions.push((open(config, name).await, id(name)));
        }

        let since = Instant::now();
        let fleet = hub.fleet.clone();
        let attacks: Vec<_> = sessions
            .iter()
            .map(|(s, r)| tokio::spawn(impersonate(s.clone(), fleet.clone(), r.clone(), Duration::from_secs(3))))
            .collect();
        run_ticks(&hub, members.clone(), 40).await;
        for a in attacks {
            within!(10, "an outsider to finish", a).unwrap();
        }

        for (s, name) in &sessions {
            let links = s.info().peers_zid().await.count();
            assert_eq!(links, 0, "outsider {name} got {links} links into the fleet");
        }
        assert!(member.info().peers_zid().await.count() >= 1, "the member r3 got no link: the test proves nothing");
        let leaked: Vec<_> = keys_seen
            .lock()
            .unwrap()
            .iter()
            .filter(|k| ["mallory", "nocert", "r9", "r4"].iter().any(|n| k.contains(&format!("/{n}/"))))
            .cloned()
            .collect();
        assert!(leaked.is_empty(), "outsiders' messages reached the hub: {leaked:?}");
        only_members_counted(&collector, &members, since, 20);
        assert!(Credentials::load(&dirs.fleet, "r4").unwrap_err().to_string().contains("expired on"));
        for a in agents {
            a.stop().await.unwrap();
        }
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn outsiders_get_no_quic_link_either() {
    let _serial = serial().await;
    within!(60, "the test", async {
        let dirs = Dirs::make("quic");
        let hub =
            Hub::start_secured_listening(&dirs.fleet.root, "world", "quic/127.0.0.1:0?mixed_rel=1").await.unwrap();
        assert!(hub.locator.starts_with("quic/"), "the hub listens on {}", hub.locator);
        let quic_peer = |ca: &Path, presented: Option<(PathBuf, PathBuf)>| {
            let mut c = tls_peer(&hub.locator, ca, presented);
            c.insert_json5("transport/link/protocols", r#"["quic"]"#).unwrap();
            c
        };
        // A control: a member's own session does get a QUIC link.
        let (member, _) = secured_peer(&dirs.fleet.root, "r3", std::slice::from_ref(&hub.locator)).unwrap();
        let member = open(member, "r3").await;
        let outsiders = [
            (quic_peer(&dirs.fleet.ca_cert(), None), "nocert"),
            (quic_peer(&dirs.other.ca_cert(), Some((dirs.other.member_cert("r9"), dirs.other.member_key("r9")))), "r9"),
            (quic_peer(&dirs.fleet.ca_cert(), Some((dirs.fleet.member_cert("r4"), dirs.fleet.member_key("r4")))), "r4"),
        ];
        let mut sessions = Vec::new();
        for (config, name) in outsiders {
            sessions.push((open(config, name).await, name));
        }
        tokio::time::sleep(Duration::from_secs(3)).await; // connection retries
        assert!(
            member.info().peers_zid().await.count() >= 1,
            "the member r3 got no QUIC link: the test proves nothing"
        );
        for (s, name) in &sessions {
            let links = s.info().peers_zid().await.count();
            assert_eq!(links, 0, "outsider {name} got {links} QUIC links into the fleet");
        }
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_member_cannot_speak_for_another_robot() {
    let _serial = serial().await;
    within!(90, "the test", async {
        let dirs = Dirs::make("impostor");
        let Observed { hub, keys_seen, collector, _watch } = observe(&dirs).await;
        let models = models();
        let r1 = InProcessAgent::start(&hub, &id("r1"), &models, AgentConfig::default()).await.unwrap();
        // A whole daemon calling itself r2 with r3's certificate, and r3's raw session
        // speaking for r2 (and, as a control, for itself).
        let (zenoh, credentials) = hub.member_config("r3").unwrap();
        let impostor = InProcessAgent::start_with(agent_as(&hub, "r2", zenoh, credentials), &models).await.unwrap();
        let (raw, _) = secured_peer(&dirs.fleet.root, "r3", std::slice::from_ref(&hub.locator)).unwrap();
        let r3 = open(raw, "r3").await;

        let since = Instant::now();
        let fleet = hub.fleet.clone();
        // The hub publishes frames for r1 only, so that any message on r2's keys it
        // receives is the impostors'.
        tokio::join!(
            run_ticks(&hub, vec![id("r1")], 40),
            impersonate(r3.clone(), fleet.clone(), id("r2"), Duration::from_secs(3)),
            impersonate(r3.clone(), fleet.clone(), id("r3"), Duration::from_secs(3)),
        );

        let seen = keys_seen.lock().unwrap().clone();
        let from = |robot: &str, topic: Topic| {
            seen.iter().filter(|k| **k == keys::robot_topic(&fleet, &id(robot), topic)).count()
        };
        assert!(from("r3", Topic::Embedding) > 0, "r3's own votes were refused too: the test proves nothing");
        for topic in [Topic::Embedding, Topic::Vote, Topic::Decision, Topic::Detections, Topic::Ballots] {
            assert_eq!(from("r2", topic), 0, "a message on r2's {} reached the hub", topic.as_str());
        }
        // r1 counts itself and r3 (whose own token is its right), never r2.
        let mut counted_r3 = false;
        let seen = collector.all();
        assert!(seen.iter().all(|s| s.msg.robot != id("r2")), "a decision as r2 reached the hub");
        for s in seen.iter().filter(|s| s.at >= since && s.msg.robot == id("r1")) {
            assert!(!s.msg.voters.contains(&id("r2")), "r1 counted a vote of r2 at tick {}", s.msg.tick);
            counted_r3 |= s.msg.live_members == 2;
            assert!(s.msg.live_members <= 2, "r1 counted {} members at tick {}", s.msg.live_members, s.msg.tick);
        }
        assert!(counted_r3, "r1 never counted r3's own token: the test proves nothing");
        impostor.stop().await.unwrap();
        r1.stop().await.unwrap();
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_revoked_robot_cannot_rejoin_with_its_old_files() {
    let _serial = serial().await;
    within!(90, "the test", async {
        let dirs = Dirs::make("revoked");
        // r2 keeps a copy of the fleet directory from before its revocation.
        let stale = dirs.root.join("stale");
        copy_dir(&dirs.fleet.root, &stale);
        authority::revoke(&dirs.fleet, "r2").unwrap();
        let e = Credentials::load(&dirs.fleet, "r2").unwrap_err().to_string();
        assert!(e.contains("r2 is revoked"), "{e}");

        let Observed { hub, keys_seen, collector, _watch } = observe(&dirs).await;
        let models = models();
        let r1 = InProcessAgent::start(&hub, &id("r1"), &models, AgentConfig::default()).await.unwrap();
        let (zenoh, creds) = secured_peer(&stale, "r2", std::slice::from_ref(&hub.locator)).unwrap();
        let r2 = InProcessAgent::start_with(agent_as(&hub, "r2", zenoh, Some(creds)), &models).await.unwrap();
        let since = Instant::now();
        run_ticks(&hub, vec![id("r1"), id("r2")], 30).await;

        only_members_counted(&collector, &[id("r1")], since, 15);
        // (the hub's own frames for r2 aside: the world may publish them)
        let leaked =
            keys_seen.lock().unwrap().iter().filter(|k| k.contains("/r2/") && !k.ends_with("/detections")).count();
        assert_eq!(leaked, 0, "the revoked r2 reached the hub");
        r2.stop().await.unwrap();
        r1.stop().await.unwrap();
    });
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_router_on_the_path_enforces_the_rules_it_is_trusted_with() {
    let _serial = serial().await;
    within!(60, "the test", async {
        let dirs = Dirs::make("router");
        // The router (as spwi-router configures it), the hub connected to it, and r3 as
        // a client of the router: everything r3 says reaches the hub through the router,
        // which is the last hop the hub judges.
        let creds = Credentials::load(&dirs.fleet, "router").unwrap();
        let mut config =
            zenoh_config::build(None, &[r#"mode:"router""#.into(), r#"listen/endpoints:["tcp/127.0.0.1:0"]"#.into()])
                .unwrap();
        config.insert_json5("scouting/multicast/enabled", "false").unwrap();
        spwi_agent::fleet::secure::apply(&mut config, &creds).unwrap();
        let router = open(config, "router").await;
        let at = router.info().locators().await.into_iter().next().unwrap().to_string();
        assert!(at.starts_with("tls/"), "the router listens on {at}");
        let (hub, _) = secured_peer(&dirs.fleet.root, "world", std::slice::from_ref(&at)).unwrap();
        let hub = open(hub, "hub").await;
        let fleet = FleetId::new("sec-router").unwrap();
        let seen = Arc::new(Mutex::new(Vec::new()));
        let s = seen.clone();
        let _sub = hub
            .declare_subscriber(keys::everything(&fleet))
            .callback(move |sample| s.lock().unwrap().push(sample.key_expr().as_str().to_owned()))
            .await
            .unwrap();
        let (mut client, _) = secured_peer(&dirs.fleet.root, "r3", std::slice::from_ref(&at)).unwrap();
        client.insert_json5("mode", r#""client""#).unwrap();
        client.insert_json5("listen/endpoints", "[]").unwrap();
        let r3 = open(client, "r3").await;
        tokio::time::sleep(Duration::from_millis(500)).await; // declarations reach the router
        tokio::join!(
            impersonate(r3.clone(), fleet.clone(), id("r2"), Duration::from_secs(2)),
            impersonate(r3.clone(), fleet.clone(), id("r3"), Duration::from_secs(2)),
        );
        tokio::time::sleep(Duration::from_millis(300)).await;
        let seen = seen.lock().unwrap().clone();
        let own = seen.iter().filter(|k| k.contains("/robot/r3/")).count();
        let forged = seen.iter().filter(|k| k.contains("/robot/r2/")).count();
        assert!(own > 0, "the router forwarded nothing of r3's own: the test proves nothing");
        assert_eq!(forged, 0, "the router forwarded r3's messages as r2");
    });
}

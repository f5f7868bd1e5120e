//! An adversary that holds a valid certificate of the fleet: a member whose word is
//! false. Real Zenoh over mutual TLS, access control from the roster, agents with the
//! fixture models; the adversary is a raw session presenting member r4's certificate.
//!
//! Covers: a member that votes a wrong station every tick at confidence 1, claiming
//! the fullest view, stops counting once the others have seen it disagree; a vote
//! signed in an earlier run of the fleet is never counted after a restart, neither at
//! its own tick nor carried to the current one; a member flooding ticks far off the
//! clock in a secured fleet stops nothing (tests/tests/clock.rs: in an open one).
//! Run: `cargo test -p spwi-tests --test adversary -- --nocapture` to see the figures.

use spwi_agent::config::AgentConfig;
use spwi_agent::fleet::authority::{self, Validity};
use spwi_agent::fleet::{FleetDir, Role};
use spwi_agent::metrics::DropReason;
use spwi_core::model::{Backend, ModelSet};
use spwi_proto::keys::{self, Topic};
use spwi_proto::*;
use spwi_sim::service::{self, WorldOptions};
use spwi_tests::*;
use spwi_world::layout::Layout;
use spwi_world::world::Scenario;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::qos::CongestionControl;

const TICK: Duration = Duration::from_millis(100);

/// A fleet directory with the world and robots r1..r4, removed when dropped.
struct Fleet {
    root: PathBuf,
    dir: FleetDir,
}

impl Fleet {
    fn make(test: &str) -> Fleet {
        let root = std::env::temp_dir().join(format!("spwi-adversary-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let dir = FleetDir::new(root.join("fleet"));
        let members = [
            ("world", Role::World),
            ("r1", Role::Robot),
            ("r2", Role::Robot),
            ("r3", Role::Robot),
            ("r4", Role::Robot),
        ];
        authority::create(&dir, &FleetId::new(format!("adv-{test}")).unwrap(), &members, Validity::days(30)).unwrap();
        Fleet { root, dir }
    }
}

impl Drop for Fleet {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.root);
    }
}

/// Member `name`'s own raw session: its certificate, its liveliness token.
async fn member_session(fleet: &Fleet, hub: &Hub, name: &str) -> (zenoh::Session, zenoh::liveliness::LivelinessToken) {
    let (config, _) = secured_peer(&fleet.dir.root, name, std::slice::from_ref(&hub.locator)).unwrap();
    let session = within!(10, "the adversary's session", zenoh::open(config)).unwrap();
    let token = session.liveliness().declare_token(keys::alive(&hub.fleet, &id(name))).await.unwrap();
    (session, token)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_confident_liar_with_a_valid_certificate_stops_counting() {
    let _serial = serial().await;
    within!(120, "test", async {
        let fleet = Fleet::make("liar");
        let hub = Hub::start_secured(&fleet.dir.root, "world").await.unwrap();
        // The trained models on the simulated floor: honest robots that mostly agree, as
        // real ones do (random fixture weights would disagree among themselves).
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/default");
        let models = ModelSet::load(&dir, Backend::Tract, None).unwrap();
        let collector = hub.decisions().await.unwrap();
        let honest = vec![id("r1"), id("r2"), id("r3")];
        let mut agents = Vec::new();
        for r in &honest {
            agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
        }
        let (stop_world, world) = {
            let (stop, rx) = tokio::sync::watch::channel(false);
            let opts = WorldOptions {
                fleet: hub.fleet.clone(),
                workers: 1,
                scenario: Scenario::Dynamic,
                seed: 3,
                layout: Layout::default_layout(),
                zenoh: hub.member_config("world").unwrap().0,
                credentials: None,
                stuck_slot: None,
            };
            (stop, tokio::spawn(service::run(opts, rx)))
        };
        collector.wait_members(&honest, 3, Instant::now(), Duration::from_secs(20)).await.unwrap();

        // r4 votes, every tick, a station other than the one the honest robots decided
        // last, sure of it.
        let (session, _token) = member_session(&fleet, &hub, "r4").await;
        let liar = id("r4");
        let key = keys::robot_topic(&hub.fleet, &liar, Topic::Embedding);
        let started = Instant::now();
        let lie_for = Duration::from_secs(20);
        while started.elapsed() < lie_for {
            let t = clock_tick();
            let last = collector.lock().values().next_back().and_then(|d| d.get(&honest[0]).and_then(|d| d.class()));
            let wrong = Station::ALL[(last.map_or(0, |c| c.index()) + 1) % NUM_CLASSES];
            session.put(&key, encode(&lying_share(&liar, t, wrong))).await.unwrap();
            tokio::time::sleep(TICK).await;
        }
        for a in &agents {
            let s = a.started.status.lock().unwrap().clone();
            eprintln!("{} holds trust {:?}, set aside {} votes", a.robot, s.trust, s.metrics.votes_set_aside);
        }
        let settled = clock_tick() - 80; // its last 8 s, from its 12th second
        let mut decisions = 0;
        for (tick, by) in collector.lock().range(settled..) {
            for r in &honest {
                if let Some(d) = by.get(r) {
                    decisions += 1;
                    assert!(!d.msg.voters.contains(&liar), "{r} counted the liar at tick {tick}: {:?}", d.msg.voters);
                }
            }
        }
        assert!(decisions >= 150, "only {decisions} decisions to check");
        stop_world.send(true).unwrap();
        world.await.unwrap().unwrap();
        for a in &agents {
            let s = a.started.status.lock().unwrap().clone();
            eprintln!(
                "{} holds r4's trust at {:.2}, set aside {} votes",
                a.robot, s.trust[&liar], s.metrics.votes_set_aside
            );
            assert!(s.trust[&liar] < 0.5, "{}: {:?}", a.robot, s.trust);
            assert!(honest.iter().all(|r| s.trust.get(r).is_none_or(|&t| t >= 0.5)), "{}: {:?}", a.robot, s.trust);
        }
        for a in agents {
            a.stop().await.unwrap();
        }
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_vote_signed_in_an_earlier_run_is_never_counted() {
    let _serial = serial().await;
    within!(90, "test", async {
        let fleet = Fleet::make("replay");
        let hub = Hub::start_secured(&fleet.dir.root, "world").await.unwrap();
        let models = models();
        let collector = hub.decisions().await.unwrap();
        let (session, _token) = member_session(&fleet, &hub, "r4").await;

        // Run 1: r1, r2, r3. r4 keeps r2's latest signed vote.
        let first = vec![id("r1"), id("r2"), id("r3")];
        let kept: Arc<Mutex<Option<VoteMsg>>> = Arc::default();
        let k = kept.clone();
        let _listen = session
            .declare_subscriber(keys::robot_topic(&hub.fleet, &id("r2"), Topic::Embedding))
            .callback(move |s| {
                if let Ok(e) = decode::<EmbeddingMsg>(&s.payload().to_bytes()) {
                    if let Some(v) = e.vote.filter(|v| !v.signature.is_empty()) {
                        *k.lock().unwrap() = Some(v);
                    }
                }
            })
            .await
            .unwrap();
        let mut agents = Vec::new();
        for r in &first {
            agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
        }
        let publisher = Publisher::start(&hub, first.clone(), TICK);
        collector.wait_members(&first, 4, Instant::now(), Duration::from_secs(20)).await.unwrap();
        tokio::time::sleep(Duration::from_secs(2)).await;
        drop(publisher);
        for a in agents {
            a.stop().await.unwrap();
        }
        let old = kept.lock().unwrap().clone().expect("r2 voted, signed, in run 1");

        // Run 2: r1 and r3 come back, r2 does not. r4 relays r2's old vote at its own
        // tick and carried to the current one.
        let second = vec![id("r1"), id("r3")];
        let mut agents = Vec::new();
        for r in &second {
            agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
        }
        let since = Instant::now();
        let publisher = Publisher::start(&hub, second.clone(), TICK);
        collector.wait_members(&second, 3, since, Duration::from_secs(20)).await.unwrap();
        let key = keys::robot_topic(&hub.fleet, &id("r4"), Topic::Ballots);
        for _ in 0..30 {
            let now = clock_tick();
            let as_it_was = BallotsMsg { robot: id("r4"), instance: 4, tick: old.tick, votes: vec![old.clone()] };
            let carried = BallotsMsg {
                robot: id("r4"),
                instance: 4,
                tick: now,
                votes: vec![VoteMsg { tick: now, ..old.clone() }],
            };
            for b in [as_it_was, carried] {
                session.put(&key, encode(&b)).congestion_control(CongestionControl::Block).await.unwrap();
            }
            tokio::time::sleep(TICK).await;
        }
        for d in collector.all().iter().filter(|d| d.at >= since) {
            assert!(!d.msg.voters.contains(&id("r2")), "r2's old vote counted at tick {}: {:?}", d.msg.tick, d.msg);
        }
        for a in &agents {
            let s = a.started.status.lock().unwrap().clone();
            let off = s.metrics.off_clock.values().sum::<u64>();
            let forged = s.transport.bad_messages.get(&DropReason::ForgedRelayedVote).copied().unwrap_or(0);
            eprintln!("{}: {off} refused off the clock, {forged} forged relayed votes", a.robot);
            assert!(off >= 25 && forged >= 25, "{}: {off} off the clock, {forged} forged", a.robot);
        }
        drop(publisher);
        for a in agents {
            a.stop().await.unwrap();
        }
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_member_flooding_ticks_off_the_clock_in_a_secured_fleet_stops_nothing() {
    let _serial = serial().await;
    within!(60, "test", async {
        let fleet = Fleet::make("flood");
        let hub = Hub::start_secured(&fleet.dir.root, "world").await.unwrap();
        let models = models();
        let collector = hub.decisions().await.unwrap();
        let honest = vec![id("r1"), id("r2"), id("r3")];
        let mut agents = Vec::new();
        for r in &honest {
            agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
        }
        let (session, _token) = member_session(&fleet, &hub, "r4").await;
        let publisher = Publisher::start(&hub, honest.clone(), TICK);
        collector.wait_members(&honest, 4, Instant::now(), Duration::from_secs(20)).await.unwrap();
        let tick0 = publisher.current_tick();
        let off_clock = flood_off_clock(&session, &hub.fleet, &id("r4")).await;
        tokio::time::sleep(Duration::from_secs(1)).await;
        flood_changed_nothing(&agents, &collector, &id("r4"), off_clock, tick0 + 1, publisher.current_tick() - 1);
        drop(publisher);
        for a in agents {
            a.stop().await.unwrap();
        }
    });
}

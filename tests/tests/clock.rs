//! The fleet's clock over real Zenoh: a member that floods ticks far from ours stops
//! nothing and every message is counted; a restarted world is followed at once; a
//! robot whose clock is 30 ms off still agrees; a 256 MB message is refused by the
//! link before it is buffered.
//! Run: `cargo test -p spwi-tests --test clock -- --nocapture` to see the figures.

use spwi_agent::clock::OffClock;
use spwi_agent::config::AgentConfig;
use spwi_proto::keys::{self, Topic};
use spwi_proto::*;
use spwi_sim::service::{self, WorldOptions};
use spwi_tests::*;
use spwi_world::layout::Layout;
use spwi_world::world::Scenario;
use std::time::{Duration, Instant};
use zenoh::qos::CongestionControl;

const EXE: &str = env!("CARGO_BIN_EXE_spwi-test-agent");
const TICK: Duration = Duration::from_millis(100);

/// A share of tick `tick` from `robot`, voting storage at confidence 1.
fn share(robot: &RobotId, tick: u64) -> EmbeddingMsg {
    EmbeddingMsg {
        robot: robot.clone(),
        instance: 99,
        tick,
        embedding: None,
        visibility: 1000,
        vote: Some(VoteMsg {
            robot: robot.clone(),
            instance: 99,
            tick,
            steps: vec![StepVote { class: Station::Storage, confidence: 1.0 }],
            visibility: 1000,
            quality: 1.0,
            worker: None,
            signature: Vec::new(),
        }),
        worker: None,
        facing: None,
        landmarks: Vec::new(),
        verdict: None,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_member_flooding_ticks_off_our_clock_stops_nothing_and_every_message_is_counted() {
    let _serial = serial().await;
    within!(60, "test", async {
        let hub = Hub::start("flood").await.unwrap();
        let models = models();
        let collector = hub.decisions().await.unwrap();
        let ids: Vec<_> = (0..3).map(|i| id(&format!("r{i}"))).collect();
        let mut agents = Vec::new();
        for r in &ids {
            agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
        }
        // z is a member: it holds its liveliness token and speaks on its own key.
        let z = id("z");
        let _token = hub.session.liveliness().declare_token(keys::alive(&hub.fleet, &z)).await.unwrap();
        let publisher = Publisher::start(&hub, ids.clone(), TICK);
        let mut all = ids.clone();
        all.push(z.clone());
        collector.wait_members(&ids, 4, Instant::now(), Duration::from_secs(15)).await.unwrap();

        // A thousand messages in 4 s: ticks near 2^62, a minute ahead, a minute behind,
        // tick 0 — and, between them, z's shares of the ticks just ahead of ours.
        let key = keys::robot_topic(&hub.fleet, &z, Topic::Embedding);
        let (tick0, mut off_clock_sent) = (publisher.current_tick(), 0u64);
        for k in 0..1000u64 {
            let now = clock_tick();
            let t = match k % 5 {
                0 => (1 << 62) + k,
                1 => now + 600,
                2 => now - 600,
                3 => 0,
                _ => now + 1, // within the window: repeated, one share per tick counts
            };
            off_clock_sent += u64::from(k % 5 != 4);
            let bytes = encode(&share(&z, t));
            hub.session.put(&key, bytes).congestion_control(CongestionControl::Block).await.unwrap();
            tokio::time::sleep(Duration::from_millis(4)).await;
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
        let tick1 = publisher.current_tick();
        for r in &ids {
            let gap = collector.longest_gap(r, tick0 + 1, tick1 - 1);
            assert!(gap <= 1, "{r} left {gap} ticks in a row undecided during the flood");
        }
        for a in &agents {
            let s = a.started.status.lock().unwrap().clone();
            let refused: u64 = [OffClock::MessageTooNew, OffClock::MessageTooOld]
                .iter()
                .filter_map(|w| s.metrics.off_clock.get(w))
                .sum();
            eprintln!(
                "{}: {refused} of {off_clock_sent} refused off the clock; z's clock {:?}",
                a.robot,
                s.clocks.get(&z)
            );
            assert_eq!(refused, off_clock_sent, "{}: every message off our clock refused and counted", a.robot);
            assert!(s.clocks[&z].refused >= off_clock_sent, "/status shows z's messages off our clock");
            assert!(s.health.problem.is_none(), "{:?}", s.health);
        }
        drop(publisher);
        for a in agents {
            a.stop().await.unwrap();
        }
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_restarted_world_is_followed_at_once() {
    let _serial = serial().await;
    within!(60, "test", async {
        let hub = Hub::start("restart").await.unwrap();
        let models = models();
        let collector = hub.decisions().await.unwrap();
        let ids: Vec<_> = (0..3).map(|i| id(&format!("w{i}"))).collect();
        let mut agents = Vec::new();
        for r in &ids {
            agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
        }
        let world = |seed| {
            let (stop, rx) = tokio::sync::watch::channel(false);
            let opts = WorldOptions {
                fleet: hub.fleet.clone(),
                scenario: Scenario::Dynamic,
                seed,
                layout: Layout::default_layout(),
                zenoh: hub.peer_config().unwrap(),
                stuck_slot: None,
            };
            (stop, tokio::spawn(service::run(opts, rx)))
        };
        let (stop, first) = world(1);
        collector.wait_members(&ids, 3, Instant::now(), Duration::from_secs(15)).await.unwrap();
        tokio::time::sleep(Duration::from_secs(4)).await;
        stop.send(true).unwrap();
        first.await.unwrap().unwrap();

        // The world comes back, its own tick counter at 0: the robots decide again at once.
        let restarted = Instant::now();
        let (stop, second) = world(2);
        let took = collector.wait_members(&ids, 3, restarted, Duration::from_secs(5)).await.unwrap();
        eprintln!("every robot decided again {took:?} after the world restarted");
        assert!(took < Duration::from_millis(1200), "decisions came back after {took:?}");
        for a in &agents {
            let s = a.started.status.lock().unwrap().clone();
            assert_eq!(s.metrics.off_clock.values().sum::<u64>(), 0, "{}: no frame refused", a.robot);
        }
        stop.send(true).unwrap();
        second.await.unwrap().unwrap();
        for a in agents {
            a.stop().await.unwrap();
        }
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_robot_whose_clock_is_30_ms_behind_still_agrees() {
    let _serial = serial().await;
    within!(60, "test", async {
        let hub = Hub::start("offset").await.unwrap();
        let models = models();
        let collector = hub.decisions().await.unwrap();
        let ids: Vec<_> = (0..3).map(|i| id(&format!("o{i}"))).collect();
        let mut agents = Vec::new();
        for (i, r) in ids.iter().enumerate() {
            let mut config = AgentConfig::default();
            if i == 0 {
                config.tick.clock_offset_ms = -30;
            }
            agents.push(InProcessAgent::start(&hub, r, &models, config).await.unwrap());
        }
        let publisher = Publisher::start(&hub, ids.clone(), TICK);
        collector.wait_members(&ids, 3, Instant::now(), Duration::from_secs(15)).await.unwrap();
        let from = publisher.current_tick() + 1;
        tokio::time::sleep(Duration::from_secs(8)).await;
        let to = publisher.current_tick() - 2;
        let (agreed, common) = collector.agreement(&ids, from, to);
        eprintln!("one clock 30 ms behind: {common} ticks decided by all, {:.1} % agreed", agreed * 100.0);
        assert!(common as u64 + 2 >= to - from, "only {common} of {} ticks decided by all", to + 1 - from);
        assert!(agreed >= 0.99, "agreement {agreed}");
        let s = agents[1].started.status.lock().unwrap().clone();
        let offset = s.clocks[&ids[0]].offset_ms.unwrap();
        eprintln!("o1 sees o0's ticks start {offset:.1} ms from when it hears them");
        drop(publisher);
        for a in agents {
            a.stop().await.unwrap();
        }
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_256_mb_message_is_refused_by_the_link_before_it_is_buffered() {
    let _serial = serial().await;
    within!(120, "test", async {
        let hub = Hub::start("huge").await.unwrap();
        let collector = hub.decisions().await.unwrap();
        let robot = id("m0");
        let agent = agent_process(EXE, &hub, &robot);
        let _publisher = Publisher::start(&hub, vec![robot.clone()], TICK);
        collector.wait_members(std::slice::from_ref(&robot), 1, Instant::now(), Duration::from_secs(15)).await.unwrap();
        tokio::time::sleep(Duration::from_secs(1)).await;
        let before = spwi_sim::loopback::usage(agent.pid()).unwrap();
        let huge = vec![7u8; 256 << 20];
        let key = keys::robot_topic(&hub.fleet, &id("z"), Topic::Embedding);
        hub.session.put(&key, huge).congestion_control(CongestionControl::Block).await.unwrap();
        tokio::time::sleep(Duration::from_secs(3)).await;
        let after = spwi_sim::loopback::usage(agent.pid()).unwrap();
        let grew = after.rss_mb - before.rss_mb;
        eprintln!("a 256 MB message: the agent's RSS {:.1} -> {:.1} MB", before.rss_mb, after.rss_mb);
        assert!(grew < 10.0, "the agent grew by {grew:.1} MB");
    });
}

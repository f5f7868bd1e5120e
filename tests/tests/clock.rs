//! The fleet's clock over real Zenoh: a member that floods ticks far from ours stops
//! nothing and every message is counted; a restarted world is followed at once; a
//! robot whose clock is 30 ms off still agrees; a 256 MB message is refused by the
//! link before it is buffered.
//! Run: `cargo test -p spwi-tests --test clock -- --nocapture` to see the figures.

use spwi_agent::config::AgentConfig;
use spwi_proto::keys::{self, Topic};
use spwi_sim::service::{self, WorldOptions};
use spwi_tests::*;
use spwi_world::layout::Layout;
use spwi_world::world::Scenario;
use std::time::{Duration, Instant};

const EXE: &str = env!("CARGO_BIN_EXE_spwi-test-agent");
const TICK: Duration = Duration::from_millis(100);

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
        collector.wait_members(&ids, 4, Instant::now(), Duration::from_secs(15)).await.unwrap();

        let tick0 = publisher.current_tick();
        let off_clock = flood_off_clock(&hub.session, &hub.fleet, &z).await;
        tokio::time::sleep(Duration::from_secs(1)).await;
        flood_changed_nothing(&agents, &collector, &z, off_clock, tick0 + 1, publisher.current_tick() - 1);
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
                workers: 1,
                scenario: Scenario::Dynamic,
                seed,
                layout: Layout::default_layout(),
                zenoh: hub.peer_config().unwrap(),
                credentials: None,
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
        hub.session.put(&key, huge).congestion_control(zenoh::qos::CongestionControl::Block).await.unwrap();
        tokio::time::sleep(Duration::from_secs(3)).await;
        let after = spwi_sim::loopback::usage(agent.pid()).unwrap();
        let grew = after.rss_mb - before.rss_mb;
        eprintln!("a 256 MB message: the agent's RSS {:.1} -> {:.1} MB", before.rss_mb, after.rss_mb);
        assert!(grew < 10.0, "the agent grew by {grew:.1} MB");
    });
}

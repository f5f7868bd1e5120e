//! The simulated world as a service over real Zenoh, driving real agents: robots are
//! the agents whose liveliness tokens the world sees; each gets frames from its own
//! camera at 10 Hz, decides with its peers, and the world publishes the truth.
//! Run: `cargo test -p spwi-tests --test world`.

use spwi_agent::config::AgentConfig;
use spwi_proto::keys;
use spwi_proto::*;
use spwi_sim::service::{self, WorldOptions};
use spwi_tests::*;
use spwi_world::layout::Layout;
use spwi_world::world::Scenario;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn agents_decide_on_what_the_simulated_world_shows_them() {
    within!(60, "test", async {
        let hub = Hub::start("simworld").await.unwrap();
        let models = models();
        let collector = Collector::start(&hub).await.unwrap();
        let truths = Arc::new(Mutex::new(Vec::<TruthMsg>::new()));
        let t = truths.clone();
        let _truth_sub = hub
            .session
            .declare_subscriber(keys::truth(&hub.fleet))
            .callback(move |s| {
                if let Ok(m) = decode::<TruthMsg>(&s.payload().to_bytes()) {
                    t.lock().unwrap().push(m);
                }
            })
            .await
            .unwrap();

        let ids: Vec<_> = (0..3).map(|i| id(&format!("w{i}"))).collect();
        let mut agents = Vec::new();
        for r in &ids {
            agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await);
        }
        let (stop_world, rx) = tokio::sync::watch::channel(false);
        let opts = WorldOptions {
            fleet: hub.fleet.clone(),
            scenario: Scenario::Dynamic,
            seed: 11,
            layout: Layout::default_layout(),
            zenoh: hub.peer_config(),
            tick: Duration::from_millis(100),
        };
        let world = tokio::spawn(service::run(opts, rx));

        collector.wait_members(&ids, 3, Instant::now(), Duration::from_secs(10)).await;
        tokio::time::sleep(Duration::from_secs(3)).await;

        // the truth lists exactly the live robots, and every robot decides ticks in a row
        let last = truths.lock().unwrap().last().cloned().expect("truth published");
        let mut listed: Vec<_> = last.robots.iter().map(|r| r.robot.clone()).collect();
        listed.sort();
        assert_eq!(listed, ids);
        let by = collector.by_robot();
        for r in &ids {
            let ticks: Vec<u64> = by[r].keys().copied().collect();
            assert!(ticks.len() >= 20, "{r} decided only {} ticks", ticks.len());
            let recent = &ticks[ticks.len() - 20..];
            assert!(recent.windows(2).all(|w| w[1] == w[0] + 1), "{r} skipped ticks: {recent:?}");
        }

        // a robot that leaves frees its slot: the world stops listing it
        agents.pop().unwrap().stop().await;
        tokio::time::sleep(Duration::from_millis(500)).await;
        let last = truths.lock().unwrap().last().cloned().unwrap();
        assert_eq!(last.robots.len(), 2, "{:?}", last.robots);

        stop_world.send(true).unwrap();
        within!(10, "world to stop", world).unwrap().unwrap();
        for a in agents {
            a.stop().await;
        }
    });
}

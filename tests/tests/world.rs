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
        let collector = hub.decisions().await.unwrap();
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
            agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
        }
        let (stop_world, rx) = tokio::sync::watch::channel(false);
        let opts = WorldOptions {
            fleet: hub.fleet.clone(),
            workers: 1,
            scenario: Scenario::Dynamic,
            seed: 11,
            layout: Layout::default_layout(),
            zenoh: hub.peer_config().unwrap(),
            credentials: None,
            stuck_slot: None,
        };
        let world = tokio::spawn(service::run(opts, rx));

        collector.wait_members(&ids, 3, Instant::now(), Duration::from_secs(10)).await.unwrap();
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
        agents.pop().unwrap().stop().await.unwrap();
        tokio::time::sleep(Duration::from_millis(500)).await;
        let last = truths.lock().unwrap().last().cloned().unwrap();
        assert_eq!(last.robots.len(), 2, "{:?}", last.robots);

        stop_world.send(true).unwrap();
        within!(10, "world to stop", world).unwrap().unwrap();
        for a in agents {
            a.stop().await.unwrap();
        }
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_robot_whose_camera_freezes_leaves_the_vote_and_the_others_carry_on() {
    within!(90, "test", async {
        let hub = Hub::start("stuckworld").await.unwrap();
        let models = models();
        let collector = hub.decisions().await.unwrap();
        let ids: Vec<_> = (0..3).map(|i| id(&format!("s{i}"))).collect();
        let mut agents = Vec::new();
        for r in &ids {
            agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
        }
        let (stop_world, rx) = tokio::sync::watch::channel(false);
        let opts = WorldOptions {
            fleet: hub.fleet.clone(),
            workers: 1,
            scenario: Scenario::Dynamic,
            seed: 11,
            layout: Layout::default_layout(),
            zenoh: hub.peer_config().unwrap(),
            credentials: None,
            stuck_slot: Some(0),
        };
        let world = tokio::spawn(service::run(opts, rx));
        collector.wait_members(&ids, 3, Instant::now(), Duration::from_secs(10)).await.unwrap();

        // Whichever robot holds slot 0 sees its feed freeze once it has seen the worker.
        let stale = loop {
            let stale: Vec<_> = agents
                .iter()
                .filter(|a| a.started.status.lock().unwrap().feed_stale)
                .map(|a| a.robot.clone())
                .collect();
            if !stale.is_empty() {
                break stale;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        };
        assert_eq!(stale.len(), 1, "one camera is stuck: {stale:?}");
        let frozen = &stale[0];
        let from = collector.by_robot()[frozen].keys().last().copied().unwrap() + 2;
        tokio::time::sleep(Duration::from_secs(2)).await;

        // From then on nobody counts its vote, and every robot, it included, keeps deciding.
        let by = collector.by_robot();
        for r in &ids {
            let after: Vec<&DecisionMsg> = by[r].range(from..).map(|(_, d)| d).collect();
            assert!(after.len() >= 15, "{r} decided only {} ticks in 2 s", after.len());
            assert!(after.iter().all(|d| !d.voters.contains(frozen)), "{r} counted {frozen}'s frozen vote");
        }
        let m = agents.iter().find(|a| &a.robot == frozen).unwrap().started.status.lock().unwrap().metrics.clone();
        assert!(m.repeated_frames >= 15, "{m:?}");

        stop_world.send(true).unwrap();
        within!(10, "world to stop", world).unwrap().unwrap();
        for a in agents {
            a.stop().await.unwrap();
        }
    });
}

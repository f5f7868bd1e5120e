//! Faults, with agents as real processes where the fault is a process's: SIGKILL (the
//! kernel closes its links: seen at once) and SIGSTOP (frozen, links stay open: seen
//! only when its Zenoh lease runs out, ≈ 1 s), then SIGCONT (it comes back); robots
//! that are Zenoh clients of two routers when one router is killed (its robots move to
//! the other). Also bad input on every key and a second daemon with a taken robot id.
//! Run: `cargo test -p spwi-tests --test faults -- --nocapture` to see the timings.

use spwi_agent::config::AgentConfig;
use spwi_agent::metrics::DropReason;
use spwi_proto::keys::{self, Topic};
use spwi_proto::*;
use spwi_tests::*;
use std::time::{Duration, Instant};

const EXE: &str = env!("CARGO_BIN_EXE_spwi-test-agent");
const ROUTER: &str = env!("CARGO_BIN_EXE_spwi-test-router");
const TICK: Duration = Duration::from_millis(100);

/// Three agent processes deciding; returns them once all count 3 members.
async fn three_processes(hub: &Hub, collector: &Decisions) -> Vec<AgentProcess> {
    let ids: Vec<_> = (0..3).map(|i| id(&format!("p{i}"))).collect();
    let agents: Vec<_> = ids.iter().map(|r| agent_process(EXE, hub, r)).collect();
    collector.wait_members(&ids, 3, Instant::now(), Duration::from_secs(15)).await.unwrap();
    agents
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_killed_agent_is_out_within_1_5_s_and_decisions_go_on() {
    let _serial = serial().await;
    within!(60, "test", async {
        let hub = Hub::start("kill").await.unwrap();
        let collector = hub.decisions().await.unwrap();
        let ids: Vec<_> = (0..3).map(|i| id(&format!("p{i}"))).collect();
        let publisher = Publisher::start(&hub, ids.clone(), TICK);
        let mut agents = three_processes(&hub, &collector).await;
        let victim = agents.pop().unwrap();
        let (t0, tick0) = (Instant::now(), publisher.current_tick());
        victim.signal("KILL").unwrap();
        let took = collector.wait_members(&ids[..2], 2, t0, Duration::from_millis(1500)).await.unwrap();
        eprintln!("SIGKILL seen in {took:?}");
        tokio::time::sleep(Duration::from_secs(1)).await;
        let tick1 = publisher.current_tick();
        for r in &ids[..2] {
            assert!(collector.longest_gap(r, tick0 + 1, tick1 - 1) <= 1, "{r} stopped deciding");
        }
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_frozen_agent_is_out_within_1_5_s_and_back_after_sigcont() {
    let _serial = serial().await;
    within!(60, "test", async {
        let hub = Hub::start("freeze").await.unwrap();
        let collector = hub.decisions().await.unwrap();
        let ids: Vec<_> = (0..3).map(|i| id(&format!("p{i}"))).collect();
        let publisher = Publisher::start(&hub, ids.clone(), TICK);
        let agents = three_processes(&hub, &collector).await;
        let (t0, tick0) = (Instant::now(), publisher.current_tick());
        agents[2].signal("STOP").unwrap();
        let took = collector.wait_members(&ids[..2], 2, t0, Duration::from_millis(1500)).await.unwrap();
        eprintln!("SIGSTOP seen in {took:?}");
        tokio::time::sleep(Duration::from_millis(500)).await;
        let tick1 = publisher.current_tick();
        for r in &ids[..2] {
            assert!(collector.longest_gap(r, tick0 + 1, tick1 - 1) <= 1, "{r} stopped deciding while p2 was frozen");
        }
        let t1 = Instant::now();
        agents[2].signal("CONT").unwrap();
        let took = collector.wait_members(&ids, 3, t1, Duration::from_secs(10)).await.unwrap();
        eprintln!("SIGCONT: back in {took:?}");
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn bad_messages_on_every_key_are_dropped_and_counted_while_decisions_go_on() {
    let _serial = serial().await;
    within!(60, "test", async {
        let hub = Hub::start("bad").await.unwrap();
        let models = models();
        let collector = hub.decisions().await.unwrap();
        let ids = vec![id("a"), id("b")];
        let a = InProcessAgent::start(&hub, &ids[0], &models, AgentConfig::default()).await.unwrap();
        let b = InProcessAgent::start(&hub, &ids[1], &models, AgentConfig::default()).await.unwrap();
        let publisher = Publisher::start(&hub, ids.clone(), TICK);
        collector.wait_members(&ids, 2, Instant::now(), Duration::from_secs(5)).await.unwrap();

        // One of each kind of bad input, on every key the agents read.
        let good = EmbeddingMsg {
            robot: id("b"),
            instance: 1,
            tick: 1,
            embedding: None,
            visibility: 1,
            vote: Some(VoteMsg {
                robot: id("b"),
                instance: 1,
                tick: 1,
                steps: vec![StepVote { class: Station::Workstation, confidence: 0.5 }],
                visibility: 1,
                worker: None,
                quality: 1.0,
                signature: Vec::new(),
            }),
            worker: None,
            facing: None,
            landmarks: vec![],
            verdict: None,
            people: Vec::new(),
        };
        let mut wrong_version = encode(&good);
        wrong_version[0] = 99;
        let mut truncated = encode(&scripted_frame(&ids[0], 0, 1));
        truncated.truncate(truncated.len() / 2);
        let nan_embedding = encode(&EmbeddingMsg { embedding: Some(vec![f32::NAN; EMBEDDING_DIM]), ..good.clone() });
        let spoofed = encode(&EmbeddingMsg { robot: id("mallory"), vote: None, ..good });
        let bads: Vec<(&str, Vec<u8>)> = vec![
            ("garbage", vec![0xde, 0xad, 0xbe, 0xef]),
            ("empty", vec![]),
            ("truncated", truncated),
            ("wrong version", wrong_version),
            ("oversized", vec![1u8; MAX_MESSAGE_BYTES + 1]),
            ("nan", nan_embedding),
            ("spoofed", spoofed),
        ];
        let tick0 = publisher.current_tick();
        for topic in Topic::ALL {
            for (_, bytes) in &bads {
                let key = keys::robot_topic(&hub.fleet, &ids[1], topic);
                hub.session.put(&key, bytes.clone()).await.unwrap();
                let key = keys::robot_topic(&hub.fleet, &ids[0], topic);
                hub.session.put(&key, bytes.clone()).await.unwrap();
            }
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
        let tick1 = publisher.current_tick();
        let status = a.started.status.lock().unwrap().clone();
        let bad = status.transport.bad_total();
        // a reads its own detections and everyone's embedding, ballots and map keys:
        // 7 bad payloads on 2 robots' keys for 3 topics + on its own detections.
        assert!(bad >= 7 * 7, "only {bad} bad messages counted: {:?}", status.transport.bad_messages);
        for reason in [
            DropReason::Malformed,
            DropReason::Version,
            DropReason::TooLarge,
            DropReason::Invalid,
            DropReason::RobotMismatch,
        ] {
            assert!(
                status.transport.bad_messages.get(&reason).copied().unwrap_or(0) > 0,
                "no {reason:?}: {:?}",
                status.transport.bad_messages
            );
        }
        for r in &ids {
            assert!(collector.longest_gap(r, tick0 + 1, tick1 - 1) <= 1, "{r} stopped deciding under bad input");
        }
        a.stop().await.unwrap();
        b.stop().await.unwrap();
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_second_daemon_with_a_taken_robot_id_is_refused() {
    let _serial = serial().await;
    within!(60, "test", async {
        let hub = Hub::start("dup").await.unwrap();
        let models = models();
        let a = InProcessAgent::start(&hub, &id("same"), &models, AgentConfig::default()).await.unwrap();
        tokio::time::sleep(Duration::from_millis(500)).await;
        let mut second = agent_process(EXE, &hub, &id("same"));
        let status = second.wait_exit(Duration::from_secs(20)).await.unwrap();
        assert!(!status.success(), "a daemon with a taken robot id must refuse to start");
        a.stop().await.unwrap();
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn clients_of_a_router_that_dies_move_to_the_other_and_the_fleet_decides_on() {
    let _serial = serial().await;
    within!(90, "test", async {
        let mut routers = Routers::start(std::path::Path::new(ROUTER), 2).unwrap();
        // The detections come through router 1 (on a robot its camera is local).
        let hub = Hub::start_client("routed", &routers.connect_from(1)).await.unwrap();
        let collector = hub.decisions().await.unwrap();
        let ids: Vec<_> = (0..4).map(|i| id(&format!("c{i}"))).collect();
        let _agents: Vec<_> = ids
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let launch =
                    Launch { routers: routers.connect_from(k % 2), models: Some(models_dir()), ..Launch::new(&hub, r) };
                AgentProcess::spawn(std::process::Command::new(EXE), launch).unwrap()
            })
            .collect();
        let publisher = Publisher::start(&hub, ids.clone(), TICK);
        collector.wait_members(&ids, 4, Instant::now(), Duration::from_secs(20)).await.unwrap();
        tokio::time::sleep(Duration::from_secs(2)).await;
        let tick0 = publisher.current_tick();
        let (agreed, common) = collector.agreement(&ids, tick0 - 15, tick0 - 1);
        assert!(
            common >= 14 && agreed >= 0.99,
            "through routers: {common} of 15 ticks decided by all, {agreed} agreed"
        );

        routers.kill(0).unwrap();
        let killed = Instant::now();
        let at_home_on_0 = [ids[0].clone(), ids[2].clone()];
        // A decision published after the kill reaches the observer only through router 1.
        let took = collector
            .wait_members(&at_home_on_0, 4, killed + Duration::from_millis(100), Duration::from_secs(10))
            .await
            .unwrap();
        eprintln!("router 0 killed: its robots decide through router 1 after {took:?}");
        tokio::time::sleep(Duration::from_secs(2)).await;
        let tick1 = publisher.current_tick();
        for r in [&ids[1], &ids[3]] {
            assert!(collector.longest_gap(r, tick0, tick1 - 1) <= 2, "{r}, at home on router 1, stopped deciding");
        }
        let (agreed, common) = collector.agreement(&ids, tick1 - 10, tick1 - 1);
        assert!(common >= 9 && agreed >= 0.99, "after the move: {common} of 10 ticks decided by all, {agreed} agreed");
    });
}

//! The fleet on loopback: real Zenoh peers, real agents (in-process, each with its own
//! session), the fixture models, a scripted detection publisher at 10 Hz.
//!
//! Covers: every agent decides every tick and all agree (1, 3 and 8 agents); an agent
//! that leaves gracefully is out of the member count within 1.5 s and the others go on
//! without a gap; an agent that joins mid-run is counted within a second and decides,
//! and is sent every member's station map.
//! Run: `cargo test -p spwi-tests --test fleet`.

use spwi_agent::config::AgentConfig;
use spwi_proto::keys::{self, Topic};
use spwi_proto::{decode, MapMsg};
use spwi_tests::*;
use std::time::{Duration, Instant};

const TICK: Duration = Duration::from_millis(100);

fn robots(n: usize) -> Vec<spwi_proto::RobotId> {
    (0..n).map(|i| id(&format!("r{i}"))).collect()
}

/// Starts n agents, runs `ticks` ticks, and checks every agent decided every tick of
/// the second half and that their decisions agree on ≥ 99 % of those ticks.
async fn decide_together(n: usize, ticks: u64) {
    let hub = Hub::start(&format!("together{n}")).await.unwrap();
    let models = models();
    let collector = hub.decisions().await.unwrap();
    let ids = robots(n);
    let mut agents = Vec::new();
    for r in &ids {
        agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
    }
    tokio::time::sleep(Duration::from_millis(700)).await; // mesh and membership settle
    let publisher = Publisher::start(&hub, ids.clone(), TICK);
    within!(ticks as f64 * 0.1 + 30.0, "ticks to pass", async {
        while publisher.published() < ticks + 3 {
            tokio::time::sleep(TICK).await;
        }
    });
    let first = publisher.first_tick();
    drop(publisher);
    tokio::time::sleep(Duration::from_millis(300)).await;

    let by = collector.by_robot();
    let checked = first + ticks / 2..=first + ticks;
    let mut same = 0;
    for t in checked.clone() {
        let classes: Vec<_> = ids
            .iter()
            .map(|r| {
                let d = by.get(r).and_then(|m| m.get(&t)).unwrap_or_else(|| panic!("{r} did not decide tick {t}"));
                assert_eq!(d.live_members, n as u32, "{r} at tick {t}");
                d.steps.first().map(|s| s.class)
            })
            .collect();
        same += u64::from(classes.windows(2).all(|w| w[0] == w[1]));
    }
    let total = checked.count() as u64;
    assert!(same * 100 >= total * 99, "{n} agents agreed on only {same} of {total} ticks");
    for a in agents {
        a.stop().await.unwrap();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn one_agent_decides_every_tick() {
    let _serial = serial().await;
    within!(60, "test", decide_together(1, 30));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn three_agents_decide_every_tick_and_agree() {
    let _serial = serial().await;
    within!(90, "test", decide_together(3, 40));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn eight_agents_decide_every_tick_and_agree() {
    let _serial = serial().await;
    within!(120, "test", decide_together(8, 40));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_graceful_leave_and_a_join_change_the_members_and_decisions_go_on() {
    let _serial = serial().await;
    within!(90, "test", async {
        let hub = Hub::start("churn").await.unwrap();
        let models = models();
        let collector = hub.decisions().await.unwrap();
        let ids = robots(4);
        let mut agents = Vec::new();
        for r in &ids[..3] {
            agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
        }
        let _publisher = Publisher::start(&hub, ids.clone(), TICK);
        collector.wait_members(&ids[..3], 3, Instant::now(), Duration::from_secs(5)).await.unwrap();

        // r2 leaves gracefully.
        let leaver = agents.pop().unwrap();
        let t0 = Instant::now();
        let tick0 = _publisher.current_tick();
        leaver.stop().await.unwrap();
        let took = collector.wait_members(&ids[..2], 2, t0, Duration::from_millis(1500)).await.unwrap();
        eprintln!("graceful leave seen in {took:?}");
        tokio::time::sleep(Duration::from_millis(500)).await;
        let tick1 = _publisher.current_tick();
        for r in &ids[..2] {
            assert!(collector.longest_gap(r, tick0, tick1 - 1) <= 1, "{r} stopped deciding when r2 left");
        }

        // r3 joins and is counted within a second, and decides.
        let t1 = Instant::now();
        agents.push(InProcessAgent::start(&hub, &ids[3], &models, AgentConfig::default()).await.unwrap());
        let ours = [ids[0].clone(), ids[1].clone(), ids[3].clone()];
        let took = collector.wait_members(&ours, 3, t1, Duration::from_secs(1)).await.unwrap();
        eprintln!("join seen in {took:?}");
        // and its vote counts: soon every decision lists three voters
        within!(5, "the newcomer's vote to be counted", async {
            loop {
                let mut seen = collector.all();
                seen.sort_by_key(|s| s.at);
                if seen.iter().rev().take(6).all(|s| s.msg.voters.len() == 3 || s.msg.steps.is_empty())
                    && seen.len() > 6
                {
                    break;
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        });
        for a in agents {
            a.stop().await.unwrap();
        }
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_recorded_run_replays_to_the_same_decisions_bit_for_bit() {
    let _serial = serial().await;
    within!(60, "test", async {
        let hub = Hub::start("record").await.unwrap();
        let models = models();
        let collector = hub.decisions().await.unwrap();
        let ids = robots(3);
        let file = std::env::temp_dir().join(format!("spwi-record-{}.mcap", std::process::id()));
        let recorded =
            InProcessAgent::start_recording(&hub, &ids[0], &models, AgentConfig::default(), Some(file.clone()))
                .await
                .unwrap();
        let mut others = Vec::new();
        for r in &ids[1..] {
            others.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
        }
        let publisher = Publisher::start(&hub, ids.clone(), TICK);
        collector.wait_members(&ids, 3, Instant::now(), Duration::from_secs(5)).await.unwrap();
        // churn while recording: one peer leaves
        others.pop().unwrap().stop().await.unwrap();
        tokio::time::sleep(Duration::from_secs(2)).await;
        drop(publisher);
        recorded.stop().await.unwrap();
        for a in others {
            a.stop().await.unwrap();
        }

        let recording = spwi_agent::record::read(&file).unwrap();
        let replayed = spwi_agent::record::replay(&recording, &models).unwrap();
        assert_eq!(replayed.outputs, recording.outputs, "replay must reproduce every output");
        assert_eq!(replayed.states, recording.states, "and every judgement of the peers");
        let trusted = recording.states.last().expect("a peer state per decision").trust.len();
        assert!(trusted >= 2, "the last state judges {trusted} robots: the recording shows no peer");
        let decided: Vec<_> = replayed
            .outputs
            .iter()
            .filter_map(|o| if let spwi_core::engine::Output::Decision(d) = o { Some(d.clone()) } else { None })
            .collect();
        assert!(decided.len() >= 20, "only {} decisions recorded", decided.len());
        assert_eq!(recording.states.len(), decided.len(), "one peer state per decision");
        // and they are the decisions the fleet saw on the wire
        let live = collector.by_robot();
        for d in &decided {
            assert_eq!(live[&ids[0]].get(&d.tick), Some(d), "tick {}", d.tick);
        }
        viewer_reads(&file);
        std::fs::remove_file(file).unwrap();
    });
}

/// The recording as a viewer reads it: every channel has a JSON Schema and every message
/// matches it, checked by the `mcap` project's own Python reader (tests/mcap_schemas.py;
/// `SPWI_PYTHON`, else `python3`). `.ci/run` installs the reader and sets
/// SPWI_REQUIRE_MCAP_READER=1, so there a missing reader fails the test.
fn viewer_reads(file: &std::path::Path) {
    let Some(python) =
        python_with("mcap, jsonschema", "SPWI_REQUIRE_MCAP_READER", "reading the recording with mcap's reader")
    else {
        return;
    };
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("mcap_schemas.py");
    let out = std::process::Command::new(&python).arg(script).arg(file).output().unwrap();
    assert!(
        out.status.success(),
        "a viewer cannot read the recording:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!("{}", String::from_utf8_lossy(&out.stdout).trim());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_robot_that_joins_a_working_fleet_is_sent_its_station_map() {
    let _serial = serial().await;
    within!(60, "test", async {
        let hub = Hub::start("maps").await.unwrap();
        let models = models();
        let collector = hub.decisions().await.unwrap();
        let sent = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let s = sent.clone();
        let _maps = hub
            .session
            .declare_subscriber(keys::all_robots(&hub.fleet, Topic::Map))
            .callback(move |m| s.lock().unwrap().push(decode::<MapMsg>(&m.payload().to_bytes()).unwrap()))
            .await
            .unwrap();
        let ids = robots(3);
        let mut agents = Vec::new();
        for r in &ids[..2] {
            agents.push(InProcessAgent::start(&hub, r, &models, AgentConfig::default()).await.unwrap());
        }
        let publisher = Publisher::start(&hub, ids.clone(), TICK);
        collector.wait_members(&ids[..2], 2, Instant::now(), Duration::from_secs(5)).await.unwrap();
        tokio::time::sleep(Duration::from_secs(1)).await; // the station objects in view, seen 10 times
        assert!(sent.lock().unwrap().is_empty(), "no map sent while nobody joins");

        let file = std::env::temp_dir().join(format!("spwi-joiner-{}.mcap", std::process::id()));
        let joiner =
            InProcessAgent::start_recording(&hub, &ids[2], &models, AgentConfig::default(), Some(file.clone()))
                .await
                .unwrap();
        collector.wait_members(&ids, 3, Instant::now(), Duration::from_secs(5)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(500)).await;
        drop(publisher);
        joiner.stop().await.unwrap();
        for a in agents {
            a.stop().await.unwrap();
        }

        let sent = sent.lock().unwrap().clone();
        let senders: Vec<_> = sent.iter().map(|m| m.robot.clone()).collect();
        assert_eq!(senders.len(), 2, "each member sends its map once when r2 joins: {senders:?}");
        assert!(senders.contains(&ids[0]) && senders.contains(&ids[1]), "{senders:?}");
        assert!(sent.iter().all(|m| m.stations.iter().any(Option::is_some)), "{sent:?}");
        // ... and the joiner got both, through its own subscription
        let recording = spwi_agent::record::read(&file).unwrap();
        let received: Vec<_> = recording
            .inputs
            .iter()
            .filter_map(|(_, i)| if let spwi_core::engine::Input::Map(m) = i { Some(m.clone()) } else { None })
            .collect();
        assert_eq!(received.len(), 2, "{received:?}");
        assert!(received.iter().all(|m| sent.contains(m)));
        std::fs::remove_file(file).unwrap();
    });
}

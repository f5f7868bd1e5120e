//! The Python client (`clients/python`) on a live fleet: a Python program feeds three
//! real agent processes their detection frames and follows their decisions, and what
//! Python reads must be what a Rust observer reads — on an open fleet, and on a secured
//! one where Python presents the world's certificate to feed and an observer's to
//! follow (and the observer's attempt to publish reaches no one). The README's two
//! Python sections are run against the same fleet.
//!
//! Needs a Python with `eclipse-zenoh` (`SPWI_PYTHON`, else `python3`); without one the
//! tests say so and skip, unless SPWI_REQUIRE_PYTHON_CLIENT is set (as `.ci/run` does).
//! Run: `cargo test -p spwi-tests --test python_client`.

use serde_json::Value;
use spwi_agent::fleet::authority::{self, Validity};
use spwi_agent::fleet::{FleetDir, Role};
use spwi_proto::{DecisionMsg, FleetId, RobotId};
use spwi_tests::*;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

const AGENT: &str = env!("CARGO_BIN_EXE_spwi-test-agent");

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The Python to run the client with (the checkout's `clients/python` first on its
/// path), or `None` when it has no Zenoh and the tests may skip.
fn python() -> Option<Command> {
    let python = python_with("zenoh", "SPWI_REQUIRE_PYTHON_CLIENT", "the Python client's live tests")?;
    let mut c = Command::new(python);
    c.env("PYTHONPATH", repo().join("clients/python"));
    Some(c)
}

/// Runs `script` of the client's tests with `args` (for at most `limit`); panics with
/// its output if it fails.
async fn run_python(mut python: Command, script: &str, args: &[String], limit: Duration) {
    python.arg(repo().join("clients/python/tests").join(script)).args(args);
    let out =
        within!(limit.as_secs_f64(), format!("python {script}"), tokio::task::spawn_blocking(move || python.output()))
            .unwrap()
            .unwrap();
    assert!(
        out.status.success(),
        "python {script} failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn robots() -> Vec<RobotId> {
    ["r0", "r1", "r2"].map(id).to_vec()
}

/// Starts three agents on `hub`, waits until each holds its liveliness token.
async fn agents(hub: &Hub) -> Vec<AgentProcess> {
    let started: Vec<_> = robots().iter().map(|r| agent_process(AGENT, hub, r)).collect();
    let alive = hub.session.liveliness();
    within!(30, "three agents to join", async {
        loop {
            let replies = alive.get(spwi_proto::keys::all_alive(&hub.fleet)).await.unwrap();
            let mut n = 0;
            while let Ok(r) = replies.recv_async().await {
                n += usize::from(r.result().is_ok());
            }
            if n == 3 {
                break;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    });
    started
}

/// Feeds the fleet from Python for a few seconds and checks that Python read the
/// decisions the Rust observer read, field for field, on the ticks it fed.
async fn python_feeds_and_reads_what_rust_reads(python: Command, hub: &Hub, extra: &[&str]) {
    let collector = hub.decisions().await.unwrap();
    let out = std::env::temp_dir().join(format!("spwi-python-{}-{}.jsonl", hub.fleet, std::process::id()));
    let names: Vec<_> = robots().iter().map(|r| r.to_string()).collect();
    let mut args: Vec<String> =
        ["--connect", &hub.locator, "--robots", &names.join(","), "--seconds", "5"].map(str::to_owned).to_vec();
    args.extend(["--out".to_owned(), out.display().to_string()]);
    args.extend(extra.iter().map(|s| s.to_string()));
    run_python(python, "live_fleet.py", &args, Duration::from_secs(60)).await;

    let text = std::fs::read_to_string(&out).unwrap();
    let _ = std::fs::remove_file(&out);
    let mut lines = text.lines().map(|l| serde_json::from_str::<Value>(l).unwrap());
    let head = lines.next().expect("a summary line");
    let members: Vec<&str> = head["members"].as_array().unwrap().iter().map(|m| m.as_str().unwrap()).collect();
    assert_eq!(members, names, "the members Python sees");
    assert_eq!(head["refused"], 0, "Python refused decisions the agents published");
    let python_read: Vec<Value> = lines.collect();
    let rust_read: BTreeMap<(RobotId, u64), DecisionMsg> =
        collector.all().into_iter().map(|d| ((d.msg.robot.clone(), d.msg.tick), d.msg)).collect();
    assert!(
        python_read.len() >= 3 * 30,
        "Python read only {} decisions in 5 s of three robots deciding at 10 Hz",
        python_read.len()
    );
    let seen_worker = python_read.iter().filter(|d| !d["class"].is_null()).count();
    assert!(seen_worker * 2 > python_read.len(), "the frames Python fed were not used: {seen_worker} with a class");
    for d in &python_read {
        let key = (id(d["robot"].as_str().unwrap()), d["tick"].as_u64().unwrap());
        let rust = rust_read.get(&key).unwrap_or_else(|| panic!("Python read {key:?}, the Rust observer did not"));
        let voters: Vec<&str> = rust.voters.iter().map(|v| v.as_str()).collect();
        let ours = serde_json::json!({
            "robot": rust.robot.as_str(),
            "instance": rust.instance,
            "tick": rust.tick,
            "class": rust.steps.first().map(|s| u8::from(s.class)),
            "digest": rust.digest,
            "voters": voters,
            "live_members": rust.live_members,
        });
        assert_eq!(d, &ours, "Python and Rust read different decisions");
    }
    assert!(
        collector.all().iter().all(|d| d.msg.instance != 999),
        "the observer's forged decision reached the Rust observer"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn python_feeds_an_open_fleet_and_reads_the_decisions_rust_reads_and_the_readme_runs() {
    let Some(python) = python() else { return };
    let _serial = serial().await;
    within!(150, "test", async {
        let hub = Hub::start("pyopen").await.unwrap();
        let _agents = agents(&hub).await;
        python_feeds_and_reads_what_rust_reads(python, &hub, &["--fleet", "pyopen"]).await;
        let args = [
            "--readme",
            &repo().join("README.md").display().to_string(),
            "--connect",
            &hub.locator,
            "--fleet",
            "pyopen",
        ]
        .map(str::to_owned);
        run_python(self::python().unwrap(), "readme_snippets.py", &args, Duration::from_secs(40)).await;
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn python_feeds_a_secured_fleet_as_its_world_and_follows_it_as_an_observer_that_can_say_nothing() {
    let Some(python) = python() else { return };
    let _serial = serial().await;
    within!(150, "test", async {
        let dir = FleetDir::new(std::env::temp_dir().join(format!("spwi-python-secured-{}", std::process::id())));
        let _ = std::fs::remove_dir_all(&dir.root);
        let members = [
            ("world", Role::World),
            ("dashboard", Role::Observer),
            ("r0", Role::Robot),
            ("r1", Role::Robot),
            ("r2", Role::Robot),
        ];
        authority::create(&dir, &FleetId::new("pysecured").unwrap(), &members, Validity::days(1)).unwrap();
        let hub = Hub::start_secured(&dir.root, "world").await.unwrap();
        let _agents = agents(&hub).await;
        let fleet_dir = dir.root.display().to_string();
        let extra = ["--fleet-dir", &fleet_dir, "--feeder", "world", "--follower", "dashboard", "--forge"];
        python_feeds_and_reads_what_rust_reads(python, &hub, &extra).await;
        let _ = std::fs::remove_dir_all(&dir.root);
    });
}

//! The demo, headless and short: the world and three agents in one process, one agent
//! stopped and one started mid-run; the summary must report decisions from every robot,
//! the membership changes and an agreement rate. Once through the library, once through
//! the command line's `--json FILE`. No assertion on speed.
//! Run: `cargo test -p spwi-tests --test demo`.

use spwi_sim::demo::{self, DemoOptions};
use spwi_tests::*;
use spwi_world::layout::Layout;
use spwi_world::world::Scenario;
use std::time::Duration;

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_short_headless_demo_reports_every_robot_and_the_churn() {
    within!(60, "demo", async {
        let opts = DemoOptions {
            robots: 3,
            workers: 1,
            scenario: Scenario::Dynamic,
            seed: 2,
            duration: Duration::from_secs(7),
            kill_after: Some(Duration::from_secs(3)),
            join_after: Some(Duration::from_secs(4)),
            layout: Layout::default_layout(),
            agent: spwi_agent::config::AgentConfig {
                models: spwi_agent::config::ModelsConfig { dir: Some(models_dir()), ..Default::default() },
                ..Default::default()
            },
            view: false,
            http: None,
            on_http: None,
        };
        let (_stop, rx) = tokio::sync::watch::channel(false);
        let s = demo::run(opts, models(), rx).await.unwrap();
        assert!(s.ticks >= 40, "{s:?}");
        for r in ["robot0", "robot1", "robot2", "robot3"] {
            assert!(s.decisions.get(r).copied().unwrap_or(0) >= 5, "{r} barely decided: {:?}", s.decisions);
        }
        assert_eq!(s.members_changes.iter().map(|c| c.event.as_str()).collect::<Vec<_>>(), ["left", "joined"]);
        assert!((0.0..=1.0).contains(&s.agreement) && s.agreement > 0.8, "agreement {}", s.agreement);
        assert!(s.messages_per_tick > 3.0 && s.bytes_per_tick > 1000.0, "{s:?}");
        assert!(s.fixture_models);
    });
}

#[test]
fn the_demo_command_writes_its_json_summary() {
    let file = std::env::temp_dir().join(format!("spwi-demo-{}.json", std::process::id()));
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_spwi-test-sim"))
        .args(["demo", "--robots", "2", "--duration", "4s", "--quiet", "--json"])
        .arg(&file)
        .arg("--models")
        .arg(models_dir())
        .env("RUST_LOG", "warn")
        .output()
        .expect("run spwi-sim demo");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    assert_eq!(s["robots"], 2);
    for r in ["robot0", "robot1"] {
        assert!(s["decisions"][r].as_u64().unwrap() > 10, "{s}");
    }
    for key in ["agreement", "ticks", "members_changes", "latency_ms", "accuracy"] {
        assert!(!s[key].is_null(), "summary lacks {key}: {s}");
    }
    assert!((0.0..=1.0).contains(&s["agreement"].as_f64().unwrap()));
    std::fs::remove_file(file).unwrap();
}

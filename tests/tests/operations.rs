//! Operating a daemon: the HTTP endpoints (`/healthz`, `/status`, `/metrics`) while it
//! decides, and SIGTERM leaving the fleet cleanly (exit 0, peers see it go at once).
//! Run: `cargo test -p spwi-tests --test operations`.

use spwi_agent::config::AgentConfig;
use spwi_tests::*;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

const EXE: &str = env!("CARGO_BIN_EXE_spwi-test-agent");

fn get(addr: std::net::SocketAddr, path: &str) -> (u16, String) {
    request(addr, "GET", path)
}

/// One request on its own connection; returns the status code and the body.
fn request(addr: std::net::SocketAddr, method: &str, path: &str) -> (u16, String) {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    write!(s, "{method} {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n").unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).unwrap();
    let code = text.split_whitespace().nth(1).unwrap().parse().unwrap();
    (code, text.split("\r\n\r\n").nth(1).unwrap_or("").to_owned())
}

/// A GET whose headers run to 1 MB. Returns the status code the server answered, or
/// `None` when it closed the connection without one.
fn huge_request(addr: std::net::SocketAddr) -> Option<u16> {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let header = format!("X-Filler: {}\r\n", "a".repeat(1 << 20));
    // The server may stop reading (and reset the connection) before all is sent.
    let _ = write!(s, "GET /status HTTP/1.1\r\nHost: x\r\n{header}Connection: close\r\n\r\n");
    let mut text = String::new();
    let _ = s.read_to_string(&mut text);
    text.split_whitespace().nth(1).and_then(|c| c.parse().ok())
}

/// The families of `text` as the Prometheus project's own OpenMetrics parser reads
/// them (Python's `prometheus_client`, strict where a scraper is): one "name type
/// samples" line each. `None` when no Python with `prometheus_client` is at hand
/// (`SPWI_PYTHON`, else `python3`); `.ci/run` installs one and sets
/// SPWI_REQUIRE_OPENMETRICS_PARSER=1, so there a missing parser fails the test.
fn parsed_as_openmetrics(text: &str) -> Option<String> {
    const PARSE: &str =
        "import sys\nfrom prometheus_client.openmetrics.parser import text_string_to_metric_families as p\n\
                         for f in p(sys.stdin.read()): print(f.name, f.type, len(f.samples))";
    let python = python_with(
        "prometheus_client.openmetrics.parser",
        "SPWI_REQUIRE_OPENMETRICS_PARSER",
        "parsing /metrics as OpenMetrics",
    )?;
    let mut child = std::process::Command::new(&python)
        .args(["-c", PARSE])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(text.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "/metrics is not OpenMetrics: {}\n{text}", String::from_utf8_lossy(&out.stderr));
    Some(String::from_utf8(out.stdout).unwrap())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn status_metrics_and_health_are_served_while_deciding() {
    within!(60, "test", async {
        let hub = Hub::start("http").await.unwrap();
        let models = models();
        let collector = hub.decisions().await.unwrap();
        let ids = vec![id("h0"), id("h1")];
        let mut config = AgentConfig::default();
        config.http.listen = Some("127.0.0.1:0".parse().unwrap());
        let plan = std::env::temp_dir().join(format!("spwi-status-plan-{}.toml", std::process::id()));
        std::fs::write(&plan, "[stations.storage]\nposition = [1.0, 2.0]\nuncertainty_m = 0.5\n").unwrap();
        config.floor.plan = Some(plan.clone());
        let a = InProcessAgent::start(&hub, &ids[0], &models, config).await.unwrap();
        std::fs::remove_file(&plan).unwrap();
        let b = InProcessAgent::start(&hub, &ids[1], &models, AgentConfig::default()).await.unwrap();
        let _publisher = Publisher::start(&hub, ids.clone(), Duration::from_millis(100));
        collector.wait_members(&ids, 2, Instant::now(), Duration::from_secs(5)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(500)).await;
        let addr = a.started.http.expect("http address");

        let (code, body) = tokio::task::spawn_blocking(move || get(addr, "/healthz")).await.unwrap();
        assert_eq!((code, body.as_str()), (200, "ok\n"));

        let (code, body) = tokio::task::spawn_blocking(move || get(addr, "/status")).await.unwrap();
        assert_eq!(code, 200);
        let status: serde_json::Value = serde_json::from_str(&body).unwrap();
        assert_eq!(status["robot"], "h0");
        assert_eq!(status["members"], serde_json::json!(["h0", "h1"]));
        assert!(status["last_decision"]["tick"].as_u64().unwrap() > 0);
        // Stations by name: the legend of the class numbers, and each recent decision's.
        assert_eq!(status["stations"], serde_json::json!(["storage", "workstation", "assembly", "manufacturing"]));
        let recent = status["recent_decisions"].as_array().expect("recent decisions");
        assert!(recent.iter().any(|d| !d["class"].is_null()), "no recent decision names a class: {recent:?}");
        for d in recent {
            let named = d["class"].as_u64().map(|c| status["stations"][c as usize].clone());
            assert_eq!(d["station"], named.unwrap_or(serde_json::Value::Null), "{d}");
        }
        assert!(status["fixture_models"].as_bool().unwrap());
        assert!(status["metrics"]["decisions"].as_u64().unwrap() > 0);
        assert_eq!(status["feed_stale"], false);
        assert_eq!(status["stale_peers"], serde_json::json!([]));
        assert_eq!(status["consensus"], "trust");
        assert!(status["roster_version"].is_null(), "an open fleet holds no roster");
        assert_eq!(status["floor_plan"]["stations"], 1, "the plan it was given");
        assert!(status["floor_plan"]["contradicted"].is_array(), "{}", status["floor_plan"]);
        // The scripted robot is localised and sees one person, whom it names with a
        // team id while the person's feet are in view (the script sweeps them across
        // the image every 12.5 s; above the horizon nobody is placed on the floor).
        let mut people = status["people"].as_array().expect("people").clone();
        let sweep = Instant::now();
        while people.is_empty() && sweep.elapsed() < Duration::from_secs(13) {
            tokio::time::sleep(Duration::from_millis(200)).await;
            let (_, body) = tokio::task::spawn_blocking(move || get(addr, "/status")).await.unwrap();
            let now: serde_json::Value = serde_json::from_str(&body).unwrap();
            people = now["people"].as_array().expect("people").clone();
        }
        // (The script's person jumps across the floor as it sweeps, so a track just
        // left behind may still be listed beside the new one for half a second.)
        assert!((1..=spwi_proto::MAX_HUMANS).contains(&people.len()), "{people:?}");
        let ids: std::collections::BTreeSet<u64> = people.iter().map(|p| p["worker"].as_u64().unwrap()).collect();
        assert_eq!(ids.len(), people.len(), "an id named twice: {people:?}");
        for p in &people {
            assert_eq!(p["name"], format!("w{:04x}", p["worker"].as_u64().unwrap() & 0xffff));
        }
        let trust = status["trust"].as_object().expect("trust per voter");
        assert!(!trust.is_empty() && trust.keys().all(|r| r == "h0" || r == "h1"), "{trust:?}");
        assert!(trust.values().all(|t| (0.0..=1.0).contains(&t.as_f64().unwrap())), "{trust:?}");

        let (code, body) = tokio::task::spawn_blocking(move || get(addr, "/metrics")).await.unwrap();
        assert_eq!(code, 200);
        for needle in [
            "spwi_decisions_total{robot=\"h0\"}",
            "spwi_members{robot=\"h0\"} 2",
            "stage=\"gcn\"",
            "stage=\"frame_to_decision\"",
            "spwi_feed_stale{robot=\"h0\"} 0",
            "spwi_decided_on_fewer_ballots_total{robot=\"h0\"}",
            "spwi_trust{robot=\"h0\",peer=\"h1\"}",
            "spwi_members_joined_total{robot=\"h0\"} 1",
            "spwi_members_left_total{robot=\"h0\"} 0",
        ] {
            assert!(body.contains(needle), "/metrics lacks {needle}:\n{body}");
        }
        let text = body.clone();
        if let Some(families) = tokio::task::spawn_blocking(move || parsed_as_openmetrics(&text)).await.unwrap() {
            for family in ["spwi_decisions counter", "spwi_members gauge", "spwi_stage_seconds histogram"] {
                assert!(
                    families.lines().any(|l| l.starts_with(family)),
                    "no {family} in the parsed families:\n{families}"
                );
            }
        }
        let (code, _) = tokio::task::spawn_blocking(move || get(addr, "/nope")).await.unwrap();
        assert_eq!(code, 404);
        let (code, body) = tokio::task::spawn_blocking(move || request(addr, "HEAD", "/healthz")).await.unwrap();
        assert_eq!((code, body.as_str()), (200, ""), "HEAD answers like GET, without the body");
        let (code, _) = tokio::task::spawn_blocking(move || request(addr, "POST", "/status")).await.unwrap();
        assert_eq!(code, 405, "the endpoints only read");
        let answer = tokio::task::spawn_blocking(move || huge_request(addr)).await.unwrap();
        assert!(matches!(answer, None | Some(431)), "a request with 1 MB of headers got {answer:?}");
        let (code, _) = tokio::task::spawn_blocking(move || get(addr, "/healthz")).await.unwrap();
        assert_eq!(code, 200, "still serving after refusing the 1 MB request");
        a.stop().await.unwrap();
        b.stop().await.unwrap();
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn sigterm_leaves_the_fleet_cleanly() {
    within!(60, "test", async {
        let hub = Hub::start("term").await.unwrap();
        let models = models();
        let collector = hub.decisions().await.unwrap();
        let ids = vec![id("t0"), id("t1")];
        let stays = InProcessAgent::start(&hub, &ids[0], &models, AgentConfig::default()).await.unwrap();
        let mut leaves = agent_process(EXE, &hub, &ids[1]);
        let _publisher = Publisher::start(&hub, ids.clone(), Duration::from_millis(100));
        collector.wait_members(&ids, 2, Instant::now(), Duration::from_secs(15)).await.unwrap();
        let t0 = Instant::now();
        leaves.signal("TERM").unwrap();
        let took = collector.wait_members(&ids[..1], 1, t0, Duration::from_millis(1500)).await.unwrap();
        eprintln!("SIGTERM: out of the vote in {took:?}");
        let status = leaves.wait_exit(Duration::from_secs(10)).await.unwrap();
        assert!(status.success(), "SIGTERM must end the daemon cleanly: {status}");
        stays.stop().await.unwrap();
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_agent_that_cannot_start_says_why_even_with_its_warnings_hidden() {
    within!(30, "test", async {
        let hub = Hub::start("nostart").await.unwrap();
        let robot = id("n0");
        let missing = std::env::temp_dir().join(format!("spwi-no-models-{}", std::process::id()));
        // As the benchmarks start agents: stderr kept aside, not shown.
        let launch = Launch { models: Some(missing.clone()), stderr: false, ..Launch::new(&hub, &robot) };
        let mut agent = AgentProcess::spawn(std::process::Command::new(EXE), launch).unwrap();
        assert!(!agent.wait_exit(Duration::from_secs(20)).await.unwrap().success());
        let why = agent.exited().unwrap().expect("it has exited");
        assert!(why.contains("n0") && why.contains("cannot read model manifest"), "{why}");
        assert!(why.contains(&missing.join("manifest.json").display().to_string()), "{why}");
    });
}

/// Started anywhere, with no model set named, an agent finds the one copied beside the
/// folder it runs in (the first place it looks, before an installed one and the source
/// tree), and decides with it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_agent_started_elsewhere_finds_the_model_set_copied_there() {
    within!(60, "test", async {
        let _serial = serial().await;
        let hub = Hub::start("elsewhere").await.unwrap();
        let robot = id("e0");
        let place = std::env::temp_dir().join(format!("spwi-elsewhere-{}", std::process::id()));
        let set = place.join("models/default");
        std::fs::create_dir_all(&set).unwrap();
        for f in std::fs::read_dir(models_dir()).unwrap() {
            let f = f.unwrap().path();
            std::fs::copy(&f, set.join(f.file_name().unwrap())).unwrap();
        }
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let mut command = std::process::Command::new(EXE);
        command.current_dir(&place).env_remove("SPWI_MODELS_DIR").args(["--http", &format!("127.0.0.1:{port}")]);
        let collector = hub.decisions().await.unwrap();
        let _agent = AgentProcess::spawn(command, Launch::new(&hub, &robot)).unwrap();
        let _publisher = Publisher::start(&hub, vec![robot.clone()], Duration::from_millis(100));
        collector.wait_members(std::slice::from_ref(&robot), 1, Instant::now(), Duration::from_secs(20)).await.unwrap();
        let addr = std::net::SocketAddr::from(([127, 0, 0, 1], port));
        let (code, body) = tokio::task::spawn_blocking(move || get(addr, "/status")).await.unwrap();
        assert_eq!(code, 200);
        let status: serde_json::Value = serde_json::from_str(&body).unwrap();
        assert_eq!(status["fixture_models"], true, "the copy (the fixture set), not the shipped default: {body}");
        assert!(status["last_decision"]["tick"].as_u64().is_some(), "it decides: {body}");
        std::fs::remove_dir_all(&place).unwrap();
    });
}

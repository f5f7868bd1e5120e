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

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn status_metrics_and_health_are_served_while_deciding() {
    within!(60, "test", async {
        let hub = Hub::start("http").await.unwrap();
        let models = models();
        let collector = Collector::start(&hub).await.unwrap();
        let ids = vec![id("h0"), id("h1")];
        let mut config = AgentConfig::default();
        config.http.listen = Some("127.0.0.1:0".parse().unwrap());
        let a = InProcessAgent::start(&hub, &ids[0], &models, config).await;
        let b = InProcessAgent::start(&hub, &ids[1], &models, AgentConfig::default()).await;
        let _publisher = Publisher::start(&hub, ids.clone(), Duration::from_millis(100));
        collector.wait_members(&ids, 2, Instant::now(), Duration::from_secs(5)).await;
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
        assert!(status["fixture_models"].as_bool().unwrap());
        assert!(status["metrics"]["decisions"].as_u64().unwrap() > 0);
        assert_eq!(status["feed_stale"], false);
        assert_eq!(status["stale_peers"], serde_json::json!([]));
        assert_eq!(status["consensus"], "trust");
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
        ] {
            assert!(body.contains(needle), "/metrics lacks {needle}:\n{body}");
        }
        let (code, _) = tokio::task::spawn_blocking(move || get(addr, "/nope")).await.unwrap();
        assert_eq!(code, 404);
        let (code, body) = tokio::task::spawn_blocking(move || request(addr, "HEAD", "/healthz")).await.unwrap();
        assert_eq!((code, body.as_str()), (200, ""), "HEAD answers like GET, without the body");
        let (code, _) = tokio::task::spawn_blocking(move || request(addr, "POST", "/status")).await.unwrap();
        assert_eq!(code, 405, "the endpoints only read");
        a.stop().await;
        b.stop().await;
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn sigterm_leaves_the_fleet_cleanly() {
    within!(60, "test", async {
        let hub = Hub::start("term").await.unwrap();
        let models = models();
        let collector = Collector::start(&hub).await.unwrap();
        let ids = vec![id("t0"), id("t1")];
        let stays = InProcessAgent::start(&hub, &ids[0], &models, AgentConfig::default()).await;
        let mut leaves = ProcessAgent::start(EXE, &hub, &ids[1]);
        let _publisher = Publisher::start(&hub, ids.clone(), Duration::from_millis(100));
        collector.wait_members(&ids, 2, Instant::now(), Duration::from_secs(15)).await;
        let t0 = Instant::now();
        leaves.signal("TERM");
        let took = collector.wait_members(&ids[..1], 1, t0, Duration::from_millis(1500)).await;
        eprintln!("SIGTERM: out of the vote in {took:?}");
        let status = leaves.wait_exit(Duration::from_secs(10)).await;
        assert!(status.success(), "SIGTERM must end the daemon cleanly: {status}");
        stays.stop().await;
    });
}

//! The demo's live page in a real headless browser (Debian's chromium): the page must
//! render a row per robot and a tick that advances. `.ci/run` installs chromium and sets
//! SPWI_REQUIRE_BROWSER=1, so there a missing browser fails the test; elsewhere the test
//! says loudly that it skipped.
//! Run: `cargo test -p spwi-tests --test demo_page -- --nocapture`.

use spwi_sim::demo::{self, DemoOptions};
use spwi_tests::*;
use spwi_world::layout::Layout;
use spwi_world::world::Scenario;
use std::process::Command;
use std::time::Duration;

fn browser() -> Option<&'static str> {
    ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|b| Command::new(b).arg("--version").output().is_ok_and(|o| o.status.success()))
}

/// The page's DOM after the browser ran its scripts for a while.
fn dump_dom(browser: &str, url: &str) -> String {
    let out = Command::new(browser)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=600", "--dump-dom", url])
        .output()
        .expect("run the browser");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn rendered_tick(dom: &str) -> u64 {
    let at = dom.find("data-tick=\"").expect("tick element") + "data-tick=\"".len();
    dom[at..].split('"').next().unwrap().parse().unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_live_page_renders_the_robots_and_updates() {
    let Some(browser) = browser() else {
        assert!(
            std::env::var_os("SPWI_REQUIRE_BROWSER").is_none(),
            "SPWI_REQUIRE_BROWSER is set but no chromium was found"
        );
        eprintln!("\n!!!!!!!! SKIPPED the_live_page_renders_the_robots_and_updates: no chromium on PATH !!!!!!!!\n");
        return;
    };
    within!(90, "demo page test", async {
        let (tx, rx) = tokio::sync::oneshot::channel();
        let opts = DemoOptions {
            robots: 3,
            workers: 1,
            scenario: Scenario::Dynamic,
            seed: 4,
            duration: Duration::from_secs(25),
            kill_after: None,
            join_after: None,
            layout: Layout::default_layout(),
            agent: spwi_agent::config::AgentConfig {
                models: spwi_agent::config::ModelsConfig { dir: Some(models_dir()), ..Default::default() },
                ..Default::default()
            },
            view: false,
            http: Some("127.0.0.1:0".parse().unwrap()),
            on_http: Some(tx),
        };
        let (stop, stop_rx) = tokio::sync::watch::channel(false);
        let demo = tokio::spawn(demo::run(opts, models(), stop_rx));
        let addr = within!(10, "the page to be served", rx).unwrap();
        tokio::time::sleep(Duration::from_secs(3)).await;
        let url = format!("http://{addr}/");
        let first = tokio::task::spawn_blocking({
            let url = url.clone();
            move || dump_dom(browser, &url)
        })
        .await
        .unwrap();
        for r in ["robot0", "robot1", "robot2"] {
            assert!(first.contains(&format!("id=\"robot-{r}\"")), "no row for {r} in the page:\n{first}");
        }
        let t1 = rendered_tick(&first);
        assert!(t1 > 0, "the page shows no tick");
        tokio::time::sleep(Duration::from_secs(2)).await;
        let second = tokio::task::spawn_blocking(move || dump_dom(browser, &url)).await.unwrap();
        let t2 = rendered_tick(&second);
        assert!(t2 > t1, "the page did not update: tick {t1} then {t2}");
        stop.send(true).unwrap();
        within!(20, "demo to stop", demo).unwrap().unwrap();
    });
}

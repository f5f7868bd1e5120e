//! Test harness: a hub session on an ephemeral loopback port, a scripted detection
//! publisher, agents in-process (each with its own Zenoh session) or as real processes,
//! and a collector of the decisions every agent publishes. Multicast scouting is off;
//! gossip completes the mesh. Every wait has a timeout. `netns` builds a network of
//! namespaces whose links drop real packets.

pub mod netns;

use anyhow::{anyhow, Context, Result};
use spwi_agent::config::AgentConfig;
use spwi_agent::daemon::{self, Options, Started};
use spwi_agent::fleet::{Credentials, FleetDir};
use spwi_agent::model::{Backend, ModelSet};
use spwi_agent::zenoh_config;
use spwi_proto::keys::{self, Topic};
use spwi_proto::*;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::watch;
use tokio::task::JoinHandle;

/// Wraps a future in a timeout that names what was awaited.
#[macro_export]
macro_rules! within {
    ($secs:expr, $what:expr, $fut:expr) => {
        tokio::time::timeout(std::time::Duration::from_secs_f64($secs as f64), $fut)
            .await
            .unwrap_or_else(|_| panic!("timed out after {} s: {}", $secs, $what))
    };
}

/// Serialises the timing-sensitive tests of one test binary: cargo runs a binary's
/// tests in parallel, and a dozen agents per test on two cores would stretch the very
/// latencies the tests bound. Take it before the test's own timeout starts.
pub async fn serial() -> tokio::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::OnceLock<tokio::sync::Mutex<()>> = std::sync::OnceLock::new();
    LOCK.get_or_init(|| tokio::sync::Mutex::new(())).lock().await
}

pub fn id(s: &str) -> RobotId {
    RobotId::new(s).unwrap()
}

pub fn models_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/fixture")
}

pub fn models() -> Arc<ModelSet> {
    ModelSet::load(&models_dir(), Backend::Tract, None).expect("fixture models")
}

/// The hub: the test's own Zenoh session, which every agent connects to.
pub struct Hub {
    pub session: zenoh::Session,
    pub locator: String,
    pub fleet: FleetId,
    /// The fleet directory when the fleet is secured (the hub is then its `world`).
    pub fleet_dir: Option<PathBuf>,
}

impl Hub {
    pub async fn start(fleet: &str) -> Result<Hub> {
        Self::start_listening(fleet, "tcp/127.0.0.1:0").await
    }

    /// A hub listening on `endpoint` (e.g. an address on a test network's bridge).
    pub async fn start_listening(fleet: &str, endpoint: &str) -> Result<Hub> {
        let mut config = zenoh_config::loopback_peer(&[])?;
        config.insert_json5("listen/endpoints", &serde_json::to_string(&[endpoint])?).map_err(|e| anyhow!(e))?;
        let session = zenoh::open(config).await.map_err(|e| anyhow!(e))?;
        let locator = session.info().locators().await.into_iter().next().context("hub listens nowhere")?.to_string();
        Ok(Hub { session, locator, fleet: FleetId::new(fleet)?, fleet_dir: None })
    }

    /// A hub for the secured fleet in `dir`, presenting the certificate of `identity`
    /// (a member of role world: it publishes the detections).
    pub async fn start_secured(dir: &std::path::Path, identity: &str) -> Result<Hub> {
        let (config, creds) = secured_peer(dir, identity, &[])?;
        let session = zenoh::open(config).await.map_err(|e| anyhow!(e))?;
        let locator = session.info().locators().await.into_iter().next().context("hub listens nowhere")?.to_string();
        Ok(Hub { session, locator, fleet: creds.roster.fleet.clone(), fleet_dir: Some(dir.to_owned()) })
    }

    /// A Zenoh config for an agent: loopback peer connected to the hub.
    pub fn peer_config(&self) -> zenoh::Config {
        zenoh_config::loopback_peer(std::slice::from_ref(&self.locator)).unwrap()
    }

    /// The config and credentials for a process presenting `identity`: open when the
    /// hub is, else secured from the hub's fleet directory.
    pub fn member_config(&self, identity: &str) -> Result<(zenoh::Config, Option<Arc<Credentials>>)> {
        match &self.fleet_dir {
            None => Ok((self.peer_config(), None)),
            Some(dir) => {
                let (c, creds) = secured_peer(dir, identity, std::slice::from_ref(&self.locator))?;
                Ok((c, Some(creds)))
            }
        }
    }
}

/// A loopback peer connected to `connect`, secured as `identity` of the fleet in `dir`.
pub fn secured_peer(
    dir: &std::path::Path,
    identity: &str,
    connect: &[String],
) -> Result<(zenoh::Config, Arc<Credentials>)> {
    let creds = Credentials::load(&FleetDir::new(dir), identity)?;
    let mut c = zenoh_config::loopback_peer(connect)?;
    spwi_agent::fleet::secure::apply(&mut c, &creds)?;
    Ok((c, Arc::new(creds)))
}

/// A frame for `robot` at `tick`: the worker is seen unless `tick % 11 == robot_index`.
pub fn scripted_frame(robot: &RobotId, index: usize, tick: u64) -> DetectionFrame {
    let seed = tick as f32 * 0.21 + index as f32 * 1.7;
    let feat = |k: f32| (0..FEATURE_DIM).map(|i| (i as f32 * 0.05 + k + seed).sin()).collect::<Vec<_>>();
    let x = 100.0 + ((tick as f32 * 0.05 + index as f32).sin() + 1.0) * 200.0;
    DetectionFrame {
        robot: robot.clone(),
        tick,
        pose: Some(FloorPose { position: [3.0 * index as f32, 0.0], heading: 0.1 * index as f32 }),
        image_size: [640.0, 480.0],
        human: (tick % 11 != index as u64).then(|| HumanDetection {
            bbox: BBox { x, y: 150.0, w: 40.0, h: 140.0 },
            keypoints: (0..KEYPOINT_VALUES).map(|i| x + i as f32).collect(),
            feature: feat(1.0),
        }),
        objects: (0..(2 + index % 4))
            .map(|k| ObjectDetection {
                class: ObjectClass::ALL[(k + index) % 10],
                bbox: BBox { x: 60.0 * k as f32, y: 300.0, w: 50.0, h: 50.0 },
                score: 0.9,
                feature: feat(2.0 + k as f32),
            })
            .collect(),
        scene_feature: feat(0.0),
    }
}

/// Publishes a frame per robot per tick at `period`, from the hub, until dropped.
pub struct Publisher {
    task: JoinHandle<()>,
    pub tick: Arc<Mutex<u64>>,
}

impl Publisher {
    pub fn start(hub: &Hub, robots: Vec<RobotId>, period: Duration) -> Publisher {
        let session = hub.session.clone();
        let fleet = hub.fleet.clone();
        let tick = Arc::new(Mutex::new(0u64));
        let t = tick.clone();
        let task = tokio::spawn(async move {
            let mut interval = tokio::time::interval(period);
            loop {
                interval.tick().await;
                let now = {
                    let mut g = t.lock().unwrap();
                    *g += 1;
                    *g
                };
                for (i, r) in robots.iter().enumerate() {
                    let bytes = encode(&scripted_frame(r, i, now));
                    let _ = session.put(keys::robot_topic(&fleet, r, Topic::Detections), bytes).await;
                }
            }
        });
        Publisher { task, tick }
    }

    pub fn current_tick(&self) -> u64 {
        *self.tick.lock().unwrap()
    }
}

impl Drop for Publisher {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// A decision as received by the collector.
#[derive(Debug, Clone)]
pub struct Seen {
    pub at: Instant,
    pub msg: DecisionMsg,
}

/// Collects every decision published in the fleet.
pub struct Collector {
    pub seen: Arc<Mutex<Vec<Seen>>>,
    _sub: zenoh::pubsub::Subscriber<()>,
}

impl Collector {
    pub async fn start(hub: &Hub) -> Result<Collector> {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let s = seen.clone();
        let sub = hub
            .session
            .declare_subscriber(keys::all_robots(&hub.fleet, Topic::Decision))
            .callback(move |sample| {
                if let Ok(msg) = decode::<DecisionMsg>(&sample.payload().to_bytes()) {
                    s.lock().unwrap().push(Seen { at: Instant::now(), msg });
                }
            })
            .await
            .map_err(|e| anyhow!(e))?;
        Ok(Collector { seen, _sub: sub })
    }

    /// Decisions per robot, by tick.
    pub fn by_robot(&self) -> BTreeMap<RobotId, BTreeMap<u64, DecisionMsg>> {
        let mut m: BTreeMap<RobotId, BTreeMap<u64, DecisionMsg>> = BTreeMap::new();
        for s in self.seen.lock().unwrap().iter() {
            m.entry(s.msg.robot.clone()).or_default().insert(s.msg.tick, s.msg.clone());
        }
        m
    }

    /// Waits until every robot in `robots` publishes a decision counting `members`
    /// live members, received after `since`; returns the time it took.
    pub async fn wait_members(&self, robots: &[RobotId], members: u32, since: Instant, limit: Duration) -> Duration {
        let deadline = Instant::now() + limit;
        loop {
            let latest = {
                let seen = self.seen.lock().unwrap();
                robots
                    .iter()
                    .map(|r| {
                        seen.iter()
                            .find(|s| s.at >= since && s.msg.robot == *r && s.msg.live_members == members)
                            .map(|s| s.at)
                    })
                    .collect::<Option<Vec<_>>>()
                    .map(|ts| ts.into_iter().max().unwrap())
            };
            if let Some(t) = latest {
                return t - since;
            }
            if Instant::now() > deadline {
                let seen = self.seen.lock().unwrap();
                let last: Vec<_> = robots
                    .iter()
                    .map(|r| (r.to_string(), seen.iter().rev().find(|s| s.msg.robot == *r).map(|s| s.msg.live_members)))
                    .collect();
                panic!("not all of {robots:?} counted {members} members within {limit:?}; last counts: {last:?}");
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// Over ticks `from..=to`: the share of ticks every robot of `robots` decided on
    /// which they all named the same intent at every step, and how many ticks every
    /// robot decided.
    pub fn agreement(&self, robots: &[RobotId], from: u64, to: u64) -> (f64, usize) {
        let by = self.by_robot();
        let (mut same, mut common) = (0, 0);
        for t in from..=to {
            let Some(ds) = robots.iter().map(|r| by.get(r).and_then(|m| m.get(&t))).collect::<Option<Vec<_>>>() else {
                continue;
            };
            common += 1;
            let classes = |d: &DecisionMsg| d.steps.iter().map(|s| s.class).collect::<Vec<_>>();
            same += usize::from(ds.iter().all(|d| classes(d) == classes(ds[0])));
        }
        (if common == 0 { 0.0 } else { same as f64 / common as f64 }, common)
    }

    /// The longest run of consecutive ticks in `from..=to` that `robot` did not decide.
    pub fn longest_gap(&self, robot: &RobotId, from: u64, to: u64) -> u64 {
        let by = self.by_robot();
        let ticks = by.get(robot).cloned().unwrap_or_default();
        let (mut gap, mut run) = (0, 0);
        for t in from..=to {
            if ticks.contains_key(&t) {
                run = 0;
            } else {
                run += 1;
                gap = gap.max(run);
            }
        }
        gap
    }
}

/// An agent running in this process with its own Zenoh session.
pub struct InProcessAgent {
    pub robot: RobotId,
    pub started: Started,
    shutdown: watch::Sender<bool>,
    task: JoinHandle<Result<()>>,
}

impl InProcessAgent {
    pub async fn start(hub: &Hub, robot: &RobotId, models: &Arc<ModelSet>, config: AgentConfig) -> InProcessAgent {
        Self::start_recording(hub, robot, models, config, None).await
    }

    /// Starts an agent that records its engine's inputs and outputs to `record`.
    pub async fn start_recording(
        hub: &Hub,
        robot: &RobotId,
        models: &Arc<ModelSet>,
        config: AgentConfig,
        record: Option<PathBuf>,
    ) -> InProcessAgent {
        let (zenoh, credentials) = hub.member_config(robot.as_str()).expect("agent credentials");
        let opts = Options { robot: robot.clone(), fleet: hub.fleet.clone(), config, zenoh, record, credentials };
        Self::start_with(opts, models).await
    }

    /// Starts an agent with options of the test's own making (another identity's
    /// certificate, a stale roster).
    pub async fn start_with(opts: Options, models: &Arc<ModelSet>) -> InProcessAgent {
        let robot = opts.robot.clone();
        let (tx, rx) = watch::channel(false);
        let (ready_tx, ready_rx) = tokio::sync::oneshot::channel();
        let task = tokio::spawn(daemon::run(opts, models.clone(), rx, Some(ready_tx)));
        let started = within!(10, format!("agent {robot} to start"), ready_rx).expect("agent failed to start");
        InProcessAgent { robot: robot.clone(), started, shutdown: tx, task }
    }

    /// Graceful stop: token undeclared, session closed.
    pub async fn stop(self) {
        let _ = self.shutdown.send(true);
        within!(10, format!("agent {} to stop", self.robot), self.task).unwrap().unwrap();
    }
}

/// An agent as a real OS process (`spwi-test-agent`), for SIGKILL and SIGSTOP.
pub struct ProcessAgent {
    pub robot: RobotId,
    pub child: Child,
}

impl ProcessAgent {
    /// `exe` is `env!("CARGO_BIN_EXE_spwi-test-agent")`, known only to the test files.
    pub fn start(exe: &str, hub: &Hub, robot: &RobotId) -> ProcessAgent {
        Self::start_with(Command::new(exe), hub, robot, "tcp/127.0.0.1:0")
    }

    /// Starts the agent `command` runs (the agent itself, or a wrapper that ends by
    /// executing it, as `ip netns exec` does), listening on `listen`.
    pub fn start_with(mut command: Command, hub: &Hub, robot: &RobotId, listen: &str) -> ProcessAgent {
        let child = command
            .args(["--robot-id", robot.as_str(), "--fleet", hub.fleet.as_str()])
            .arg("--models")
            .arg(models_dir())
            .args(["--cfg", "mode:\"peer\""])
            .args(["--cfg", &format!("listen/endpoints:[\"{listen}\"]")])
            .args(["--cfg", &format!("connect/endpoints:[\"{}\"]", hub.locator)])
            .args(["--cfg", "scouting/multicast/enabled:false"])
            .env("RUST_LOG", "warn")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("spawn spwi-test-agent");
        ProcessAgent { robot: robot.clone(), child }
    }

    /// Waits (polling) for the process to exit, at most `limit`.
    pub async fn wait_exit(&mut self, limit: Duration) -> std::process::ExitStatus {
        let deadline = Instant::now() + limit;
        loop {
            if let Some(s) = self.child.try_wait().expect("try_wait") {
                return s;
            }
            assert!(Instant::now() < deadline, "{} did not exit within {limit:?}", self.robot);
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    pub fn signal(&self, sig: &str) {
        let ok =
            Command::new("kill").args([&format!("-{sig}"), &self.child.id().to_string()]).status().unwrap().success();
        assert!(ok, "kill -{sig} failed");
    }
}

impl Drop for ProcessAgent {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

//! Test harness on top of the fleet toolkit the demo and the bench use
//! (`spwi_sim::loopback`: hub, agents in-process or as processes, the decisions they
//! publish): the fixture models, a scripted detection publisher, and timeouts that
//! name what was awaited. `netns` builds a network of namespaces whose links drop real
//! packets.

pub mod netns;

use spwi_core::model::{Backend, ModelSet};
use spwi_proto::keys::{self, Topic};
use spwi_proto::*;
pub use spwi_sim::loopback::{secured_peer, AgentProcess, Decisions, Hub, InProcessAgent, Launch, Routers};
use std::path::PathBuf;
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::Duration;
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

/// A frame for `robot` captured at the start of `tick`: the worker is seen unless
/// `tick % 11 == robot_index`.
pub fn scripted_frame(robot: &RobotId, index: usize, tick: u64) -> DetectionFrame {
    // Ticks of the wall clock are about 2e10: too large for an f32 to tell apart.
    let phase = (tick % 100_000) as f32;
    let seed = phase * 0.21 + index as f32 * 1.7;
    let feat = |k: f32| (0..FEATURE_DIM).map(|i| (i as f32 * 0.05 + k + seed).sin()).collect::<Vec<_>>();
    let x = 100.0 + ((phase * 0.05 + index as f32).sin() + 1.0) * 200.0;
    DetectionFrame {
        robot: robot.clone(),
        capture_us: DetectionFrame::capture_at_tick(tick),
        pose: Some(FloorPose { position: [3.0 * index as f32, 0.0], heading: 0.1 * index as f32 }),
        image_size: [640.0, 480.0],
        humans: (tick % 11 != index as u64)
            .then(|| HumanDetection {
                bbox: BBox { x, y: 150.0, w: 40.0, h: 140.0 },
                keypoints: (0..KEYPOINT_VALUES).map(|i| x + i as f32).collect(),
                feature: feat(1.0),
                track: None,
            })
            .into_iter()
            .collect(),
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

/// The Python a test runs its checks with (`SPWI_PYTHON`, else `python3`), if it can
/// `import` what `imports` names. Without one the test says so loudly and skips what
/// it would have checked — unless `required_by` is set in the environment (as
/// `.ci/run` sets it), in which case a missing Python fails the test.
pub fn python_with(imports: &str, required_by: &str, skipped: &str) -> Option<String> {
    let python = std::env::var("SPWI_PYTHON").unwrap_or_else(|_| "python3".into());
    let found = Command::new(&python).args(["-c", &format!("import {imports}")]).status().is_ok_and(|s| s.success());
    if !found {
        assert!(std::env::var_os(required_by).is_none(), "{required_by} is set but {python} cannot import {imports}");
        eprintln!("\n!!!!!!!! SKIPPED {skipped}: {python} cannot import {imports} !!!!!!!!\n");
        return None;
    }
    Some(python)
}

/// The tick of the fleet's clock now (the host's wall clock).
pub fn clock_tick() -> u64 {
    tick_at(spwi_core::clock::FleetClock::default().now())
}

/// Publishes a frame per robot per tick of the fleet's clock, captured at the tick's
/// start, from the hub, until dropped: a detector node on each robot would.
pub struct Publisher {
    task: JoinHandle<()>,
    /// (the first tick published, the latest), on the fleet's clock.
    ticks: Arc<Mutex<Option<(u64, u64)>>>,
}

impl Publisher {
    pub fn start(hub: &Hub, robots: Vec<RobotId>, period: Duration) -> Publisher {
        let session = hub.session.clone();
        let fleet = hub.fleet.clone();
        let ticks = Arc::new(Mutex::new(None));
        let t = ticks.clone();
        let task = tokio::spawn(async move {
            let clock = spwi_core::clock::FleetClock::default();
            // 5 ms into each period of the clock, as a camera triggered on it.
            let into_next = tick_start(tick_at(clock.now()) + 1) + Duration::from_millis(5);
            let start = tokio::time::Instant::now() + clock.until(into_next);
            let mut interval = tokio::time::interval_at(start, period);
            loop {
                interval.tick().await;
                let now = tick_at(clock.now());
                {
                    let mut g = t.lock().unwrap();
                    *g = Some((g.map_or(now, |(first, _)| first), now));
                }
                for (i, r) in robots.iter().enumerate() {
                    let bytes = encode(&scripted_frame(r, i, now));
                    let _ = session.put(keys::robot_topic(&fleet, r, Topic::Detections), bytes).await;
                }
            }
        });
        Publisher { task, ticks }
    }

    /// The latest tick published (the clock's tick before the first).
    pub fn current_tick(&self) -> u64 {
        self.ticks.lock().unwrap().map_or_else(clock_tick, |(_, last)| last)
    }

    /// The first tick published (the clock's tick before the first).
    pub fn first_tick(&self) -> u64 {
        self.ticks.lock().unwrap().map_or_else(clock_tick, |(first, _)| first)
    }

    /// How many ticks were published.
    pub fn published(&self) -> u64 {
        self.ticks.lock().unwrap().map_or(0, |(first, last)| last + 1 - first)
    }
}

impl Drop for Publisher {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// An agent process of the fixture models, listening on loopback; `exe` is
/// `env!("CARGO_BIN_EXE_spwi-test-agent")`, known only to the test files.
pub fn agent_process(exe: &str, hub: &Hub, robot: &RobotId) -> AgentProcess {
    agent_process_with(Command::new(exe), hub, robot, "tcp/127.0.0.1:0")
}

/// The same, run by `command` (the agent itself or a wrapper such as `ip netns exec`)
/// and listening on `listen`.
pub fn agent_process_with(command: Command, hub: &Hub, robot: &RobotId, listen: &str) -> AgentProcess {
    let launch = Launch { listen: listen.into(), models: Some(models_dir()), ..Launch::new(hub, robot) };
    AgentProcess::spawn(command, launch).expect("spawn spwi-test-agent")
}

/// `robot`'s share of `tick` voting `class` for t and 20 steps ahead at confidence 1,
/// claiming the fullest view and a thousand detections.
pub fn lying_share(robot: &RobotId, tick: u64, class: Station) -> EmbeddingMsg {
    let vote = VoteMsg {
        robot: robot.clone(),
        instance: 4,
        tick,
        steps: vec![StepVote { class, confidence: 1.0 }; 21],
        visibility: 1000,
        quality: 1.0,
        worker: None,
        signature: Vec::new(),
    };
    EmbeddingMsg {
        robot: robot.clone(),
        instance: 4,
        tick,
        embedding: None,
        visibility: 1000,
        vote: Some(vote),
        worker: None,
        facing: None,
        landmarks: Vec::new(),
        verdict: None,
        people: Vec::new(),
    }
}

/// `robot` (a member, on its own key) puts a thousand shares in 4 s: for ticks near
/// 2^62, a minute ahead, a minute behind, tick 0 — and, between them, shares of the
/// tick just ahead of the clock's, repeated. Returns how many were off the clock.
pub async fn flood_off_clock(session: &zenoh::Session, fleet: &FleetId, robot: &RobotId) -> u64 {
    let key = keys::robot_topic(fleet, robot, Topic::Embedding);
    let mut off_clock = 0;
    for k in 0..1000u64 {
        let now = clock_tick();
        let t = match k % 5 {
            0 => (1 << 62) + k,
            1 => now + 600,
            2 => now - 600,
            3 => 0,
            _ => now + 1, // within the window: repeated, one share per tick counts
        };
        off_clock += u64::from(k % 5 != 4);
        let bytes = encode(&lying_share(robot, t, Station::Storage));
        session.put(&key, bytes).congestion_control(zenoh::qos::CongestionControl::Block).await.unwrap();
        tokio::time::sleep(Duration::from_millis(4)).await;
    }
    off_clock
}

/// After [`flood_off_clock`] by `flooder` from tick `from` to `to`: every robot of
/// `agents` decided every tick but at most one in a row, refused and counted every one
/// of the `off_clock` messages, shows the flooder's refusals in `/status` and is healthy.
pub fn flood_changed_nothing(
    agents: &[InProcessAgent],
    decisions: &Decisions,
    flooder: &RobotId,
    off_clock: u64,
    from: u64,
    to: u64,
) {
    use spwi_core::clock::OffClock;
    for a in agents {
        let gap = decisions.longest_gap(&a.robot, from, to);
        assert!(gap <= 1, "{} left {gap} ticks in a row undecided during the flood", a.robot);
        let s = a.started.status.lock().unwrap().clone();
        let refused: u64 =
            [OffClock::MessageTooNew, OffClock::MessageTooOld].iter().filter_map(|w| s.metrics.off_clock.get(w)).sum();
        eprintln!(
            "{}: {refused} of {off_clock} refused off the clock; the flooder's clock {:?}",
            a.robot,
            s.clocks.get(flooder)
        );
        assert_eq!(refused, off_clock, "{}: every message off our clock refused and counted", a.robot);
        assert!(s.clocks[flooder].refused >= off_clock, "/status shows the flooder's messages off our clock");
        assert!(s.health.problem.is_none(), "{:?}", s.health);
    }
}

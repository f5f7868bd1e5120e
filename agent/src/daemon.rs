//! The daemon: Zenoh in, the [`Engine`] in the middle, Zenoh out.
//!
//! One event loop owns the engine. Zenoh callbacks only parse the key and queue the raw
//! bytes (bounded queue; overflow is counted, never blocks Zenoh); decoding, checks
//! and counting happen in the loop, so a bad message costs one log line (rate-limited)
//! and one counter. The loop also wakes at the engine's next deadline, so ticks are
//! decided on time even when peers fall silent.
//!
//! Start-up refuses to join a fleet where a live daemon already holds our robot id
//! (Zenoh would merge the two liveliness tokens into one member); a clash that happens
//! later (both started at once) is detected from the instance ids in the messages and
//! reported in logs, `/status` and `/metrics`.

use crate::config::AgentConfig;
use crate::engine::{Engine, EngineConfig, Input, Output};
use crate::model::ModelSet;
use crate::record::{PeerState, RecordedConfig, Recorder};
use crate::status::{RecentDecision, SharedStatus, Status};
use anyhow::{anyhow, bail, Result};
use spwi_proto::keys::{self, Topic};
use spwi_proto::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};
use zenoh::sample::SampleKind;

/// Who this daemon is and how it connects.
pub struct Options {
    pub robot: RobotId,
    pub fleet: FleetId,
    pub config: AgentConfig,
    pub zenoh: zenoh::Config,
    /// Record every input and output of the engine to this MCAP file.
    pub record: Option<std::path::PathBuf>,
    /// The fleet's credentials when it is secured (`--fleet-dir`); `zenoh` already
    /// carries their TLS and access rules.
    pub credentials: Option<Arc<crate::fleet::Credentials>>,
}

/// A message as the Zenoh callbacks hand it to the loop.
struct Message {
    topic: Topic,
    robot: RobotId,
    bytes: Vec<u8>,
}

/// A liveliness change. These travel on their own unbounded queue: they are rare, and
/// losing one would leave a ghost member (or miss a new one) for good.
struct Membership {
    robot: RobotId,
    alive: bool,
}

/// Loads the model set named by the config.
pub fn load_models(cfg: &AgentConfig) -> Result<Arc<ModelSet>> {
    let set = ModelSet::load(&cfg.models.dir, cfg.models.backend, cfg.models.ort_library.as_deref())?;
    if set.manifest.fixture {
        tracing::warn!(dir = %set.dir.display(), "running FIXTURE models (random weights): decisions are plumbing tests, not predictions");
    }
    Ok(set)
}

/// A running daemon's handles, for callers that embed it (tests, the demo).
pub struct Started {
    pub status: SharedStatus,
    pub http: Option<std::net::SocketAddr>,
}

/// Runs the daemon until `shutdown` turns true, then leaves the fleet cleanly
/// (undeclares the liveliness token, closes the session). `ready` receives the
/// status handle once the daemon has joined.
pub async fn run(
    opts: Options,
    models: Arc<ModelSet>,
    mut shutdown: watch::Receiver<bool>,
    ready: Option<tokio::sync::oneshot::Sender<Started>>,
) -> Result<()> {
    let Options { robot, fleet, config, zenoh, record, credentials } = opts;
    config.validate()?;
    let instance = random_instance();
    let m = &models.manifest;
    let engine_config = EngineConfig::new(robot.clone(), instance, &config.tick, &config.camera, m);
    let mut recorder = match &record {
        Some(path) => {
            Some(Recorder::create(path, &RecordedConfig { engine: engine_config.clone(), model_set: m.name.clone() })?)
        }
        None => None,
    };
    let mut engine = Engine::new(engine_config, models.inference(config.tick.temporal)?);

    let session = zenoh::open(zenoh).await.map_err(|e| anyhow!("cannot open the Zenoh session: {e}"))?;
    let alive_key = keys::alive(&fleet, &robot);
    refuse_duplicate(&session, &alive_key, &robot).await?;
    let token = session.liveliness().declare_token(&alive_key).await.map_err(|e| anyhow!("{alive_key}: {e}"))?;

    let (tx, mut rx) = mpsc::channel::<Message>(config.tick.event_queue);
    let (member_tx, mut member_rx) = mpsc::unbounded_channel::<Membership>();
    let overflow = Arc::new(AtomicU64::new(0));
    let mut subscribers = Vec::new();
    for (key, topic) in [
        (keys::robot_topic(&fleet, &robot, Topic::Detections), Topic::Detections),
        (keys::all_robots(&fleet, Topic::Embedding), Topic::Embedding),
        (keys::all_robots(&fleet, Topic::Vote), Topic::Vote),
        (keys::all_robots(&fleet, Topic::Decision), Topic::Decision),
        (keys::all_robots(&fleet, Topic::Ballots), Topic::Ballots),
    ] {
        let (tx, overflow, fleet) = (tx.clone(), overflow.clone(), fleet.clone());
        let sub = session
            .declare_subscriber(&key)
            .callback(move |s| {
                if let Some((robot, t)) = keys::parse_robot_topic(&fleet, s.key_expr().as_str()) {
                    debug_assert_eq!(t, topic);
                    let ev = Message { topic: t, robot, bytes: s.payload().to_bytes().into_owned() };
                    if tx.try_send(ev).is_err() {
                        overflow.fetch_add(1, Ordering::Relaxed);
                    }
                }
            })
            .await
            .map_err(|e| anyhow!("subscribing to {key}: {e}"))?;
        subscribers.push(sub);
    }
    let membership = {
        let fleet = fleet.clone();
        session
            .liveliness()
            .declare_subscriber(keys::all_alive(&fleet))
            .history(true)
            .callback(move |s| {
                if let Some(robot) = keys::parse_alive(&fleet, s.key_expr().as_str()) {
                    let _ = member_tx.send(Membership { robot, alive: s.kind() == SampleKind::Put });
                }
            })
            .await
            .map_err(|e| anyhow!("subscribing to membership: {e}"))?
    };
    drop(tx);

    let publish = |t: Topic| keys::robot_topic(&fleet, &robot, t);
    let publishers = Publishers {
        embedding: session.declare_publisher(publish(Topic::Embedding)).express(true).await.map_err(|e| anyhow!(e))?,
        vote: session.declare_publisher(publish(Topic::Vote)).express(true).await.map_err(|e| anyhow!(e))?,
        decision: session.declare_publisher(publish(Topic::Decision)).express(true).await.map_err(|e| anyhow!(e))?,
        ballots: session.declare_publisher(publish(Topic::Ballots)).express(true).await.map_err(|e| anyhow!(e))?,
    };
    let (out_tx, out_rx) = mpsc::channel::<(Topic, Vec<u8>)>(OUTGOING_QUEUE);
    let outgoing_dropped = Arc::new(AtomicU64::new(0));
    let publisher_thread = std::thread::Builder::new()
        .name("spwi-publish".into())
        .spawn(move || publishers.run(out_rx))
        .map_err(|e| anyhow!("cannot start the publisher thread: {e}"))?;

    let status: SharedStatus = Arc::new(Mutex::new(Status {
        robot: robot.to_string(),
        fleet: fleet.to_string(),
        instance,
        model_set: models.manifest.name.clone(),
        fixture_models: models.manifest.fixture,
        backend: format!("{:?}", models.backend).to_lowercase(),
        temporal: format!("{:?}", config.tick.temporal).to_lowercase(),
        consensus: config.tick.consensus.name().to_owned(),
        identity: credentials.as_ref().map(|c| c.identity.name.to_string()),
        members: engine.members(),
        last_decision: None,
        recent_decisions: Default::default(),
        duplicate_robot_id: Vec::new(),
        feed_stale: false,
        stale_peers: Vec::new(),
        trust: Default::default(),
        metrics: engine.metrics.clone(),
    }));
    let mut http_task = None;
    let mut http_addr = None;
    if let Some(addr) = config.http.listen {
        let (bound, fut) = crate::http::serve(addr, status.clone(), shutdown.clone()).await?;
        http_addr = Some(bound);
        http_task = Some(tokio::spawn(fut));
    }
    let secured = credentials.is_some();
    tracing::info!(%robot, %fleet, instance, secured, http = ?http_addr, model_set = %models.manifest.name, "joined the fleet");
    if let Some(ready) = ready {
        let _ = ready.send(Started { status: status.clone(), http: http_addr });
    }

    let mut signed_votes = credentials.map(|c| crate::fleet::signed_votes::SignedVotes::new(c, robot.clone()));
    let start = Instant::now();
    let mut bad_log = RateLimitedLog::new(Duration::from_secs(5));
    loop {
        let deadline = engine.next_deadline().map(|d| tokio::time::Instant::from_std(start + d));
        let mut input = tokio::select! {
            _ = shutdown.changed() => break,
            Some(Membership { robot: r, alive }) = member_rx.recv() => {
                tracing::info!(robot = %r, alive, "membership change");
                if alive { Input::MemberJoined(r) } else { Input::MemberLeft(r) }
            }
            msg = rx.recv() => match msg {
                None => break,
                Some(Message { topic, robot: r, bytes }) => match decode_input(topic, &r, &bytes) {
                    Ok(i) => i,
                    Err(e) => {
                        engine.metrics.bad_message(e.reason());
                        bad_log.warn(|| format!("dropped a bad message on {}'s {}: {e}", r, topic.as_str()));
                        continue;
                    }
                },
            },
            _ = sleep_until(deadline) => Input::Poll,
        };
        if let Some(s) = signed_votes.as_mut() {
            let forged = s.check(&mut input);
            if forged > 0 {
                *engine.metrics.bad_messages.entry("forged_relayed_vote").or_default() += forged as u64;
                bad_log.warn(|| format!("dropped {forged} relayed vote(s) without their origin's signature"));
            }
        }
        let membership_change = matches!(input, Input::MemberJoined(_) | Input::MemberLeft(_));
        let now = start.elapsed();
        if let Some(r) = recorder.as_mut() {
            if let Err(e) = r.input(&input, now) {
                tracing::error!("recording stopped: {e:#}");
                recorder = None;
            }
        }
        let outputs = engine.handle(input, now);
        if let Some(r) = recorder.as_mut() {
            let states = PeerState::after(&engine, &outputs);
            let recorded = outputs.iter().try_for_each(|o| r.output(o, now));
            if let Err(e) = recorded.and_then(|()| states.iter().try_for_each(|s| r.state(s, now))) {
                tracing::error!("recording stopped: {e:#}");
                recorder = None;
            }
        }
        let mut decided = Vec::new();
        for mut o in outputs {
            if let Some(s) = signed_votes.as_mut() {
                s.sign(&mut o);
            }
            let out = match &o {
                Output::Embedding(m) => (Topic::Embedding, encode(m)),
                Output::Vote(m) => (Topic::Vote, encode(m)),
                Output::Ballots(m) => (Topic::Ballots, encode(m)),
                Output::Decision(m) => {
                    decided.push(RecentDecision { tick: m.tick, class: m.steps.first().map(|s| s.class) });
                    (Topic::Decision, encode(m))
                }
            };
            if out_tx.try_send(out).is_err() {
                outgoing_dropped.fetch_add(1, Ordering::Relaxed);
                bad_log.warn(|| "Zenoh is holding up publishing: dropping outgoing messages".to_owned());
            }
        }
        if !decided.is_empty() || membership_change {
            let lost = overflow.swap(0, Ordering::Relaxed);
            if lost > 0 {
                *engine.metrics.bad_messages.entry("queue_full").or_default() += lost;
            }
            engine.metrics.outgoing_dropped += outgoing_dropped.swap(0, Ordering::Relaxed);
            if let Ok(mut s) = status.lock() {
                s.members = engine.members();
                s.last_decision = engine.last_decision.clone();
                s.remember(decided);
                s.duplicate_robot_id = engine.duplicates.iter().copied().collect();
                s.feed_stale = engine.feed_is_stale();
                s.stale_peers = engine.stale_peers();
                s.trust = engine.trust();
                s.metrics = engine.metrics.clone();
            }
        }
    }

    tracing::info!(%robot, "leaving the fleet");
    if let Some(r) = recorder {
        if let Err(e) = r.finish() {
            tracing::error!("finishing the recording: {e:#}");
        }
    }
    drop(out_tx); // the publisher thread sends what is queued, then ends
    let _ = tokio::task::spawn_blocking(move || publisher_thread.join()).await;
    drop(subscribers);
    drop(membership);
    let _ = token.undeclare().await;
    let _ = session.close().await;
    if let Some(t) = http_task {
        let _ = t.await;
    }
    Ok(())
}

/// Outgoing messages queued between the tick loop and the publisher task.
const OUTGOING_QUEUE: usize = 256;
/// A put slower than this is logged: Zenoh is holding up publishing.
const SLOW_PUT: Duration = Duration::from_millis(100);

/// This robot's publishers, driven by their own OS thread: a put that Zenoh holds up
/// (seen when a peer's link is cut and its lease has not yet run out) blocks the thread
/// it runs on, and must never hold a runtime worker the tick loop needs. When the
/// thread falls behind, the loop drops and counts messages instead.
struct Publishers {
    embedding: zenoh::pubsub::Publisher<'static>,
    vote: zenoh::pubsub::Publisher<'static>,
    decision: zenoh::pubsub::Publisher<'static>,
    ballots: zenoh::pubsub::Publisher<'static>,
}

impl Publishers {
    fn run(self, mut rx: mpsc::Receiver<(Topic, Vec<u8>)>) {
        use zenoh::Wait;
        let mut log = RateLimitedLog::new(Duration::from_secs(5));
        while let Some((topic, bytes)) = rx.blocking_recv() {
            let publisher = match topic {
                Topic::Embedding => &self.embedding,
                Topic::Vote => &self.vote,
                Topic::Decision => &self.decision,
                Topic::Ballots => &self.ballots,
                Topic::Detections => unreachable!("agents publish no detections"),
            };
            let started = Instant::now();
            if let Err(e) = publisher.put(bytes).wait() {
                log.warn(|| format!("publishing on {} failed: {e}", topic.as_str()));
            }
            let took = started.elapsed();
            if took > SLOW_PUT {
                log.warn(|| format!("publishing on {} took {} ms", topic.as_str(), took.as_millis()));
            }
        }
    }
}

fn decode_input(topic: Topic, robot: &RobotId, bytes: &[u8]) -> Result<Input, DecodeError> {
    Ok(match topic {
        Topic::Detections => Input::Frame(decode_from(bytes, robot)?),
        Topic::Embedding => Input::Embedding(decode_from(bytes, robot)?),
        Topic::Vote => Input::Vote(decode_from(bytes, robot)?),
        Topic::Decision => Input::Decision(decode_from(bytes, robot)?),
        Topic::Ballots => Input::Ballots(decode_from(bytes, robot)?),
    })
}

async fn sleep_until(deadline: Option<tokio::time::Instant>) {
    match deadline {
        Some(d) => tokio::time::sleep_until(d).await,
        None => std::future::pending().await,
    }
}

/// Refuses to start when a live daemon already holds our liveliness token. Peers only
/// answer for themselves and the mesh takes a moment to form after `open`, so the
/// question is asked a few times over about a second before the token is declared.
async fn refuse_duplicate(session: &zenoh::Session, alive_key: &str, robot: &RobotId) -> Result<()> {
    for attempt in 0..4 {
        if attempt > 0 {
            tokio::time::sleep(Duration::from_millis(300)).await;
        }
        let replies = session.liveliness().get(alive_key).await.map_err(|e| anyhow!("{alive_key}: {e}"))?;
        let found = tokio::time::timeout(Duration::from_secs(1), async {
            while let Ok(reply) = replies.recv_async().await {
                if reply.result().is_ok() {
                    return true;
                }
            }
            false
        })
        .await
        .unwrap_or(false);
        if found {
            bail!("robot id \"{robot}\" is already in use by a live daemon of this fleet ({alive_key}); give each robot a unique --robot-id");
        }
    }
    Ok(())
}

fn random_instance() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default().as_nanos());
    h.write_u32(std::process::id());
    h.finish()
}

/// Logs at most one warning per period and says how many were suppressed.
struct RateLimitedLog {
    period: Duration,
    last: Option<Instant>,
    suppressed: u64,
}

impl RateLimitedLog {
    fn new(period: Duration) -> Self {
        RateLimitedLog { period, last: None, suppressed: 0 }
    }

    fn warn(&mut self, msg: impl FnOnce() -> String) {
        let now = Instant::now();
        if self.last.is_some_and(|l| now - l < self.period) {
            self.suppressed += 1;
            return;
        }
        tracing::warn!(suppressed = self.suppressed, "{}", msg());
        self.last = Some(now);
        self.suppressed = 0;
    }
}

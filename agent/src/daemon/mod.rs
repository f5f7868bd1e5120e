//! The daemon: Zenoh in, the [`Engine`] in the middle, Zenoh out.
//!
//! One event loop owns the engine ([`run`]). What comes in is queued raw by the Zenoh
//! callbacks ([`connection`]); decoding, checks and counting happen in the loop, so a
//! bad message costs one log line (rate-limited, [`log`]) and one counter. The loop
//! also wakes at the engine's next deadline, so ticks are decided on time even when
//! peers fall silent. Its clock is the fleet's ([`spwi_core::clock::FleetClock`]): the
//! host's wall clock, which chrony or PTP keeps in step with the other robots'. What goes out is put on Zenoh by a thread of its own
//! ([`publishing`]), and `/status` is refreshed after each decision and membership
//! change. The `spwi-agent` process gives its heap's free pages back every half minute
//! ([`memory`]; once per process, not per daemon, as the heap is the process's).
//!
//! In a secured fleet the daemon takes a newer signed roster while it runs
//! ([`crate::fleet::live`]): from then on a revoked robot's messages are refused and it
//! is no longer a member, a new robot's signed votes count, and shortly after (0.2 s,
//! then spread over 1.5 s by robot) the session is reopened with the new roster's
//! access rules, which Zenoh sets only when a session opens. Members seen to leave
//! in those seconds are held a moment, as they are most likely reopening too
//! ([`departures`]). A roster that revokes this robot makes it leave the fleet.
//!
//! Start-up refuses to join a fleet where a live daemon already holds our robot id
//! (Zenoh would merge the two liveliness tokens into one member); a clash that happens
//! later (both started at once) is detected from the instance ids in the messages and
//! reported in logs, `/status` and `/metrics`.

mod connection;
mod departures;
pub(crate) mod log;
pub mod memory;
mod publishing;

use crate::config::AgentConfig;
use crate::fleet::live::{self, Adopted, Watch};
use crate::metrics::{DropReason, TransportCounters};
use crate::record::{PeerState, RecordedConfig, Recorder};
use crate::status::{FloorPlanStatus, Health, RecentDecision, SharedStatus, Status};
use anyhow::Result;
use connection::{Connection, Joining, Membership, Message};
use departures::Departures;
use log::RateLimitedLog;
use publishing::Outbox;
use spwi_core::clock::FleetClock;
use spwi_core::engine::{Engine, EngineConfig, Input, Output};
use spwi_core::model::{locate, ModelSet};
use spwi_proto::*;
use std::collections::VecDeque;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::watch;

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

/// Loads the model set named by the config.
pub fn load_models(cfg: &AgentConfig) -> Result<Arc<ModelSet>> {
    let dir = locate::model_set(cfg.models.dir.as_deref(), locate::DEFAULT_SET)?;
    let set = ModelSet::load(&dir, cfg.models.backend, cfg.models.ort_library.as_deref())?;
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
    let mut engine_config = EngineConfig::new(robot.clone(), instance, &config.tick, &config.camera, m);
    engine_config.floor_plan = config.floor.load_plan()?;
    let mut recorder = match &record {
        Some(path) => Some(Recorder::create(
            path,
            &RecordedConfig { protocol: PROTOCOL_VERSION, engine: engine_config.clone(), model_set: m.name.clone() },
        )?),
        None => None,
    };
    let mut engine = Engine::new(engine_config, models.inference(config.tick.temporal)?);

    let secured = credentials.is_some();
    let queue = config.tick.event_queue;
    let mut conn = Connection::open(zenoh.clone(), &fleet, &robot, queue, Joining::First).await?;
    let mut outbox = Outbox::start(&conn.session, &fleet, &robot).await?;
    let mut roster = credentials.clone().map(Watch::new);
    if let Some(w) = roster.as_mut() {
        w.listen(&conn.session).await?;
    }

    let mut health = Health::new(Duration::from_millis(config.http.unhealthy_after_ms));
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
        roster_version: credentials.as_ref().map(|c| c.roster.version),
        roster_adopted_at: roster.as_ref().map(|w| crate::fleet::authority::rfc3339(w.roster.adopted_at.into())),
        members: engine.members(),
        last_decision: None,
        stations: crate::status::STATION_NAMES,
        recent_decisions: Default::default(),
        duplicate_robot_id: Vec::new(),
        catching_up: false,
        feed_stale: false,
        stale_peers: Vec::new(),
        trust: Default::default(),
        metrics: engine.metrics().clone(),
        transport: TransportCounters::default(),
        clocks: Default::default(),
        health: health.clone(),
        floor_plan: engine
            .config()
            .floor_plan
            .as_ref()
            .map(|p| FloorPlanStatus { stations: p.len(), ..Default::default() }),
        people: Vec::new(),
    }));
    let mut http_task = None;
    let mut http_addr = None;
    if let Some(addr) = config.http.listen {
        let (bound, fut) = crate::http::serve(addr, status.clone(), shutdown.clone()).await?;
        http_addr = Some(bound);
        http_task = Some(tokio::spawn(fut));
    }
    tracing::info!(%robot, %fleet, instance, secured, http = ?http_addr, model_set = %models.manifest.name, "joined the fleet");
    if let Some(ready) = ready {
        let _ = ready.send(Started { status: status.clone(), http: http_addr });
    }

    let mut signed_votes =
        credentials.map(|c| crate::fleet::signed_votes::SignedVotes::new(c, fleet.clone(), robot.clone()));
    let clock = FleetClock::with_offset_ms(config.tick.clock_offset_ms);
    if config.tick.clock_offset_ms != 0 {
        tracing::warn!(
            offset_ms = config.tick.clock_offset_ms,
            "this robot's clock is shifted on purpose (tick.clock_offset_ms): for tests only"
        );
    }
    let window = engine.config().window;
    let mut next_refresh = Instant::now();
    let mut bad_log = RateLimitedLog::new(Duration::from_secs(5));
    let mut slow_log = RateLimitedLog::new(Duration::from_secs(5));
    let mut transport = TransportCounters::default();
    let mut reopen_at: Option<tokio::time::Instant> = None;
    // Inputs the daemon makes itself (a revoked robot leaving), handled before the next wait.
    let mut pending: VecDeque<Input> = VecDeque::new();
    let mut departures = Departures::default();
    // In a secured fleet, robots the roster held admits (and this one, whatever its
    // certificate): anyone else's messages are refused even before the session is
    // reopened with the roster's access rules.
    let admitted = |roster: &Option<Watch>, r: &RobotId| {
        *r == robot || roster.as_ref().is_none_or(|w| w.credentials().admits_robot(r))
    };
    let mut left = None;
    loop {
        let deadline = engine.next_deadline().map(|d| tokio::time::Instant::now() + clock.until(d));
        let refresh_at = tokio::time::Instant::from_std(next_refresh);
        let wake = match pending.pop_front() {
            Some(input) => Wake::Input(input),
            None => tokio::select! {
            _ = shutdown.changed() => break,
            Some(Membership { robot: r, alive }) = conn.membership.recv() => {
                if !admitted(&roster, &r) {
                    continue; // a revoked robot still running, until its links go
                }
                if alive {
                    if !departures.joined(&r) {
                        tracing::info!(robot = %r, alive, "membership change");
                    }
                    Wake::Input(Input::MemberJoined(r))
                } else if departures.left(&r, Instant::now()) {
                    tracing::info!(robot = %r, alive, "membership change");
                    Wake::Input(Input::MemberLeft(r))
                } else {
                    tracing::debug!(robot = %r, "token withdrawn during a roster change: held while it reopens");
                    continue;
                }
            }
            _ = sleep_until(departures.next_due().map(tokio::time::Instant::from_std)) => {
                for r in departures.due(Instant::now()) {
                    tracing::info!(robot = %r, alive = false, "membership change (did not come back)");
                    pending.push_back(Input::MemberLeft(r));
                }
                continue;
            }
            adopted = live::adopted(roster.as_mut(), &conn.session) => match adopted {
                Ok(adopted) => Wake::Roster(adopted),
                Err(e) => {
                    tracing::error!("{e:#}: this robot leaves the fleet");
                    left = Some(e);
                    break;
                }
            },
            _ = sleep_until(reopen_at) => Wake::Reopen,
            msg = conn.messages.recv() => Wake::Input(match msg {
                None => break,
                Some(Message { robot: r, .. }) if !admitted(&roster, &r) => {
                    transport.bad_messages(DropReason::NotAdmitted, 1);
                    continue;
                }
                Some(Message { topic, robot: r, bytes }) => match Input::from_peer(topic, &r, &bytes) {
                    Ok(Some(i)) => i,
                    Ok(None) => continue, // a topic robots do not read
                    Err(e) => {
                        transport.bad_messages(DropReason::from(&e), 1);
                        bad_log.warn(|| format!("dropped a bad message on {}'s {}: {e}", r, topic.as_str()));
                        continue;
                    }
                },
            }),
            _ = sleep_until(deadline) => Wake::Input(Input::Poll),
            _ = tokio::time::sleep_until(refresh_at) => Wake::Input(Input::Poll),
            },
        };
        let mut input = match wake {
            Wake::Input(input) => input,
            Wake::Roster(Adopted { credentials, revoked, .. }) => {
                if let Some(s) = signed_votes.as_mut() {
                    s.set_credentials(credentials.clone());
                }
                pending.extend(revoked.into_iter().filter(|r| *r != robot).map(Input::MemberLeft));
                reopen_at = Some(tokio::time::Instant::now() + live::reopen_delay(&robot));
                departures.roster_adopted(Instant::now());
                if let (Ok(mut s), Some(w)) = (status.lock(), &roster) {
                    s.roster_version = Some(credentials.roster.version);
                    s.roster_adopted_at = Some(crate::fleet::authority::rfc3339(w.roster.adopted_at.into()));
                }
                continue;
            }
            Wake::Reopen => {
                reopen_at = None;
                let watch = roster.as_mut().expect("only an adopted roster reopens");
                let began = Instant::now();
                outbox.finish().await;
                conn.close().await;
                let mut secured_config = zenoh.clone();
                crate::fleet::secure::apply(&mut secured_config, watch.credentials())?;
                live::for_reopening(&mut secured_config)?;
                conn = Connection::reopen(secured_config, &fleet, &robot, queue).await?;
                outbox = Outbox::start(&conn.session, &fleet, &robot).await?;
                watch.listen(&conn.session).await?;
                departures.reopened(engine.members().into_iter().filter(|m| *m != robot), Instant::now());
                let held = &watch.roster;
                tracing::info!(
                    took_ms = began.elapsed().as_millis() as u64,
                    version = held.credentials().roster.version,
                    "reopened the session with the roster's access rules"
                );
                continue;
            }
        };
        let now = clock.now();
        // A tick off our clock is refused by the engine; its votes are not worth
        // checking a signature for.
        let on_clock = input.tick().is_none_or(|t| window.refuses(t, now).is_none());
        if let (Some(s), true) = (signed_votes.as_mut(), on_clock) {
            let checked = s.check(&mut input);
            if checked.forged > 0 {
                transport.bad_messages(DropReason::ForgedRelayedVote, checked.forged as u64);
                bad_log.warn(|| format!("dropped {} relayed vote(s) without their origin's signature", checked.forged));
            }
            if !checked.equivocated.is_empty() {
                transport.bad_messages(DropReason::EquivocatedVote, checked.equivocated.len() as u64);
                let who: Vec<&str> = checked.equivocated.iter().map(|r| r.as_str()).collect();
                bad_log.warn(|| format!("{} signed two different votes for one tick (equivocation)", who.join(", ")));
            }
        }
        let membership_change = matches!(input, Input::MemberJoined(_) | Input::MemberLeft(_));
        if matches!(input, Input::Frame(_)) {
            health.frame(Instant::now());
        }
        let handled_at = Instant::now();
        if let Some(r) = recorder.as_mut() {
            if let Err(e) = r.input(&input, now) {
                tracing::error!("recording stopped: {e:#}");
                recorder = None;
            }
        }
        let outputs = engine.handle(input, now);
        let took = handled_at.elapsed();
        if took > TICK_PERIOD {
            slow_log
                .warn(|| format!("one event took {} ms, longer than a tick: decisions will be late", took.as_millis()));
        }
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
            if let Output::Decision(m) = &o {
                decided.push(RecentDecision::of(m));
            }
            if !outbox.publish(&o) {
                bad_log.warn(|| "Zenoh is holding up publishing: dropping outgoing messages".to_owned());
            }
        }
        if !decided.is_empty() {
            health.decision(Instant::now());
        }
        // After a decision or a membership change, and at least twice a second
        // whatever peers send: /status and /metrics follow the engine.
        if !decided.is_empty() || membership_change || Instant::now() >= next_refresh {
            next_refresh = Instant::now() + STATUS_REFRESH;
            if let Some(w) = &roster {
                (transport.rosters_adopted, transport.rosters_refused) = (w.roster.adopted, w.roster.refused);
            }
            let lost = conn.overflow.swap(0, Ordering::Relaxed);
            if lost > 0 {
                transport.bad_messages(DropReason::QueueFull, lost);
            }
            transport.outgoing_dropped += outbox.take_dropped();
            if let Ok(mut s) = status.lock() {
                s.refresh(&engine, &transport, decided);
                health.problem = health.check(Instant::now());
                s.health = health.clone();
            }
        }
    }

    tracing::info!(%robot, "leaving the fleet");
    if let Some(r) = recorder {
        if let Err(e) = r.finish() {
            tracing::error!("finishing the recording: {e:#}");
        }
    }
    outbox.finish().await; // what is queued is sent first
    conn.close().await;
    if let Some(t) = http_task {
        if left.is_some() {
            t.abort(); // it ends on the shutdown signal, which a robot that leaves by itself never gets
        }
        match t.await {
            Err(e) if !e.is_cancelled() => tracing::warn!("the HTTP server task ended badly: {e}"),
            _ => {}
        }
    }
    left.map_or(Ok(()), Err)
}

/// What woke the loop. Short-lived, one at a time: its size does not matter.
#[allow(clippy::large_enum_variant)]
enum Wake {
    Input(Input),
    /// A newer roster adopted (from our file or heard on the fleet).
    Roster(Adopted),
    /// The time to reopen the session with an adopted roster's access rules.
    Reopen,
}

/// How often `/status` and `/metrics` are refreshed at least.
const STATUS_REFRESH: Duration = Duration::from_millis(500);

async fn sleep_until(deadline: Option<tokio::time::Instant>) {
    match deadline {
        Some(d) => tokio::time::sleep_until(d).await,
        None => std::future::pending().await,
    }
}

fn random_instance() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default().as_nanos());
    h.write_u32(std::process::id());
    h.finish()
}

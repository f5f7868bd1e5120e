//! What this robot says, put on Zenoh from an OS thread of its own: a put that Zenoh
//! holds up (seen when a peer's link is cut and its lease has not yet run out) blocks
//! the thread it runs on, and must never hold a runtime worker the tick loop needs.
//! When the thread falls behind, the loop drops and counts messages instead.

use super::log::RateLimitedLog;
use anyhow::{anyhow, Result};
use spwi_core::engine::Output;
use spwi_proto::keys::{self, Topic};
use spwi_proto::{FleetId, RobotId};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;

/// Outgoing messages queued between the tick loop and the publisher thread.
const OUTGOING_QUEUE: usize = 256;
/// A put slower than this is logged: Zenoh is holding up publishing.
const SLOW_PUT: Duration = Duration::from_millis(100);

/// The loop's end of the publisher thread.
pub(super) struct Outbox {
    tx: mpsc::Sender<(Topic, Vec<u8>)>,
    thread: std::thread::JoinHandle<()>,
    /// Messages dropped because the thread was behind, since last taken.
    dropped: Arc<AtomicU64>,
}

impl Outbox {
    /// Declares this robot's publishers and starts the thread that drives them.
    /// Not express: a message still leaves as soon as the link's sending task runs,
    /// but what queues behind it meanwhile (the rest of this robot's tick; on a
    /// router, the other robots' shares it forwards on the same link) leaves in the
    /// same batch, one write and one read instead of one each (docs/BENCHMARKS.md,
    /// "Batched, not express"). Best effort: a message is worth something only within
    /// its tick, so on a link of mixed reliability (QUIC with `mixed_rel=1`,
    /// deploy/README.md) it goes as a datagram, and a lost packet loses the messages of
    /// that batch (the ballot relays cover the votes) instead of holding up every later
    /// one until it is resent. On TCP and TLS links nothing changes.
    pub async fn start(session: &zenoh::Session, fleet: &FleetId, robot: &RobotId) -> Result<Outbox> {
        let declare = |t: Topic| {
            session
                .declare_publisher(keys::robot_topic(fleet, robot, t))
                .express(false)
                .reliability(zenoh::qos::Reliability::BestEffort)
        };
        let reliable = |t: Topic| {
            session.declare_publisher(keys::robot_topic(fleet, robot, t)).reliability(zenoh::qos::Reliability::Reliable)
        };
        let publishers = Publishers {
            embedding: declare(Topic::Embedding).await.map_err(|e| anyhow!(e))?,
            vote: declare(Topic::Vote).await.map_err(|e| anyhow!(e))?,
            decision: declare(Topic::Decision).await.map_err(|e| anyhow!(e))?,
            ballots: declare(Topic::Ballots).await.map_err(|e| anyhow!(e))?,
            // Sent once when a robot joins, useful for longer than a tick: reliable.
            map: reliable(Topic::Map).await.map_err(|e| anyhow!(e))?,
            history: reliable(Topic::History).await.map_err(|e| anyhow!(e))?,
        };
        let (tx, rx) = mpsc::channel(OUTGOING_QUEUE);
        let thread = std::thread::Builder::new()
            .name("spwi-publish".into())
            .spawn(move || publishers.run(rx))
            .map_err(|e| anyhow!("cannot start the publisher thread: {e}"))?;
        Ok(Outbox { tx, thread, dropped: Arc::new(AtomicU64::new(0)) })
    }

    /// Queues one of the engine's outputs; `false` (and counted) when the thread is
    /// behind.
    pub fn publish(&self, output: &Output) -> bool {
        let queued = self.tx.try_send(output.to_wire()).is_ok();
        if !queued {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
        queued
    }

    /// Messages dropped since the last call.
    pub fn take_dropped(&self) -> u64 {
        self.dropped.swap(0, Ordering::Relaxed)
    }

    /// Sends what is queued, then stops the thread.
    pub async fn finish(self) {
        drop(self.tx);
        let thread = self.thread;
        if let Ok(Err(_)) = tokio::task::spawn_blocking(move || thread.join()).await {
            tracing::error!("the publisher thread panicked");
        }
    }
}

/// This robot's publishers, one per topic it speaks on.
struct Publishers {
    embedding: zenoh::pubsub::Publisher<'static>,
    vote: zenoh::pubsub::Publisher<'static>,
    decision: zenoh::pubsub::Publisher<'static>,
    ballots: zenoh::pubsub::Publisher<'static>,
    map: zenoh::pubsub::Publisher<'static>,
    history: zenoh::pubsub::Publisher<'static>,
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
                Topic::Map => &self.map,
                Topic::History => &self.history,
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

//! The daemon's place in the fleet: its Zenoh session, the check that no live daemon
//! holds its robot id, its liveliness token, and its subscriptions. Zenoh callbacks
//! only parse the key and queue the raw bytes (bounded queue; overflow is counted,
//! never blocks Zenoh); everything else happens in the event loop.

use anyhow::{anyhow, bail, Result};
use spwi_core::engine::io::TOPICS_READ;
use spwi_proto::keys::{self, Topic};
use spwi_proto::{FleetId, RobotId};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::mpsc;
use zenoh::sample::SampleKind;

/// A message as the Zenoh callbacks hand it to the loop.
pub(super) struct Message {
    pub topic: Topic,
    pub robot: RobotId,
    pub bytes: Vec<u8>,
}

/// A liveliness change. These travel on their own unbounded queue: they are rare, and
/// losing one would leave a ghost member (or miss a new one) for good.
pub(super) struct Membership {
    pub robot: RobotId,
    pub alive: bool,
}

/// An open connection to the fleet and the queues its callbacks fill.
pub(super) struct Connection {
    pub session: zenoh::Session,
    pub messages: mpsc::Receiver<Message>,
    pub membership: mpsc::UnboundedReceiver<Membership>,
    /// Messages the callbacks dropped because the queue was full, since last taken.
    pub overflow: Arc<AtomicU64>,
    token: zenoh::liveliness::LivelinessToken,
    subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    membership_subscriber: zenoh::pubsub::Subscriber<()>,
    alive_key: String,
}

/// How many times [`Connection::reopen`] tries.
const REOPEN_ATTEMPTS: u32 = 5;

/// How [`Connection::open`] joins.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Joining {
    /// At start: refuse a robot id that a live daemon holds.
    First,
    /// Again, after closing our own session to take a new roster's access rules: our
    /// token may still be seen for a moment, so there is nothing to check.
    Again,
}

impl Connection {
    /// Opens the session, refuses a robot id a live daemon holds, subscribes to what
    /// a robot reads ([`TOPICS_READ`]: its own detections, every robot's shares,
    /// ballots and maps) and declares this robot's liveliness token.
    pub async fn open(
        zenoh: zenoh::Config,
        fleet: &FleetId,
        robot: &RobotId,
        queue: usize,
        joining: Joining,
    ) -> Result<Connection> {
        let session = zenoh::open(zenoh).await.map_err(|e| anyhow!("cannot open the Zenoh session: {e}"))?;
        let alive_key = keys::alive(fleet, robot);
        if joining == Joining::First {
            refuse_duplicate(&session, &alive_key, robot).await?;
        }

        let (tx, messages) = mpsc::channel::<Message>(queue);
        let overflow = Arc::new(AtomicU64::new(0));
        let mut subscribers = Vec::new();
        for topic in TOPICS_READ {
            // Our own detections; every robot's share of the rest.
            let key = match topic {
                Topic::Detections => keys::robot_topic(fleet, robot, topic),
                _ => keys::all_robots(fleet, topic),
            };
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
        let (member_tx, membership) = mpsc::unbounded_channel::<Membership>();
        let membership_subscriber = {
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
        // The token last: a member that sees it sends us its station map at once, and
        // our subscriptions, declared before on the same links, reach it first.
        let token = session.liveliness().declare_token(&alive_key).await.map_err(|e| anyhow!("{alive_key}: {e}"))?;
        Ok(Connection { session, messages, membership, overflow, token, subscribers, membership_subscriber, alive_key })
    }

    /// Joins again after [`Connection::close`], with another config (a new roster's
    /// access rules). Tried a few times: the port the closed session listened on may
    /// take a moment to be free.
    pub async fn reopen(zenoh: zenoh::Config, fleet: &FleetId, robot: &RobotId, queue: usize) -> Result<Connection> {
        let mut tried = 0;
        loop {
            match Connection::open(zenoh.clone(), fleet, robot, queue, Joining::Again).await {
                Ok(c) => return Ok(c),
                Err(e) if tried + 1 < REOPEN_ATTEMPTS => {
                    tracing::warn!("reopening the session: {e:#}; trying again");
                    tried += 1;
                    tokio::time::sleep(Duration::from_millis(300)).await;
                }
                Err(e) => return Err(e.context(format!("reopening the session {REOPEN_ATTEMPTS} times"))),
            }
        }
    }

    /// Leaves the fleet: the subscriptions end, the token is withdrawn (peers see this
    /// robot leave at once rather than when its lease runs out) and the session closes.
    /// Failures are logged: the daemon is leaving either way.
    pub async fn close(self) {
        let Connection { session, token, subscribers, membership_subscriber, alive_key, .. } = self;
        drop(subscribers);
        drop(membership_subscriber);
        if let Err(e) = token.undeclare().await {
            tracing::warn!("withdrawing {alive_key}: {e}");
        }
        if let Err(e) = session.close().await {
            tracing::warn!("closing the Zenoh session: {e}");
        }
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

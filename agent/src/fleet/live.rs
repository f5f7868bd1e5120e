//! A roster that changes while the fleet runs.
//!
//! Admitting or revoking a member must not need every daemon restarted. Each secured
//! process (robot, world, router) therefore takes a newer roster from two places:
//! - its own `fleet.toml`, read again whenever the file changes (checked every second:
//!   an operator who copies the new roster to a host is done);
//! - the fleet: every member but an observer says the roster it holds on
//!   `spwi/<fleet>/roster/<name>` when it joins and when it adopts a newer one, and
//!   says it again to a member heard saying an older one, so a process that started
//!   with a stale copy catches up; the operator says one with `spwi-agent fleet
//!   publish`.
//!
//! Where it comes from does not matter: a roster is adopted only if the fleet's CA
//! signed it, it is of this fleet, newer than the one held and still admits this
//! process ([`Credentials::adopt`]). One heard on the fleet is also written to the
//! process's `fleet.toml`, so a restart does not go back to the older one. A roster
//! that no longer admits this process makes it leave the fleet.
//!
//! [`LiveRoster`] decides; [`Watch`] listens to both sources and answers stale members.
//! What adoption changes is up to the process: the access rules (Zenoh 1.10 sets them
//! when a session opens, so the session is reopened, [`reopen_delay`]), the robots
//! whose signed votes count, and the members counted.

use super::credentials::{Credentials, Refusal};
use super::roster::Roster;
use crate::daemon::log::RateLimitedLog;
use anyhow::{anyhow, Result};
use spwi_proto::{keys, FleetId, RobotId};
use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::{Duration, SystemTime};
use tokio::sync::mpsc;

/// The largest roster accepted from the fleet (a roster of 100 members is ≈ 25 kB).
pub const MAX_ROSTER_BYTES: usize = 256 * 1024;

/// How often a process looks at its `fleet.toml` for a change.
pub const FILE_CHECK_PERIOD: Duration = Duration::from_secs(1);

/// The least time between two answers to members saying an older roster.
const ANSWER_PERIOD: Duration = Duration::from_secs(2);

/// What came of a roster read or heard.
#[derive(Debug, PartialEq, Eq)]
pub enum Heard {
    /// Adopted: the members it admits that the last one did not, and those it no
    /// longer admits.
    Adopted { admitted: Vec<RobotId>, revoked: Vec<RobotId> },
    /// The one held.
    Same,
    /// An older one than held: say ours (at most every 2 s, [`LiveRoster::should_answer`]).
    Older,
    /// Refused, with the reason (counted here, logged by the caller).
    Refused(String),
    /// A valid newer roster revokes this process (or no longer lists it): leave.
    Revoked(String),
}

/// The roster a process holds, and where newer ones come from.
pub struct LiveRoster {
    creds: Arc<Credentials>,
    /// When the roster held was adopted (its first load counts).
    pub adopted_at: SystemTime,
    pub adopted: u64,
    pub refused: u64,
    file_stamp: Option<(SystemTime, u64)>,
    last_answer: Option<std::time::Instant>,
}

impl LiveRoster {
    pub fn new(creds: Arc<Credentials>) -> LiveRoster {
        let file_stamp = stamp(&creds);
        LiveRoster { creds, adopted_at: SystemTime::now(), adopted: 0, refused: 0, file_stamp, last_answer: None }
    }

    pub fn credentials(&self) -> &Arc<Credentials> {
        &self.creds
    }

    /// Reads `fleet.toml` again if it changed since last looked at.
    pub fn check_file(&mut self) -> Option<Heard> {
        let now = stamp(&self.creds);
        if now == self.file_stamp {
            return None;
        }
        self.file_stamp = now;
        let path = self.creds.dir.roster();
        let heard = match Roster::load(&path) {
            Ok(roster) => self.offer(roster),
            // A copy being written may be read half-done: its next change is read again.
            Err(e) => Heard::Refused(format!("{e:#}")),
        };
        Some(self.count(match heard {
            Heard::Refused(why) => Heard::Refused(format!("{}: {why}", path.display())),
            other => other,
        }))
    }

    /// A roster `from` said on the fleet (its `fleet.toml` text).
    pub fn hear(&mut self, bytes: &[u8], from: &RobotId) -> Heard {
        let heard = if bytes.len() > MAX_ROSTER_BYTES {
            Heard::Refused(format!("{} bytes, more than {MAX_ROSTER_BYTES}", bytes.len()))
        } else {
            match std::str::from_utf8(bytes).map_err(anyhow::Error::from).and_then(Roster::parse) {
                Ok(roster) => self.offer(roster),
                Err(e) => Heard::Refused(format!("not a roster: {e:#}")),
            }
        };
        if let Heard::Adopted { .. } = heard {
            // Written back, so that a restart starts from it; a read-only copy is kept.
            let path = self.creds.dir.roster();
            match self.creds.roster.save(&path) {
                Ok(()) => self.file_stamp = stamp(&self.creds),
                Err(e) => {
                    tracing::warn!("the roster adopted from {from} could not be kept in {}: {e:#}", path.display())
                }
            }
        }
        self.count(match heard {
            Heard::Refused(why) => Heard::Refused(format!("the roster {from} said: {why}")),
            other => other,
        })
    }

    /// Whether to answer a member heard saying an older roster now (rate-limited).
    pub fn should_answer(&mut self) -> bool {
        let now = std::time::Instant::now();
        if self.last_answer.is_some_and(|t| now.duration_since(t) < ANSWER_PERIOD) {
            return false;
        }
        self.last_answer = Some(now);
        true
    }

    fn offer(&mut self, roster: Roster) -> Heard {
        let signature = roster.signature.clone();
        match self.creds.adopt(roster) {
            Ok(newer) => {
                let admitted_by =
                    |c: &Credentials| -> BTreeSet<RobotId> { c.roster.admitted().map(|m| m.name.clone()).collect() };
                let (before, after) = (admitted_by(&self.creds), admitted_by(&newer));
                self.creds = Arc::new(newer);
                self.adopted_at = SystemTime::now();
                Heard::Adopted {
                    admitted: after.difference(&before).cloned().collect(),
                    revoked: before.difference(&after).cloned().collect(),
                }
            }
            Err(Refusal::NotNewer { version, held }) if version == held => {
                // The signature covers all the rest: the same signature, the same roster.
                if signature == self.creds.roster.signature {
                    Heard::Same
                } else {
                    Heard::Refused(format!("roster version {version} differs from the one held of that version"))
                }
            }
            Err(Refusal::NotNewer { .. }) => Heard::Older,
            Err(Refusal::NotAdmitted(why)) => Heard::Revoked(why),
            Err(Refusal::Invalid(why)) => Heard::Refused(why),
        }
    }

    fn count(&mut self, heard: Heard) -> Heard {
        match &heard {
            Heard::Adopted { .. } => self.adopted += 1,
            Heard::Refused(_) => self.refused += 1,
            _ => {}
        }
        heard
    }
}

/// Rosters heard and not yet read, at most; more in one burst are dropped (whoever
/// holds a newer one says it again).
const HEARD_QUEUE: usize = 8;

/// A newer roster, adopted.
pub struct Adopted {
    pub credentials: Arc<Credentials>,
    /// Robots and other members it admits that the last one did not.
    pub admitted: Vec<RobotId>,
    /// Members it no longer admits.
    pub revoked: Vec<RobotId>,
}

/// Where a process hears of newer rosters: its `fleet.toml`, checked every second, and
/// what members say on the fleet, heard on the session given to [`Watch::listen`]
/// (again after each reopen). Refusals are logged (at most every 5 s) and counted.
pub struct Watch {
    pub roster: LiveRoster,
    fleet: FleetId,
    heard: mpsc::Receiver<(RobotId, Vec<u8>)>,
    heard_tx: mpsc::Sender<(RobotId, Vec<u8>)>,
    subscriber: Option<zenoh::pubsub::Subscriber<()>>,
    file_check: tokio::time::Interval,
    refusals: RateLimitedLog,
}

impl Watch {
    pub fn new(creds: Arc<Credentials>) -> Watch {
        let (heard_tx, heard) = mpsc::channel(HEARD_QUEUE);
        let fleet = creds.roster.fleet.clone();
        let mut file_check = tokio::time::interval(FILE_CHECK_PERIOD);
        file_check.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        Watch {
            roster: LiveRoster::new(creds),
            fleet,
            heard,
            heard_tx,
            subscriber: None,
            file_check,
            refusals: RateLimitedLog::new(Duration::from_secs(5)),
        }
    }

    pub fn credentials(&self) -> &Arc<Credentials> {
        self.roster.credentials()
    }

    /// Listens for rosters on `session` (replacing the last session's subscriber) and
    /// says the one held there.
    pub async fn listen(&mut self, session: &zenoh::Session) -> Result<()> {
        self.subscriber = None;
        let (fleet, tx) = (self.fleet.clone(), self.heard_tx.clone());
        let subscriber = session
            .declare_subscriber(keys::all_rosters(&self.fleet))
            .callback(move |s| {
                if let Some(from) = keys::parse_roster(&fleet, s.key_expr().as_str()) {
                    let _ = tx.try_send((from, s.payload().to_bytes().into_owned()));
                }
            })
            .await
            .map_err(|e| anyhow!("subscribing to rosters: {e}"))?;
        self.subscriber = Some(subscriber);
        self.say(session).await;
        Ok(())
    }

    /// Waits for a newer roster and adopts it; answers members saying an older one on
    /// `session`. An error when a valid newer roster no longer admits this process.
    /// Cancel-safe between rosters (what was heard and not yet read stays queued).
    pub async fn adopted(&mut self, session: &zenoh::Session) -> Result<Adopted> {
        loop {
            let heard = tokio::select! {
                Some((from, bytes)) = self.heard.recv() => self.roster.hear(&bytes, &from),
                _ = self.file_check.tick() => match self.roster.check_file() {
                    Some(heard) => heard,
                    None => continue,
                },
            };
            match heard {
                Heard::Adopted { admitted, revoked } => {
                    let credentials = self.roster.credentials().clone();
                    tracing::info!(version = credentials.roster.version, ?admitted, ?revoked, "adopted a newer roster");
                    return Ok(Adopted { credentials, admitted, revoked });
                }
                Heard::Older if self.roster.should_answer() => self.say(session).await,
                Heard::Refused(why) => self.refusals.warn(|| format!("refused a roster: {why}")),
                Heard::Revoked(why) => return Err(anyhow!("{why}: no longer a member of fleet {}", self.fleet)),
                Heard::Older | Heard::Same => {}
            }
        }
    }

    /// Says the roster held on `session`, as this process's identity.
    pub async fn say(&self, session: &zenoh::Session) {
        let key = keys::roster(&self.fleet, &self.credentials().identity.name);
        if let Err(e) = session.put(&key, self.credentials().roster.said()).await {
            tracing::warn!("saying the roster on {key}: {e}");
        }
    }
}

/// [`Watch::adopted`] of `watch`, or never for an open fleet (no roster to watch).
pub async fn adopted(watch: Option<&mut Watch>, session: &zenoh::Session) -> Result<Adopted> {
    match watch {
        Some(w) => w.adopted(session).await,
        None => std::future::pending().await,
    }
}

/// How long after adopting a roster a process reopens its session: 0.2 s (so that the
/// members it told have adopted the roster too, and hold its departure as a reopen)
/// and up to 1.5 s more by a hash of its name, so that the members of a fleet, told at
/// once, do not all drop their links in the same moment.
pub fn reopen_delay(name: &RobotId) -> Duration {
    let h = name.as_str().bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3));
    Duration::from_millis(200 + h % 1500)
}

/// Readies the config of a session reopened to take a roster's access rules: it
/// rejoins a mesh that is already there, so it does not wait Zenoh's scouting delay
/// (500 ms by default, all spent whenever a peer's start conditions are not met at
/// once) before it returns. Its links form within tens of milliseconds either way;
/// waiting cost the reopening robot up to five ticks of frames and votes.
pub fn for_reopening(config: &mut zenoh::Config) -> Result<()> {
    config.insert_json5("scouting/delay", "0").map_err(|e| anyhow!("scouting/delay: {e}"))
}

fn stamp(creds: &Credentials) -> Option<(SystemTime, u64)> {
    let meta = std::fs::metadata(creds.dir.roster()).ok()?;
    Some((meta.modified().ok()?, meta.len()))
}

#[cfg(test)]
mod tests {
    use super::super::authority::{add, revoke, ThrowawayFleet, Validity};
    use super::super::{FleetDir, Role};
    use super::*;

    fn fleet(label: &str) -> ThrowawayFleet {
        let members = [("world", Role::World), ("r1", Role::Robot), ("r2", Role::Robot)];
        ThrowawayFleet::create(&format!("live-{label}"), &FleetId::new("f").unwrap(), &members).unwrap()
    }

    /// `name`'s credentials from a copy of the fleet directory of its own (its host's).
    fn host_copy(t: &ThrowawayFleet, name: &str) -> (FleetDir, LiveRoster) {
        let host = FleetDir::new(t.dir.root.join(format!("host-{name}")));
        std::fs::create_dir_all(host.members()).unwrap();
        for (from, to) in [
            (t.dir.roster(), host.roster()),
            (t.dir.ca_cert(), host.ca_cert()),
            (t.dir.member_cert(name), host.member_cert(name)),
            (t.dir.member_key(name), host.member_key(name)),
        ] {
            std::fs::copy(from, to).unwrap();
        }
        let creds = Credentials::load(&host, name).unwrap();
        (host, LiveRoster::new(Arc::new(creds)))
    }

    fn said(dir: &FleetDir) -> Vec<u8> {
        std::fs::read(dir.roster()).unwrap()
    }

    #[test]
    fn a_newer_roster_heard_is_adopted_kept_on_disk_and_said_back() {
        let t = fleet("adopt");
        let (host, mut live) = host_copy(&t, "r1");
        let r3 = RobotId::new("r3").unwrap();
        add(&t.dir, &r3, Role::Robot, Validity::days(1)).unwrap();
        revoke(&t.dir, "r2").unwrap();
        let from = RobotId::new("world").unwrap();
        let heard = live.hear(&said(&t.dir), &from);
        assert_eq!(heard, Heard::Adopted { admitted: vec![r3.clone()], revoked: vec![RobotId::new("r2").unwrap()] });
        assert!(live.credentials().admits_robot(&r3) && !live.credentials().admits_robot(&RobotId::new("r2").unwrap()));
        assert_eq!((live.adopted, live.refused), (1, 0));
        assert_eq!(Roster::load(&host.roster()).unwrap().version, 6, "kept in the host's copy");
        assert_eq!(live.check_file(), None, "its own write is not news");
        assert_eq!(live.hear(&said(&t.dir), &from), Heard::Same);
        assert_eq!(
            &Roster::parse(std::str::from_utf8(&live.credentials().roster.said()).unwrap()).unwrap(),
            &live.credentials().roster
        );
    }

    #[test]
    fn an_older_roster_is_answered_and_a_forged_or_foreign_one_refused() {
        let (t, other) = (fleet("refuse"), fleet("refuse-other"));
        let old = said(&t.dir);
        add(&t.dir, &RobotId::new("r3").unwrap(), Role::Robot, Validity::days(1)).unwrap();
        let (_host, mut live) = host_copy(&t, "r1");
        let from = RobotId::new("r2").unwrap();
        assert_eq!(live.hear(&old, &from), Heard::Older);
        assert!(live.should_answer() && !live.should_answer(), "answers at most every 2 s");
        // another CA's roster of the same fleet name and a higher version
        let mut foreign = Roster::load(&other.dir.roster()).unwrap();
        foreign.version = 99;
        let heard = live.hear(toml::to_string(&foreign).unwrap().as_bytes(), &from);
        assert!(
            matches!(&heard, Heard::Refused(why) if why.contains("r2 said") && why.contains("not signed by the fleet's CA")),
            "{heard:?}"
        );
        // ours, tampered: a revocation undone by hand
        revoke(&t.dir, "r2").unwrap();
        let mut undone = Roster::load(&t.dir.roster()).unwrap();
        undone.members.iter_mut().for_each(|m| m.revoked = false);
        let heard = live.hear(toml::to_string(&undone).unwrap().as_bytes(), &from);
        assert!(matches!(&heard, Heard::Refused(why) if why.contains("not signed")), "{heard:?}");
        let heard = live.hear(b"\xff not toml", &from);
        assert!(matches!(&heard, Heard::Refused(why) if why.contains("not a roster")), "{heard:?}");
        assert_eq!(
            live.hear(&vec![b' '; MAX_ROSTER_BYTES + 1], &from),
            Heard::Refused(format!("the roster r2 said: {} bytes, more than {MAX_ROSTER_BYTES}", MAX_ROSTER_BYTES + 1))
        );
        assert_eq!((live.adopted, live.refused), (0, 4));
        assert_eq!(live.credentials().roster.version, 5, "the roster held stays");
    }

    #[test]
    fn a_changed_file_is_read_and_a_roster_revoking_us_says_so() {
        let t = fleet("file");
        let (host, mut live) = host_copy(&t, "r2");
        assert_eq!(live.check_file(), None);
        std::fs::write(host.roster(), "garbage").unwrap();
        let heard = live.check_file().unwrap();
        assert!(matches!(&heard, Heard::Refused(why) if why.contains("fleet.toml")), "names the file: {heard:?}");
        revoke(&t.dir, "r2").unwrap();
        std::fs::copy(t.dir.roster(), host.roster()).unwrap();
        let heard = live.check_file().unwrap();
        assert!(
            matches!(&heard, Heard::Revoked(why) if why.contains("r2 is revoked by roster version 5")),
            "{heard:?}"
        );
    }

    #[test]
    fn reopening_waits_a_moment_then_is_spread_over_a_second_and_a_half_by_name() {
        let delays: BTreeSet<_> = (0..20).map(|i| reopen_delay(&RobotId::new(format!("r{i}")).unwrap())).collect();
        let within = |d: &Duration| (Duration::from_millis(200)..Duration::from_millis(1700)).contains(d);
        assert!(delays.len() > 15 && delays.iter().all(within), "{delays:?}");
    }
}

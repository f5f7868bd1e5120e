//! Every decision the agents of a fleet publish, as one observer receives them: by
//! tick and robot, each with the instant it arrived. Agreement, latency, gaps and
//! membership are read from here by the tests, `spwi-sim bench` and its soak.

use crate::measures::Agreement;
use anyhow::{anyhow, bail, Result};
use spwi_proto::keys::{self, Topic};
use spwi_proto::{decode, DecisionMsg, FleetId, RobotId, Station};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// One robot's decision of one tick.
#[derive(Debug, Clone)]
pub struct Decided {
    pub msg: DecisionMsg,
    /// When the observer received it.
    pub at: Instant,
}

impl Decided {
    /// The team's class at t; `None` when no member saw the worker.
    pub fn class(&self) -> Option<Station> {
        self.msg.steps.first().map(|s| s.class)
    }
}

/// tick → robot → its decision.
pub type ByTick = BTreeMap<u64, BTreeMap<RobotId, Decided>>;

pub struct Decisions {
    log: Arc<Mutex<ByTick>>,
    _sub: zenoh::pubsub::Subscriber<()>,
}

impl Decisions {
    /// Collects, from now on, every decision published in `fleet` that `session`
    /// receives, filed under the robot it names (whatever key carried it: a test of the
    /// fleet's defences wants to see a forged one).
    pub async fn subscribe(session: &zenoh::Session, fleet: &FleetId) -> Result<Decisions> {
        let log = Arc::new(Mutex::new(ByTick::new()));
        let l = log.clone();
        let sub = session
            .declare_subscriber(keys::all_robots(fleet, Topic::Decision))
            .callback(move |sample| {
                if let Ok(msg) = decode::<DecisionMsg>(&sample.payload().to_bytes()) {
                    let (tick, robot) = (msg.tick, msg.robot.clone());
                    l.lock()
                        .expect("decision log")
                        .entry(tick)
                        .or_default()
                        .insert(robot, Decided { msg, at: Instant::now() });
                }
            })
            .await
            .map_err(|e| anyhow!("subscribing to the fleet's decisions: {e}"))?;
        Ok(Decisions { log, _sub: sub })
    }

    /// The decisions so far, by tick.
    pub fn lock(&self) -> MutexGuard<'_, ByTick> {
        self.log.lock().expect("decision log")
    }

    /// Every decision received so far, by tick.
    pub fn all(&self) -> Vec<Decided> {
        self.lock().values().flat_map(|d| d.values()).cloned().collect()
    }

    /// Decisions per robot, by tick.
    pub fn by_robot(&self) -> BTreeMap<RobotId, BTreeMap<u64, DecisionMsg>> {
        let mut m: BTreeMap<RobotId, BTreeMap<u64, DecisionMsg>> = BTreeMap::new();
        for (tick, ds) in self.lock().iter() {
            for (robot, d) in ds {
                m.entry(robot.clone()).or_default().insert(*tick, d.msg.clone());
            }
        }
        m
    }

    /// Waits until every robot in `robots` has published a decision counting `members`
    /// live members, received after `since`; returns how long after `since` the last
    /// of them arrived.
    pub async fn wait_members(
        &self,
        robots: &[RobotId],
        members: u32,
        since: Instant,
        limit: Duration,
    ) -> Result<Duration> {
        let deadline = Instant::now() + limit;
        loop {
            let first_counting = |log: &ByTick, r: &RobotId| {
                log.values()
                    .filter_map(|d| d.get(r))
                    .filter(|d| d.at >= since && d.msg.live_members == members)
                    .map(|d| d.at)
                    .min()
            };
            let latest = {
                let log = self.lock();
                robots
                    .iter()
                    .map(|r| first_counting(&log, r))
                    .collect::<Option<Vec<_>>>()
                    .and_then(|ts| ts.into_iter().max())
            };
            if let Some(t) = latest {
                return Ok(t - since);
            }
            if Instant::now() > deadline {
                let log = self.lock();
                let last: Vec<_> = robots
                    .iter()
                    .map(|r| (r.as_str(), log.values().rev().find_map(|d| d.get(r)).map(|d| d.msg.live_members)))
                    .collect();
                bail!("not all of {robots:?} counted {members} members within {limit:?}; last counts: {last:?}");
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// Over ticks `from..=to`: the share of the ticks every robot of `robots` decided on
    /// which they all named the same intent at every step, and how many such ticks.
    pub fn agreement(&self, robots: &[RobotId], from: u64, to: u64) -> (f64, usize) {
        let log = self.lock();
        let classes = |d: &Decided| d.msg.steps.iter().map(|s| s.class).collect::<Vec<_>>();
        let mut agreement = Agreement::default();
        for ds in log.range(from..=to).map(|(_, ds)| ds) {
            let Some(ds) = robots.iter().map(|r| ds.get(r)).collect::<Option<Vec<_>>>() else {
                continue;
            };
            agreement.tick(ds.iter().map(|d| classes(d)));
        }
        (agreement.share(), agreement.compared as usize)
    }

    /// The longest run of consecutive ticks in `from..=to` that `robot` did not decide.
    pub fn longest_gap(&self, robot: &RobotId, from: u64, to: u64) -> u64 {
        let log = self.lock();
        let (mut gap, mut run) = (0, 0);
        for t in from..=to {
            if log.get(&t).is_some_and(|d| d.contains_key(robot)) {
                run = 0;
            } else {
                run += 1;
                gap = gap.max(run);
            }
        }
        gap
    }
}

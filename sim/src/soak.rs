//! `spwi-sim bench --soak 30m --robots 8 --churn 30s`: does the fleet stay up? The
//! world feeds N agent processes at 10 Hz for the whole run while, every `churn`, the
//! last robot leaves (SIGTERM) or comes back, and every `freeze_every` the one before it
//! is frozen (SIGSTOP) for 5 s and then resumed. The other robots are never touched.
//!
//! For each tick outside the few seconds after an event, the robots expected live are
//! the untouched ones, the last one if running and the frozen one if not frozen; then:
//! - undecided: one of them published no decision for the tick;
//! - false removal: one of them counted fewer live members than there are (a live,
//!   unfrozen robot dropped from its members); a ghost member: more;
//! - agreement: all of them named the same class at t.
//!
//! Resident memory and open files of the untouched agents are read at the start and
//! at the end: a leak shows as growth. Their resident memory is also sampled every
//! minute, so a long run tells growth that levels off (warm-up, the allocator's
//! arenas) from growth that does not (a leak).

use crate::loopback::{layout_with_slots, FleetOptions, LoopbackFleet, Usage};
use crate::measures::{Agreement, LatencyMs};
use anyhow::{bail, Result};
use serde::Serialize;
use spwi_proto::{RobotId, TICK_PERIOD};
use spwi_world::world::{Scenario, World};
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// How long a robot stays frozen.
pub const FREEZE_FOR: Duration = Duration::from_secs(5);
/// Ticks after an event left out of the counts: a departure is seen within the 1 s
/// lease, a newcomer is counted by all within a few seconds of its start.
pub const SETTLE: Duration = Duration::from_secs(5);
/// Warm-up before anything is measured.
const WARMUP: Duration = Duration::from_secs(2);
/// How often the untouched agents' resident memory is sampled.
const RSS_EVERY: Duration = Duration::from_secs(60);

pub struct SoakOptions {
    pub fleet: FleetOptions,
    pub duration: Duration,
    pub churn: Duration,
    pub freeze_every: Duration,
    pub scenario: Scenario,
}

/// `--json` keeps these keys.
#[derive(Debug, Clone, Serialize)]
pub struct SoakReport {
    pub robots: usize,
    pub seconds: f64,
    pub ticks: u64,
    pub leaves: u32,
    pub joins: u32,
    pub freezes: u32,
    /// Ticks counted: not within SETTLE of an event.
    pub settled_ticks: u64,
    pub undecided_ticks: u64,
    /// Settled ticks each robot did not decide (robots that missed none left out).
    pub undecided_by_robot: BTreeMap<RobotId, u64>,
    /// The events, in seconds from the start of the measurement.
    pub events: Vec<(f64, String)>,
    /// Settled ticks on which a robot counted fewer live members than there are.
    pub false_removals: u64,
    /// ... more than there are.
    pub ghost_members: u64,
    /// Settled ticks on which every expected robot decided the same class at t,
    /// among those every one decided.
    pub agreement: f64,
    /// Frame published → the last expected robot's decision, settled ticks.
    pub latency_ms: LatencyMs,
    /// The untouched agents at the start and the end of the run (mean resident MB,
    /// largest growth of one, total open files).
    pub rss_mb_start: f64,
    pub rss_mb_end: f64,
    pub rss_growth_max: f64,
    /// The same for the anonymous part of the RSS (heap, stacks; not the binary's code
    /// pages, which fault in as code paths first run).
    pub anon_mb_start: f64,
    pub anon_mb_end: f64,
    pub anon_growth_max: f64,
    /// (seconds from the start of the measurement, mean resident MB of the untouched
    /// agents, the anonymous part of it), every minute and at the end.
    pub rss_mb_along: Vec<(f64, f64, f64)>,
    pub open_files_start: usize,
    pub open_files_end: usize,
}

impl SoakReport {
    /// What the soak asks of the fleet, with at most `max_undecided` of the settled
    /// ticks not decided by every live robot; `None` when it held.
    pub fn failure(&self, max_undecided: f64) -> Option<String> {
        let mut bad = Vec::new();
        if self.false_removals > 0 {
            bad.push(format!("{} ticks with a live robot missing from someone's members", self.false_removals));
        }
        if self.ghost_members > 0 {
            bad.push(format!("{} ticks with a departed robot still counted", self.ghost_members));
        }
        if self.undecided_ticks as f64 > max_undecided * self.settled_ticks as f64 {
            bad.push(format!(
                "{} of {} settled ticks not decided by every live robot (at most {:.1} % allowed)",
                self.undecided_ticks,
                self.settled_ticks,
                100.0 * max_undecided
            ));
        }
        if self.open_files_end > self.open_files_start {
            bad.push(format!("open files grew from {} to {}", self.open_files_start, self.open_files_end));
        }
        (!bad.is_empty()).then(|| bad.join("; "))
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Event {
    Leave,
    Join,
    Freeze,
    Thaw,
}

pub async fn run(o: &SoakOptions) -> Result<SoakReport> {
    let robots = o.fleet.robots;
    if robots < 3 {
        bail!("a soak needs at least 3 robots: one leaves and comes back, one is frozen, the others are watched");
    }
    let (churning, freezing) = (robots - 1, robots - 2);
    let untouched = 0..freezing;
    let mut fleet = LoopbackFleet::start(o.fleet.clone()).await?;
    let mut world = World::new(layout_with_slots(robots), o.scenario, 1, robots);
    let resources = |fleet: &LoopbackFleet| -> Vec<Usage> { untouched.clone().map(|slot| fleet.usage(slot)).collect() };
    let started = Instant::now();
    let mut next = crate::loopback::next_tick_instant();
    let mut published: BTreeMap<u64, Instant> = BTreeMap::new();
    let mut events: Vec<(u64, Event)> = Vec::new();
    let (mut measure_from, mut at_start) = (None, Vec::new());
    let (mut rss_mb_along, mut next_rss) = (Vec::new(), WARMUP);
    let mean_rss = |usage: &[Usage]| mean(usage.iter().map(|u| u.rss_mb));
    let mean_anon = |usage: &[Usage]| mean(usage.iter().map(|u| u.anon_mb));
    let (mut next_churn, mut next_freeze) = (WARMUP + o.churn, WARMUP + o.freeze_every / 2 + o.churn / 2);
    let mut thaw_at: Option<Duration> = None;
    let ticks = (o.duration.as_secs_f64() / TICK_PERIOD.as_secs_f64()).round() as u64;
    let progress = crate::progress::Progress::new("soak ticks", ticks, 10);
    loop {
        let since = started.elapsed();
        if measure_from.is_none() && since >= WARMUP {
            at_start = resources(&fleet);
            measure_from = Some((Instant::now(), world.clock_tick() + 1));
        }
        if since >= WARMUP + o.duration {
            break;
        }
        if since >= next_rss {
            let now = resources(&fleet);
            rss_mb_along.push(((since - WARMUP).as_secs_f64(), mean_rss(&now), mean_anon(&now)));
            next_rss += RSS_EVERY;
        }
        if since >= next_churn {
            let event = if fleet.pid(churning).is_some() {
                fleet.stop_agent(churning).await?;
                Event::Leave
            } else {
                fleet.start_agent(churning)?;
                Event::Join
            };
            events.push((world.clock_tick(), event));
            next_churn += o.churn;
        }
        if thaw_at.is_none() && since >= next_freeze {
            fleet.signal_agent(freezing, "STOP")?;
            events.push((world.clock_tick(), Event::Freeze));
            thaw_at = Some(since + FREEZE_FOR);
            next_freeze += o.freeze_every;
        }
        if thaw_at.is_some_and(|t| since >= t) {
            fleet.signal_agent(freezing, "CONT")?;
            events.push((world.clock_tick(), Event::Thaw));
            thaw_at = None;
        }
        world.step();
        let sent = fleet.publish(&mut world).await?;
        published.insert(world.clock_tick(), sent);
        if measure_from.is_some() {
            progress.inc();
        }
        next += TICK_PERIOD;
        tokio::time::sleep_until(tokio::time::Instant::from_std(next)).await;
    }
    drop(progress);
    if thaw_at.is_some() {
        fleet.signal_agent(freezing, "CONT")?;
    }
    tokio::time::sleep(Duration::from_millis(300)).await; // the last decisions
    let at_end = resources(&fleet);
    let (measured_since, first_tick) = measure_from.expect("measured after the warm-up");
    let seconds = measured_since.elapsed().as_secs_f64();
    rss_mb_along.push((seconds, mean_rss(&at_end), mean_anon(&at_end)));
    let (decisions, ids) = (std::mem::take(&mut *fleet.decisions.lock()), fleet.ids.clone());
    drop(fleet);

    let settle_ticks = (SETTLE.as_secs_f64() / TICK_PERIOD.as_secs_f64()).round() as u64;
    let last_tick = world.clock_tick();
    let mut report = SoakReport {
        robots,
        seconds,
        ticks: last_tick + 1 - first_tick,
        leaves: count(&events, Event::Leave),
        joins: count(&events, Event::Join),
        freezes: count(&events, Event::Freeze),
        settled_ticks: 0,
        undecided_ticks: 0,
        undecided_by_robot: BTreeMap::new(),
        events: events
            .iter()
            .map(|&(at, e)| ((at + 1).saturating_sub(first_tick) as f64 * TICK_PERIOD.as_secs_f64(), format!("{e:?}")))
            .collect(),
        false_removals: 0,
        ghost_members: 0,
        agreement: 0.0,
        latency_ms: LatencyMs::default(),
        rss_mb_start: mean_rss(&at_start),
        rss_mb_end: mean_rss(&at_end),
        rss_growth_max: largest_growth(&at_start, &at_end, |u| u.rss_mb),
        anon_mb_start: mean_anon(&at_start),
        anon_mb_end: mean_anon(&at_end),
        anon_growth_max: largest_growth(&at_start, &at_end, |u| u.anon_mb),
        rss_mb_along,
        open_files_start: at_start.iter().map(|u| u.open_files).sum(),
        open_files_end: at_end.iter().map(|u| u.open_files).sum(),
    };
    let (mut agreement, mut latencies) = (Agreement::default(), Vec::new());
    let (mut churning_live, mut frozen) = (true, false);
    let mut pending = events.iter().peekable();
    for t in first_tick..=last_tick {
        while let Some(&(_, e)) = pending.next_if(|(at, _)| *at < t) {
            match e {
                Event::Leave => churning_live = false,
                Event::Join => churning_live = true,
                Event::Freeze => frozen = true,
                Event::Thaw => frozen = false,
            }
        }
        let settling = events.iter().any(|&(at, _)| at < t && t <= at + settle_ticks);
        if settling {
            continue;
        }
        report.settled_ticks += 1;
        let expected: Vec<_> = untouched
            .clone()
            .chain((!frozen).then_some(freezing))
            .chain(churning_live.then_some(churning))
            .map(|slot| &ids[slot])
            .collect();
        let decided = decisions.get(&t);
        let got: Vec<_> = expected.iter().filter_map(|r| decided.and_then(|d| d.get(*r))).collect();
        if got.len() < expected.len() {
            report.undecided_ticks += 1;
            for r in expected.iter().filter(|r| decided.is_none_or(|d| !d.contains_key(**r))) {
                *report.undecided_by_robot.entry((*r).clone()).or_default() += 1;
            }
            continue;
        }
        let live = expected.len() as u32;
        report.false_removals += u64::from(got.iter().any(|d| d.msg.live_members < live));
        report.ghost_members += u64::from(got.iter().any(|d| d.msg.live_members > live));
        agreement.tick(got.iter().map(|d| d.class()));
        let last = got.iter().map(|d| d.at).max().expect("at least one robot expected");
        latencies.push((last - published[&t]).as_secs_f64() * 1e3);
    }
    report.agreement = agreement.share();
    report.latency_ms = LatencyMs::of(latencies);
    Ok(report)
}

fn count(events: &[(u64, Event)], kind: Event) -> u32 {
    events.iter().filter(|(_, e)| *e == kind).count() as u32
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = v.fold((0.0, 0), |(s, n), x| (s + x, n + 1));
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

/// The largest relative growth of one agent's `measure` from `start` to `end`.
fn largest_growth(start: &[Usage], end: &[Usage], measure: impl Fn(&Usage) -> f64) -> f64 {
    let growth = |(a, b): (&Usage, &Usage)| if measure(a) > 0.0 { measure(b) / measure(a) - 1.0 } else { 0.0 };
    start.iter().zip(end).map(growth).fold(0.0, f64::max)
}

pub fn print(r: &SoakReport) {
    println!(
        "soak, {} robots, {:.0} s ({} ticks): {} leaves, {} joins, {} freezes · {} settled ticks: {} undecided, {} false removals, {} ghost members, agreement {:.2}%, frame → every decision p50 {:.2} ms, p99 {:.2} ms · untouched agents: RSS {:.1} → {:.1} MB (largest growth {:+.1}%), of it anonymous {:.1} → {:.1} MB (largest growth {:+.1}%), open files {} → {}",
        r.robots,
        r.seconds,
        r.ticks,
        r.leaves,
        r.joins,
        r.freezes,
        r.settled_ticks,
        r.undecided_ticks,
        r.false_removals,
        r.ghost_members,
        100.0 * r.agreement,
        r.latency_ms.p50,
        r.latency_ms.p99,
        r.rss_mb_start,
        r.rss_mb_end,
        100.0 * r.rss_growth_max,
        r.anon_mb_start,
        r.anon_mb_end,
        100.0 * r.anon_growth_max,
        r.open_files_start,
        r.open_files_end
    );
    let along: Vec<String> =
        r.rss_mb_along.iter().map(|(s, mb, anon)| format!("{s:.0} s {mb:.1} ({anon:.1})")).collect();
    println!("untouched agents' mean RSS (anonymous) along the run (MB): {}", along.join(", "));
    if !r.undecided_by_robot.is_empty() {
        println!("settled ticks not decided, by robot: {:?}; events (s): {:?}", r.undecided_by_robot, r.events);
    }
}

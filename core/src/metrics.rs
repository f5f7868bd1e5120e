//! What the engine counts and times, as plain numbers: the daemon's single event loop
//! owns them (no atomics on the hot path) and exposes a snapshot as OpenMetrics text
//! and in `/status`; the evaluation and the benchmarks read them directly.

use crate::clock::OffClock;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Duration;

/// Bucket upper bounds in seconds: 50 µs … 1 s.
pub const BOUNDS: [f64; 14] =
    [50e-6, 100e-6, 200e-6, 500e-6, 1e-3, 2e-3, 5e-3, 10e-3, 20e-3, 50e-3, 100e-3, 200e-3, 500e-3, 1.0];

/// A latency histogram with the fixed [`BOUNDS`].
#[derive(Debug, Clone, Default, Serialize)]
pub struct Histogram {
    counts: [u64; BOUNDS.len() + 1],
    sum: f64,
    count: u64,
}

impl Histogram {
    /// Counts per bucket, the last one unbounded ([`BOUNDS`] are the others' bounds).
    pub fn buckets(&self) -> &[u64] {
        &self.counts
    }

    /// Seconds observed in all.
    pub fn sum(&self) -> f64 {
        self.sum
    }

    pub fn observe(&mut self, d: Duration) {
        let s = d.as_secs_f64();
        let i = BOUNDS.iter().position(|&b| s <= b).unwrap_or(BOUNDS.len());
        self.counts[i] += 1;
        self.sum += s;
        self.count += 1;
    }

    pub fn count(&self) -> u64 {
        self.count
    }

    /// Upper bound of the bucket holding quantile `q` (seconds); `None` if empty.
    pub fn quantile_upper_bound(&self, q: f64) -> Option<f64> {
        if self.count == 0 {
            return None;
        }
        let rank = (q * self.count as f64).ceil().max(1.0) as u64;
        let mut seen = 0;
        for (i, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return Some(BOUNDS.get(i).copied().unwrap_or(f64::INFINITY));
            }
        }
        None
    }
}

/// Pipeline stages timed per tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    Graph,
    Gcn,
    Gru,
    Consensus,
    /// From our detection frame's arrival to our decision.
    FrameToDecision,
}

impl Stage {
    /// The `stage` label of `spwi_stage_seconds`.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Graph => "graph",
            Stage::Gcn => "gcn",
            Stage::Gru => "gru",
            Stage::Consensus => "consensus",
            Stage::FrameToDecision => "frame_to_decision",
        }
    }
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct Metrics {
    /// Detection frames processed.
    pub frames: u64,
    /// Frames in which the worker was seen.
    pub frames_with_worker: u64,
    pub decisions: u64,
    pub decisions_by_deadline: u64,
    /// Peer messages for a tick already decided: counted and dropped.
    pub late_messages: u64,
    /// Frames for a tick already decided (duplicates, replays): dropped.
    pub stale_frames: u64,
    /// Messages from another live daemon using our robot id.
    pub duplicate_id_messages: u64,
    /// Open ticks dropped because too many were open.
    pub evicted_ticks: u64,
    /// Model runs that failed (the tick goes on without this robot's vote).
    pub model_errors: u64,
    /// Peer decisions (the verdicts their embeddings carry) compared with ours, and
    /// how many were the same.
    pub agreement_compared: u64,
    pub agreement_same: u64,
    /// Peer decisions that counted other ballots than ours (their digest differs).
    pub ballot_sets_differ: u64,
    /// ... of which counted every ballot we did and more: we decided on fewer.
    pub decided_on_fewer_ballots: u64,
    /// Peers' votes we got only through another peer's relay.
    pub relayed_ballots_used: u64,
    /// Relayed votes that arrived after we decided without them.
    pub late_relayed_ballots: u64,
    /// Our ballots sent again because we still waited for a member's vote (asks)...
    pub ballot_asks: u64,
    /// ... and because a peer's ballots lacked a vote we held (answers).
    pub ballot_answers: u64,
    /// Our own frames set aside because the feed repeated itself (a frozen camera).
    pub repeated_frames: u64,
    /// Messages of peers whose feed repeats itself, left out.
    pub stale_peer_messages: u64,
    /// Frames and peer messages refused for a tick outside our window, by side.
    pub off_clock: BTreeMap<OffClock, u64>,
    /// Relayed votes refused: their origin is no live member, or they are of another
    /// instance than the one it runs.
    pub foreign_votes: u64,
    /// Votes not counted: their voter's trust is below the counting threshold.
    pub votes_set_aside: u64,
    /// Ticks decided without a class although a vote came: its lone voter was not
    /// established while another trusted member was live (the lone-voter rule).
    pub lone_stranger_ticks: u64,
    /// Ticks decided without a class although votes came: every voter was trusted
    /// below the counting threshold while a trusted member was live.
    pub doubted_only_ticks: u64,
    /// Ticks we decided but did not publish: we were catching up with the team's
    /// history (engine/history.rs).
    pub decisions_withheld: u64,
    /// The team's history asked for while we were new (engine/history.rs).
    pub histories_asked: u64,
    /// Our lessons sent to members that asked.
    pub histories_sent: u64,
    /// Peers' histories that taught us nothing: from no live member, or for ticks out
    /// of reach or ours (a robot that has run a while takes none).
    pub histories_ignored: u64,
    /// Votes of others learned from peers' histories.
    pub history_votes_learned: u64,
    /// Robots that became members, and members that left (a member that flaps in and
    /// out shows here first).
    pub members_joined: u64,
    pub members_left: u64,
    pub stages: BTreeMap<Stage, Histogram>,
}

impl Metrics {
    pub fn count_off_clock(&mut self, why: OffClock) {
        *self.off_clock.entry(why).or_default() += 1;
    }

    pub fn observe(&mut self, stage: Stage, d: Duration) {
        self.stages.entry(stage).or_default().observe(d);
    }

    /// Share of compared peer decisions equal to ours (1.0 before any comparison).
    pub fn agreement(&self) -> f64 {
        if self.agreement_compared == 0 {
            1.0
        } else {
            self.agreement_same as f64 / self.agreement_compared as f64
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_are_the_upper_bounds_of_their_buckets() {
        let mut m = Metrics::default();
        for us in [30, 80, 150, 900] {
            m.observe(Stage::Gcn, Duration::from_micros(us));
        }
        let h = &m.stages[&Stage::Gcn];
        assert_eq!(h.quantile_upper_bound(0.5), Some(100e-6));
        assert_eq!(h.quantile_upper_bound(1.0), Some(1e-3));
        assert_eq!(h.buckets().iter().sum::<u64>(), 4);
    }
}

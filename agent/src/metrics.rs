//! Counters and latency histograms, rendered as Prometheus text for `/metrics` and
//! summarised in `/status`. Owned by the daemon's single event loop (no atomics on
//! the hot path); the HTTP side reads a snapshot refreshed once per decision.

use serde::Serialize;
use spwi_proto::DecodeError;
use std::collections::BTreeMap;
use std::fmt::Write;
use std::time::Duration;

/// Bucket upper bounds in seconds: 50 µs … 1 s.
const BOUNDS: [f64; 14] =
    [50e-6, 100e-6, 200e-6, 500e-6, 1e-3, 2e-3, 5e-3, 10e-3, 20e-3, 50e-3, 100e-3, 200e-3, 500e-3, 1.0];

/// Why a message never reached the engine: the codec refused it, its relayed vote
/// was not signed by its origin, or the event queue was full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DropReason {
    TooLarge,
    Version,
    Malformed,
    Trailing,
    Invalid,
    RobotMismatch,
    ForgedRelayedVote,
    QueueFull,
}

impl DropReason {
    /// The `reason` label of `spwi_bad_messages_total`.
    pub fn label(self) -> &'static str {
        match self {
            DropReason::TooLarge => "too_large",
            DropReason::Version => "version",
            DropReason::Malformed => "malformed",
            DropReason::Trailing => "trailing",
            DropReason::Invalid => "invalid",
            DropReason::RobotMismatch => "robot_mismatch",
            DropReason::ForgedRelayedVote => "forged_relayed_vote",
            DropReason::QueueFull => "queue_full",
        }
    }
}

impl From<&DecodeError> for DropReason {
    fn from(e: &DecodeError) -> Self {
        match e {
            DecodeError::TooLarge { .. } => DropReason::TooLarge,
            DecodeError::UnknownVersion { .. } => DropReason::Version,
            DecodeError::Malformed { .. } => DropReason::Malformed,
            DecodeError::TrailingBytes { .. } => DropReason::Trailing,
            DecodeError::Invalid { .. } => DropReason::Invalid,
            DecodeError::RobotMismatch { .. } => DropReason::RobotMismatch,
        }
    }
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct Histogram {
    counts: [u64; BOUNDS.len() + 1],
    sum: f64,
    count: u64,
}

impl Histogram {
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

    fn render(&self, out: &mut String, name: &str, labels: &str) {
        let mut cum = 0;
        for (i, c) in self.counts.iter().enumerate() {
            cum += c;
            let le = BOUNDS.get(i).map_or("+Inf".to_string(), |b| b.to_string());
            let _ = writeln!(out, "{name}_bucket{{{labels}le=\"{le}\"}} {cum}");
        }
        let _ = writeln!(out, "{name}_sum{{{}}} {}", labels.trim_end_matches(','), self.sum);
        let _ = writeln!(out, "{name}_count{{{}}} {}", labels.trim_end_matches(','), self.count);
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
    fn name(self) -> &'static str {
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
    /// Messages refused before the engine, by reason.
    pub bad_messages: BTreeMap<DropReason, u64>,
    /// Messages from another live daemon using our robot id.
    pub duplicate_id_messages: u64,
    /// Open ticks dropped because too many were open.
    pub evicted_ticks: u64,
    /// Model runs that failed (the tick goes on without this robot's vote).
    pub model_errors: u64,
    /// Outgoing messages dropped because Zenoh held up the publisher task.
    pub outgoing_dropped: u64,
    /// Peer decisions compared with ours, and how many were the same.
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
    /// Our own frames set aside because the feed repeated itself (a frozen camera).
    pub repeated_frames: u64,
    /// Messages of peers whose feed repeats itself, left out.
    pub stale_peer_messages: u64,
    pub stages: BTreeMap<Stage, Histogram>,
}

impl Metrics {
    pub fn observe(&mut self, stage: Stage, d: Duration) {
        self.stages.entry(stage).or_default().observe(d);
    }

    pub fn bad_messages(&mut self, reason: DropReason, n: u64) {
        *self.bad_messages.entry(reason).or_default() += n;
    }

    pub fn bad_total(&self) -> u64 {
        self.bad_messages.values().sum()
    }

    /// Share of compared peer decisions equal to ours (1.0 before any comparison).
    pub fn agreement(&self) -> f64 {
        if self.agreement_compared == 0 {
            1.0
        } else {
            self.agreement_same as f64 / self.agreement_compared as f64
        }
    }

    /// Prometheus text exposition.
    pub fn render(&self, robot: &str, members: usize) -> String {
        let mut o = String::new();
        let l = format!("robot=\"{robot}\"");
        let counters: [(&str, &str, u64); 17] = [
            ("spwi_frames_total", "detection frames processed", self.frames),
            ("spwi_frames_with_worker_total", "frames in which the worker was seen", self.frames_with_worker),
            ("spwi_decisions_total", "team decisions published", self.decisions),
            (
                "spwi_decisions_by_deadline_total",
                "decisions taken when the deadline passed",
                self.decisions_by_deadline,
            ),
            ("spwi_late_messages_total", "peer messages for an already decided tick", self.late_messages),
            ("spwi_stale_frames_total", "frames for an already decided tick", self.stale_frames),
            (
                "spwi_duplicate_id_messages_total",
                "messages from another daemon using our robot id",
                self.duplicate_id_messages,
            ),
            ("spwi_evicted_ticks_total", "open ticks dropped for lack of room", self.evicted_ticks),
            ("spwi_model_errors_total", "failed model runs", self.model_errors),
            (
                "spwi_outgoing_dropped_total",
                "outgoing messages dropped while Zenoh held up publishing",
                self.outgoing_dropped,
            ),
            ("spwi_agreement_compared_total", "peer decisions compared with ours", self.agreement_compared),
            (
                "spwi_ballot_sets_differ_total",
                "peer decisions whose ballot digest differs from ours",
                self.ballot_sets_differ,
            ),
            (
                "spwi_decided_on_fewer_ballots_total",
                "peer decisions that counted every ballot we did and more",
                self.decided_on_fewer_ballots,
            ),
            (
                "spwi_relayed_ballots_used_total",
                "peer votes received only through another peer's relay",
                self.relayed_ballots_used,
            ),
            (
                "spwi_late_relayed_ballots_total",
                "relayed votes that arrived after we decided without them",
                self.late_relayed_ballots,
            ),
            ("spwi_repeated_frames_total", "own frames set aside: the feed repeated itself", self.repeated_frames),
            (
                "spwi_stale_peer_messages_total",
                "messages of peers whose feed repeats itself, left out",
                self.stale_peer_messages,
            ),
        ];
        for (name, help, v) in counters {
            let _ = writeln!(o, "# HELP {name} {help}\n# TYPE {name} counter\n{name}{{{l}}} {v}");
        }
        let _ = writeln!(o, "# HELP spwi_agreement_same_total peer decisions equal to ours\n# TYPE spwi_agreement_same_total counter\nspwi_agreement_same_total{{{l}}} {}", self.agreement_same);
        let _ = writeln!(o, "# HELP spwi_agreement share of peer decisions equal to ours\n# TYPE spwi_agreement gauge\nspwi_agreement{{{l}}} {}", self.agreement());
        let _ = writeln!(o, "# HELP spwi_members live members counted, this robot included\n# TYPE spwi_members gauge\nspwi_members{{{l}}} {members}");
        let _ = writeln!(
            o,
            "# HELP spwi_bad_messages_total messages refused, by reason\n# TYPE spwi_bad_messages_total counter"
        );
        for (reason, v) in &self.bad_messages {
            let _ = writeln!(o, "spwi_bad_messages_total{{{l},reason=\"{}\"}} {v}", reason.label());
        }
        let _ = writeln!(o, "# HELP spwi_stage_seconds time per pipeline stage\n# TYPE spwi_stage_seconds histogram");
        for (stage, h) in &self.stages {
            h.render(&mut o, "spwi_stage_seconds", &format!("{l},stage=\"{}\",", stage.name()));
        }
        o
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_quantiles_and_rendering() {
        let mut m = Metrics::default();
        for us in [30, 80, 150, 900] {
            m.observe(Stage::Gcn, Duration::from_micros(us));
        }
        let h = &m.stages[&Stage::Gcn];
        assert_eq!(h.quantile_upper_bound(0.5), Some(100e-6));
        assert_eq!(h.quantile_upper_bound(1.0), Some(1e-3));
        m.bad_messages(DropReason::Version, 1);
        let text = m.render("r1", 3);
        assert!(text.contains("spwi_stage_seconds_bucket{robot=\"r1\",stage=\"gcn\",le=\"+Inf\"} 4"), "{text}");
        assert!(text.contains("spwi_bad_messages_total{robot=\"r1\",reason=\"version\"} 1"));
        assert!(text.contains("spwi_members{robot=\"r1\"} 3"));
    }
}

//! Counters and latency histograms, exposed as OpenMetrics text for `/metrics` (through
//! prometheus-client: HELP and TYPE lines, label escaping) and summarised in `/status`.
//! Owned by the daemon's single event loop as plain numbers (no atomics on the hot
//! path); the HTTP side reads a snapshot refreshed once per decision and registers it
//! in a registry of its own per scrape.

use crate::clock::OffClock;
use prometheus_client::encoding::{EncodeMetric, MetricEncoder, NoLabelSet};
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::gauge::ConstGauge;
use prometheus_client::metrics::MetricType;
use prometheus_client::registry::Registry;
use serde::Serialize;
use spwi_proto::DecodeError;
use std::borrow::Cow;
use std::collections::BTreeMap;
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

    /// Registers every counter and histogram, as they stand, in `registry` (the
    /// scrape's own: see [`exposition`]); `members` is the live member count.
    pub fn register(&self, registry: &mut Registry, members: usize) {
        let counters: [(&str, &str, u64); 21] = [
            ("spwi_frames", "detection frames processed", self.frames),
            ("spwi_frames_with_worker", "frames in which the worker was seen", self.frames_with_worker),
            ("spwi_decisions", "team decisions published", self.decisions),
            ("spwi_decisions_by_deadline", "decisions taken when the deadline passed", self.decisions_by_deadline),
            ("spwi_late_messages", "peer messages for an already decided tick", self.late_messages),
            ("spwi_stale_frames", "frames for an already decided tick", self.stale_frames),
            (
                "spwi_duplicate_id_messages",
                "messages from another daemon using our robot id",
                self.duplicate_id_messages,
            ),
            ("spwi_evicted_ticks", "open ticks dropped for lack of room", self.evicted_ticks),
            ("spwi_model_errors", "failed model runs", self.model_errors),
            ("spwi_agreement_compared", "peer decisions compared with ours", self.agreement_compared),
            ("spwi_agreement_same", "peer decisions equal to ours", self.agreement_same),
            (
                "spwi_ballot_sets_differ",
                "peer decisions whose ballot digest differs from ours",
                self.ballot_sets_differ,
            ),
            (
                "spwi_decided_on_fewer_ballots",
                "peer decisions that counted every ballot we did and more",
                self.decided_on_fewer_ballots,
            ),
            (
                "spwi_relayed_ballots_used",
                "peer votes received only through another peer's relay",
                self.relayed_ballots_used,
            ),
            (
                "spwi_late_relayed_ballots",
                "relayed votes that arrived after we decided without them",
                self.late_relayed_ballots,
            ),
            ("spwi_ballot_asks", "our ballots sent again while we waited for a member's vote", self.ballot_asks),
            (
                "spwi_ballot_answers",
                "our ballots sent to a peer whose ballots lacked a vote we held",
                self.ballot_answers,
            ),
            ("spwi_repeated_frames", "own frames set aside: the feed repeated itself", self.repeated_frames),
            (
                "spwi_stale_peer_messages",
                "messages of peers whose feed repeats itself, left out",
                self.stale_peer_messages,
            ),
            (
                "spwi_foreign_votes",
                "relayed votes refused: origin not live, or another instance than its live one",
                self.foreign_votes,
            ),
            (
                "spwi_votes_set_aside",
                "votes not counted: their voter's trust is below the threshold",
                self.votes_set_aside,
            ),
        ];
        for (name, help, v) in counters {
            registry.register(name, help, ConstCounter::new(v));
        }
        let off = self.off_clock.iter().map(|(r, &n)| (r.label().to_owned(), ConstCounter::new(n)));
        registry.register(
            "spwi_off_clock",
            "frames and peer messages refused: their tick lies outside our clock's window",
            ByLabel::new("reason", MetricType::Counter, off),
        );
        registry.register("spwi_agreement", "share of peer decisions equal to ours", ConstGauge::new(self.agreement()));
        registry.register("spwi_members", "live members counted, this robot included", ConstGauge::new(members as i64));
        let stages = self.stages.iter().map(|(s, h)| (s.name().to_owned(), h.clone()));
        registry.register(
            "spwi_stage_seconds",
            "time per pipeline stage",
            ByLabel::new("stage", MetricType::Histogram, stages),
        );
    }
}

/// What the daemon counts around the engine: messages refused before it, by reason,
/// and its own messages Zenoh held up.
#[derive(Debug, Clone, Default, Serialize)]
pub struct TransportCounters {
    pub bad_messages: BTreeMap<DropReason, u64>,
    /// Outgoing messages dropped because Zenoh held up the publisher task.
    pub outgoing_dropped: u64,
}

impl TransportCounters {
    pub fn bad_messages(&mut self, reason: DropReason, n: u64) {
        *self.bad_messages.entry(reason).or_default() += n;
    }

    pub fn bad_total(&self) -> u64 {
        self.bad_messages.values().sum()
    }

    /// Registers both counters in `registry`.
    pub fn register(&self, registry: &mut Registry) {
        let reasons = self.bad_messages.iter().map(|(r, &n)| (r.label().to_owned(), ConstCounter::new(n)));
        registry.register(
            "spwi_bad_messages",
            "messages refused, by reason",
            ByLabel::new("reason", MetricType::Counter, reasons),
        );
        registry.register(
            "spwi_outgoing_dropped",
            "outgoing messages dropped while Zenoh held up publishing",
            ConstCounter::new(self.outgoing_dropped),
        );
    }
}

/// A scrape's registry: every metric carries the label `robot`.
pub fn registry(robot: &str) -> Registry {
    Registry::with_labels(std::iter::once((Cow::Borrowed("robot"), Cow::Owned(robot.to_owned()))))
}

/// The OpenMetrics text of `registry` (`/metrics`).
pub fn exposition(registry: &Registry) -> String {
    let mut text = String::new();
    prometheus_client::encoding::text::encode(&mut text, registry).expect("writing to a String cannot fail");
    text
}

/// Values of one metric by the value of one label (a reason, a stage, a peer), taken
/// from the event loop's plain counters at scrape time: the loop keeps sole ownership
/// and no atomics, and the metric's HELP and TYPE are written even while it is empty.
#[derive(Debug)]
pub struct ByLabel<M> {
    label: &'static str,
    kind: MetricType,
    values: Vec<(String, M)>,
}

impl<M: EncodeMetric> ByLabel<M> {
    pub fn new(label: &'static str, kind: MetricType, values: impl IntoIterator<Item = (String, M)>) -> Self {
        ByLabel { label, kind, values: values.into_iter().collect() }
    }
}

impl<M: EncodeMetric> EncodeMetric for ByLabel<M> {
    fn encode(&self, mut encoder: MetricEncoder) -> std::fmt::Result {
        for (value, metric) in &self.values {
            metric.encode(encoder.encode_family(&[(self.label, value.as_str())])?)?;
        }
        Ok(())
    }

    fn metric_type(&self) -> MetricType {
        self.kind
    }
}

impl EncodeMetric for Histogram {
    fn encode(&self, mut encoder: MetricEncoder) -> std::fmt::Result {
        // The last bucket has no bound: prometheus-client writes f64::MAX as +Inf.
        let bounds = BOUNDS.iter().copied().chain(std::iter::once(f64::MAX));
        let buckets: Vec<(f64, u64)> = bounds.zip(self.counts.iter().copied()).collect();
        encoder.encode_histogram::<NoLabelSet>(self.sum, self.count, &buckets, None)
    }

    fn metric_type(&self) -> MetricType {
        MetricType::Histogram
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
        let mut transport = TransportCounters::default();
        transport.bad_messages(DropReason::Version, 1);
        let mut registry = registry("r1");
        m.register(&mut registry, 3);
        transport.register(&mut registry);
        let text = exposition(&registry);
        assert!(text.contains("spwi_stage_seconds_bucket{robot=\"r1\",le=\"+Inf\",stage=\"gcn\"} 4"), "{text}");
        assert!(text.contains("spwi_stage_seconds_count{robot=\"r1\",stage=\"gcn\"} 4"), "{text}");
        assert!(text.contains("# TYPE spwi_decisions counter\nspwi_decisions_total{robot=\"r1\"} 0"), "{text}");
        assert!(text.contains("spwi_bad_messages_total{robot=\"r1\",reason=\"version\"} 1"));
        assert!(text.contains("spwi_members{robot=\"r1\"} 3"));
    }
}

//! `/metrics`: the engine's counters and latency histograms ([`spwi_core::metrics`]) and
//! the daemon's own, as OpenMetrics text through prometheus-client (HELP and TYPE lines,
//! label escaping). The HTTP side reads a snapshot refreshed by the event loop and
//! registers it in a registry of its own per scrape.

use prometheus_client::encoding::{EncodeMetric, MetricEncoder, NoLabelSet};
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::gauge::ConstGauge;
use prometheus_client::metrics::MetricType;
use prometheus_client::registry::Registry;
use serde::Serialize;
use spwi_core::metrics::{Histogram, Metrics, BOUNDS};
use spwi_proto::DecodeError;
use std::borrow::Cow;
use std::collections::BTreeMap;

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
    /// From a robot the roster held does not admit (revoked, or admitted after us and
    /// not yet in our roster).
    NotAdmitted,
    /// A vote its origin signed for a tick for which it signed another: proof that it
    /// told different robots different things.
    EquivocatedVote,
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
            DropReason::NotAdmitted => "not_admitted",
            DropReason::EquivocatedVote => "equivocated_vote",
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

/// Registers every counter and histogram of the engine, as they stand, in `registry` (the
/// scrape's own: see [`exposition`]); `members` is the live member count.
pub fn register_engine(m: &Metrics, registry: &mut Registry, members: usize) {
    let counters: [(&str, &str, u64); 30] = [
        ("spwi_frames", "detection frames processed", m.frames),
        ("spwi_frames_with_worker", "frames in which the worker was seen", m.frames_with_worker),
        ("spwi_decisions", "team decisions published", m.decisions),
        ("spwi_decisions_by_deadline", "decisions taken when the deadline passed", m.decisions_by_deadline),
        ("spwi_late_messages", "peer messages for an already decided tick", m.late_messages),
        ("spwi_stale_frames", "frames for an already decided tick", m.stale_frames),
        ("spwi_duplicate_id_messages", "messages from another daemon using our robot id", m.duplicate_id_messages),
        ("spwi_evicted_ticks", "open ticks dropped for lack of room", m.evicted_ticks),
        ("spwi_model_errors", "failed model runs", m.model_errors),
        ("spwi_agreement_compared", "peer decisions compared with ours", m.agreement_compared),
        ("spwi_agreement_same", "peer decisions equal to ours", m.agreement_same),
        ("spwi_ballot_sets_differ", "peer decisions whose ballot digest differs from ours", m.ballot_sets_differ),
        (
            "spwi_decided_on_fewer_ballots",
            "peer decisions that counted every ballot we did and more",
            m.decided_on_fewer_ballots,
        ),
        ("spwi_relayed_ballots_used", "peer votes received only through another peer's relay", m.relayed_ballots_used),
        (
            "spwi_late_relayed_ballots",
            "relayed votes that arrived after we decided without them",
            m.late_relayed_ballots,
        ),
        ("spwi_ballot_asks", "our ballots sent again while we waited for a member's vote", m.ballot_asks),
        ("spwi_ballot_answers", "our ballots sent to a peer whose ballots lacked a vote we held", m.ballot_answers),
        ("spwi_repeated_frames", "own frames set aside: the feed repeated itself", m.repeated_frames),
        ("spwi_stale_peer_messages", "messages of peers whose feed repeats itself, left out", m.stale_peer_messages),
        (
            "spwi_foreign_votes",
            "relayed votes refused: origin not live, or another instance than its live one",
            m.foreign_votes,
        ),
        ("spwi_votes_set_aside", "votes not counted: their voter's trust is below the threshold", m.votes_set_aside),
        (
            "spwi_lone_stranger_ticks",
            "ticks left without a class: a lone voter not yet established while a trusted member was live",
            m.lone_stranger_ticks,
        ),
        (
            "spwi_doubted_only_ticks",
            "ticks left without a class: every voter trusted below the threshold while a trusted member was live",
            m.doubted_only_ticks,
        ),
        (
            "spwi_decisions_withheld",
            "ticks decided but not published while this robot learned the team's history",
            m.decisions_withheld,
        ),
        ("spwi_histories_asked", "the team's history asked for while this robot was new", m.histories_asked),
        ("spwi_histories_sent", "our recent lessons sent to a member that asked for them", m.histories_sent),
        (
            "spwi_histories_ignored",
            "peers' histories that taught us nothing (not from a live member, or for ticks out of reach)",
            m.histories_ignored,
        ),
        ("spwi_history_votes_learned", "votes of others learned from peers' histories", m.history_votes_learned),
        ("spwi_members_joined", "robots that became members", m.members_joined),
        ("spwi_members_left", "members that left (revoked, gone, or not back within a reopen's grace)", m.members_left),
    ];
    for (name, help, v) in counters {
        registry.register(name, help, ConstCounter::new(v));
    }
    let off = m.off_clock.iter().map(|(r, &n)| (r.label().to_owned(), ConstCounter::new(n)));
    registry.register(
        "spwi_off_clock",
        "frames and peer messages refused: their tick lies outside our clock's window",
        ByLabel::new("reason", MetricType::Counter, off),
    );
    registry.register("spwi_agreement", "share of peer decisions equal to ours", ConstGauge::new(m.agreement()));
    registry.register("spwi_members", "live members counted, this robot included", ConstGauge::new(members as i64));
    let stages = m.stages.iter().map(|(s, h)| (s.name().to_owned(), Buckets(h.clone())));
    registry.register(
        "spwi_stage_seconds",
        "time per pipeline stage",
        ByLabel::new("stage", MetricType::Histogram, stages),
    );
}

/// What the daemon counts around the engine: messages refused before it, by reason,
/// and its own messages Zenoh held up.
#[derive(Debug, Clone, Default, Serialize)]
pub struct TransportCounters {
    pub bad_messages: BTreeMap<DropReason, u64>,
    /// Outgoing messages dropped because Zenoh held up the publisher task.
    pub outgoing_dropped: u64,
    /// Rosters adopted while running, and rosters refused (not the CA's, another
    /// fleet's, unreadable), in a secured fleet.
    pub rosters_adopted: u64,
    pub rosters_refused: u64,
}

impl TransportCounters {
    pub fn bad_messages(&mut self, reason: DropReason, n: u64) {
        *self.bad_messages.entry(reason).or_default() += n;
    }

    pub fn bad_total(&self) -> u64 {
        self.bad_messages.values().sum()
    }

    /// Registers the counters in `registry`.
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
        registry.register(
            "spwi_rosters_adopted",
            "newer signed rosters adopted while running",
            ConstCounter::new(self.rosters_adopted),
        );
        registry.register(
            "spwi_rosters_refused",
            "rosters refused: not signed by the fleet's CA, of another fleet, or unreadable",
            ConstCounter::new(self.rosters_refused),
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

/// A histogram as prometheus-client encodes it.
#[derive(Debug)]
struct Buckets(Histogram);

impl EncodeMetric for Buckets {
    fn encode(&self, mut encoder: MetricEncoder) -> std::fmt::Result {
        // The last bucket has no bound: prometheus-client writes f64::MAX as +Inf.
        let bounds = BOUNDS.iter().copied().chain(std::iter::once(f64::MAX));
        let buckets: Vec<(f64, u64)> = bounds.zip(self.0.buckets().iter().copied()).collect();
        encoder.encode_histogram::<NoLabelSet>(self.0.sum(), self.0.count(), &buckets, None)
    }

    fn metric_type(&self) -> MetricType {
        MetricType::Histogram
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spwi_core::metrics::Stage;
    use std::time::Duration;

    #[test]
    fn the_exposition_names_every_stage_and_reason() {
        let mut m = Metrics::default();
        for us in [30, 80, 150, 900] {
            m.observe(Stage::Gcn, Duration::from_micros(us));
        }
        let mut transport = TransportCounters::default();
        transport.bad_messages(DropReason::Version, 1);
        let mut registry = registry("r1");
        register_engine(&m, &mut registry, 3);
        transport.register(&mut registry);
        let text = exposition(&registry);
        assert!(text.contains("spwi_stage_seconds_bucket{robot=\"r1\",le=\"+Inf\",stage=\"gcn\"} 4"), "{text}");
        assert!(text.contains("spwi_stage_seconds_count{robot=\"r1\",stage=\"gcn\"} 4"), "{text}");
        assert!(text.contains("# TYPE spwi_decisions counter\nspwi_decisions_total{robot=\"r1\"} 0"), "{text}");
        assert!(text.contains("spwi_bad_messages_total{robot=\"r1\",reason=\"version\"} 1"));
        assert!(text.contains("spwi_members{robot=\"r1\"} 3"));
    }
}

//! How a figure reads on the results page: a share as a percentage, with its interval,
//! one model's lead over another, how a run's maps started. Shared by the page and its
//! reading of the targets.

use super::scored::Scored;
use super::Report;

/// The mean trust the others held of the untrue robots (lying cameras, liars, a pose
/// off) / of the rest.
pub(super) fn trust_split(r: &Report) -> String {
    let lying = r.faults.untrue();
    let mean = |ps: &[super::PerRobot]| {
        let ts: Vec<f64> = ps.iter().filter_map(|p| p.trust).collect();
        if ts.is_empty() {
            "–".to_owned()
        } else {
            format!("{:.2}", ts.iter().sum::<f64>() / ts.len() as f64)
        }
    };
    let split = lying.min(r.per_robot.len());
    let faulty = if lying == 0 { "–".to_owned() } else { mean(&r.per_robot[..split]) };
    format!("{faulty} / {}", mean(&r.per_robot[split..]))
}

/// "+9.0": `model`'s accuracy at t less `other`'s, in points ("–" if either is absent).
pub(super) fn points(r: &Report, model: Scored, other: Scored) -> String {
    lead(r, model, other).map_or("–".into(), |g| format!("{:+.1}", 100.0 * g))
}

/// "empty" or "warm, 60 s": how a run's station maps started.
pub(super) fn maps(r: &Report) -> String {
    if r.warm_map_s > 0.0 {
        format!("warm, {} s", r.warm_map_s)
    } else {
        "empty".into()
    }
}

pub(super) fn pct(v: f64) -> String {
    format!("{:.1}", 100.0 * v)
}

/// "81.0 (79.2–82.7)": a figure with its 95 % interval.
pub(super) fn with_ci(v: f64, ci: [f64; 2]) -> String {
    format!("{} ({}–{})", pct(v), pct(ci[0]), pct(ci[1]))
}

/// A model's accuracy at t and over t+1…H, each with its interval ("–" if absent).
pub(super) fn acc(r: &Report, model: Scored) -> (String, String) {
    acc_in(&r.models, model)
}

pub(super) fn acc_in(
    m: &std::collections::BTreeMap<Scored, super::score::Accuracy>,
    model: Scored,
) -> (String, String) {
    m.get(&model).map_or(("–".into(), "–".into()), |a| {
        let future = match (a.future, a.future_ci95) {
            (Some(f), Some(ci)) => with_ci(f, ci),
            _ => "–".into(),
        };
        (with_ci(a.t, a.t_ci95), future)
    })
}

/// A model's accuracy at t and its interval.
pub(super) fn at(r: &Report, model: Scored) -> Option<(f64, [f64; 2])> {
    r.models.get(&model).map(|a| (a.t, a.t_ci95))
}

/// How far `model`'s accuracy at t leads `other`'s, as a fraction.
pub(super) fn lead(r: &Report, model: Scored, other: Scored) -> Option<f64> {
    Some(at(r, model)?.0 - at(r, other)?.0)
}

/// A table of the page, as a value: its header and its rows, each row a cell per
/// column, written out as markdown by its one `Display`.
#[derive(Debug, Clone, Default)]
pub(super) struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    pub(super) fn new<S: ToString>(header: impl IntoIterator<Item = S>) -> Table {
        Table { header: header.into_iter().map(|h| h.to_string()).collect(), rows: Vec::new() }
    }

    /// No row yet.
    pub(super) fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// One row; as many cells as the header has columns.
    pub(super) fn row<S: ToString>(&mut self, cells: impl IntoIterator<Item = S>) {
        let row: Vec<String> = cells.into_iter().map(|c| c.to_string()).collect();
        debug_assert_eq!(row.len(), self.header.len(), "a row of {row:?} under {:?}", self.header);
        self.rows.push(row);
    }
}

impl std::fmt::Display for Table {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let line = |f: &mut std::fmt::Formatter<'_>, cells: &[String]| writeln!(f, "| {} |", cells.join(" | "));
        line(f, &self.header)?;
        writeln!(f, "|{}", "---|".repeat(self.header.len()))?;
        for r in &self.rows {
            line(f, r)?;
        }
        Ok(())
    }
}

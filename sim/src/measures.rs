//! The two measures every tool reports the same way: how often robots decided alike
//! ([`Agreement`]) and how long a decision took ([`LatencyMs`]). The demo, the bench,
//! the soak, the evaluation and the loopback toolkit's decision log all count with
//! these, so one word means one figure everywhere.

use serde::Serialize;

/// Of the ticks compared, those on which every robot named the same answer. What is
/// compared (the class at t, or every step) and which ticks count is the caller's.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Agreement {
    pub same: u64,
    pub compared: u64,
}

impl Agreement {
    /// One tick's answers, one per robot: alike when all are equal.
    pub fn tick<T: PartialEq>(&mut self, answers: impl IntoIterator<Item = T>) {
        let mut answers = answers.into_iter();
        let first = answers.next();
        self.compared += 1;
        self.same += u64::from(answers.all(|a| Some(a) == first));
    }

    /// The share of the compared ticks that were alike (0 when none was compared).
    pub fn share(&self) -> f64 {
        if self.compared == 0 {
            0.0
        } else {
            self.same as f64 / self.compared as f64
        }
    }
}

impl std::ops::AddAssign for Agreement {
    fn add_assign(&mut self, o: Agreement) {
        self.same += o.same;
        self.compared += o.compared;
    }
}

/// Latencies in milliseconds: median, 99th percentile and the largest.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct LatencyMs {
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

impl LatencyMs {
    /// Of `samples`, in any order.
    pub fn of(mut samples: Vec<f64>) -> LatencyMs {
        samples.sort_by(f64::total_cmp);
        LatencyMs {
            p50: percentile(&samples, 0.5),
            p99: percentile(&samples, 0.99),
            max: samples.last().copied().unwrap_or(0.0),
        }
    }
}

/// The `q` quantile of sorted values, nearest rank (0 when empty).
pub fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    sorted[((q * (sorted.len() - 1) as f64).round() as usize).min(sorted.len() - 1)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(percentile(&v, 0.5), 51.0);
        assert_eq!(percentile(&v, 0.99), 99.0);
        assert_eq!(percentile(&[], 0.5), 0.0);
        let l = LatencyMs::of(vec![3.0, 1.0, 2.0]);
        assert_eq!((l.p50, l.max), (2.0, 3.0));
    }

    #[test]
    fn a_tick_is_alike_only_when_every_answer_is() {
        let mut a = Agreement::default();
        a.tick([Some(1), Some(1)]);
        a.tick([Some(1), None]);
        a.tick([2]);
        assert_eq!(a, Agreement { same: 2, compared: 3 });
        assert_eq!(Agreement::default().share(), 0.0);
    }
}

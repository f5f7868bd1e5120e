//! Tallies of predictions against the truth, and the figures the report shows.

use serde::Serialize;
use spwi_proto::{Station, NUM_CLASSES};

/// Accuracy at t and averaged over t+1 … t+H, as fractions 0–1, each with its 95 %
/// bootstrap confidence interval by episode (see [`estimate`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Accuracy {
    pub t: f64,
    pub t_ci95: [f64; 2],
    #[serde(skip_serializing_if = "Option::is_none")]
    pub future: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub future_ci95: Option<[f64; 2]>,
}

/// Bootstrap resamples behind every interval.
const RESAMPLES: usize = 1000;

/// The accuracy of the episodes' pooled tallies, with 95 % percentile-bootstrap
/// intervals from resampling whole episodes (ticks of one episode are not independent
/// draws; episodes are). Deterministic: the resampling stream is fixed.
pub fn estimate(episodes: &[Tally]) -> Accuracy {
    use rand::{Rng, SeedableRng};
    let mut pooled = Tally::default();
    episodes.iter().for_each(|e| pooled.merge(e));
    let point = pooled.fractions();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0xb007);
    let (mut ts, mut fs) = (Vec::with_capacity(RESAMPLES), Vec::with_capacity(RESAMPLES));
    if !episodes.is_empty() {
        for _ in 0..RESAMPLES {
            let mut r = Tally::default();
            for _ in 0..episodes.len() {
                r.merge(&episodes[rng.gen_range(0..episodes.len())]);
            }
            let (t, f) = r.fractions();
            ts.push(t);
            fs.extend(f);
        }
    }
    let ci = |v: &mut Vec<f64>| {
        if v.is_empty() {
            return [0.0, 0.0];
        }
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        [at(0.025), at(0.975)]
    };
    Accuracy { t: point.0, t_ci95: ci(&mut ts), future: point.1, future_ci95: point.1.map(|_| ci(&mut fs)) }
}

/// Hits and counts behind an [`Accuracy`].
#[derive(Debug, Clone, Copy, Default)]
pub struct Tally {
    hits_t: u64,
    n_t: u64,
    hits_future: u64,
    n_future: u64,
}

impl Tally {
    pub const EMPTY: Tally = Tally { hits_t: 0, n_t: 0, hits_future: 0, n_future: 0 };

    /// `pred[h]` is the class predicted for t+h, `truth[h]` the true intent at t+h.
    pub fn add<T: PartialEq>(&mut self, pred: &[T], truth: &[T]) {
        for (h, (p, y)) in pred.iter().zip(truth).enumerate() {
            let hit = u64::from(p == y);
            if h == 0 {
                self.hits_t += hit;
                self.n_t += 1;
            } else {
                self.hits_future += hit;
                self.n_future += 1;
            }
        }
    }

    /// [`Tally::add`], except that no prediction (`pred` empty) is wrong at every step
    /// of `truth`: how a tick the team left undecided counts.
    pub fn add_or_miss<T: PartialEq>(&mut self, pred: &[T], truth: &[T]) {
        if !pred.is_empty() {
            return self.add(pred, truth);
        }
        if let Some(future) = truth.len().checked_sub(1) {
            self.n_t += 1;
            self.n_future += future as u64;
        }
    }

    pub fn merge(&mut self, o: &Tally) {
        self.hits_t += o.hits_t;
        self.n_t += o.n_t;
        self.hits_future += o.hits_future;
        self.n_future += o.n_future;
    }

    pub fn samples(&self) -> u64 {
        self.n_t
    }

    /// Accuracy at t, and over the future steps if any were scored.
    fn fractions(&self) -> (f64, Option<f64>) {
        let frac = |h: u64, n: u64| if n == 0 { 0.0 } else { h as f64 / n as f64 };
        (frac(self.hits_t, self.n_t), (self.n_future > 0).then(|| frac(self.hits_future, self.n_future)))
    }
}

/// Counts of (true class, predicted class) at t.
pub type Confusion = [[u64; NUM_CLASSES]; NUM_CLASSES];

pub fn confuse(c: &mut Confusion, pred: Station, truth: Station) {
    c[truth.index()][pred.index()] += 1;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accuracy_at_t_and_over_the_future_steps() {
        let mut t = Tally::default();
        t.add(&[1, 1, 2], &[1, 2, 2]); // hit at t; 1 of 2 future
        t.add(&[0, 0, 0], &[3, 0, 0]); // miss at t; 2 of 2 future
        let a = estimate(&[t]);
        assert_eq!(a.t, 0.5);
        assert_eq!(a.future, Some(0.75));
        assert_eq!(estimate(&[]).t, 0.0);
        assert_eq!(estimate(&[Tally::default()]).future, None);
        t.add_or_miss(&[], &[1, 2, 2]); // no prediction: wrong at t and at both future steps
        let a = estimate(&[t]);
        assert!((a.t - 1.0 / 3.0).abs() < 1e-12 && a.future == Some(0.5), "{a:?}");
    }

    #[test]
    fn intervals_hold_the_estimate_and_narrow_with_more_episodes() {
        // Episodes of 10 ticks, 7 right on average, varying from episode to episode.
        let episode = |k: usize| {
            let mut t = Tally::default();
            for i in 0..10 {
                let right = i < 4 + k % 7; // 4..10 right: mean 7 of 10
                t.add(&[u8::from(!right)], &[0]);
            }
            t
        };
        let few: Vec<Tally> = (0..10).map(episode).collect();
        let many: Vec<Tally> = (0..280).map(episode).collect();
        let (a, b) = (estimate(&few), estimate(&many));
        for x in [a, b] {
            assert!(x.t_ci95[0] <= x.t && x.t <= x.t_ci95[1], "{x:?}");
        }
        assert!((b.t - 0.7).abs() < 0.01, "{b:?}");
        let width = |x: Accuracy| x.t_ci95[1] - x.t_ci95[0];
        assert!(width(b) < width(a) / 3.0, "{a:?} vs {b:?}");
        assert!(width(a) > 0.02, "episodes that differ give an interval: {a:?}");
        assert_eq!(estimate(&few), estimate(&few), "the same episodes give the same interval");
    }
}

//! Tallies of predictions against the truth, and the figures the report shows.

use serde::Serialize;
use spwi_proto::NUM_CLASSES;

/// Accuracy at t and averaged over t+1 … t+H, as fractions 0–1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Accuracy {
    pub t: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub future: Option<f64>,
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
    /// `pred[h]` is the class predicted for t+h, `truth[h]` the true intent at t+h.
    pub fn add(&mut self, pred: &[u8], truth: &[u8]) {
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

    pub fn merge(&mut self, o: &Tally) {
        self.hits_t += o.hits_t;
        self.n_t += o.n_t;
        self.hits_future += o.hits_future;
        self.n_future += o.n_future;
    }

    pub fn samples(&self) -> u64 {
        self.n_t
    }

    pub fn accuracy(&self) -> Accuracy {
        let frac = |h: u64, n: u64| if n == 0 { 0.0 } else { h as f64 / n as f64 };
        Accuracy {
            t: frac(self.hits_t, self.n_t),
            future: (self.n_future > 0).then(|| frac(self.hits_future, self.n_future)),
        }
    }
}

/// Counts of (true class, predicted class) at t.
pub type Confusion = [[u64; NUM_CLASSES]; NUM_CLASSES];

pub fn confuse(c: &mut Confusion, pred: u8, truth: u8) {
    c[truth as usize][pred as usize] += 1;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accuracy_at_t_and_over_the_future_steps() {
        let mut t = Tally::default();
        t.add(&[1, 1, 2], &[1, 2, 2]); // hit at t; 1 of 2 future
        t.add(&[0, 0, 0], &[3, 0, 0]); // miss at t; 2 of 2 future
        let a = t.accuracy();
        assert_eq!(a.t, 0.5);
        assert_eq!(a.future, Some(0.75));
        assert_eq!(Tally::default().accuracy(), Accuracy { t: 0.0, future: None });
    }
}

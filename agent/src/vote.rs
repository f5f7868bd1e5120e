//! GRU logits → this robot's vote (paper III-E): for t and each forecast step, the
//! argmax class and its calibrated confidence softmax(z / T) of that class. Pure.

use spwi_proto::{StepVote, NUM_CLASSES};

/// Softmax of `logits / temperature`, computed stably.
pub fn softmax(logits: &[f32; NUM_CLASSES], temperature: f32) -> [f32; NUM_CLASSES] {
    let max = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mut p = logits.map(|z| ((z - max) / temperature).exp());
    let sum: f32 = p.iter().sum();
    p.iter_mut().for_each(|v| *v /= sum);
    p
}

/// Index of the largest value; the lowest index wins a tie.
pub fn argmax(xs: &[f32]) -> usize {
    let mut best = 0;
    for (i, &x) in xs.iter().enumerate() {
        if x > xs[best] {
            best = i;
        }
    }
    best
}

/// One [`StepVote`] per row of logits (row 0 = t).
pub fn vote(logits: &[[f32; NUM_CLASSES]], temperature: f32) -> Vec<StepVote> {
    logits
        .iter()
        .map(|z| {
            let k = argmax(z);
            StepVote { class: k as u8, confidence: softmax(z, temperature)[k] }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn confidence_is_the_tempered_softmax_of_the_top_class() {
        let v = vote(&[[0.0, 2.0, 0.0, 0.0]], 1.0);
        let e2 = 2.0f32.exp();
        assert_eq!(v[0].class, 1);
        assert!((v[0].confidence - e2 / (e2 + 3.0)).abs() < 1e-6);
        // a higher temperature flattens the distribution
        let cold = vote(&[[0.0, 2.0, 0.0, 0.0]], 2.0)[0].confidence;
        assert!(cold < v[0].confidence);
    }

    #[test]
    fn huge_logits_stay_finite_and_ties_pick_the_lowest_class() {
        let v = vote(&[[1e30, 1e30, -1e30, 0.0]], 1.0);
        assert_eq!(v[0].class, 0);
        assert!((v[0].confidence - 0.5).abs() < 1e-6);
    }
}

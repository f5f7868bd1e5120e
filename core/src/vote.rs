//! GRU logits → this robot's vote (paper III-E): for t and each forecast step, the
//! argmax class and its calibrated confidence softmax(z / T) of that class; and how
//! well the robot sees the worker, which the trust rule weighs the vote by. Pure.

use spwi_proto::{DetectionFrame, Station, StepVote, NUM_CLASSES};

/// A worker this tall in the image (share of its height) is seen as well as it gets:
/// keypoints carry a few pixels of noise, so a smaller figure gives a noisier pose.
const FULL_VIEW_HEIGHT: f32 = 0.25;
/// The least quality of a vote: one from the team's track alone, without a view.
pub const TRACK_ONLY_QUALITY: f32 = 0.1;

/// How well `frame` shows the worker, in [`TRACK_ONLY_QUALITY`], 1]: the worker's
/// height in the image against [`FULL_VIEW_HEIGHT`], times the share of its keypoints
/// inside the image (a figure cut by the image border shows less of its pose).
pub fn view_quality(frame: &DetectionFrame) -> f32 {
    let Some(h) = frame.worker() else { return TRACK_ONLY_QUALITY };
    let [w_img, h_img] = frame.image_size;
    let size = (h.bbox.h / (FULL_VIEW_HEIGHT * h_img)).min(1.0);
    let points = h.keypoints.chunks_exact(2);
    let n = points.len().max(1) as f32;
    let inside = points.filter(|p| (0.0..=w_img).contains(&p[0]) && (0.0..=h_img).contains(&p[1])).count() as f32 / n;
    (size * inside).clamp(TRACK_ONLY_QUALITY, 1.0)
}

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

/// The station of the largest score; the lowest index wins a tie.
pub fn top_station(scores: &[f32; NUM_CLASSES]) -> Station {
    Station::ALL[argmax(scores)]
}

/// One [`StepVote`] per row of logits (row 0 = t).
pub fn vote(logits: &[[f32; NUM_CLASSES]], temperature: f32) -> Vec<StepVote> {
    logits
        .iter()
        .map(|z| {
            let k = argmax(z);
            StepVote { class: Station::ALL[k], confidence: softmax(z, temperature)[k] }
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
        assert_eq!(v[0].class, Station::Workstation);
        assert!((v[0].confidence - e2 / (e2 + 3.0)).abs() < 1e-6);
        // a higher temperature flattens the distribution
        let cold = vote(&[[0.0, 2.0, 0.0, 0.0]], 2.0)[0].confidence;
        assert!(cold < v[0].confidence);
    }

    #[test]
    fn a_near_whole_worker_is_seen_best_and_a_vote_from_the_track_least() {
        let mut f = crate::engine::tests::frame("r1", 1, true);
        let h_img = f.image_size[1];
        let human = &mut f.humans[0];
        human.bbox.h = 0.5 * h_img;
        let inside = human.keypoints.clone();
        assert!(
            inside.chunks(2).all(|p| p[0] >= 0.0 && p[1] >= 0.0 && p[1] <= h_img),
            "the test frame's pose is in view"
        );
        assert_eq!(view_quality(&f), 1.0);
        f.humans[0].bbox.h = 0.125 * h_img;
        assert!((view_quality(&f) - 0.5).abs() < 1e-6, "half the full height");
        let human = &mut f.humans[0];
        human.bbox.h = 0.5 * h_img;
        let half = human.keypoints.len() / 4 * 2; // the first half of the points, moved out of the image
        human.keypoints[..half].chunks_mut(2).for_each(|p| p[0] = -10.0);
        let share = (human.keypoints.len() / 2 - half / 2) as f32 / (human.keypoints.len() / 2) as f32;
        assert!((view_quality(&f) - share).abs() < 1e-6, "{} vs {share}", view_quality(&f));
        f.humans.clear();
        assert_eq!(view_quality(&f), TRACK_ONLY_QUALITY);
    }

    #[test]
    fn huge_logits_stay_finite_and_ties_pick_the_lowest_class() {
        let v = vote(&[[1e30, 1e30, -1e30, 0.0]], 1.0);
        assert_eq!(v[0].class, Station::Storage);
        assert!((v[0].confidence - 0.5).abs() < 1e-6);
    }
}

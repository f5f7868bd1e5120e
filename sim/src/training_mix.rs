//! The conditions a training episode runs under, drawn per episode: where the fleet's
//! cameras point, and how long the fleet has worked on the floor before the episode
//! starts (its station maps warm from that work).
//!
//! Why: a fleet at work meets both camera policies and both cold and warm maps (a
//! daemon keeps its map for as long as it runs), and a model trained only on fixed
//! cameras and empty maps meets the others as a shift of its input distribution —
//! more ticks with the worker in view, stations on the map from the first tick. The
//! draws depend on the episode's seed alone, so an export is reproducible and the
//! conditions of its episodes are written into its `dataset.json`.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use spwi_world::layout::CameraPolicy;

/// What share of the episodes run under which conditions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrainingMix {
    /// Share of the episodes whose cameras track the worker (the others keep the
    /// floor's own policy).
    pub track_share: f64,
    /// Share of the episodes whose fleet first works on the floor (unscored, another
    /// worker) for a time drawn uniformly from (0, `warm_up_max_ticks`].
    pub warm_share: f64,
    pub warm_up_max_ticks: u32,
}

/// The conditions of one episode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EpisodeConditions {
    pub camera: CameraPolicy,
    /// Ticks the fleet worked on the floor before the episode; 0: maps start empty.
    pub warm_up_ticks: u32,
}

impl TrainingMix {
    /// Every episode as its floor says, maps empty: the exports before the mix.
    pub const NONE: TrainingMix = TrainingMix { track_share: 0.0, warm_share: 0.0, warm_up_max_ticks: 0 };

    /// Refuses shares outside 0..=1 and a warm share without a warm-up time.
    pub fn new(track_share: f64, warm_share: f64, warm_up_max_ticks: u32) -> anyhow::Result<Self> {
        for (flag, share) in [("--track-share", track_share), ("--warm-share", warm_share)] {
            if !(0.0..=1.0).contains(&share) {
                anyhow::bail!("{flag} {share}: a share of the episodes, within 0..=1");
            }
        }
        if warm_share > 0.0 && warm_up_max_ticks == 0 {
            anyhow::bail!("--warm-share {warm_share} needs --warm-up-max (seconds) above 0");
        }
        Ok(TrainingMix { track_share, warm_share, warm_up_max_ticks })
    }

    /// The conditions of the episode of `episode_seed` on a floor whose own camera
    /// policy is `floor_policy`.
    pub fn draw(&self, episode_seed: u64, floor_policy: CameraPolicy) -> EpisodeConditions {
        let mut rng = ChaCha8Rng::seed_from_u64(episode_seed ^ 0x434f_4e44_4954_494f); // "CONDITIO"
        let (track, warm, fraction) = (rng.gen::<f64>(), rng.gen::<f64>(), rng.gen::<f64>());
        let camera = if track < self.track_share { CameraPolicy::Track } else { floor_policy };
        let warm_up_ticks = if warm < self.warm_share {
            // (0, max]: at least one tick, so a warm episode is never a cold one.
            ((1.0 - fraction) * f64::from(self.warm_up_max_ticks)).ceil() as u32
        } else {
            0
        };
        EpisodeConditions { camera, warm_up_ticks }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_mix_keeps_every_floor_as_it_is() {
        for seed in 0..200 {
            for policy in [CameraPolicy::Fixed, CameraPolicy::Track] {
                assert_eq!(
                    TrainingMix::NONE.draw(seed, policy),
                    EpisodeConditions { camera: policy, warm_up_ticks: 0 }
                );
            }
        }
    }

    #[test]
    fn episodes_take_the_conditions_in_the_shares_asked_and_the_same_each_time() {
        let mix = TrainingMix::new(0.3, 0.6, 1200).unwrap();
        let drawn: Vec<_> = (0..4000).map(|s| mix.draw(s, CameraPolicy::Fixed)).collect();
        assert_eq!(drawn, (0..4000).map(|s| mix.draw(s, CameraPolicy::Fixed)).collect::<Vec<_>>());
        let share = |f: &dyn Fn(&EpisodeConditions) -> bool| drawn.iter().filter(|c| f(c)).count() as f64 / 4000.0;
        let track = share(&|c| c.camera == CameraPolicy::Track);
        let warm = share(&|c| c.warm_up_ticks > 0);
        assert!((track - 0.3).abs() < 0.03 && (warm - 0.6).abs() < 0.03, "track {track}, warm {warm}");
        // Camera and warm-up are drawn independently of each other.
        let both = share(&|c| c.camera == CameraPolicy::Track && c.warm_up_ticks > 0);
        assert!((both - 0.18).abs() < 0.03, "both {both}");
        // Warm-ups spread over (0, max].
        let ticks: Vec<u32> = drawn.iter().map(|c| c.warm_up_ticks).filter(|&t| t > 0).collect();
        assert!(ticks.iter().all(|&t| (1..=1200).contains(&t)));
        let short = ticks.iter().filter(|&&t| t <= 600).count() as f64 / ticks.len() as f64;
        assert!((short - 0.5).abs() < 0.05, "{short} of the warm-ups within the first half");
    }

    #[test]
    fn shares_outside_zero_to_one_and_a_warm_share_without_time_are_refused() {
        assert!(TrainingMix::new(1.5, 0.0, 0).unwrap_err().to_string().contains("--track-share 1.5"));
        assert!(TrainingMix::new(0.0, -0.1, 600).unwrap_err().to_string().contains("--warm-share -0.1"));
        assert!(TrainingMix::new(0.0, 0.5, 0).unwrap_err().to_string().contains("--warm-up-max"));
        assert!(TrainingMix::new(f64::NAN, 0.0, 0).is_err());
    }
}

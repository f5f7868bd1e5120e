//! The world seed of each episode of a run: the dataset export and the evaluation draw
//! their episodes the same way, so the evaluation can refuse any episode a model set
//! was trained on.

/// The seed of episode `e` of a dataset seeded `seed` (disjoint across seeds).
pub fn episode_seed(seed: u64, e: u32) -> u64 {
    seed.wrapping_mul(1_000_003).wrapping_add(e as u64)
}

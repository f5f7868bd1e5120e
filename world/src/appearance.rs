//! Synthetic 512-d appearance features, standing in for the paper's ResNet50 output.
//!
//! Each class has a fixed prototype (the same in every world: it plays the part of a
//! fixed, pretrained backbone), and a view basis that makes the feature drift with the
//! angle it is seen from. Observation noise grows with distance. The worker's feature
//! carries a noisy trace of its body orientation relative to the camera — the cue a
//! real backbone picks up from posture. The global scene feature mixes the prototypes
//! of what is in view, and nothing else: no feature carries where on the floor the
//! robot or the object stands (a probe test below checks it), so a model cannot learn
//! one floor's places instead of the worker's relations to objects.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use spwi_proto::{ObjectClass, FEATURE_DIM};

/// Seed of the class prototypes: part of the simulated world's definition, not of a run.
const APPEARANCE_SEED: u64 = 0x5eed_f00d;

/// A standard normal sample (Box–Muller).
pub fn gauss(rng: &mut ChaCha8Rng) -> f32 {
    let u1: f32 = rng.gen_range(f32::EPSILON..1.0);
    let u2: f32 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f32::consts::PI * u2).cos()
}

fn random_vector(rng: &mut ChaCha8Rng) -> Vec<f32> {
    (0..FEATURE_DIM).map(|_| gauss(rng)).collect()
}

pub struct Appearance {
    prototypes: Vec<Vec<f32>>, // per ObjectClass::ALL index
    view: Vec<[Vec<f32>; 2]>,
    human: Vec<f32>,
    orientation: [Vec<f32>; 2],
    /// What every view shows besides objects (floor, walls, light): the same everywhere.
    background: Vec<f32>,
}

impl Default for Appearance {
    fn default() -> Self {
        Self::new()
    }
}

impl Appearance {
    pub fn new() -> Appearance {
        let mut rng = ChaCha8Rng::seed_from_u64(APPEARANCE_SEED);
        let n = ObjectClass::ALL.len();
        Appearance {
            prototypes: (0..n).map(|_| random_vector(&mut rng)).collect(),
            view: (0..n).map(|_| [random_vector(&mut rng), random_vector(&mut rng)]).collect(),
            human: random_vector(&mut rng),
            orientation: [random_vector(&mut rng), random_vector(&mut rng)],
            background: random_vector(&mut rng),
        }
    }

    fn index(class: ObjectClass) -> usize {
        ObjectClass::ALL.iter().position(|&c| c == class).expect("every class is listed")
    }

    /// An object's feature seen from `view_angle` (radians: the camera ray's direction
    /// against the object's own facing) at relative distance
    /// `d` ∈ [0, 1] (distance / camera range); `extra_noise` for false positives.
    pub fn object(
        &self,
        class: ObjectClass,
        view_angle: f32,
        d: f32,
        extra_noise: f32,
        rng: &mut ChaCha8Rng,
    ) -> Vec<f32> {
        let i = Self::index(class);
        let (c, s) = (view_angle.cos(), view_angle.sin());
        let sigma = 0.35 + 0.6 * d + extra_noise;
        (0..FEATURE_DIM)
            .map(|k| {
                self.prototypes[i][k] + 0.3 * (c * self.view[i][0][k] + s * self.view[i][1][k]) + sigma * gauss(rng)
            })
            .collect()
    }

    /// The worker's feature; `orientation` is its body heading relative to the line of
    /// sight (0: walking away from the camera, π: towards it).
    pub fn human(&self, orientation: f32, d: f32, rng: &mut ChaCha8Rng) -> Vec<f32> {
        let (c, s) = (orientation.cos(), orientation.sin());
        let sigma = 0.4 + 0.6 * d;
        (0..FEATURE_DIM)
            .map(|k| {
                self.human[k] + 0.5 * (c * self.orientation[0][k] + s * self.orientation[1][k]) + sigma * gauss(rng)
            })
            .collect()
    }

    /// The global feature of a view: the classes in it, over a background that is the
    /// same on every floor.
    pub fn scene(&self, visible: &[ObjectClass], rng: &mut ChaCha8Rng) -> Vec<f32> {
        let n = visible.len().max(1) as f32;
        (0..FEATURE_DIM)
            .map(|k| {
                let content: f32 = visible.iter().map(|&c| self.prototypes[Self::index(c)][k]).sum::<f32>() / n;
                0.7 * content + 0.3 * self.background[k] + 0.2 * gauss(rng)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cos(a: &[f32], b: &[f32]) -> f32 {
        let dot: f32 = a.iter().zip(b).map(|(x, y)| x * y).sum();
        let n = |v: &[f32]| v.iter().map(|x| x * x).sum::<f32>().sqrt();
        dot / (n(a) * n(b))
    }

    #[test]
    fn same_class_features_are_closer_than_other_classes_and_fade_with_distance() {
        let a = Appearance::new();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let crate1 = a.object(ObjectClass::Crate, 0.0, 0.1, 0.0, &mut rng);
        let crate2 = a.object(ObjectClass::Crate, 0.5, 0.1, 0.0, &mut rng);
        let desk = a.object(ObjectClass::Desk, 0.0, 0.1, 0.0, &mut rng);
        let far_crate = a.object(ObjectClass::Crate, 0.0, 1.0, 0.0, &mut rng);
        assert!(cos(&crate1, &crate2) > 0.5);
        assert!(cos(&crate1, &desk).abs() < 0.2);
        assert!(cos(&crate1, &far_crate) < cos(&crate1, &crate2));
    }
}

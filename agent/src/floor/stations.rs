//! The map of the stations, built from back-projected detections of the objects that
//! mark them — never from a layout file. The robots share their landmarks each tick,
//! so every robot's team map holds what any robot saw.
//!
//! Landmarks of one station class merge into clusters (running, inverse-variance
//! weighted means) when they fall near each other; a cluster counts once it has been
//! seen [`MIN_HITS`] times, which keeps false positives and one-off misplacements off
//! the map. A station's position is the weighted centre of its counted clusters
//! around the best supported one (its objects stand around its work spot).

use spwi_proto::{Landmark, NUM_CLASSES};

/// Landmarks nearer than this (m, plus twice their own sigma) to a cluster join it.
const MERGE_M: f32 = 1.0;
/// Sightings before a cluster counts.
pub const MIN_HITS: u32 = 3;
/// Counted clusters within this of the best one make up the station (m).
const STATION_RADIUS_M: f32 = 4.0;
/// Clusters kept; the least seen goes first beyond.
const MAX_CLUSTERS: usize = 256;

#[derive(Debug, Clone, PartialEq)]
struct Cluster {
    station: u8,
    sum: [f64; 2],
    weight: f64,
    hits: u32,
}

impl Cluster {
    fn mean(&self) -> [f32; 2] {
        [(self.sum[0] / self.weight) as f32, (self.sum[1] / self.weight) as f32]
    }
}

#[derive(Debug, Clone, Default, PartialEq)]
pub struct StationMap {
    clusters: Vec<Cluster>,
}

fn dist(a: [f32; 2], b: [f32; 2]) -> f32 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

impl StationMap {
    pub fn add(&mut self, l: &Landmark) {
        let w = 1.0 / (l.sigma as f64).powi(2);
        let near = self
            .clusters
            .iter_mut()
            .filter(|c| c.station == l.station)
            .map(|c| (dist(c.mean(), l.position), c))
            .filter(|(d, _)| *d <= MERGE_M + 2.0 * l.sigma)
            .min_by(|a, b| a.0.total_cmp(&b.0));
        match near {
            Some((_, c)) => {
                c.sum[0] += w * l.position[0] as f64;
                c.sum[1] += w * l.position[1] as f64;
                c.weight += w;
                c.hits += 1;
            }
            None => {
                if self.clusters.len() >= MAX_CLUSTERS {
                    let least = (0..self.clusters.len()).min_by_key(|&i| self.clusters[i].hits).expect("full");
                    self.clusters.swap_remove(least);
                }
                self.clusters.push(Cluster {
                    station: l.station,
                    sum: [w * l.position[0] as f64, w * l.position[1] as f64],
                    weight: w,
                    hits: 1,
                });
            }
        }
    }

    /// Where each station stands, for the stations seen often enough.
    pub fn stations(&self) -> [Option<[f32; 2]>; NUM_CLASSES] {
        std::array::from_fn(|s| self.station(s as u8))
    }

    pub fn station(&self, station: u8) -> Option<[f32; 2]> {
        let counted = || self.clusters.iter().filter(move |c| c.station == station && c.hits >= MIN_HITS);
        let best = counted().max_by(|a, b| a.hits.cmp(&b.hits).then(b.weight.total_cmp(&a.weight)))?.mean();
        let (mut sum, mut weight) = ([0.0f64; 2], 0.0f64);
        for c in counted().filter(|c| dist(c.mean(), best) <= STATION_RADIUS_M) {
            sum[0] += c.sum[0];
            sum[1] += c.sum[1];
            weight += c.weight;
        }
        Some([(sum[0] / weight) as f32, (sum[1] / weight) as f32])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lm(station: u8, x: f32, y: f32) -> Landmark {
        Landmark { station, position: [x, y], sigma: 0.3 }
    }

    #[test]
    fn a_station_appears_after_a_few_sightings_and_converges() {
        let mut m = StationMap::default();
        // a new station comes into view at (8, 3): two objects, seen every tick with noise
        for t in 0..30 {
            let n = ((t * 37 % 11) as f32 - 5.0) * 0.06;
            m.add(&lm(2, 7.5 + n, 3.0 - n));
            m.add(&lm(2, 8.5 - n, 3.0 + n));
            if t + 1 < MIN_HITS as usize {
                assert_eq!(m.station(2), None, "not before {MIN_HITS} sightings");
            }
            if t >= 20 {
                // within two seconds (20 ticks) of coming into view
                let p = m.station(2).unwrap();
                assert!(dist(p, [8.0, 3.0]) < 0.2, "{p:?}");
            }
        }
        assert_eq!(m.stations()[0], None);
    }

    #[test]
    fn a_one_off_false_positive_stays_off_the_map_and_stations_stay_apart() {
        let mut m = StationMap::default();
        for _ in 0..10 {
            m.add(&lm(3, 10.0, 10.0));
            m.add(&lm(2, 12.5, 10.0)); // a close pair, 2.5 m apart
        }
        m.add(&lm(0, 1.0, 1.0));
        assert_eq!(m.station(0), None);
        assert!(dist(m.station(3).unwrap(), [10.0, 10.0]) < 1e-3);
        assert!(dist(m.station(2).unwrap(), [12.5, 10.0]) < 1e-3);
    }
}

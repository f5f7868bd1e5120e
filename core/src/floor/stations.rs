//! The map of the stations, built from back-projected detections of the objects that
//! mark them — never from a layout file. The robots share their landmarks each tick,
//! so every robot's team map holds what any robot saw.
//!
//! Landmarks of one station class merge into clusters (running, inverse-variance
//! weighted means) when they fall near each other; a cluster counts once it has been
//! seen [`MIN_HITS`] times within [`CONFIRM_TICKS`]. A real object in view is seen
//! nearly every tick; a detector's false positives land anywhere in the image, now and
//! then, and only a camera that never moves puts a few of them of one class in the same
//! spot — over minutes, never within a second or two. Counting sightings alone let
//! such a spot onto the map after a minute or two, metres from any station. A
//! station's position is the weighted centre of its counted clusters around the best
//! supported one (its objects stand around its work spot).
//!
//! The objects' centre can lie a metre or two from where the worker actually stands
//! to work, which matters most between two stations a few metres apart. So the map
//! also watches the worker: a worker whose track stays put for a second, next to
//! the objects of a mapped station, is at work there, and once it has been seen there
//! [`SPOT_SAMPLES`] ticks the station's position is where the worker stood (the mean
//! of those positions) instead of its objects' centre.
//!
//! A robot that joins a working fleet has seen nothing yet, and with cameras that
//! turn to the worker a station may stay out of view for minutes. So the members send
//! it where their maps put each station ([`MapMsg`](spwi_proto::MapMsg)), and its team
//! map [`borrow`](StationMap::borrow)s those positions for the stations it has not
//! mapped itself, until it has.
//!
//! A floor plan ([`super::plan`]) given to the daemon seeds the map: a planned station
//! stands where the plan puts it until the robots have watched the worker at work
//! there, and the plan's stations count as places the worker may be at work at, so
//! a plan that is a little off is corrected by where the worker actually stands.

use super::plan::{FloorPlan, PlannedStation};
use spwi_proto::{Landmark, Station, WorkerEstimate, NUM_CLASSES};
use std::collections::VecDeque;

/// Landmarks nearer than this (m, plus twice their own sigma) to a cluster join it.
const MERGE_M: f32 = 1.0;
/// Sightings before a cluster counts ...
pub const MIN_HITS: u32 = 3;
/// ... all within this many ticks (2 s at 10 Hz).
pub const CONFIRM_TICKS: u64 = 20;
/// Counted clusters within this of the best one make up the station (m).
const STATION_RADIUS_M: f32 = 4.0;
/// Clusters kept; beyond, the least seen of those not on the map goes first.
const MAX_CLUSTERS: usize = 256;
/// Ticks of standing still (1 s) before the worker counts as at work.
pub const DWELL_TICKS: usize = 10;
/// The worker stands still while its track's last [`DWELL_TICKS`] positions all lie
/// within this of their mean (m): the track's velocity is too noisy to tell.
const STILL_RADIUS_M: f32 = 0.35;
/// A worker at work is at the station whose nearest counted object cluster lies
/// within this (m): the worker stands at the objects it works on, and a large
/// object's landmark (the bottom of its box) can lie a metre past its centre.
const AT_OBJECTS_M: f32 = 3.0;
/// ... unless another station's objects are nearly as near (within this much more,
/// m): then where the worker stands says nothing sure about either.
const AMBIGUOUS_M: f32 = 1.0;
/// Track positions less certain than this (m, 1 σ) teach no work spot.
const SPOT_SIGMA_M: f32 = 0.5;
/// Worker positions at a station before they stand for it instead of its objects.
pub const SPOT_SAMPLES: u32 = 5;
/// How far a station's objects' centre may lie from where the worker stands to work
/// (m): a planned position at least this certain stands for the station before its
/// objects' centre does.
const OBJECTS_OFF_M: f32 = 1.0;
/// A learned work spot further than this (m, plus twice the plan's uncertainty) from
/// the plan's position contradicts the plan.
const SPOT_OFF_M: f32 = 0.5;

#[derive(Debug, Clone, PartialEq)]
struct Cluster {
    station: Station,
    sum: [f64; 2],
    weight: f64,
    hits: u32,
    /// The ticks of its last [`MIN_HITS`] sightings (by `hits` modulo their number).
    last_seen: [u64; MIN_HITS as usize],
    /// Seen [`MIN_HITS`] times within [`CONFIRM_TICKS`], once: it is on the map.
    counts: bool,
}

impl Cluster {
    fn new(station: Station) -> Self {
        Cluster { station, sum: [0.0; 2], weight: 0.0, hits: 0, last_seen: [0; MIN_HITS as usize], counts: false }
    }

    fn mean(&self) -> [f32; 2] {
        [(self.sum[0] / self.weight) as f32, (self.sum[1] / self.weight) as f32]
    }

    fn see(&mut self, l: &Landmark, tick: u64) {
        let w = 1.0 / (l.sigma as f64).powi(2);
        self.sum[0] += w * l.position[0] as f64;
        self.sum[1] += w * l.position[1] as f64;
        self.weight += w;
        self.last_seen[self.hits as usize % self.last_seen.len()] = tick;
        self.hits += 1;
        let (first, last) = self.last_seen.iter().fold((u64::MAX, 0), |(lo, hi), &t| (lo.min(t), hi.max(t)));
        self.counts |= self.hits >= MIN_HITS && last - first <= CONFIRM_TICKS;
    }
}

/// Where the worker was seen standing at work at one station (or where peers put
/// it): a running mean.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct WorkSpot {
    sum: [f64; 2],
    samples: u32,
}

impl WorkSpot {
    fn add(&mut self, p: [f32; 2]) {
        self.sum[0] += f64::from(p[0]);
        self.sum[1] += f64::from(p[1]);
        self.samples += 1;
    }

    /// The mean, once there are at least `min` samples.
    fn mean(&self, min: u32) -> Option<[f32; 2]> {
        let n = f64::from(self.samples);
        (self.samples >= min.max(1)).then(|| [(self.sum[0] / n) as f32, (self.sum[1] / n) as f32])
    }
}

#[derive(Debug, Clone, Default, PartialEq)]
pub struct StationMap {
    clusters: Vec<Cluster>,
    spots: [WorkSpot; NUM_CLASSES],
    /// Where peers' maps put each station: the mean of what they sent.
    borrowed: [WorkSpot; NUM_CLASSES],
    /// Whether the worker, while tracked well, stands still.
    dwell: Dwell,
    /// Where the floor plan puts each station, if one was given.
    planned: [Option<PlannedStation>; NUM_CLASSES],
}

/// The worker's last [`DWELL_TICKS`] positions: whether it stands still, as it does at
/// work. The track's velocity is too noisy to tell; its positions are not.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Dwell {
    recent: VecDeque<[f32; 2]>,
}

impl Dwell {
    /// Forgets the positions held (the worker was lost).
    pub fn clear(&mut self) {
        self.recent.clear();
    }

    /// Takes the worker's position this tick; returns where it stood still over the last
    /// [`DWELL_TICKS`] (their mean, all within [`STILL_RADIUS_M`] of it), if it did.
    pub fn observe(&mut self, position: [f32; 2]) -> Option<[f32; 2]> {
        if self.recent.len() == DWELL_TICKS {
            self.recent.pop_front();
        }
        self.recent.push_back(position);
        if self.recent.len() < DWELL_TICKS {
            return None;
        }
        let n = self.recent.len() as f32;
        let mean = self.recent.iter().fold([0.0, 0.0], |m, p| [m[0] + p[0] / n, m[1] + p[1] / n]);
        self.recent.iter().all(|&p| dist(p, mean) <= STILL_RADIUS_M).then_some(mean)
    }
}

/// The station a worker standing at `at` works at: the one of `places` (where each
/// station's objects or work spot lie, several per station allowed) nearest it within
/// [`AT_OBJECTS_M`], unless another station's lies nearly as near ([`AMBIGUOUS_M`]).
pub fn at_one_station(at: [f32; 2], places: impl Iterator<Item = ([f32; 2], Station)> + Clone) -> Option<Station> {
    let near = || places.clone().map(|(p, station)| (dist(p, at), station));
    let (d, station) = near().min_by(|a, b| a.0.total_cmp(&b.0)).filter(|(d, _)| *d <= AT_OBJECTS_M)?;
    (!near().any(|(e, other)| other != station && e <= d + AMBIGUOUS_M)).then_some(station)
}

fn dist(a: [f32; 2], b: [f32; 2]) -> f32 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

impl StationMap {
    /// A landmark seen at `tick` (the tick of the frame it came from).
    pub fn add(&mut self, l: &Landmark, tick: u64) {
        let near = self
            .clusters
            .iter_mut()
            .filter(|c| c.station == l.station)
            .map(|c| (dist(c.mean(), l.position), c))
            .filter(|(d, _)| *d <= MERGE_M + 2.0 * l.sigma)
            .min_by(|a, b| a.0.total_cmp(&b.0));
        match near {
            Some((_, c)) => c.see(l, tick),
            None => {
                if self.clusters.len() >= MAX_CLUSTERS {
                    let least = (0..self.clusters.len())
                        .min_by_key(|&i| (self.clusters[i].counts, self.clusters[i].hits))
                        .expect("full");
                    self.clusters.swap_remove(least);
                }
                let mut c = Cluster::new(l.station);
                c.see(l, tick);
                self.clusters.push(c);
            }
        }
    }

    /// The worker's track this tick (`None`: nobody tracks it). A worker staying put
    /// for a second next to a mapped station's objects teaches where that station's
    /// work spot is.
    pub fn observe_worker(&mut self, worker: Option<&WorkerEstimate>) {
        let Some(w) = worker.filter(|w| w.covariance[0].max(0.0).sqrt() <= SPOT_SIGMA_M) else {
            self.dwell.clear();
            return;
        };
        let Some(still) = self.dwell.observe(w.position) else { return };
        let counted = self.clusters.iter().filter(|c| c.counts).map(|c| (c.mean(), c.station));
        let planned = Station::ALL.into_iter().filter_map(|k| Some((self.planned[k.index()]?.position, k)));
        if let Some(station) = at_one_station(still, counted.chain(planned)) {
            self.spots[station.index()].add(w.position);
        }
    }

    /// Where each station stands, for the stations seen often enough or borrowed.
    pub fn stations(&self) -> [Option<[f32; 2]>; NUM_CLASSES] {
        Station::ALL.map(|s| self.station(s))
    }

    /// Where the worker stands to work at `station`, if it was seen there long enough;
    /// else where the floor plan puts it, if the plan is surer than the objects; else
    /// the centre of the station's objects, if they are on the map; else where the plan
    /// puts it; else where peers' maps put it, if they sent one.
    pub fn station(&self, station: Station) -> Option<[f32; 2]> {
        let k = station.index();
        let planned = self.planned[k];
        let sure = planned.filter(|p| p.uncertainty_m <= OBJECTS_OFF_M);
        (self.spots[k].mean(SPOT_SAMPLES))
            .or(sure.map(|p| p.position))
            .or_else(|| self.objects_centre(station))
            .or(planned.map(|p| p.position))
            .or_else(|| self.borrowed[k].mean(1))
    }

    /// Where this map places `station` from its own sightings: the worker's work spot
    /// if seen long enough (at its objects, or at the plan's place), else its objects'
    /// centre.
    fn placed(&self, station: Station) -> Option<[f32; 2]> {
        self.spots[station.index()].mean(SPOT_SAMPLES).or_else(|| self.objects_centre(station))
    }

    /// Seeds the map with a floor plan.
    pub fn plan(&mut self, plan: &FloorPlan) {
        self.planned = plan.stations;
    }

    /// The planned stations the robot's own sightings put elsewhere: a work spot
    /// further than [`SPOT_OFF_M`], or objects' centre further than the reach of a
    /// worker at work ([`AT_OBJECTS_M`]), from the plan's position, beyond twice its
    /// uncertainty.
    pub fn contradicts(&self) -> Vec<Station> {
        Station::ALL
            .into_iter()
            .filter(|&k| {
                let Some(p) = self.planned[k.index()] else { return false };
                let slack = 2.0 * p.uncertainty_m;
                match (self.spots[k.index()].mean(SPOT_SAMPLES), self.objects_centre(k)) {
                    (Some(spot), _) => dist(spot, p.position) > SPOT_OFF_M + slack,
                    (None, Some(objects)) => dist(objects, p.position) > AT_OBJECTS_M + slack,
                    (None, None) => false,
                }
            })
            .collect()
    }

    /// A peer's map: its positions stand for the stations this map has not placed
    /// itself (the mean of every peer's that sent one), until it has.
    pub fn borrow(&mut self, stations: &[Option<[f32; 2]>; NUM_CLASSES]) {
        for (k, p) in Station::ALL.into_iter().zip(stations) {
            if let (Some(p), None) = (p, self.objects_centre(k)) {
                self.borrowed[k.index()].add(*p);
            }
        }
    }

    /// What this map places itself, not what it borrowed: what it sends a robot that
    /// joins (a borrowed position passed on would outlive the map it came from).
    pub fn own_stations(&self) -> [Option<[f32; 2]>; NUM_CLASSES] {
        Station::ALL.map(|s| self.placed(s))
    }

    fn objects_centre(&self, station: Station) -> Option<[f32; 2]> {
        let counted = || self.clusters.iter().filter(move |c| c.station == station && c.counts);
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
    use spwi_proto::Station::*;

    fn lm(station: Station, x: f32, y: f32) -> Landmark {
        Landmark { station, position: [x, y], sigma: 0.3 }
    }

    fn worker(x: f32, y: f32, speed: f32) -> WorkerEstimate {
        WorkerEstimate { position: [x, y], velocity: [speed, 0.0], covariance: [0.04, 0.0, 0.1] }
    }

    /// A close pair: assembly's bench at (10, 11), manufacturing's machine at (12.5, 11.5).
    fn close_pair() -> StationMap {
        let mut m = StationMap::default();
        for t in 0..u64::from(MIN_HITS) {
            m.add(&lm(Assembly, 10.0, 11.0), t);
            m.add(&lm(Manufacturing, 12.5, 11.5), t);
        }
        m
    }

    #[test]
    fn a_worker_standing_at_a_station_marks_its_work_spot() {
        let mut m = close_pair();
        assert!(dist(m.station(Assembly).unwrap(), [10.0, 11.0]) < 1e-3, "before: the objects' centre");
        // walks in, then works a second and a half in front of the bench, at (10, 10)
        for t in 0..20 {
            m.observe_worker(Some(&worker(8.0 + 0.1 * t as f32, 10.0, 1.0)));
        }
        for t in 0..15 {
            let jitter = if t % 2 == 0 { 0.05 } else { -0.05 };
            m.observe_worker(Some(&worker(10.0 + jitter, 10.0, 0.02)));
        }
        assert!(dist(m.station(Assembly).unwrap(), [10.0, 10.0]) < 0.05, "{:?}", m.station(Assembly));
        assert!(
            dist(m.station(Manufacturing).unwrap(), [12.5, 11.5]) < 1e-3,
            "the other station of the pair keeps its objects' centre"
        );
    }

    #[test]
    fn a_worker_standing_between_two_stations_marks_neither() {
        let mut m = close_pair();
        for _ in 0..30 {
            m.observe_worker(Some(&worker(11.25, 10.5, 0.0))); // as near the bench as the machine
        }
        assert_eq!(m.stations(), close_pair().stations(), "no work spot learned");
    }

    #[test]
    fn a_worker_passing_by_or_pausing_away_from_every_station_marks_nothing() {
        let mut m = close_pair();
        for t in 0..40 {
            m.observe_worker(Some(&worker(8.0 + 0.1 * t as f32, 10.0, 1.0))); // walking past the bench
        }
        for _ in 0..30 {
            m.observe_worker(Some(&worker(4.0, 4.0, 0.0))); // standing, nowhere near
        }
        for _ in 0..30 {
            m.observe_worker(None); // nobody tracks it
        }
        for t in 0..30 {
            // standing at the bench, but every other tick untracked: never a second in a row
            m.observe_worker((t % 2 == 0).then(|| worker(10.0, 10.0, 0.0)).as_ref());
        }
        assert_eq!(m.stations(), close_pair().stations(), "no work spot learned");
    }

    #[test]
    fn a_station_appears_after_a_few_sightings_and_converges() {
        let mut m = StationMap::default();
        // a new station comes into view at (8, 3): two objects, seen every tick with noise
        for t in 0..30 {
            let n = ((t * 37 % 11) as f32 - 5.0) * 0.06;
            m.add(&lm(Assembly, 7.5 + n, 3.0 - n), t as u64);
            m.add(&lm(Assembly, 8.5 - n, 3.0 + n), t as u64);
            if t + 1 < MIN_HITS as usize {
                assert_eq!(m.station(Assembly), None, "not before {MIN_HITS} sightings");
            }
            if t >= 20 {
                // within two seconds (20 ticks) of coming into view
                let p = m.station(Assembly).unwrap();
                assert!(dist(p, [8.0, 3.0]) < 0.2, "{p:?}");
            }
        }
        assert_eq!(m.stations()[0], None);
    }

    #[test]
    fn a_peers_map_stands_for_the_stations_not_seen_until_they_are() {
        let mut m = close_pair();
        let peer = [Some([3.0, 3.0]), Some([3.0, 11.0]), Some([0.0, 0.0]), None];
        let other = [Some([3.2, 3.4]), None, None, None];
        m.borrow(&peer);
        m.borrow(&other);
        assert!(dist(m.station(Storage).unwrap(), [3.1, 3.2]) < 1e-3, "the mean of what peers sent");
        assert_eq!(m.station(Workstation), Some([3.0, 11.0]));
        assert!(dist(m.station(Assembly).unwrap(), [10.0, 11.0]) < 1e-3, "what it mapped itself wins");
        assert_eq!(m.own_stations()[0], None, "a borrowed station is not passed on");
        assert_eq!(m.own_stations()[2], m.station(Assembly));
        for t in 0..u64::from(MIN_HITS) {
            m.add(&lm(Storage, 1.5, 2.0), t);
        }
        assert!(dist(m.station(Storage).unwrap(), [1.5, 2.0]) < 1e-3, "its own sightings take over");
    }

    fn planned(stations: &[(Station, [f32; 2], f32)]) -> FloorPlan {
        let mut plan = FloorPlan::default();
        for &(k, position, uncertainty_m) in stations {
            plan.stations[k.index()] = Some(PlannedStation { position, uncertainty_m });
        }
        plan
    }

    /// The worker stands still at `at` for a second and a half.
    fn works_at(m: &mut StationMap, at: [f32; 2]) {
        for t in 0..15 {
            let jitter = if t % 2 == 0 { 0.05 } else { -0.05 };
            m.observe_worker(Some(&worker(at[0] + jitter, at[1], 0.02)));
        }
    }

    #[test]
    fn a_planned_station_stands_where_the_plan_puts_it_until_the_worker_is_seen_there() {
        let mut m = close_pair();
        m.plan(&planned(&[
            (Storage, [3.0, 3.0], 1.0),
            (Assembly, [10.0, 10.0], 0.5),
            (Manufacturing, [12.5, 11.0], 2.0),
        ]));
        assert_eq!(m.station(Storage), Some([3.0, 3.0]), "never seen: the plan's place");
        assert_eq!(m.station(Assembly), Some([10.0, 10.0]), "a plan surer than the objects' centre wins");
        assert!(dist(m.station(Manufacturing).unwrap(), [12.5, 11.5]) < 1e-3, "an unsure plan yields to the objects");
        assert_eq!(m.own_stations()[0], None, "a planned station is not passed on");
        m.borrow(&[Some([8.0, 8.0]), None, None, None]);
        assert_eq!(m.station(Storage), Some([3.0, 3.0]), "the plan before a peer's word");
        // The plan put storage 0.8 m off where the worker works at it: the map learns.
        works_at(&mut m, [3.8, 3.0]);
        assert!(dist(m.station(Storage).unwrap(), [3.8, 3.0]) < 0.05, "{:?}", m.station(Storage));
        assert!(dist(m.own_stations()[0].unwrap(), [3.8, 3.0]) < 0.05, "a spot seen is passed on");
        assert!(m.contradicts().is_empty(), "{:?}", m.contradicts());
    }

    #[test]
    fn a_plan_the_cameras_contradict_is_named() {
        let mut m = close_pair(); // assembly's objects at (10, 11), manufacturing's at (12.5, 11.5)
        m.plan(&planned(&[
            (Assembly, [10.0, 4.0], 0.5),
            (Manufacturing, [13.0, 12.0], 0.5),
            (Storage, [1.0, 1.0], 0.5),
        ]));
        assert_eq!(m.contradicts(), vec![Assembly], "objects 7 m from the plan; the others agree or are unseen");
        let mut m = close_pair();
        m.plan(&planned(&[(Manufacturing, [12.5, 11.0], 0.3)]));
        works_at(&mut m, [12.5, 12.6]); // works 1.6 m from the plan, 1.1 m from the machine
        assert_eq!(m.contradicts(), vec![Manufacturing], "the work spot seen is not the plan's");
    }

    #[test]
    fn a_one_off_false_positive_stays_off_the_map_and_stations_stay_apart() {
        let mut m = StationMap::default();
        for t in 0..10 {
            m.add(&lm(Manufacturing, 10.0, 10.0), t);
            m.add(&lm(Assembly, 12.5, 10.0), t); // a close pair, 2.5 m apart
        }
        m.add(&lm(Storage, 1.0, 1.0), 10);
        assert_eq!(m.station(Storage), None);
        assert!(dist(m.station(Manufacturing).unwrap(), [10.0, 10.0]) < 1e-3);
        assert!(dist(m.station(Assembly).unwrap(), [12.5, 10.0]) < 1e-3);
    }

    #[test]
    fn false_positives_a_fixed_camera_sees_now_and_then_in_one_spot_never_make_a_station() {
        let mut m = StationMap::default();
        // over five minutes, one false crate every eight seconds in front of the camera
        for k in 0..40u64 {
            m.add(&lm(Storage, 2.0 + 0.1 * (k % 3) as f32, 1.0), 80 * k);
        }
        assert_eq!(m.station(Storage), None, "40 sightings, never {MIN_HITS} within {CONFIRM_TICKS} ticks");
        // the real storage area, in view for a moment: three frames in a row
        for t in 3200..3203 {
            m.add(&lm(Storage, 12.0, 9.0), t);
        }
        assert!(dist(m.station(Storage).unwrap(), [12.0, 9.0]) < 1e-3, "{:?}", m.station(Storage));
        // once on the map, a station stays there however seldom it is seen again
        m.add(&lm(Storage, 12.0, 9.0), 9000);
        assert!(m.station(Storage).is_some());
    }
}

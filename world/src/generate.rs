//! Random factory floors, and named families of them.
//!
//! A model trained on one floor learns *where* things are on it; one trained on many
//! floors has to learn what the worker walks *towards*. [`layout`] makes a floor from a
//! seed: 14 × 10 m to 30 × 20 m, the four stations built from the paper's Table I
//! object groups (how many objects, where round the work spot, which way they face all
//! vary), the work spots at random places with a close pair (2–3.5 m apart) in about
//! half of the floors, 0–5 obstacles, and 8 robot slots whose spawn poses and patrol
//! legs are checked clear of obstacles, objects and work spots. Every floor it makes
//! passes [`Layout::validate`] (tested over 500 seeds).
//!
//! Families keep training and evaluation apart: `train:A..B` and `heldout:A..B` draw
//! from disjoint seed ranges, so no held-out floor can ever be a training floor.

use crate::camera::ROBOT_RADIUS;
use crate::geometry::*;
use crate::layout::{Camera, CameraPolicy, Floor, Layout, Object, Obstacle, RobotSlot, StationSite, WORKER_CLEARANCE};
use anyhow::{bail, Context, Result};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use spwi_proto::{ObjectClass, Station};
use std::f32::consts::PI;
use std::path::PathBuf;

/// Robot slots on every generated floor.
pub const ROBOT_SLOTS: usize = 8;
/// Held-out floors use seeds from here on; training floors stay below.
pub const HELDOUT_BASE: u64 = 1 << 40;

/// The floor of generator seed `seed` (always valid).
pub fn layout(seed: u64) -> Layout {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    loop {
        // An attempt that cannot place everything gives up; the stream goes on.
        if let Some(l) = attempt(&mut rng).filter(|l| l.validate().is_ok()) {
            return l;
        }
    }
}

/// An object template: class and nominal size (width, depth, height).
type Template = (ObjectClass, [f32; 3]);

const PALLET: Template = (ObjectClass::Pallet, [1.2, 1.0, 0.3]);
const CRATE: Template = (ObjectClass::Crate, [0.8, 0.8, 0.9]);
const BOX: Template = (ObjectClass::Box, [0.5, 0.5, 0.5]);
const DESK: Template = (ObjectClass::Desk, [1.6, 0.8, 0.75]);
const COMPUTER: Template = (ObjectClass::Computer, [0.5, 0.3, 1.2]);
const CHAIR: Template = (ObjectClass::Chair, [0.5, 0.5, 0.9]);
const DRAWER: Template = (ObjectClass::StorageDrawer, [0.6, 0.6, 1.1]);
const WORKBENCH: Template = (ObjectClass::Workbench, [2.0, 0.8, 0.9]);
const CNC: Template = (ObjectClass::CncMachine, [1.6, 1.2, 1.9]);
const TABLE: Template = (ObjectClass::Table, [0.8, 1.2, 0.8]);

/// The objects of station `id` (paper Table I): the main one first (in front of the
/// work spot), then the others round it. A computer, if any, stands on the desk.
fn station_objects(id: Station, rng: &mut ChaCha8Rng) -> Vec<Template> {
    let mut v = match id {
        Station::Storage => {
            let mut v = vec![*[PALLET, CRATE].choose(rng).expect("two")];
            for _ in 0..rng.gen_range(1..=4) {
                v.push(*[PALLET, CRATE, BOX, BOX].choose(rng).expect("four"));
            }
            v
        }
        Station::Workstation => {
            let mut v = vec![DESK];
            for (t, p) in [(COMPUTER, 0.8), (CHAIR, 0.8), (DRAWER, 0.7)] {
                if rng.gen_bool(p) {
                    v.push(t);
                }
            }
            v
        }
        Station::Assembly => {
            let mut v = vec![WORKBENCH];
            v.extend(std::iter::repeat_n(CHAIR, rng.gen_range(0..=2)));
            v
        }
        Station::Manufacturing => {
            let mut v = vec![CNC];
            if rng.gen_bool(0.85) {
                v.push(TABLE);
            }
            v
        }
    };
    for t in &mut v {
        for s in &mut t.1 {
            *s *= rng.gen_range(0.85..1.15);
        }
    }
    v
}

/// A footprint for `size` facing `yaw`: axis-aligned, so width and depth swap when the
/// object stands nearer north–south than east–west.
fn footprint(centre: P2, size: [f32; 3], yaw: f32) -> (Rect, [f32; 3]) {
    let size = if yaw.cos().abs() >= yaw.sin().abs() { [size[1], size[0], size[2]] } else { size };
    let (hw, hd) = (size[0] / 2.0, size[1] / 2.0);
    (Rect { min: [centre[0] - hw, centre[1] - hd], max: [centre[0] + hw, centre[1] + hd] }, size)
}

fn clearance(r: &Rect, p: P2) -> f32 {
    dist(r.closest(p), p)
}

fn attempt(rng: &mut ChaCha8Rng) -> Option<Layout> {
    let round = |v: f32| (v * 2.0).round() / 2.0;
    let w = round(rng.gen_range(14.0..=30.0));
    let h = round(rng.gen_range(10.0..=20.0f32.min(w)));
    let inside = |r: &Rect, margin: f32| {
        r.min[0] >= margin && r.min[1] >= margin && r.max[0] <= w - margin && r.max[1] <= h - margin
    };
    let random_point =
        |rng: &mut ChaCha8Rng, margin: f32| [rng.gen_range(margin..w - margin), rng.gen_range(margin..h - margin)];

    // Work spots: a random order of the stations; with a close pair, the second stands
    // 2-3.5 m from the first; every other pair stands at least 5 m apart.
    let mut order = Station::ALL;
    order.shuffle(rng);
    let close_pair = rng.gen_bool(0.5);
    let mut spots: Vec<(Station, P2)> = Vec::new();
    for (k, &id) in order.iter().enumerate() {
        let mut placed = None;
        for _ in 0..200 {
            let p = if k == 1 && close_pair {
                let (d, a) = (rng.gen_range(2.0..=3.5f32), rng.gen_range(-PI..PI));
                add(spots[0].1, [d * a.cos(), d * a.sin()])
            } else {
                random_point(rng, 2.5)
            };
            let on = p[0] >= 2.5 && p[0] <= w - 2.5 && p[1] >= 2.5 && p[1] <= h - 2.5;
            let apart = spots.iter().enumerate().all(|(j, (_, q))| {
                let d = dist(p, *q);
                if k == 1 && j == 0 && close_pair {
                    (2.0..=3.5).contains(&d)
                } else {
                    d >= 5.0
                }
            });
            if on && apart {
                placed = Some(p);
                break;
            }
        }
        spots.push((id, placed?));
    }

    // Objects round each work spot, facing it.
    let mut objects: Vec<(Station, Object)> = Vec::new();
    let mut stations = Vec::new();
    for &(id, spot) in &spots {
        let templates = station_objects(id, rng);
        let facing = rng.gen_range(-PI..PI); // the worker faces the main object from the spot
        let mut mine = Vec::new();
        let mut desk: Option<(P2, f32)> = None;
        for (i, &(class, size)) in templates.iter().enumerate() {
            let mut ok = None;
            for _ in 0..60 {
                let (centre, yaw) = if class == ObjectClass::Computer {
                    let (c, yaw) = desk?;
                    (c, yaw)
                } else if i == 0 {
                    let reach = size[0].max(size[1]) / 2.0 + 0.5 + rng.gen_range(0.0..0.3);
                    (add(spot, [reach * facing.cos(), reach * facing.sin()]), facing + PI)
                } else {
                    let side = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
                    let a = facing + side * rng.gen_range(0.7..2.2);
                    let reach = size[0].max(size[1]) / 2.0 + rng.gen_range(0.6..1.6);
                    let c = add(spot, [reach * a.cos(), reach * a.sin()]);
                    let to_spot = sub(spot, c);
                    (c, to_spot[1].atan2(to_spot[0]) + rng.gen_range(-0.4..0.4))
                };
                let (fp, size) = footprint(centre, size, yaw);
                let stacked = class == ObjectClass::Computer;
                let clear_of_spots = spots.iter().all(|(_, s)| clearance(&fp, *s) >= WORKER_CLEARANCE + 0.1);
                let clear_of_objects = objects.iter().all(|(_, o)| !o.footprint().inflate(0.1).overlaps(&fp))
                    || (stacked
                        && objects
                            .iter()
                            .any(|(_, o)| o.class == ObjectClass::Desk && o.footprint().contains_rect(&fp)));
                if inside(&fp, 0.3) && clear_of_spots && clear_of_objects {
                    ok = Some(Object { class, position: centre, size, yaw_deg: yaw.to_degrees() });
                    break;
                }
            }
            let Some(o) = ok else {
                if i == 0 {
                    return None; // no main object, no station
                }
                continue;
            };
            if class == ObjectClass::Desk {
                desk = Some((o.position, o.yaw_deg.to_radians()));
            }
            objects.push((id, o.clone()));
            mine.push(o);
        }
        stations.push(StationSite { id, name: id.name().to_owned(), work_spot: spot, objects: mine });
    }
    stations.sort_by_key(|s| s.id);

    // Obstacles: boxes 1.5 m clear of the walls and of each other (so the free floor
    // stays connected), of every object and of every work spot's surroundings.
    let mut obstacles: Vec<Obstacle> = Vec::new();
    for _ in 0..rng.gen_range(0..=5) {
        for _ in 0..50 {
            let size = [rng.gen_range(0.8..3.0f32), rng.gen_range(0.8..3.0f32)];
            let c = random_point(rng, 1.6 + size[0].max(size[1]) / 2.0);
            let r = Rect { min: sub(c, scale(size, 0.5)), max: add(c, scale(size, 0.5)) };
            let fits = inside(&r, 1.5)
                && obstacles.iter().all(|o| !o.rect().inflate(1.5).overlaps(&r))
                && objects.iter().all(|(_, o)| !o.footprint().inflate(0.8).overlaps(&r))
                && spots.iter().all(|(_, s)| clearance(&r, *s) >= 1.5);
            if fits {
                obstacles.push(Obstacle { min: r.min, max: r.max, height: 2.2 });
                break;
            }
        }
    }

    // Robot slots: spawn poses and patrol legs clear of obstacles, objects, work spots.
    let body = ROBOT_RADIUS + 0.15;
    let point_clear = |p: P2| {
        p[0] >= 0.7
            && p[0] <= w - 0.7
            && p[1] >= 0.7
            && p[1] <= h - 0.7
            && obstacles.iter().all(|o| clearance(&o.rect(), p) >= body + 0.3)
            && objects.iter().all(|(_, o)| clearance(&o.footprint(), p) >= body + 0.5)
            && spots.iter().all(|(_, s)| dist(*s, p) >= 1.5)
    };
    let leg_clear = |a: P2, b: P2| {
        obstacles.iter().all(|o| !o.rect().inflate(body).blocks(a, b))
            && objects.iter().all(|(_, o)| !o.footprint().inflate(body).blocks(a, b))
            && spots.iter().all(|(_, s)| segment_dist(a, b, *s) >= 1.0)
    };
    let centre = [w / 2.0, h / 2.0];
    let mut robots: Vec<RobotSlot> = Vec::new();
    for _ in 0..ROBOT_SLOTS {
        let mut placed = None;
        for _ in 0..300 {
            let spawn = random_point(rng, 0.7);
            if !point_clear(spawn) || robots.iter().any(|r| dist(r.spawn, spawn) < 2.0) {
                continue;
            }
            let mut patrol = vec![spawn];
            for _ in 0..rng.gen_range(2..=3) {
                for _ in 0..30 {
                    let last = *patrol.last().expect("spawn");
                    let (d, a) = (rng.gen_range(1.5..5.0f32), rng.gen_range(-PI..PI));
                    let p = add(last, [d * a.cos(), d * a.sin()]);
                    if point_clear(p) && leg_clear(last, p) {
                        patrol.push(p);
                        break;
                    }
                }
            }
            while patrol.len() > 1 && !leg_clear(*patrol.last().expect("spawn"), spawn) {
                patrol.pop(); // the loop must close clear too
            }
            if patrol.len() < 2 {
                continue;
            }
            let look = sub(centre, spawn);
            let heading = look[1].atan2(look[0]) + rng.gen_range(-0.6..0.6);
            placed = Some(RobotSlot { spawn, heading_deg: heading.to_degrees(), patrol });
            break;
        }
        robots.push(placed?);
    }
    Some(Layout {
        floor: Floor { size: [w, h] },
        camera: Camera { fov_deg: 90.0, range: 12.0, height: 1.0, image: [640, 480], policy: CameraPolicy::Fixed },
        stations,
        obstacles,
        robots,
    })
}

/// A family of generated floors, with seed ranges that never meet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    Train,
    Heldout,
}

impl Family {
    fn name(self) -> &'static str {
        match self {
            Family::Train => "train",
            Family::Heldout => "heldout",
        }
    }

    /// The generator seed of floor `k` of the family.
    pub fn seed(self, k: u64) -> u64 {
        match self {
            Family::Train => k,
            Family::Heldout => HELDOUT_BASE + k,
        }
    }
}

/// Where floors come from: `train:A..B`, `heldout:A..B`, or a layout file.
#[derive(Debug, Clone, PartialEq)]
pub enum LayoutSource {
    Generated { family: Family, start: u64, end: u64 },
    File(PathBuf),
}

impl std::str::FromStr for LayoutSource {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let family = match s.split_once(':') {
            Some(("train", r)) => Some((Family::Train, r)),
            Some(("heldout", r)) => Some((Family::Heldout, r)),
            _ => None,
        };
        let Some((family, range)) = family else { return Ok(LayoutSource::File(PathBuf::from(s))) };
        let bad = || format!("{s:?}: a family's floors are FAMILY:START..END, e.g. train:0..200");
        let (a, b) = range.split_once("..").ok_or_else(bad)?;
        let (start, end): (u64, u64) = (a.parse().map_err(|_| bad())?, b.parse().map_err(|_| bad())?);
        if start >= end {
            return Err(format!("{s:?}: the range {start}..{end} holds no floor"));
        }
        if end > HELDOUT_BASE {
            return Err(format!("{s:?}: floors are numbered below {HELDOUT_BASE}"));
        }
        Ok(LayoutSource::Generated { family, start, end })
    }
}

impl std::fmt::Display for LayoutSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LayoutSource::Generated { family, start, end } => write!(f, "{}:{start}..{end}", family.name()),
            LayoutSource::File(p) => write!(f, "{}", p.display()),
        }
    }
}

/// A floor and the name it is reported under (`train:17`, a file's path).
#[derive(Debug, Clone)]
pub struct NamedLayout {
    pub name: String,
    pub layout: Layout,
}

/// Every floor the sources name, in order; refuses two ranges of one family that
/// overlap (the same floor counted twice).
pub fn resolve(sources: &[LayoutSource]) -> Result<Vec<NamedLayout>> {
    for (i, a) in sources.iter().enumerate() {
        for b in &sources[i + 1..] {
            if let (
                LayoutSource::Generated { family: fa, start: sa, end: ea },
                LayoutSource::Generated { family: fb, start: sb, end: eb },
            ) = (a, b)
            {
                if fa == fb && sa < eb && sb < ea {
                    bail!("--layouts {a} and {b} overlap: each floor may be named once");
                }
            }
        }
    }
    let mut out = Vec::new();
    for s in sources {
        match s {
            LayoutSource::File(p) => out.push(NamedLayout {
                name: p.display().to_string(),
                layout: Layout::load(p).with_context(|| format!("--layouts {}", p.display()))?,
            }),
            LayoutSource::Generated { family, start, end } => {
                out.extend(
                    (*start..*end).map(|k| NamedLayout {
                        name: format!("{}:{k}", family.name()),
                        layout: layout(family.seed(k)),
                    }),
                );
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_generated_floor_is_valid_and_the_family_varies() {
        let (mut close, mut obstacles, mut sizes) = (0, 0, Vec::new());
        for seed in 0..500 {
            let l = layout(seed);
            l.validate().unwrap_or_else(|e| panic!("seed {seed}: {e:#}"));
            assert_eq!(l.robots.len(), ROBOT_SLOTS);
            let [w, h] = l.floor.size;
            assert!((14.0..=30.0).contains(&w) && (10.0..=20.0).contains(&h), "seed {seed}: {w} x {h}");
            for r in &l.robots {
                assert!(r.patrol.len() >= 2, "seed {seed}: a robot without a patrol");
            }
            close += usize::from(!l.close_pairs().is_empty());
            obstacles += l.obstacles.len();
            sizes.push(w * h);
        }
        assert!((175..=325).contains(&close), "{close} of 500 floors have a close pair");
        assert!(obstacles > 500, "{obstacles} obstacles over 500 floors");
        let (lo, hi) = sizes.iter().fold((f32::MAX, 0.0f32), |(a, b), &s| (a.min(s), b.max(s)));
        assert!(lo < 200.0 && hi > 450.0, "floor areas {lo}..{hi}");
    }

    #[test]
    fn patrols_keep_clear_of_obstacles_and_objects() {
        for seed in 0..100 {
            let l = layout(seed);
            for (i, r) in l.robots.iter().enumerate() {
                let mut legs: Vec<(P2, P2)> = r.patrol.windows(2).map(|w| (w[0], w[1])).collect();
                legs.push((*r.patrol.last().unwrap(), r.patrol[0]));
                for (a, b) in legs {
                    for o in &l.obstacles {
                        assert!(
                            !o.rect().inflate(ROBOT_RADIUS).blocks(a, b),
                            "seed {seed} robot {i}: leg through an obstacle"
                        );
                    }
                    for s in &l.stations {
                        for o in &s.objects {
                            assert!(
                                !o.footprint().inflate(ROBOT_RADIUS).blocks(a, b),
                                "seed {seed} robot {i}: leg through an object"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn the_same_seed_gives_the_same_floor() {
        assert_eq!(layout(7).to_toml(), layout(7).to_toml());
        assert_ne!(layout(7).to_toml(), layout(8).to_toml());
    }

    #[test]
    fn families_are_parsed_kept_apart_and_refused_when_empty_or_overlapping() {
        let train: LayoutSource = "train:0..3".parse().unwrap();
        let held: LayoutSource = "heldout:0..2".parse().unwrap();
        let floors = resolve(&[train.clone(), held]).unwrap();
        assert_eq!(
            floors.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(),
            ["train:0", "train:1", "train:2", "heldout:0", "heldout:1"]
        );
        assert_ne!(floors[0].layout.to_toml(), floors[3].layout.to_toml(), "heldout:0 is not train:0");
        assert!("train:5..5".parse::<LayoutSource>().unwrap_err().contains("holds no floor"));
        assert!("train:9..2".parse::<LayoutSource>().unwrap_err().contains("holds no floor"));
        assert!("train:x..2".parse::<LayoutSource>().unwrap_err().contains("FAMILY:START..END"));
        let e = resolve(&[train, "train:2..10".parse().unwrap()]).unwrap_err().to_string();
        assert!(e.contains("overlap"), "{e}");
        assert_eq!("some/file.toml".parse::<LayoutSource>().unwrap(), LayoutSource::File("some/file.toml".into()));
        let e = resolve(&["no/such/floor.toml".parse().unwrap()]).unwrap_err();
        assert!(format!("{e:#}").contains("no/such/floor.toml"), "{e:#}");
    }
}

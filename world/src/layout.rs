//! The factory floor, read from a TOML layout file (`world/layouts/factory.toml` is the
//! default and documents every field) or made by [`crate::generate`].
//! [`Layout::validate`] refuses a layout that could not work — a station off the floor,
//! a work spot inside an obstacle, objects that overlap, a robot spawning in a wall or
//! off the floor — with an error naming the field, so any layout that loads works
//! everywhere the default does.

use crate::geometry::{Rect, P2};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use spwi_proto::{ObjectClass, Station, NUM_CLASSES};
use std::path::Path;

/// The default layout, built into the binary.
pub const DEFAULT_LAYOUT: &str = include_str!("../layouts/factory.toml");

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Layout {
    pub floor: Floor,
    pub camera: Camera,
    pub stations: Vec<StationSite>,
    #[serde(default)]
    pub obstacles: Vec<Obstacle>,
    pub robots: Vec<RobotSlot>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Floor {
    pub size: P2,
}

/// Every robot's camera (pinhole).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    pub fov_deg: f32,
    /// Farthest detection distance, metres.
    pub range: f32,
    /// Mounting height, metres.
    pub height: f32,
    /// Image width and height, pixels.
    pub image: [u32; 2],
    /// Where the cameras point: `fixed` (their mounting heading) or `track`.
    #[serde(default)]
    pub policy: CameraPolicy,
}

/// Where a robot points its camera.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraPolicy {
    /// Along the robot's spawn heading (stationary) or over the floor (patrolling).
    #[default]
    Fixed,
    /// Towards where the fleet last saw the worker, panning at a limited rate; while
    /// the worker stands at a station only the nearest camera that shows it stays on
    /// it, and cameras with nothing to follow look round the floor (`pan.rs`).
    Track,
}

impl Camera {
    /// Focal length in pixels.
    pub fn focal(&self) -> f32 {
        self.image[0] as f32 / 2.0 / (self.fov_deg.to_radians() / 2.0).tan()
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
/// Where one station stands: its work spot and its objects.
pub struct StationSite {
    pub id: Station,
    pub name: String,
    /// Where the worker stands to work here.
    pub work_spot: P2,
    pub objects: Vec<Object>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Object {
    #[serde(with = "object_class")]
    pub class: ObjectClass,
    pub position: P2,
    /// Width (x), depth (y), height, metres.
    pub size: [f32; 3],
    /// Which way the object's front faces, degrees counter-clockwise from east: how it
    /// looks depends on the side it is seen from. The footprint stays axis-aligned.
    #[serde(default)]
    pub yaw_deg: f32,
}

impl Object {
    pub fn footprint(&self) -> Rect {
        let (hw, hd) = (self.size[0] / 2.0, self.size[1] / 2.0);
        Rect {
            min: [self.position[0] - hw, self.position[1] - hd],
            max: [self.position[0] + hw, self.position[1] + hd],
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Obstacle {
    pub min: P2,
    pub max: P2,
    pub height: f32,
}

impl Obstacle {
    pub fn rect(&self) -> Rect {
        Rect { min: self.min, max: self.max }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSlot {
    pub spawn: P2,
    pub heading_deg: f32,
    #[serde(default)]
    pub patrol: Vec<P2>,
}

/// Object classes as snake_case names in the layout file.
mod object_class {
    use serde::{Deserialize, Deserializer, Serializer};
    use spwi_proto::ObjectClass;

    pub fn name(c: ObjectClass) -> &'static str {
        match c {
            ObjectClass::Crate => "crate",
            ObjectClass::Box => "box",
            ObjectClass::Pallet => "pallet",
            ObjectClass::Desk => "desk",
            ObjectClass::Chair => "chair",
            ObjectClass::StorageDrawer => "storage_drawer",
            ObjectClass::Computer => "computer",
            ObjectClass::Workbench => "workbench",
            ObjectClass::CncMachine => "cnc_machine",
            ObjectClass::Table => "table",
            ObjectClass::Other => "other",
        }
    }

    pub fn serialize<S: Serializer>(c: &ObjectClass, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(name(*c))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<ObjectClass, D::Error> {
        let s = String::deserialize(d)?;
        ObjectClass::ALL.into_iter().find(|c| name(*c) == s).ok_or_else(|| {
            let known: Vec<_> = ObjectClass::ALL.iter().map(|c| name(*c)).collect();
            serde::de::Error::custom(format!("unknown object class {s:?}; known: {}", known.join(", ")))
        })
    }
}

/// How far the worker keeps from obstacles, metres (its body radius plus a margin).
pub const WORKER_CLEARANCE: f32 = 0.3;
/// Work spots at most this far apart make a close pair, metres.
pub const CLOSE_PAIR_M: f32 = 3.5;

impl Layout {
    pub fn default_layout() -> Layout {
        Layout::parse(DEFAULT_LAYOUT, "built-in default layout").expect("the default layout is valid")
    }

    pub fn load(path: &Path) -> Result<Layout> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read layout {}", path.display()))?;
        Layout::parse(&text, &path.display().to_string())
    }

    pub fn parse(text: &str, origin: &str) -> Result<Layout> {
        let l: Layout = toml::from_str(text).with_context(|| format!("layout {origin} is not valid"))?;
        l.validate().with_context(|| format!("layout {origin}"))?;
        Ok(l)
    }

    pub fn validate(&self) -> Result<()> {
        let [w, h] = self.floor.size;
        if !(w.is_finite() && h.is_finite() && (2.0..=1000.0).contains(&w) && (2.0..=1000.0).contains(&h)) {
            bail!("floor.size = {:?}: both sides must be within 2..=1000 m", self.floor.size);
        }
        let on_floor = |p: P2| p[0] > 0.0 && p[0] < w && p[1] > 0.0 && p[1] < h;
        let c = &self.camera;
        if !(10.0..=170.0).contains(&c.fov_deg) {
            bail!("camera.fov_deg = {}: must be within 10..=170", c.fov_deg);
        }
        if !(0.5..=100.0).contains(&c.range) {
            bail!("camera.range = {}: must be within 0.5..=100 m", c.range);
        }
        if !(0.1..=3.0).contains(&c.height) {
            bail!("camera.height = {}: must be within 0.1..=3 m", c.height);
        }
        if !(c.image.iter().all(|&s| (16..=8192).contains(&s))) {
            bail!("camera.image = {:?}: width and height must be within 16..=8192 px", c.image);
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            let ordered = o.min[0] < o.max[0] && o.min[1] < o.max[1];
            if !(ordered && (0.1..=10.0).contains(&o.height)) {
                bail!("obstacles[{i}]: min must be below max on both axes and height within 0.1..=10 m");
            }
        }
        let blocked = |p: P2| self.obstacles.iter().any(|o| o.rect().inflate(WORKER_CLEARANCE).contains(p));
        let mut ids: Vec<usize> = self.stations.iter().map(|s| s.id.index()).collect();
        ids.sort();
        if ids != (0..NUM_CLASSES).collect::<Vec<_>>() {
            bail!("stations: ids are {ids:?}; exactly one station per class 0..{NUM_CLASSES} is needed");
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            if !(on_floor(o.min) && on_floor(o.max)) {
                bail!("obstacles[{i}]: min {:?} and max {:?} must both be on the floor", o.min, o.max);
            }
        }
        // Every object with its field name, to name both sides of an overlap.
        let objects: Vec<(String, &Object)> = self
            .stations
            .iter()
            .enumerate()
            .flat_map(|(i, s)| {
                s.objects.iter().enumerate().map(move |(j, o)| (format!("stations[{i}].objects[{j}]"), o))
            })
            .collect();
        for (i, s) in self.stations.iter().enumerate() {
            if !on_floor(s.work_spot) || blocked(s.work_spot) {
                bail!("stations[{i}].work_spot = {:?}: must be on the floor and clear of obstacles", s.work_spot);
            }
            if let Some((name, _)) = objects.iter().find(|(_, o)| o.footprint().contains(s.work_spot)) {
                bail!("stations[{i}].work_spot = {:?}: stands inside {name}; the worker must reach it", s.work_spot);
            }
            if s.objects.is_empty() {
                bail!("stations[{i}].objects: a station needs at least one object that marks it");
            }
            for (j, o) in s.objects.iter().enumerate() {
                if !on_floor(o.position) || o.size.iter().any(|&v| !(0.05..=5.0).contains(&v)) || !o.yaw_deg.is_finite()
                {
                    bail!("stations[{i}].objects[{j}]: position must be on the floor, each size within 0.05..=5 m and yaw_deg finite");
                }
            }
        }
        for (a, (name_a, oa)) in objects.iter().enumerate() {
            let fa = oa.footprint();
            for (name_b, ob) in &objects[a + 1..] {
                let fb = ob.footprint();
                // One object may stand on another (a computer on a desk: inside it whole)
                // or be tucked a little under it (a chair under a bench).
                let stacked = fa.contains_rect(&fb) || fb.contains_rect(&fa);
                let tucked = fa.overlap_area(&fb) <= 0.25 * fa.area().min(fb.area());
                if !(stacked || tucked) {
                    bail!("{name_a} and {name_b} overlap (footprints {fa:?} and {fb:?}): one may stand on another only inside it whole, or tuck under it by at most a quarter");
                }
            }
            if let Some(k) = self.obstacles.iter().position(|o| o.rect().overlaps(&fa)) {
                bail!("{name_a} overlaps obstacles[{k}]");
            }
        }
        if self.robots.is_empty() {
            bail!("robots: at least one robot slot is needed");
        }
        let solid = |p: P2| self.obstacles.iter().any(|o| o.rect().contains(p));
        for (i, r) in self.robots.iter().enumerate() {
            if !on_floor(r.spawn) || solid(r.spawn) {
                bail!("robots[{i}].spawn = {:?}: must be on the floor and outside obstacles", r.spawn);
            }
            if !r.heading_deg.is_finite() {
                bail!("robots[{i}].heading_deg = {}: must be a finite angle", r.heading_deg);
            }
            for (j, p) in r.patrol.iter().enumerate() {
                if !on_floor(*p) || solid(*p) {
                    bail!("robots[{i}].patrol[{j}] = {p:?}: must be on the floor and outside obstacles");
                }
            }
        }
        Ok(())
    }

    /// Pairs of stations whose work spots stand within [`CLOSE_PAIR_M`] of each other:
    /// the paper's hard case, reported apart by the evaluation.
    pub fn close_pairs(&self) -> Vec<(Station, Station)> {
        let mut pairs = Vec::new();
        for (i, a) in self.stations.iter().enumerate() {
            for b in &self.stations[i + 1..] {
                if crate::geometry::dist(a.work_spot, b.work_spot) <= CLOSE_PAIR_M {
                    pairs.push((a.id.min(b.id), a.id.max(b.id)));
                }
            }
        }
        pairs.sort();
        pairs
    }

    /// The same floor seen in a mirror (x → width − x): every place moves, every
    /// relation between the worker and the objects stays. A model that learned places
    /// instead of relations fails here.
    pub fn mirrored(&self) -> Layout {
        let w = self.floor.size[0];
        let x = |p: P2| [w - p[0], p[1]];
        let heading = |deg: f32| 180.0 - deg;
        let mut l = self.clone();
        for s in &mut l.stations {
            s.work_spot = x(s.work_spot);
            for o in &mut s.objects {
                o.position = x(o.position);
                o.yaw_deg = heading(o.yaw_deg);
            }
        }
        for o in &mut l.obstacles {
            (o.min, o.max) = ([w - o.max[0], o.min[1]], [w - o.min[0], o.max[1]]);
        }
        for r in &mut l.robots {
            r.spawn = x(r.spawn);
            r.heading_deg = heading(r.heading_deg);
            r.patrol.iter_mut().for_each(|p| *p = x(*p));
        }
        l
    }

    /// The layout as a TOML file (what `spwi-sim layout --out` writes), numbers as
    /// short as f32 allows (1.2, not 1.2000000476837158).
    pub fn to_toml(&self) -> String {
        fn shorten(v: &mut toml::Value) {
            match v {
                toml::Value::Float(f) => *f = (*f as f32).to_string().parse().expect("a float prints as one"),
                toml::Value::Array(a) => a.iter_mut().for_each(shorten),
                toml::Value::Table(t) => t.iter_mut().for_each(|(_, v)| shorten(v)),
                _ => {}
            }
        }
        let mut v = toml::Value::try_from(self).expect("a layout serialises");
        shorten(&mut v);
        toml::to_string(&v).expect("a layout serialises")
    }

    pub fn station(&self, id: Station) -> &StationSite {
        self.stations.iter().find(|s| s.id == id).expect("validated: one station per class")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::dist;
    use spwi_proto::Station::*;

    #[test]
    fn the_default_layout_is_valid_and_has_the_close_pair() {
        let l = Layout::default_layout();
        let d = crate::geometry::dist(l.station(Assembly).work_spot, l.station(Manufacturing).work_spot);
        assert!(d < 3.0, "assembly and manufacturing must stand close: {d} m");
        assert_eq!(l.close_pairs(), vec![(Assembly, Manufacturing)]);
        assert!(l.robots.len() >= 8);
    }

    #[test]
    fn a_mirrored_floor_keeps_every_relation_and_moves_every_place() {
        let l = Layout::default_layout();
        let m = l.mirrored();
        m.validate().unwrap();
        let back = m.mirrored();
        for (a, b) in l.robots.iter().zip(&back.robots) {
            assert!(dist(a.spawn, b.spawn) < 1e-4 && (a.heading_deg - b.heading_deg).abs() < 1e-3, "mirroring twice");
        }
        let spot = |l: &Layout, k: Station| l.station(k).work_spot;
        for (a, b) in
            [(Storage, Workstation), (Workstation, Assembly), (Assembly, Manufacturing), (Storage, Manufacturing)]
        {
            let (d, dm) = (dist(spot(&l, a), spot(&l, b)), dist(spot(&m, a), spot(&m, b)));
            assert!((d - dm).abs() < 1e-4, "distance {a}-{b}: {d} vs {dm}");
        }
        assert!(dist(spot(&l, Storage), spot(&m, Storage)) > 10.0, "storage moved across the floor");
    }

    #[test]
    fn a_layout_round_trips_through_its_toml() {
        let l = Layout::default_layout();
        assert_eq!(Layout::parse(&l.to_toml(), "round trip").unwrap().to_toml(), l.to_toml());
    }

    #[test]
    fn layouts_with_errors_are_refused_naming_the_field() {
        let cases = [
            ("size = [20.0, 14.0]", "size = [20.0, -1.0]", "floor.size"),
            ("fov_deg = 90.0", "fov_deg = 200.0", "camera.fov_deg"),
            ("work_spot = [3.0, 3.0]", "work_spot = [8.0, 6.0]", "stations[0].work_spot"),
            ("spawn = [10.0, 0.8]", "spawn = [8.0, 6.0]", "robots[0].spawn"),
            ("id = 3", "id = 2", "stations: ids"),
            ("class = \"table\"", "class = \"sofa\"", "unknown object class"),
            (
                "position = [2.5, 1.4]",
                "position = [2.0, 2.4]",
                "stations[0].objects[0] and stations[0].objects[2] overlap",
            ),
            ("position = [17.4, 11.5]", "position = [8.0, 6.0]", "stations[3].objects[0] overlaps obstacles[0]"),
            (
                "work_spot = [17.0, 10.0]",
                "work_spot = [18.6, 10.0]",
                "stations[3].work_spot = [18.6, 10.0]: stands inside stations[3].objects[1]",
            ),
            ("spawn = [0.8, 7.0]", "spawn = [-0.8, 7.0]", "robots[1].spawn"),
            ("patrol = [[19.2, 5.5], [19.2, 2.0]", "patrol = [[19.2, 5.5], [25.0, 2.0]", "robots[2].patrol[1]"),
        ];
        for (from, to, field) in cases {
            assert!(DEFAULT_LAYOUT.contains(from), "{from}");
            let e = Layout::parse(&DEFAULT_LAYOUT.replacen(from, to, 1), "test").unwrap_err();
            let e = format!("{e:#}");
            assert!(e.contains(field), "{to}: {e}");
        }
    }
}

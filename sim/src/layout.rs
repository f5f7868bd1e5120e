//! The factory floor, read from a TOML layout file (`sim/layouts/factory.toml` is the
//! default and documents every field). [`Layout::validate`] refuses a layout that
//! could not work — a station off the floor, a work spot inside an obstacle, a robot
//! spawning in a wall — with an error naming the field, so any layout that loads works
//! everywhere the default does.

use crate::geometry::{Rect, P2};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use spwi_proto::{ObjectClass, NUM_CLASSES};
use std::path::Path;

/// The default layout, built into the binary.
pub const DEFAULT_LAYOUT: &str = include_str!("../layouts/factory.toml");

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Layout {
    pub floor: Floor,
    pub camera: Camera,
    pub stations: Vec<Station>,
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
}

impl Camera {
    /// Focal length in pixels.
    pub fn focal(&self) -> f32 {
        self.image[0] as f32 / 2.0 / (self.fov_deg.to_radians() / 2.0).tan()
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Station {
    pub id: u8,
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
        let mut ids: Vec<u8> = self.stations.iter().map(|s| s.id).collect();
        ids.sort();
        if ids != (0..NUM_CLASSES as u8).collect::<Vec<_>>() {
            bail!("stations: ids are {ids:?}; exactly one station per class 0..{NUM_CLASSES} is needed");
        }
        for (i, s) in self.stations.iter().enumerate() {
            if !on_floor(s.work_spot) || blocked(s.work_spot) {
                bail!("stations[{i}].work_spot = {:?}: must be on the floor and clear of obstacles", s.work_spot);
            }
            if s.objects.is_empty() {
                bail!("stations[{i}].objects: a station needs at least one object that marks it");
            }
            for (j, o) in s.objects.iter().enumerate() {
                if !on_floor(o.position) || o.size.iter().any(|&v| !(0.05..=5.0).contains(&v)) {
                    bail!("stations[{i}].objects[{j}]: position must be on the floor and each size within 0.05..=5 m");
                }
            }
        }
        if self.robots.is_empty() {
            bail!("robots: at least one robot slot is needed");
        }
        for (i, r) in self.robots.iter().enumerate() {
            if !on_floor(r.spawn) || self.obstacles.iter().any(|o| o.rect().contains(r.spawn)) {
                bail!("robots[{i}].spawn = {:?}: must be on the floor and outside obstacles", r.spawn);
            }
            for (j, p) in r.patrol.iter().enumerate() {
                if !on_floor(*p) || self.obstacles.iter().any(|o| o.rect().contains(*p)) {
                    bail!("robots[{i}].patrol[{j}] = {p:?}: must be on the floor and outside obstacles");
                }
            }
        }
        Ok(())
    }

    pub fn station(&self, id: u8) -> &Station {
        self.stations.iter().find(|s| s.id == id).expect("validated: one station per class")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_layout_is_valid_and_has_the_close_pair() {
        let l = Layout::default_layout();
        let d = crate::geometry::dist(l.station(2).work_spot, l.station(3).work_spot);
        assert!(d < 3.0, "assembly and manufacturing must stand close: {d} m");
        assert!(l.robots.len() >= 8);
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
        ];
        for (from, to, field) in cases {
            assert!(DEFAULT_LAYOUT.contains(from), "{from}");
            let e = Layout::parse(&DEFAULT_LAYOUT.replacen(from, to, 1), "test").unwrap_err();
            let e = format!("{e:#}");
            assert!(e.contains(field), "{to}: {e}");
        }
    }
}

//! A floor plan: where the factory says its stations stand.
//!
//! A robot maps the stations from its own detections ([`super::stations`]); a camera
//! that never sees a station leaves it off the map, and the goal then lies off the
//! team's map for as long. A factory knows where its stations are, so a daemon may be
//! given a plan: each station's position on the floor (metres, in the frame the robots'
//! poses use) and how far off it may be. The plan seeds the station map; what the
//! cameras see still refines it (a station whose work spot the robots have watched
//! the worker use stands there instead), and a plan the cameras contradict is
//! reported ([`super::StationMap::contradicts`]).
//!
//! The file is TOML:
//!
//! ```toml
//! [stations.storage]
//! position = [2.0, 3.5]     # metres
//! uncertainty_m = 0.5       # how far off it may be (1 σ)
//!
//! [[obstacles]]             # optional: what the worker walks around (racks, machines)
//! min = [4.0, 1.0]          # one corner of the rectangle (metres)
//! max = [5.5, 6.0]          # the opposite one
//! ```
//!
//! Stations it does not name are mapped from detections alone. The robots do not
//! use the obstacles yet; a planner reading the worker's walk does (the evaluation's
//! planning yardstick, `sim/src/eval/planner.rs`).

use spwi_proto::{Station, NUM_CLASSES};
use std::collections::BTreeMap;

/// The largest uncertainty a plan may state (m): beyond, it says nothing a camera
/// would not find better.
pub const MAX_UNCERTAINTY_M: f32 = 10.0;

/// A station where the plan puts it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannedStation {
    pub position: [f32; 2],
    pub uncertainty_m: f32,
}

/// The most obstacles a plan may mark.
pub const MAX_OBSTACLES: usize = 256;

/// An obstacle the plan marks: a rectangle of the floor (metres) the worker walks
/// around.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannedObstacle {
    pub min: [f32; 2],
    pub max: [f32; 2],
}

/// Where a factory's plan puts its stations (by [`Station::index`]), and the
/// obstacles it marks.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "PlanFile", into = "PlanFile")]
pub struct FloorPlan {
    pub stations: [Option<PlannedStation>; NUM_CLASSES],
    pub obstacles: Vec<PlannedObstacle>,
}

/// The file's shape: stations by name, then the obstacles.
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct PlanFile {
    stations: BTreeMap<String, PlannedStation>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    obstacles: Vec<PlannedObstacle>,
}

impl TryFrom<PlanFile> for FloorPlan {
    type Error = String;

    fn try_from(f: PlanFile) -> Result<FloorPlan, String> {
        let mut plan = FloorPlan::default();
        for (name, s) in f.stations {
            let station = Station::ALL.into_iter().find(|k| k.name() == name).ok_or_else(|| {
                let names: Vec<&str> = Station::ALL.iter().map(|k| k.name()).collect();
                format!("stations.{name}: no such station (the stations are {})", names.join(", "))
            })?;
            if !s.position.iter().all(|v| v.is_finite()) {
                return Err(format!("stations.{name}.position: {:?} is not a point on the floor", s.position));
            }
            if !(s.uncertainty_m > 0.0 && s.uncertainty_m <= MAX_UNCERTAINTY_M) {
                return Err(format!(
                    "stations.{name}.uncertainty_m: {} is not within (0, {MAX_UNCERTAINTY_M}] metres",
                    s.uncertainty_m
                ));
            }
            plan.stations[station.index()] = Some(s);
        }
        if plan.stations.iter().all(Option::is_none) {
            return Err("[stations] names no station".into());
        }
        if f.obstacles.len() > MAX_OBSTACLES {
            return Err(format!("obstacles: {} of them, at most {MAX_OBSTACLES}", f.obstacles.len()));
        }
        for (i, o) in f.obstacles.iter().enumerate() {
            if !o.min.iter().chain(&o.max).all(|v| v.is_finite()) || o.min[0] >= o.max[0] || o.min[1] >= o.max[1] {
                return Err(format!(
                    "obstacles[{i}]: min {:?} and max {:?} are not opposite corners of a rectangle (min below max on both axes)",
                    o.min, o.max
                ));
            }
        }
        plan.obstacles = f.obstacles;
        Ok(plan)
    }
}

impl From<FloorPlan> for PlanFile {
    fn from(p: FloorPlan) -> PlanFile {
        let stations =
            Station::ALL.into_iter().filter_map(|k| Some((k.name().to_owned(), p.stations[k.index()]?))).collect();
        PlanFile { stations, obstacles: p.obstacles }
    }
}

impl FloorPlan {
    /// Reads a plan from its TOML text; the error names what is wrong in it.
    pub fn parse(text: &str) -> Result<FloorPlan, String> {
        toml::from_str(text).map_err(|e| e.to_string().trim_end().to_owned())
    }

    /// The plan as TOML, as [`FloorPlan::parse`] reads it.
    pub fn to_toml(&self) -> String {
        let body = toml::to_string(self).expect("a plan is plain data");
        format!("# A floor plan: where the stations stand (metres, floor frame) and how far off (1 sigma).\n{body}")
    }

    /// Where the plan puts `station`.
    pub fn station(&self, station: Station) -> Option<PlannedStation> {
        self.stations[station.index()]
    }

    /// How many stations it places.
    pub fn len(&self) -> usize {
        self.stations.iter().flatten().count()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plan_reads_back_what_it_writes() {
        let mut plan = FloorPlan::default();
        plan.stations[Station::Assembly.index()] = Some(PlannedStation { position: [4.5, 2.0], uncertainty_m: 0.3 });
        plan.stations[Station::Storage.index()] = Some(PlannedStation { position: [1.0, 9.25], uncertainty_m: 1.0 });
        let text = plan.to_toml();
        assert!(text.contains("[stations.assembly]") && !text.contains("obstacles"), "{text}");
        assert_eq!(FloorPlan::parse(&text).unwrap(), plan);
        assert_eq!(plan.len(), 2);
        plan.obstacles = vec![PlannedObstacle { min: [4.0, 1.0], max: [5.5, 6.0] }];
        let text = plan.to_toml();
        assert!(text.contains("[[obstacles]]"), "{text}");
        assert_eq!(FloorPlan::parse(&text).unwrap(), plan);
    }

    #[test]
    fn a_bad_plan_is_refused_naming_the_field() {
        let bad = [
            ("[stations.kitchen]\nposition = [1.0, 2.0]\nuncertainty_m = 0.5\n", "stations.kitchen: no such station"),
            ("[stations.storage]\nposition = [1.0, 2.0]\nuncertainty_m = 0.0\n", "stations.storage.uncertainty_m"),
            ("[stations.storage]\nposition = [1.0, 2.0]\nuncertainty_m = 11.0\n", "stations.storage.uncertainty_m"),
            ("[stations.storage]\nposition = [nan, 2.0]\nuncertainty_m = 1.0\n", "stations.storage.position"),
            ("[stations.storage]\nposition = [1.0]\nuncertainty_m = 1.0\n", "position"),
            ("[stations.storage]\nposition = [1.0, 2.0]\nuncertainty = 1.0\n", "uncertainty"),
            ("[stations]\n", "names no station"),
            (
                "[stations.storage]\nposition = [1.0, 2.0]\nuncertainty_m = 1.0\n[[obstacles]]\nmin = [2.0, 1.0]\nmax = [1.0, 3.0]\n",
                "obstacles[0]: min [2.0, 1.0] and max [1.0, 3.0]",
            ),
            (
                "[stations.storage]\nposition = [1.0, 2.0]\nuncertainty_m = 1.0\n[[obstacles]]\nmin = [1.0, 1.0]\nmax = [2.0, inf]\n",
                "obstacles[0]",
            ),
            ("[stations.storage]\nposition = [1.0, 2.0]\nuncertainty_m = 1.0\n[[obstacles]]\nmin = [1.0, 1.0]\n", "max"),
            ("stations = 3\n", "stations"),
        ];
        for (text, says) in bad {
            let e = FloorPlan::parse(text).unwrap_err();
            assert!(e.contains(says), "{text:?}: {e}");
        }
    }
}

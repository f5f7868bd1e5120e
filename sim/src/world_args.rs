//! The world every `spwi-sim` tool runs in, as one set of command-line arguments:
//! which scenario, which floors (files, or generated families such as `train:0..200`),
//! and where the cameras point. Parsed once here so every tool reads floors the same way.

use anyhow::{bail, Result};
use spwi_world::generate::{self, LayoutSource, NamedLayout};
use spwi_world::layout::{CameraPolicy, Layout};
use spwi_world::world::Scenario;

#[derive(clap::Args, Debug, Clone)]
pub struct WorldArgs {
    /// 1: no obstacles, stationary robots; 2: static obstacles; 3: obstacles and moving robots.
    #[arg(long, default_value = "3", value_parser = parse_scenario)]
    pub scenario: Scenario,
    /// Floors: a layout file, or a generated family `train:A..B` / `heldout:A..B`
    /// (disjoint seed ranges); repeatable, episodes take them in turn. Default: the
    /// built-in world/layouts/factory.toml.
    #[arg(long = "layouts", visible_alias = "layout", value_name = "FILE|FAMILY:A..B")]
    pub layouts: Vec<LayoutSource>,
    /// Where the cameras point (default: each layout's own `camera.policy`).
    #[arg(long, value_parser = parse_camera)]
    pub camera: Option<CameraPolicy>,
    /// Workers on the floor, each with its own work cycle: they step round and hide
    /// one another; frames carry everyone in view. The truth and the scores describe
    /// the first.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=spwi_world::world::MAX_WORKERS as i64))]
    pub workers: u8,
}

/// The name the built-in floor is reported under.
pub const BUILT_IN: &str = "factory.toml (built in)";

impl WorldArgs {
    /// Every floor named, with the camera policy applied.
    pub fn floors(&self) -> Result<Vec<NamedLayout>> {
        let mut floors = if self.layouts.is_empty() {
            vec![NamedLayout { name: BUILT_IN.into(), layout: Layout::default_layout() }]
        } else {
            generate::resolve(&self.layouts)?
        };
        if let Some(p) = self.camera {
            floors.iter_mut().for_each(|f| f.layout.camera.policy = p);
        }
        Ok(floors)
    }

    /// The one floor of a tool that runs a single world.
    pub fn floor(&self) -> Result<NamedLayout> {
        let mut floors = self.floors()?;
        if floors.len() != 1 {
            bail!("--layouts names {} floors; this tool runs one world on one floor", floors.len());
        }
        Ok(floors.remove(0))
    }

    /// How the floors are named on the command line, for reports.
    pub fn describe(&self) -> String {
        if self.layouts.is_empty() {
            BUILT_IN.into()
        } else {
            self.layouts.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(" ")
        }
    }
}

/// Refuses a fleet larger than the floors' robot slots.
pub fn check_robots(robots: usize, floors: &[NamedLayout]) -> Result<()> {
    for f in floors {
        if robots == 0 || robots > f.layout.robots.len() {
            bail!("--robots {robots}: floor {} has slots for 1..={} robots", f.name, f.layout.robots.len());
        }
    }
    Ok(())
}

pub fn parse_scenario(s: &str) -> Result<Scenario, String> {
    s.parse::<u8>()
        .ok()
        .and_then(|n| Scenario::from_number(n).ok())
        .ok_or_else(|| format!("scenario {s:?}: 1 (ideal), 2 (static obstacles) or 3 (obstacles and moving robots)"))
}

pub fn parse_camera(s: &str) -> Result<CameraPolicy, String> {
    match s {
        "fixed" => Ok(CameraPolicy::Fixed),
        "track" => Ok(CameraPolicy::Track),
        _ => Err(format!("camera policy {s:?}: \"fixed\" or \"track\"")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        world: WorldArgs,
    }

    fn parse(args: &[&str]) -> Result<WorldArgs, String> {
        Cli::try_parse_from(std::iter::once("t").chain(args.iter().copied()))
            .map(|c| c.world)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn floors_cameras_and_scenarios_from_the_command_line() {
        let w = parse(&[]).unwrap();
        assert_eq!((w.scenario, w.floors().unwrap()[0].name.as_str()), (Scenario::Dynamic, BUILT_IN));
        let w = parse(&["--layouts", "train:0..2", "--layout", "heldout:0..1", "--camera", "track", "--scenario", "1"])
            .unwrap();
        let floors = w.floors().unwrap();
        assert_eq!(floors.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(), ["train:0", "train:1", "heldout:0"]);
        assert!(floors.iter().all(|f| f.layout.camera.policy == CameraPolicy::Track));
        assert_eq!(w.scenario, Scenario::Ideal);
        assert!(w.floor().unwrap_err().to_string().contains("names 3 floors"));
        assert_eq!(w.describe(), "train:0..2 heldout:0..1");
    }

    #[test]
    fn bad_floors_and_scenarios_are_refused_with_what_is_wrong() {
        assert!(parse(&["--layouts", "train:5..5"]).unwrap_err().contains("holds no floor"));
        assert!(parse(&["--scenario", "4"]).unwrap_err().contains("scenario \"4\""));
        assert!(parse(&["--camera", "pan"]).unwrap_err().contains("\"fixed\" or \"track\""));
        let overlapping = parse(&["--layouts", "train:0..3", "--layouts", "train:2..4"]).unwrap();
        assert!(overlapping.floors().unwrap_err().to_string().contains("overlap"));
        let floors = parse(&["--layouts", "heldout:0..1"]).unwrap().floors().unwrap();
        assert!(check_robots(9, &floors).unwrap_err().to_string().contains("slots for 1..=8"));
        check_robots(8, &floors).unwrap();
    }
}

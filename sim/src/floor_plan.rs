//! Floor plans of simulated floors: where a layout's stations' work spots stand, as a
//! factory's own plan would put them, exactly or each displaced by up to some metres
//! (what a plan that is off costs the fleet), and the layout's obstacles.

use rand::Rng;
use spwi_core::floor::{FloorPlan, PlannedObstacle, PlannedStation};
use spwi_proto::Station;
use spwi_world::layout::Layout;
use spwi_world::world::{stream, Stream};

/// The uncertainty an exact plan states (m, 1 σ): a surveyed factory floor.
pub const EXACT_UNCERTAINTY_M: f32 = 0.25;

/// The fault stream the displacements draw from.
const PLAN_STREAM: u64 = 3;

/// `layout`'s plan: every station at its work spot, each moved by up to `error_m`
/// metres in a direction drawn from `seed` (0: the exact plan), and every obstacle as
/// it stands. The plan states an uncertainty of `error_m`, at least
/// [`EXACT_UNCERTAINTY_M`].
pub fn of_layout(layout: &Layout, error_m: f32, seed: u64) -> FloorPlan {
    let mut rng = stream(seed, Stream::Fault(PLAN_STREAM));
    let mut plan = FloorPlan::default();
    for k in Station::ALL {
        let [x, y] = layout.station(k).work_spot;
        let (angle, off) = (rng.gen_range(0.0..std::f32::consts::TAU), error_m * rng.gen::<f32>());
        let position = [x + off * angle.cos(), y + off * angle.sin()];
        plan.stations[k.index()] = Some(PlannedStation { position, uncertainty_m: error_m.max(EXACT_UNCERTAINTY_M) });
    }
    plan.obstacles = layout.obstacles.iter().map(|o| PlannedObstacle { min: o.min, max: o.max }).collect();
    plan
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dist(a: [f32; 2], b: [f32; 2]) -> f32 {
        (a[0] - b[0]).hypot(a[1] - b[1])
    }

    #[test]
    fn an_exact_plan_puts_each_station_at_its_work_spot_and_a_displaced_one_within_its_error() {
        let layout = Layout::default_layout();
        let exact = of_layout(&layout, 0.0, 1);
        let off = of_layout(&layout, 1.0, 1);
        let moved: Vec<f32> = Station::ALL
            .into_iter()
            .map(|k| {
                let spot = layout.station(k).work_spot;
                assert_eq!(exact.station(k).unwrap().position, spot);
                assert_eq!(exact.station(k).unwrap().uncertainty_m, EXACT_UNCERTAINTY_M);
                assert_eq!(off.station(k).unwrap().uncertainty_m, 1.0);
                dist(off.station(k).unwrap().position, spot)
            })
            .collect();
        assert!(moved.iter().all(|&d| d <= 1.0 + 1e-5) && moved.iter().any(|&d| d > 0.1), "{moved:?}");
        assert_eq!(exact.obstacles.len(), layout.obstacles.len());
        assert!(!exact.obstacles.is_empty(), "the built-in floor has obstacles");
        assert_eq!(of_layout(&layout, 1.0, 1), off, "the same seed, the same plan");
        assert_ne!(of_layout(&layout, 1.0, 2), off, "another seed, another");
    }
}

//! The simulated camera as an agent's configuration describes it: what a robot of a
//! floor would be calibrated with. (Every generated floor uses the agent's default.)

use spwi_agent::floor::CameraCalibration;
use spwi_world::layout::Camera;

pub fn of(cam: &Camera) -> CameraCalibration {
    CameraCalibration { fov_deg: cam.fov_deg, height_m: cam.height, image: cam.image }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_agents_default_is_the_simulated_camera() {
        let floor = spwi_world::layout::Layout::default_layout();
        assert_eq!(super::of(&floor.camera), Default::default());
        let generated = spwi_world::generate::layout(7);
        assert_eq!(super::of(&generated.camera), Default::default());
    }
}

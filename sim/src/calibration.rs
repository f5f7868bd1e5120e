//! The simulated camera as an agent's configuration describes it: what a robot of a
//! floor would be calibrated with. (Every generated floor uses the agent's default.)

use spwi_core::floor::CameraCalibration;
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

    /// The angle between two headings, 0..=π.
    fn apart(a: f32, b: f32) -> f32 {
        (a - b).sin().atan2((a - b).cos()).abs()
    }

    #[test]
    fn the_worker_s_facing_comes_back_from_the_world_s_own_skeleton_and_camera() {
        use spwi_world::camera::{project, Pose};
        use spwi_world::skeleton::keypoints;
        let floor = spwi_world::layout::Layout::default_layout();
        let calibration = super::of(&floor.camera);
        let cam = Pose { position: [1.0, 2.0], heading: 0.4 };
        let agent_pose = spwi_proto::FloorPose { position: cam.position, heading: cam.heading };
        let (mut worst, mut worst_turned): (f32, f32) = (0.0, 0.0);
        for range in [3.0f32, 6.0, 9.0] {
            for off_axis in [-0.6f32, 0.0, 0.5] {
                let b = cam.heading + off_axis;
                let at = [cam.position[0] + range * b.cos(), cam.position[1] + range * b.sin()];
                for step in 0..24 {
                    let heading = -std::f32::consts::PI + step as f32 * std::f32::consts::PI / 12.0;
                    // Standing, walking at full stride, the head turned from the body.
                    for (head_yaw, gait, speed) in
                        [(0.0, 0.0, 0.0), (0.0, 1.57, 1.2), (0.0, 4.7, 1.2), (0.3, 1.57, 1.2), (-0.3, 0.0, 0.0)]
                    {
                        let kp: Vec<f32> = keypoints(at, heading, head_yaw, gait, speed)
                            .iter()
                            .flat_map(|&p| {
                                let (u, v) = project(&floor.camera, cam, p).unwrap();
                                [u, v]
                            })
                            .collect();
                        let facing = calibration.worker_facing(&agent_pose, &kp).unwrap();
                        let w = if head_yaw == 0.0 { &mut worst } else { &mut worst_turned };
                        *w = w.max(apart(facing, heading));
                    }
                }
            }
        }
        assert!(worst < 0.15, "off by {worst} rad at worst");
        // A head turned by ψ can flip a body angle within ψ of the line of sight to its
        // mirror image: an error of at most 2ψ.
        assert!(worst_turned < 0.6 + 0.15, "off by {worst_turned} rad at worst with the head turned 0.3 rad");
    }
}

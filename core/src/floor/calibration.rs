//! The robot's camera as the agent knows it from its configuration (intrinsics and
//! mounting), and back-projection of image points onto the floor.
//!
//! The camera is a pinhole mounted level at a known height, looking along the pose's
//! heading. A pixel then names a ray, and a ray meets a horizontal plane at one point:
//! the worker's ankles meet the plane at ankle height, an object's box bottom meets the
//! floor. Depth resolution falls with the square of the distance, so every point
//! comes with a standard deviation that grows with it.

use serde::{Deserialize, Serialize};
use spwi_proto::{DetectionFrame, FloorPose, Landmark, ObjectClass, ObjectDetection, KEYPOINT_VALUES};

/// Height of the ankle keypoints above the floor (m): COCO's ankles of a standing adult.
pub const ANKLE_HEIGHT: f32 = 0.08;
/// Standard deviation of a keypoint or box edge as detectors place it (pixels).
const PIXEL_SIGMA: f32 = 3.0;
/// Error that does not shrink with distance: where on its footprint a box bottom lies,
/// how the ankles sit under the body (m).
const BASE_SIGMA: f32 = 0.15;
/// Shoulder and hip width, the ears' spacing and how far the nose reaches in front of
/// the ears, of an average adult (m): [`CameraCalibration::worker_facing`].
const SHOULDERS_M: f32 = 0.40;
const HIPS_M: f32 = 0.24;
const EARS_M: f32 = 0.16;
const NOSE_REACH_M: f32 = 0.10;
/// Objects seen farther than this are not put on the map (m).
const LANDMARK_RANGE: f32 = 15.0;
/// Below this detector score an object is not put on the map.
const LANDMARK_SCORE: f32 = 0.3;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraCalibration {
    /// Horizontal field of view (degrees).
    pub fov_deg: f32,
    /// Height of the optical centre above the floor (m).
    pub height_m: f32,
    /// Image width and height (pixels).
    pub image: [u32; 2],
}

impl Default for CameraCalibration {
    /// The simulated robots' camera (`world/layouts/*.toml`, `[camera]`).
    fn default() -> Self {
        CameraCalibration { fov_deg: 90.0, height_m: 1.0, image: [640, 480] }
    }
}

impl CameraCalibration {
    /// A problem with the values, naming the field.
    pub fn problem(&self) -> Option<String> {
        if !(10.0..=170.0).contains(&self.fov_deg) {
            return Some(format!("camera.fov_deg = {}: must be within 10..=170", self.fov_deg));
        }
        if !(0.1..=5.0).contains(&self.height_m) {
            return Some(format!("camera.height_m = {}: must be within 0.1..=5 m", self.height_m));
        }
        if self.image.iter().any(|&p| !(16..=16384).contains(&p)) {
            return Some(format!("camera.image = {:?}: each side must be within 16..=16384 pixels", self.image));
        }
        None
    }

    /// Focal length in pixels.
    pub fn focal(&self) -> f32 {
        self.image[0] as f32 / 2.0 / (self.fov_deg.to_radians() / 2.0).tan()
    }

    /// Projects floor-frame point (x, y, z) into the image; `None` behind the camera.
    pub fn project(&self, pose: &FloorPose, p: [f32; 3]) -> Option<(f32, f32)> {
        let d = [p[0] - pose.position[0], p[1] - pose.position[1]];
        let (c, s) = (pose.heading.cos(), pose.heading.sin());
        let forward = d[0] * c + d[1] * s;
        let left = -d[0] * s + d[1] * c;
        if forward < 0.1 {
            return None;
        }
        let f = self.focal();
        Some((
            self.image[0] as f32 / 2.0 - f * left / forward,
            self.image[1] as f32 / 2.0 - f * (p[2] - self.height_m) / forward,
        ))
    }

    /// Where the ray through pixel (u, v) meets the horizontal plane at `height`, and
    /// the standard deviation of that point (m); `None` when the ray does not meet the
    /// plane in front of the camera within 50 m.
    pub fn back_project(&self, pose: &FloorPose, (u, v): (f32, f32), height: f32) -> Option<([f32; 2], f32)> {
        let f = self.focal();
        let dv = self.image[1] as f32 / 2.0 - v; // pixels above the image centre
        let dh = height - self.height_m;
        if dv.abs() < 1e-3 || dh.abs() < 1e-3 {
            return None;
        }
        let forward = f * dh / dv;
        if !(0.1..=50.0).contains(&forward) {
            return None;
        }
        let left = (self.image[0] as f32 / 2.0 - u) * forward / f;
        let (c, s) = (pose.heading.cos(), pose.heading.sin());
        let p = [pose.position[0] + forward * c - left * s, pose.position[1] + forward * s + left * c];
        // d(forward)/dv = forward² / (f dh): depth error grows with the square of the distance.
        let sigma = BASE_SIGMA + forward * forward * PIXEL_SIGMA / (f * dh.abs());
        Some((p, sigma))
    }

    fn inside(&self, (u, v): (f32, f32)) -> bool {
        (0.0..self.image[0] as f32).contains(&u) && (0.0..self.image[1] as f32 - 1.0).contains(&v)
    }

    /// The worker's floor position from the mean of its ankle keypoints, and its
    /// standard deviation; `None` when the ankles are out of the image.
    pub fn worker_on_floor(&self, pose: &FloorPose, keypoints: &[f32]) -> Option<([f32; 2], f32)> {
        debug_assert_eq!(keypoints.len(), KEYPOINT_VALUES);
        let ankles = [(keypoints[30], keypoints[31]), (keypoints[32], keypoints[33])];
        if !ankles.iter().all(|&a| self.inside(a)) {
            return None;
        }
        let mid = ((ankles[0].0 + ankles[1].0) / 2.0, (ankles[0].1 + ankles[1].1) / 2.0);
        self.back_project(pose, mid, ANKLE_HEIGHT)
    }

    /// Which way the worker's body faces on the floor (radians, floor frame), from its
    /// keypoints: `None` when the ankles are out of the image.
    ///
    /// A monocular view measures well how far apart the keypoints lie across the line
    /// of sight (the range of the whole body comes from its ankles) and their depth
    /// differences not at all. Across the line of sight, the shoulders and the hips
    /// span their width times the cosine of the body's angle to that line; the nose
    /// lies off the ears' midpoint by its reach times the sine of the head's angle,
    /// whose sign tells which of the two body angles with that cosine it is (a head
    /// turned by ψ can pick the mirror image of a body angle within ψ of the line of
    /// sight). Widths of an average adult.
    pub fn worker_facing(&self, pose: &FloorPose, keypoints: &[f32]) -> Option<f32> {
        debug_assert_eq!(keypoints.len(), KEYPOINT_VALUES);
        let (at, _) = self.worker_on_floor(pose, keypoints)?;
        let to = [at[0] - pose.position[0], at[1] - pose.position[1]];
        let range = to[0].hypot(to[1]);
        // Metres to the left of the line of sight (up to a shift common to all points).
        let across = |k: usize| range * (self.image[0] as f32 / 2.0 - keypoints[2 * k]).atan2(self.focal());
        let span = |l: usize, r: usize| across(r) - across(l); // − width × cos(angle)
        let body_cos = -(SHOULDERS_M * span(5, 6) + HIPS_M * span(11, 12)) / (SHOULDERS_M.powi(2) + HIPS_M.powi(2));
        let head_cos = -span(3, 4) / EARS_M;
        let head_sin = (across(0) - (across(3) + across(4)) / 2.0) / NOSE_REACH_M;
        let body = body_cos.clamp(-1.0, 1.0).acos().copysign(head_sin.atan2(head_cos));
        Some(to[1].atan2(to[0]) + body)
    }

    /// [`Self::worker_facing`] of the worker a frame shows, if the frame carries its
    /// robot's pose.
    pub fn facing_in(&self, frame: &DetectionFrame) -> Option<f32> {
        self.worker_facing(frame.pose.as_ref()?, &frame.worker()?.keypoints)
    }

    /// Where a detected object stands on the floor, and how sure that is (m): the
    /// middle of its box's bottom edge meets the floor at the object's near side.
    /// `None` for a box cut by the image's lower edge (its bottom is not in view).
    pub fn footprint(&self, pose: &FloorPose, object: &ObjectDetection) -> Option<([f32; 2], f32)> {
        let bottom = (object.bbox.x + object.bbox.w / 2.0, object.bbox.y + object.bbox.h);
        if !self.inside(bottom) {
            return None;
        }
        self.back_project(pose, bottom, 0.0)
    }

    /// The detected objects that mark one station, on the floor ([`Self::footprint`]).
    /// Boxes cut by the image's lower edge, far or doubtful detections, and chairs
    /// (found at two kinds of station) are left out.
    pub fn landmarks(&self, pose: &FloorPose, objects: &[ObjectDetection]) -> Vec<Landmark> {
        objects
            .iter()
            .filter(|o| o.class != ObjectClass::Chair && o.score >= LANDMARK_SCORE)
            .filter_map(|o| {
                let station = o.class.station()?;
                let (position, sigma) = self.footprint(pose, o)?;
                let range = (position[0] - pose.position[0]).hypot(position[1] - pose.position[1]);
                (range <= LANDMARK_RANGE).then_some(Landmark { station, position, sigma })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn back_projection_inverts_the_camera_to_a_centimetre_at_five_metres() {
        let cam = CameraCalibration::default();
        for (pose, p) in [
            (FloorPose { position: [1.0, 2.0], heading: 0.7 }, [4.0, 6.0]),
            (FloorPose { position: [-3.0, 0.5], heading: -2.0 }, [-5.0, -4.0]),
            (FloorPose { position: [0.0, 0.0], heading: 0.0 }, [5.0, 0.0]),
        ] {
            let range = (p[0] - pose.position[0]).hypot(p[1] - pose.position[1]);
            assert!((4.0..=5.5).contains(&range), "the test's points are about 5 m away");
            for height in [0.0, ANKLE_HEIGHT, 1.7] {
                let img = cam.project(&pose, [p[0], p[1], height]).unwrap();
                let (back, sigma) = cam.back_project(&pose, img, height).unwrap();
                let err = (back[0] - p[0]).hypot(back[1] - p[1]);
                assert!(err < 0.01, "{pose:?} {p:?} at {height} m: {back:?} ({err} m off)");
                assert!(sigma > BASE_SIGMA && sigma < 1.0);
            }
        }
    }

    #[test]
    fn uncertainty_grows_with_distance_and_the_horizon_has_no_floor() {
        let cam = CameraCalibration::default();
        let pose = FloorPose { position: [0.0, 0.0], heading: 0.0 };
        let sigma_at = |x: f32| cam.back_project(&pose, cam.project(&pose, [x, 0.0, 0.0]).unwrap(), 0.0).unwrap().1;
        assert!(sigma_at(2.0) < sigma_at(5.0) && sigma_at(5.0) < sigma_at(10.0));
        assert!(cam.back_project(&pose, (320.0, 100.0), 0.0).is_none(), "above the horizon: no floor point");
    }

    #[test]
    fn bad_calibration_names_the_field() {
        let c = CameraCalibration { fov_deg: 200.0, ..Default::default() };
        assert!(c.problem().unwrap().contains("camera.fov_deg"));
        assert!(CameraCalibration::default().problem().is_none());
    }
}

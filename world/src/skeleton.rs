//! A simple walking skeleton: the 17 COCO keypoints (nose, eyes, ears, shoulders,
//! elbows, wrists, hips, knees, ankles; left before right) of a person at a floor
//! position and heading, arms and legs swinging with the gait phase when walking, and
//! the head (nose, eyes, ears) turned by its own yaw.

use crate::geometry::P2;

/// (forward, left, up) offsets in metres, and how much the point swings with the gait
/// (forward metres at full stride; legs and arms in opposition).
const BODY: [([f32; 3], f32); 17] = [
    ([0.10, 0.00, 1.62], 0.0),    // nose
    ([0.08, 0.04, 1.66], 0.0),    // left eye
    ([0.08, -0.04, 1.66], 0.0),   // right eye
    ([0.00, 0.08, 1.63], 0.0),    // left ear
    ([0.00, -0.08, 1.63], 0.0),   // right ear
    ([0.00, 0.20, 1.45], 0.03),   // left shoulder
    ([0.00, -0.20, 1.45], -0.03), // right shoulder
    ([0.00, 0.23, 1.15], 0.15),   // left elbow
    ([0.00, -0.23, 1.15], -0.15), // right elbow
    ([0.03, 0.24, 0.88], 0.30),   // left wrist
    ([0.03, -0.24, 0.88], -0.30), // right wrist
    ([0.00, 0.12, 0.95], -0.02),  // left hip
    ([0.00, -0.12, 0.95], 0.02),  // right hip
    ([0.02, 0.12, 0.50], -0.20),  // left knee
    ([0.02, -0.12, 0.50], 0.20),  // right knee
    ([0.00, 0.12, 0.08], -0.35),  // left ankle
    ([0.00, -0.12, 0.08], 0.35),  // right ankle
];

/// The first keypoints that belong to the head (nose, eyes, ears).
const HEAD: usize = 5;

/// World (x, y, z) of the 17 keypoints; `head_yaw` turns the head from the body.
pub fn keypoints(position: P2, heading: f32, head_yaw: f32, gait: f32, speed: f32) -> [[f32; 3]; 17] {
    let stride = (speed / 1.2).clamp(0.0, 1.0) * gait.sin();
    let mut out = [[0.0; 3]; 17];
    for (k, ([f, l, z], swing)) in BODY.into_iter().enumerate() {
        let yaw = if k < HEAD { heading + head_yaw } else { heading };
        let (c, s) = (yaw.cos(), yaw.sin());
        let f = f + swing * stride;
        out[k] = [position[0] + f * c - l * s, position[1] + f * s + l * c, z];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standing_skeleton_faces_its_heading() {
        let k = keypoints([0.0, 0.0], 0.0, 0.0, 0.0, 0.0);
        assert!(k[0][0] > 0.0, "nose in front");
        assert!(k[5][1] > 0.0 && k[6][1] < 0.0, "left shoulder on the left");
        let walking = keypoints([0.0, 0.0], 0.0, 0.0, std::f32::consts::FRAC_PI_2, 1.2);
        assert!(walking[15][0] < 0.0 && walking[16][0] > 0.0, "feet apart mid-stride");
        let looking_left = keypoints([0.0, 0.0], 0.0, std::f32::consts::FRAC_PI_2, 0.0, 0.0);
        assert!(looking_left[0][1] > 0.05 && looking_left[0][0].abs() < 0.01, "nose turned left");
        assert_eq!(looking_left[5], k[5], "shoulders stay");
    }
}

//! A robot's camera and detector: pinhole projection of the worker and every object to
//! bounding boxes, field of view and range, occlusion, and the detector's failings
//! (misses that grow with distance and occlusion, bbox jitter, false positives, a
//! worker lost for a few frames), plus the worker's 17 projected, noised keypoints.

use crate::appearance::{gauss, Appearance};
use crate::geometry::*;
use crate::layout::{Camera, Layout, Object};
use crate::skeleton;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use spwi_proto::*;

/// The worker's height and half-width, metres.
pub const WORKER_HEIGHT: f32 = 1.75;
pub const WORKER_HALF_WIDTH: f32 = 0.25;
/// Robots: radius and height, metres.
pub const ROBOT_RADIUS: f32 = 0.35;
pub const ROBOT_HEIGHT: f32 = 0.8;

/// A camera pose: position on the floor and heading (radians).
#[derive(Debug, Clone, Copy)]
pub struct Pose {
    pub position: P2,
    pub heading: f32,
}

/// Projects world point (x, y, z) into the image: `None` if behind the camera.
pub fn project(cam: &Camera, pose: Pose, p: [f32; 3]) -> Option<(f32, f32)> {
    let d = sub([p[0], p[1]], pose.position);
    let (c, s) = (pose.heading.cos(), pose.heading.sin());
    let forward = d[0] * c + d[1] * s;
    let left = -d[0] * s + d[1] * c;
    if forward < 0.1 {
        return None;
    }
    let f = cam.focal();
    Some((
        cam.image[0] as f32 / 2.0 - f * left / forward,
        cam.image[1] as f32 / 2.0 - f * (p[2] - cam.height) / forward,
    ))
}

/// Bearing of a floor point from the camera, relative to its axis (radians).
fn bearing(pose: Pose, p: P2) -> f32 {
    let d = sub(p, pose.position);
    angle_diff(d[1].atan2(d[0]), pose.heading)
}

/// Whether floor point `p` lies within the camera's range and field of view (hidden or
/// not).
pub fn in_view(cam: &Camera, pose: Pose, p: P2) -> bool {
    dist(pose.position, p) <= cam.range && bearing(pose, p).abs() <= cam.fov_deg.to_radians() / 2.0
}

/// The bbox of a vertical box (footprint × height), clipped to the image; `None` when
/// not in front of the camera or clipped to nothing.
fn bbox_of(cam: &Camera, pose: Pose, footprint: &Rect, height: f32) -> Option<BBox> {
    let mut pts = Vec::with_capacity(8);
    for c in footprint.corners() {
        for z in [0.0, height] {
            pts.push(project(cam, pose, [c[0], c[1], z])?);
        }
    }
    let (w, h) = (cam.image[0] as f32, cam.image[1] as f32);
    let x0 = pts.iter().map(|p| p.0).fold(f32::INFINITY, f32::min).max(0.0);
    let x1 = pts.iter().map(|p| p.0).fold(f32::NEG_INFINITY, f32::max).min(w);
    let y0 = pts.iter().map(|p| p.1).fold(f32::INFINITY, f32::min).max(0.0);
    let y1 = pts.iter().map(|p| p.1).fold(f32::NEG_INFINITY, f32::max).min(h);
    (x1 - x0 >= 2.0 && y1 - y0 >= 2.0).then_some(BBox { x: x0, y: y0, w: x1 - x0, h: y1 - y0 })
}

/// Something that can hide what is behind it.
pub struct Occluder {
    pub footprint: Rect,
    pub circle: Option<(P2, f32)>,
    pub height: f32,
}

/// How much of a target at `target` (height `height`) the occluders hide from `eye`:
/// 0 (clear), 0.5 (partly, a lower occluder in front), 1 (hidden).
pub fn occlusion(eye: P2, target: P2, height: f32, occluders: &[Occluder], skip: Option<usize>) -> f32 {
    let mut worst: f32 = 0.0;
    for (i, o) in occluders.iter().enumerate() {
        if Some(i) == skip {
            continue;
        }
        let t = match o.circle {
            Some((c, r)) => circle_entry(eye, target, c, r),
            None => (!o.footprint.contains(target)).then(|| o.footprint.entry(eye, target)).flatten(),
        };
        if t.is_some_and(|t| t < 0.98) {
            worst = worst.max(if o.height >= 0.8 * height { 1.0 } else { 0.5 });
        }
    }
    worst
}

/// What a robot's detector is doing between frames (a worker lost for a while).
#[derive(Debug, Clone, Default)]
pub struct DetectorState {
    /// Frames the first worker stays lost.
    pub lost_for: u32,
    /// The same for each other worker.
    pub others_lost: Vec<u32>,
}

/// Everything one camera frame needs to know about the world.
pub struct Scene<'a> {
    pub layout: &'a Layout,
    pub objects: &'a [Object],
    /// Obstacles, then `objects` in order, then robots.
    pub occluders: &'a [Occluder],
    /// Index in `occluders` of `objects[0]`.
    pub first_object: usize,
    /// Every worker on the floor: each hides the others, as a robot does.
    pub workers: &'a [crate::worker::Worker],
    pub appearance: &'a Appearance,
}

/// One robot's detection frame.
pub fn detect(
    scene: &Scene<'_>,
    robot: RobotId,
    capture_us: u64,
    pose: Pose,
    // this robot's own entry in `scene.occluders`
    own_occluder: Option<usize>,
    state: &mut DetectorState,
    rng: &mut ChaCha8Rng,
) -> (DetectionFrame, bool) {
    let cam = &scene.layout.camera;
    let in_view = |p: P2| in_view(cam, pose, p);

    let mut objects = Vec::new();
    let mut seen_classes = Vec::new();
    for (i, o) in scene.objects.iter().enumerate() {
        if !in_view(o.position) {
            continue;
        }
        let occ = occlusion(pose.position, o.position, o.size[2], scene.occluders, Some(scene.first_object + i));
        if occ >= 1.0 {
            continue;
        }
        let Some(b) = bbox_of(cam, pose, &o.footprint(), o.size[2]) else { continue };
        let d = dist(pose.position, o.position) / cam.range;
        if rng.gen::<f32>() < 0.02 + 0.3 * d * d + 0.35 * occ {
            continue; // missed
        }
        // The side of the object the camera sees: the ray's direction against the
        // object's own facing — never where on the floor either of them stands.
        let view = bearing(pose, o.position) + pose.heading - o.yaw_deg.to_radians();
        objects.push(ObjectDetection {
            class: o.class,
            bbox: jitter(b, rng),
            score: (0.95 - 0.4 * d - 0.05 * gauss(rng).abs()).clamp(0.05, 1.0),
            feature: scene.appearance.object(o.class, view, d, 0.0, rng),
        });
        seen_classes.push(o.class);
    }
    // an occasional false positive
    if rng.gen::<f32>() < 0.04 {
        let class = ObjectClass::ALL[rng.gen_range(0..ObjectClass::ALL.len())];
        let (w, h) = (rng.gen_range(20.0..120.0), rng.gen_range(20.0..120.0));
        objects.push(ObjectDetection {
            class,
            bbox: BBox {
                x: rng.gen_range(0.0..cam.image[0] as f32 - w),
                y: rng.gen_range(0.0..cam.image[1] as f32 - h),
                w,
                h,
            },
            score: rng.gen_range(0.3..0.6),
            feature: scene.appearance.object(class, 0.0, 1.0, 0.8, rng),
        });
    }
    objects.truncate(MAX_OBJECTS);

    // the workers, the first first (a world of one draws as it always did)
    let mut humans = Vec::new();
    let mut first_seen = false;
    for (k, wk) in scene.workers.iter().enumerate() {
        if k > 0 && state.others_lost.len() < k {
            state.others_lost.resize(k, 0);
        }
        let lost_for = if k == 0 { &mut state.lost_for } else { &mut state.others_lost[k - 1] };
        let others: Vec<Occluder> =
            scene.workers.iter().enumerate().filter(|&(j, _)| j != k).map(|(_, w)| person(w.position)).collect();
        if let Some(h) = detect_person(scene, pose, wk, &others, own_occluder, lost_for, rng) {
            first_seen |= k == 0;
            humans.push(h);
        }
    }
    let scene_feature = scene.appearance.scene(&seen_classes, rng);
    let frame = DetectionFrame {
        robot,
        capture_us,
        pose: Some(FloorPose { position: pose.position, heading: pose.heading }),
        image_size: [cam.image[0] as f32, cam.image[1] as f32],
        humans,
        objects,
        scene_feature,
    };
    (frame, first_seen)
}

/// A detector's box: jittered by a couple of pixels and a few percent of its size.
fn jitter(b: BBox, rng: &mut ChaCha8Rng) -> BBox {
    let s = |v: f32, rng: &mut ChaCha8Rng| (1.5 + 0.03 * v) * gauss(rng);
    BBox {
        x: b.x + s(b.w, rng),
        y: b.y + s(b.h, rng),
        w: (b.w + s(b.w, rng)).max(1.0),
        h: (b.h + s(b.h, rng)).max(1.0),
    }
}

/// A person, as what hides what stands behind it.
fn person(at: P2) -> Occluder {
    Occluder { footprint: Rect { min: at, max: at }, circle: Some((at, WORKER_HALF_WIDTH)), height: WORKER_HEIGHT }
}

/// One worker as a camera at `pose` detects it, if it does: within range and field of
/// view, not hidden by what stands between (the scene's occluders and the `others`
/// people), not missed (more often far away and partly hidden), not lost for a few
/// frames (`lost_for`).
fn detect_person(
    scene: &Scene<'_>,
    pose: Pose,
    wk: &crate::worker::Worker,
    others: &[Occluder],
    own_occluder: Option<usize>,
    lost_for: &mut u32,
    rng: &mut ChaCha8Rng,
) -> Option<HumanDetection> {
    let cam = &scene.layout.camera;
    if *lost_for > 0 {
        *lost_for -= 1;
        return None;
    }
    if rng.gen::<f32>() < 0.015 {
        *lost_for = rng.gen_range(3..8);
        return None;
    }
    if !in_view(cam, pose, wk.position) {
        return None;
    }
    let occ = occlusion(pose.position, wk.position, WORKER_HEIGHT, scene.occluders, own_occluder).max(occlusion(
        pose.position,
        wk.position,
        WORKER_HEIGHT,
        others,
        None,
    ));
    let footprint = Rect {
        min: sub(wk.position, [WORKER_HALF_WIDTH, WORKER_HALF_WIDTH]),
        max: add(wk.position, [WORKER_HALF_WIDTH, WORKER_HALF_WIDTH]),
    };
    let d = dist(pose.position, wk.position) / cam.range;
    if occ >= 1.0 || rng.gen::<f32>() < 0.01 + 0.2 * d * d + 0.3 * occ {
        return None;
    }
    let b = bbox_of(cam, pose, &footprint, WORKER_HEIGHT)?;
    let keypoints: Vec<f32> = skeleton::keypoints(wk.position, wk.heading, wk.head_yaw, wk.gait, norm(wk.velocity))
        .iter()
        .map(|&p| project(cam, pose, p).map(|(u, v)| [u + 2.0 * gauss(rng), v + 2.0 * gauss(rng)]))
        .collect::<Option<Vec<_>>>()?
        .into_iter()
        .flatten()
        .collect();
    let line_of_sight = sub(wk.position, pose.position);
    let orientation = wk.heading - line_of_sight[1].atan2(line_of_sight[0]);
    Some(HumanDetection {
        bbox: jitter(b, rng),
        keypoints,
        feature: scene.appearance.human(orientation, d, rng),
        track: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_puts_the_axis_at_the_image_centre() {
        let l = crate::layout::Layout::default_layout();
        let pose = Pose { position: [0.0, 0.0], heading: 0.0 };
        let (u, v) = project(&l.camera, pose, [5.0, 0.0, l.camera.height]).unwrap();
        assert!((u - 320.0).abs() < 1e-3 && (v - 240.0).abs() < 1e-3);
        let (u, _) = project(&l.camera, pose, [5.0, 1.0, 0.0]).unwrap();
        assert!(u < 320.0, "a point to the left projects left");
        assert!(project(&l.camera, pose, [-1.0, 0.0, 0.0]).is_none());
    }

    #[test]
    fn an_obstacle_hides_what_is_behind_it() {
        let wall = Occluder { footprint: Rect { min: [2.0, -1.0], max: [3.0, 1.0] }, circle: None, height: 2.2 };
        assert_eq!(occlusion([0.0, 0.0], [5.0, 0.0], 1.0, std::slice::from_ref(&wall), None), 1.0);
        assert_eq!(occlusion([0.0, 0.0], [5.0, 3.0], 1.0, std::slice::from_ref(&wall), None), 0.0);
        let low = Occluder { footprint: Rect { min: [2.0, -1.0], max: [3.0, 1.0] }, circle: None, height: 0.5 };
        assert_eq!(occlusion([0.0, 0.0], [5.0, 0.0], 1.75, &[low], None), 0.5);
    }
}

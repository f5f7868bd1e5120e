//! Cameras that lie, for the faults the evaluation and the world service inject.
//!
//! - [`StuckCamera`]: once it has seen the worker it keeps returning that frame,
//!   stamped with the current tick — confident, plausible and wrong (`eval --faulty`,
//!   `world --stuck-slot`). A frame repeated exactly gives it away.
//! - [`LoopingCamera`]: once it has seen the worker it records [`LOOP_TICKS`] frames
//!   and then plays them back over and over (`eval --looping`): every frame differs
//!   from the last, but each was shown before, which gives it away once the clip comes
//!   round (`spwi_core::stale`).

use spwi_proto::DetectionFrame;

/// Length of the looping camera's clip: 5 s at 10 Hz.
pub const LOOP_TICKS: usize = 50;

#[derive(Debug, Default)]
pub struct StuckCamera {
    frozen: Option<DetectionFrame>,
}

impl StuckCamera {
    /// What the stuck camera delivers instead of `frame`.
    pub fn pass(&mut self, frame: DetectionFrame) -> DetectionFrame {
        match &self.frozen {
            Some(f) => DetectionFrame { capture_us: frame.capture_us, ..f.clone() },
            None => {
                if frame.worker().is_some() {
                    self.frozen = Some(frame.clone());
                }
                frame
            }
        }
    }
}

#[derive(Debug, Default)]
pub struct LoopingCamera {
    clip: Vec<DetectionFrame>,
    played: usize,
}

impl LoopingCamera {
    /// What the looping camera delivers instead of `frame`.
    pub fn pass(&mut self, frame: DetectionFrame) -> DetectionFrame {
        if self.clip.len() < LOOP_TICKS {
            if !self.clip.is_empty() || frame.worker().is_some() {
                self.clip.push(frame.clone());
            }
            return frame;
        }
        let old = &self.clip[self.played % LOOP_TICKS];
        self.played += 1;
        DetectionFrame { capture_us: frame.capture_us, ..old.clone() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spwi_proto::RobotId;
    use spwi_world::layout::Layout;
    use spwi_world::world::{Scenario, World};

    #[test]
    fn it_freezes_on_the_first_frame_that_shows_the_worker() {
        let mut world = World::new(Layout::default_layout(), Scenario::Dynamic, 3, 1);
        let id = RobotId::new("r0").unwrap();
        let mut cam = StuckCamera::default();
        let mut first_seen = None;
        for _ in 0..300 {
            world.step();
            let live = world.observe(0, &id);
            let out = cam.pass(live.clone());
            assert_eq!(out.capture_us, live.capture_us);
            match &first_seen {
                None if live.worker().is_some() => first_seen = Some(live),
                None => assert_eq!(out, live, "nothing to freeze on yet"),
                Some(f) => assert_eq!(DetectionFrame { capture_us: f.capture_us, ..out }, *f),
            }
        }
        assert!(first_seen.is_some(), "robot 0 saw the worker in 30 s");
    }

    #[test]
    fn it_loops_the_first_five_seconds_after_it_saw_the_worker() {
        let mut world = World::new(Layout::default_layout(), Scenario::Dynamic, 3, 1);
        let id = RobotId::new("r0").unwrap();
        let mut cam = LoopingCamera::default();
        let mut clip = Vec::new();
        let mut played = Vec::new();
        for _ in 0..300 {
            world.step();
            let live = world.observe(0, &id);
            let out = cam.pass(live.clone());
            assert_eq!(out.capture_us, live.capture_us);
            if clip.len() < LOOP_TICKS {
                if !clip.is_empty() || live.worker().is_some() {
                    clip.push(live.clone());
                }
                assert_eq!(out, live, "recording: passes the live frame");
            } else {
                played.push(out);
            }
        }
        assert!(played.len() > 2 * LOOP_TICKS, "robot 0 saw the worker early enough");
        for (i, p) in played.iter().enumerate() {
            assert_eq!(
                DetectionFrame { capture_us: clip[i % LOOP_TICKS].capture_us, ..p.clone() },
                clip[i % LOOP_TICKS]
            );
        }
        assert!(played.windows(2).any(|w| w[0].humans != w[1].humans), "the clip moves");
    }
}

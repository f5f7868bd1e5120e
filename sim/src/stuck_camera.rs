//! A camera stuck on one frame: once it has seen the worker it keeps returning that
//! frame, stamped with the current tick — confident, plausible and wrong. The fault
//! the evaluation's `--faulty` and the world service's `--stuck-slot` inject.

use spwi_proto::DetectionFrame;

#[derive(Debug, Default)]
pub struct StuckCamera {
    frozen: Option<DetectionFrame>,
}

impl StuckCamera {
    /// What the stuck camera delivers instead of `frame`.
    pub fn pass(&mut self, frame: DetectionFrame) -> DetectionFrame {
        match &self.frozen {
            Some(f) => DetectionFrame { tick: frame.tick, ..f.clone() },
            None => {
                if frame.human.is_some() {
                    self.frozen = Some(frame.clone());
                }
                frame
            }
        }
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
            assert_eq!(out.tick, live.tick);
            match &first_seen {
                None if live.human.is_some() => first_seen = Some(live),
                None => assert_eq!(out, live, "nothing to freeze on yet"),
                Some(f) => assert_eq!(DetectionFrame { tick: f.tick, ..out }, *f),
            }
        }
        assert!(first_seen.is_some(), "robot 0 saw the worker in 30 s");
    }
}

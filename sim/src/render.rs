//! `spwi-sim render`: a top-down picture of the floor (stations and their objects,
//! obstacles, robots with their camera cones, the worker, its goal) beside what each
//! robot's camera reports (the worker's box and keypoints in red, objects in their
//! station's colour, unknown classes in grey), so a person can check by eye that the
//! world is sane. A tiny rasteriser writes the PNG; no fonts (the colours are the key).

use crate::world_args::{check_robots, WorldArgs};
use anyhow::{Context, Result};
use spwi_proto::{DetectionFrame, RobotId};
use spwi_world::camera::ROBOT_RADIUS;
use spwi_world::geometry::P2;
use spwi_world::world::World;
use std::path::Path;
use std::path::PathBuf;

type Rgb = [u8; 3];
const STATION: [Rgb; spwi_proto::NUM_CLASSES] = [[184, 134, 11], [31, 119, 180], [44, 160, 44], [214, 39, 40]];
const WORKER: Rgb = [200, 30, 30];
const GREY: Rgb = [150, 150, 150];
const DARK: Rgb = [50, 50, 50];
const CONE: Rgb = [205, 215, 235];

struct Canvas {
    w: usize,
    h: usize,
    px: Vec<u8>,
}

impl Canvas {
    fn new(w: usize, h: usize) -> Canvas {
        Canvas { w, h, px: vec![255; w * h * 3] }
    }
    fn set(&mut self, x: i64, y: i64, c: Rgb) {
        if x >= 0 && y >= 0 && (x as usize) < self.w && (y as usize) < self.h {
            let i = (y as usize * self.w + x as usize) * 3;
            self.px[i..i + 3].copy_from_slice(&c);
        }
    }
    fn fill(&mut self, x0: f32, y0: f32, x1: f32, y1: f32, c: Rgb) {
        for y in y0.min(y1).round() as i64..=y0.max(y1).round() as i64 {
            for x in x0.min(x1).round() as i64..=x0.max(x1).round() as i64 {
                self.set(x, y, c);
            }
        }
    }
    fn line(&mut self, a: (f32, f32), b: (f32, f32), c: Rgb) {
        let n = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as i64).max(1);
        for i in 0..=n {
            let t = i as f32 / n as f32;
            self.set((a.0 + (b.0 - a.0) * t).round() as i64, (a.1 + (b.1 - a.1) * t).round() as i64, c);
        }
    }
    fn frame(&mut self, x0: f32, y0: f32, x1: f32, y1: f32, c: Rgb) {
        self.line((x0, y0), (x1, y0), c);
        self.line((x1, y0), (x1, y1), c);
        self.line((x1, y1), (x0, y1), c);
        self.line((x0, y1), (x0, y0), c);
    }
    fn disc(&mut self, cx: f32, cy: f32, r: f32, c: Rgb) {
        for y in (cy - r).floor() as i64..=(cy + r).ceil() as i64 {
            for x in (cx - r).floor() as i64..=(cx + r).ceil() as i64 {
                if (x as f32 - cx).powi(2) + (y as f32 - cy).powi(2) <= r * r {
                    self.set(x, y, c);
                }
            }
        }
    }
    fn save(&self, path: &Path) -> Result<()> {
        let file = std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
        let mut enc = png::Encoder::new(std::io::BufWriter::new(file), self.w as u32, self.h as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.write_header()?.write_image_data(&self.px)?;
        Ok(())
    }
}

fn station_colour(class: spwi_proto::ObjectClass) -> Rgb {
    class.station().map_or(GREY, |s| STATION[s.index()])
}

/// Draws the world as it is now and the given frames (one per robot slot, in order).
pub fn render(world: &World, frames: &[(usize, DetectionFrame)], out: &Path) -> Result<()> {
    const MAP_H: usize = 560;
    const VIEW_W: usize = 320;
    let l = &world.layout;
    let k = (MAP_H as f32 - 20.0) / l.floor.size[1];
    let map_w = (l.floor.size[0] * k + 20.0) as usize;
    let views_per_col = 2;
    let cols = frames.len().div_ceil(views_per_col).max(1);
    let mut c = Canvas::new(map_w + cols * (VIEW_W + 10) + 10, MAP_H);
    let to = |p: P2| (10.0 + p[0] * k, MAP_H as f32 - 10.0 - p[1] * k);

    // floor, camera cones, obstacles, stations
    let (a, b) = (to([0.0, 0.0]), to(l.floor.size));
    c.frame(a.0, a.1, b.0, b.1, DARK);
    let half = l.camera.fov_deg.to_radians() / 2.0;
    for (slot, _) in frames {
        let p = world.robots[*slot].pose;
        for i in 0..=40 {
            let ang = p.heading - half + 2.0 * half * i as f32 / 40.0;
            let end = [p.position[0] + l.camera.range * ang.cos(), p.position[1] + l.camera.range * ang.sin()];
            c.line(to(p.position), to(end), CONE);
        }
    }
    if world.scenario.obstacles() {
        for o in &l.obstacles {
            let (a, b) = (to(o.min), to(o.max));
            c.fill(a.0, a.1, b.0, b.1, GREY);
        }
    }
    for s in &l.stations {
        let col = STATION[s.id.index()];
        for o in &s.objects {
            let f = o.footprint();
            let (a, b) = (to(f.min), to(f.max));
            c.fill(a.0, a.1, b.0, b.1, col);
        }
        let w = to(s.work_spot);
        c.frame(w.0 - 5.0, w.1 - 5.0, w.0 + 5.0, w.1 + 5.0, col);
    }
    // every robot on the floor; those outside the fleet (no agent running) in grey
    for (slot, r) in world.robots.iter().enumerate() {
        let p = r.pose;
        let q = to(p.position);
        let in_view = frames.iter().any(|(s, _)| *s == slot);
        c.disc(q.0, q.1, ROBOT_RADIUS * k, if in_view { DARK } else { GREY });
        let nose = to([p.position[0] + 0.6 * p.heading.cos(), p.position[1] + 0.6 * p.heading.sin()]);
        c.line(q, nose, DARK);
    }
    // every worker, a line to where it goes
    for worker in &world.workers {
        let (wk, spot) = (to(worker.position), to(worker.spot()));
        c.line(wk, spot, STATION[worker.goal.index()]);
        c.disc(wk.0, wk.1, 0.3 * k, WORKER);
    }

    // camera views, scaled to VIEW_W wide
    for (i, (_, f)) in frames.iter().enumerate() {
        let s = VIEW_W as f32 / f.image_size[0];
        let (ox, oy) = (
            (map_w + 10 + (i / views_per_col) * (VIEW_W + 10)) as f32,
            10.0 + (i % views_per_col) as f32 * (f.image_size[1] * s + 20.0),
        );
        c.frame(ox, oy, ox + f.image_size[0] * s, oy + f.image_size[1] * s, DARK);
        for o in &f.objects {
            let b = o.bbox;
            c.frame(ox + b.x * s, oy + b.y * s, ox + (b.x + b.w) * s, oy + (b.y + b.h) * s, station_colour(o.class));
        }
        for h in &f.humans {
            let b = h.bbox;
            c.frame(ox + b.x * s, oy + b.y * s, ox + (b.x + b.w) * s, oy + (b.y + b.h) * s, WORKER);
            for kp in h.keypoints.chunks_exact(2) {
                c.disc(ox + kp[0] * s, oy + kp[1] * s, 1.5, WORKER);
            }
        }
    }
    c.save(out)
}

/// Runs a world to `tick` and renders it with the first `robots` robots.
pub fn render_tick(mut world: World, robots: usize, tick: u64, out: &Path) -> Result<()> {
    while world.tick < tick {
        world.step();
    }
    let frames: Vec<(usize, DetectionFrame)> = (0..robots)
        .map(|slot| Ok((slot, world.observe(slot, &RobotId::new(format!("r{slot}"))?))))
        .collect::<Result<_>>()?;
    render(&world, &frames, out)
}

/// The arguments of `spwi-sim render`.
#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[arg(long, default_value_t = 100)]
    pub tick: u64,
    #[arg(long, default_value_t = 4)]
    pub robots: usize,
    #[arg(long, default_value = "scene.png")]
    pub out: PathBuf,
}

/// `spwi-sim render`: parses nothing more, runs the tool.
pub fn main(a: RenderArgs) -> Result<()> {
    let RenderArgs { world: w, seed, tick, robots, out } = a;
    let floor = w.floor()?;
    check_robots(robots, std::slice::from_ref(&floor))?;
    let world = spwi_world::world::World::with_workers(floor.layout, w.scenario, seed, robots, usize::from(w.workers));
    crate::render::render_tick(world, robots, tick, &out)?;
    println!("wrote {}", out.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use spwi_world::layout::Layout;
    use spwi_world::world::Scenario;

    #[test]
    fn renders_a_png_with_map_and_views() {
        let out = std::env::temp_dir().join(format!("spwi-render-{}.png", std::process::id()));
        render_tick(World::new(Layout::default_layout(), Scenario::Dynamic, 1, 3), 3, 30, &out).unwrap();
        let bytes = std::fs::read(&out).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let info = decoder.read_info().unwrap();
        assert!(info.info().width > 800 && info.info().height == 560);
        std::fs::remove_file(out).unwrap();
    }
}

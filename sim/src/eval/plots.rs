//! `spwi-sim eval --plots DIR`: the studies as PNG figures (plotters, bitmap backend):
//! accuracy against the number of robots, the time horizons (with their 95 % intervals),
//! the temporal resolution, and the confusion matrices at t.
//!
//! Text needs a TrueType font; plotters is built without system-font lookup, so the
//! font is read from `SPWI_FONT` or Debian's DejaVu Sans (package fonts-dejavu-core).

use super::score::Confusion;
use super::scored::Scored;
use super::studies::Studies;
use super::Report;
use anyhow::{anyhow, Context, Result};
use plotters::prelude::*;
use spwi_world::world::Scenario;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const DEFAULT_FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
const SIZE: (u32, u32) = (720, 440);
const COLOURS: [RGBColor; 5] = [
    RGBColor(200, 40, 40),
    RGBColor(40, 90, 200),
    RGBColor(30, 150, 70),
    RGBColor(150, 90, 20),
    RGBColor(120, 60, 160),
];

/// Registers the font once per process.
fn font() -> Result<()> {
    static LOADED: OnceLock<Result<(), String>> = OnceLock::new();
    LOADED
        .get_or_init(|| {
            let path = std::env::var("SPWI_FONT").unwrap_or_else(|_| DEFAULT_FONT.to_owned());
            let bytes = std::fs::read(&path).map_err(|e| {
                format!("--plots needs a TrueType font: cannot read {path} ({e}); install fonts-dejavu-core or set SPWI_FONT")
            })?;
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
                .map_err(|_| format!("{path} is not a usable TrueType font"))
        })
        .clone()
        .map_err(|e| anyhow!(e))
}

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("drawing a figure: {e:?}")
}

/// A line chart of `series` (name, points) with y in percent.
fn lines(path: &Path, title: &str, x_desc: &str, x: (f64, f64), series: &[(String, Vec<(f64, f64)>)]) -> Result<()> {
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(44)
        .build_cartesian_2d(x.0..x.1, 0f64..100f64)
        .map_err(err)?;
    chart.configure_mesh().x_desc(x_desc).y_desc("%").draw().map_err(err)?;
    for (i, (name, points)) in series.iter().enumerate() {
        let c = COLOURS[i % COLOURS.len()];
        chart
            .draw_series(LineSeries::new(points.iter().copied(), c.stroke_width(2)))
            .map_err(err)?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], c.stroke_width(2)));
        chart.draw_series(points.iter().map(|&p| Circle::new(p, 3, c.filled()))).map_err(err)?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

/// A 4 × 4 confusion matrix at t: cells shaded by their share of the true class
/// (each row sums to 100 %); station k is the cell from k to k + 1 on each axis.
pub fn confusion(path: &Path, title: &str, c: &Confusion) -> Result<()> {
    font()?;
    let root = BitMapBackend::new(path, (480, 480)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0i32..4, 0i32..4)
        .map_err(err)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("predicted station (cell k to k+1 = station k)")
        .y_desc("true station")
        .x_labels(4)
        .y_labels(4)
        .draw()
        .map_err(err)?;
    for (truth, row) in c.iter().enumerate() {
        let total = row.iter().sum::<u64>().max(1) as f64;
        for (pred, &n) in row.iter().enumerate() {
            let share = n as f64 / total;
            let shade = (255.0 * (1.0 - share)) as u8;
            let (x, y) = (pred as i32, truth as i32);
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(x, y), (x + 1, y + 1)],
                    RGBColor(shade, shade, 255).filled(),
                )))
                .map_err(err)?;
            let ink = if share > 0.5 { WHITE } else { BLACK };
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("{:.0}%", 100.0 * share),
                    (x, y + 1),
                    ("sans-serif", 16).into_font().color(&ink),
                )))
                .map_err(err)?;
        }
    }
    root.present().map_err(err)?;
    Ok(())
}

fn pct(r: &Report, model: Scored, future: bool) -> f64 {
    r.models.get(&model).map_or(0.0, |a| 100.0 * if future { a.future.unwrap_or(0.0) } else { a.t })
}

/// Every figure of `--all` into `dir`; returns the files written.
pub fn write_all(st: &Studies, dir: &Path) -> Result<Vec<PathBuf>> {
    font()?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut written = Vec::new();

    let robots = dir.join("robots.png");
    let by_robots = |f: &dyn Fn(&Report) -> f64| st.robots.iter().map(|r| (r.robots as f64, f(r))).collect::<Vec<_>>();
    lines(
        &robots,
        "Scenario 3, 2 s → 2 s: accuracy at t against the number of robots",
        "robots",
        (0.5, 8.5),
        &[
            ("collective-GRU".into(), by_robots(&|r| pct(r, Scored::Collective, false))),
            ("consensus".into(), by_robots(&|r| pct(r, Scored::Consensus, false))),
            ("ego-GRU".into(), by_robots(&|r| pct(r, Scored::Ego, false))),
            ("coverage (ticks decided)".into(), by_robots(&|r| 100.0 * r.coverage)),
            ("team over all ticks".into(), by_robots(&|r| pct(r, Scored::TeamAllTicks, false))),
        ],
    )?;
    written.push(robots);

    let horizons = dir.join("horizons.png");
    let mut series = Vec::new();
    for robots in [1, 3] {
        let of = |f: &dyn Fn(&Report) -> f64| {
            st.horizons
                .iter()
                .filter(|r| r.robots == robots)
                .map(|r| (r.window as f64 * spwi_proto::TICK_PERIOD.as_secs_f64(), f(r)))
                .collect::<Vec<_>>()
        };
        let s = if robots > 1 { "s" } else { "" };
        series.push((format!("collective t, {robots} robot{s}"), of(&|r| pct(r, Scored::Collective, false))));
        series.push((
            format!("  95 % CI low, {robots} robot{s}"),
            of(&|r| r.models.get(&Scored::Collective).map_or(0.0, |a| 100.0 * a.t_ci95[0])),
        ));
        series.push((
            format!("  95 % CI high, {robots} robot{s}"),
            of(&|r| r.models.get(&Scored::Collective).map_or(0.0, |a| 100.0 * a.t_ci95[1])),
        ));
    }
    lines(
        &horizons,
        "Scenario 3: past = future horizon (s), collective-GRU at t",
        "seconds of past (and of future)",
        (0.5, 3.5),
        &series,
    )?;
    written.push(horizons);

    let resolution = dir.join("resolution.png");
    let by_frames =
        |f: &dyn Fn(&Report) -> f64| st.resolution.iter().map(|r| (r.frames as f64, f(r))).collect::<Vec<_>>();
    lines(
        &resolution,
        "Scenario 3, 3 robots, 1 s → 1 s: frames of the last second",
        "frames",
        (2.0, 11.0),
        &[
            ("collective t".into(), by_frames(&|r| pct(r, Scored::Collective, false))),
            ("collective t+1…H".into(), by_frames(&|r| pct(r, Scored::Collective, true))),
            ("ego t".into(), by_frames(&|r| pct(r, Scored::Ego, false))),
            ("consensus t".into(), by_frames(&|r| pct(r, Scored::Consensus, false))),
        ],
    )?;
    written.push(resolution);

    if let Some(r) = st.scenarios.iter().find(|r| r.scenario == Scenario::Dynamic) {
        for (name, c) in &r.confusion {
            let path = dir.join(format!("confusion_{name}.png"));
            confusion(&path, &format!("{name}, scenario 3, 3 robots: share of each true station"), c)?;
            written.push(path);
        }
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_confusion_matrix_becomes_a_png() {
        let path = std::env::temp_dir().join(format!("spwi-confusion-{}.png", std::process::id()));
        let c: Confusion = [[50, 2, 1, 0], [3, 40, 5, 0], [0, 4, 30, 20], [0, 0, 25, 22]];
        confusion(&path, "test", &c).expect("needs fonts-dejavu-core (or SPWI_FONT)");
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        assert!(bytes.len() > 2000, "an empty picture? {} bytes", bytes.len());
        std::fs::remove_file(path).unwrap();
    }
}

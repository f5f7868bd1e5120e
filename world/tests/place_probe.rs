//! No absolute-place shortcut: a least-squares probe cannot read a robot's floor
//! position from the global scene features of its frames.
//!
//! Frames come from many generated floors; the probe (ridge-regularised least squares
//! on all 512 features plus a bias) is fitted on 60 % of them and scored on the rest.
//! A control appends a term linear in the floor position — what the scene feature used
//! to carry — and the same probe must then recover the position, so the test can fail.

// The linear algebra reads as the maths it is: indices, not iterators.
#![allow(clippy::needless_range_loop)]

use spwi_proto::RobotId;
use spwi_world::generate;
use spwi_world::world::{Scenario, World};

/// Scene features and the (x, y) of the robot that saw them.
fn frames() -> (Vec<Vec<f64>>, Vec<[f64; 2]>) {
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    let ids: Vec<RobotId> = (0..8).map(|i| RobotId::new(format!("r{i}")).unwrap()).collect();
    for floor in 0..40 {
        let mut w = World::new(generate::layout(500 + floor), Scenario::Dynamic, floor, 8);
        for t in 0..160 {
            w.step();
            if t % 10 != 0 {
                continue; // frames 1 s apart
            }
            for (slot, id) in ids.iter().enumerate() {
                let f = w.observe(slot, id);
                xs.push(f.scene_feature.iter().map(|&v| v as f64).collect());
                let p = w.robots[slot].pose.position;
                ys.push([p[0] as f64, p[1] as f64]);
            }
        }
    }
    (xs, ys)
}

/// Solves (A + λI) w = b for symmetric positive definite A (Cholesky), in place.
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>, lambda: f64) -> Vec<f64> {
    let n = b.len();
    for (i, row) in a.iter_mut().enumerate() {
        row[i] += lambda;
    }
    for j in 0..n {
        let d = (a[j][j] - (0..j).map(|k| a[j][k] * a[j][k]).sum::<f64>()).sqrt();
        a[j][j] = d;
        for i in j + 1..n {
            a[i][j] = (a[i][j] - (0..j).map(|k| a[i][k] * a[j][k]).sum::<f64>()) / d;
        }
    }
    for i in 0..n {
        b[i] = (b[i] - (0..i).map(|k| a[i][k] * b[k]).sum::<f64>()) / a[i][i];
    }
    for i in (0..n).rev() {
        b[i] = (b[i] - (i + 1..n).map(|k| a[k][i] * b[k]).sum::<f64>()) / a[i][i];
    }
    b
}

/// Held-out R² of a linear probe for each coordinate.
fn probe_r2(xs: &[Vec<f64>], ys: &[[f64; 2]]) -> [f64; 2] {
    let rows: Vec<Vec<f64>> = xs.iter().map(|x| x.iter().copied().chain([1.0]).collect()).collect();
    let split = rows.len() * 6 / 10;
    let (train, test) = (&rows[..split], &rows[split..]);
    let d = rows[0].len();
    let mut xtx = vec![vec![0.0; d]; d];
    for r in train {
        for i in 0..d {
            for j in 0..=i {
                xtx[i][j] += r[i] * r[j];
            }
        }
    }
    for i in 0..d {
        for j in 0..i {
            xtx[j][i] = xtx[i][j];
        }
    }
    let mut r2 = [0.0; 2];
    for (c, out) in r2.iter_mut().enumerate() {
        let xty: Vec<f64> = (0..d).map(|i| train.iter().zip(ys).map(|(r, y)| r[i] * y[c]).sum()).collect();
        let w = solve(xtx.clone(), xty, 1e-3 * split as f64);
        let truth: Vec<f64> = ys[split..].iter().map(|y| y[c]).collect();
        let mean = truth.iter().sum::<f64>() / truth.len() as f64;
        let sse: f64 =
            test.iter().zip(&truth).map(|(r, y)| (r.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>() - y).powi(2)).sum();
        let sst: f64 = truth.iter().map(|y| (y - mean).powi(2)).sum();
        *out = 1.0 - sse / sst;
    }
    r2
}

#[test]
fn scene_features_do_not_tell_where_the_robot_stands() {
    let (xs, ys) = frames();
    assert!(xs.len() >= 4000, "{} frames", xs.len());
    let r2 = probe_r2(&xs, &ys);
    assert!(r2.iter().all(|&r| r < 0.1), "the probe recovers the floor position: R² = {r2:?}");

    // Control: the same probe on features that carry the position does find it.
    let with_place: Vec<Vec<f64>> = xs
        .iter()
        .zip(&ys)
        .map(|(x, y)| {
            x.iter().enumerate().map(|(k, v)| v + 0.02 * (y[0] * (k % 7) as f64 - y[1] * (k % 5) as f64)).collect()
        })
        .collect();
    let control = probe_r2(&with_place, &ys);
    eprintln!("held-out R²: scene features {r2:.3?}, with a place term {control:.3?}");
    assert!(control.iter().all(|&r| r > 0.5), "the probe is too weak to mean anything: R² = {control:?}");
}

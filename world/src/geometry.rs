//! 2-D geometry of the floor: points, boxes, segment tests. Pure and tiny.

use serde::{Deserialize, Serialize};

pub type P2 = [f32; 2];

pub fn sub(a: P2, b: P2) -> P2 {
    [a[0] - b[0], a[1] - b[1]]
}
pub fn add(a: P2, b: P2) -> P2 {
    [a[0] + b[0], a[1] + b[1]]
}
pub fn scale(a: P2, k: f32) -> P2 {
    [a[0] * k, a[1] * k]
}
pub fn norm(a: P2) -> f32 {
    (a[0] * a[0] + a[1] * a[1]).sqrt()
}
pub fn dist(a: P2, b: P2) -> f32 {
    norm(sub(a, b))
}
pub fn unit(a: P2) -> P2 {
    let n = norm(a);
    if n > 1e-9 {
        scale(a, 1.0 / n)
    } else {
        [0.0, 0.0]
    }
}

/// `a - b` wrapped to (-π, π].
pub fn angle_diff(a: f32, b: f32) -> f32 {
    (a - b).sin().atan2((a - b).cos())
}

/// Distance from `p` to the segment a→b.
pub fn segment_dist(a: P2, b: P2, p: P2) -> f32 {
    let d = sub(b, a);
    let len2 = d[0] * d[0] + d[1] * d[1];
    let t = if len2 < 1e-12 { 0.0 } else { (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0) };
    dist(p, add(a, scale(d, t)))
}

/// An axis-aligned box on the floor.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Rect {
    pub min: P2,
    pub max: P2,
}

impl Rect {
    pub fn contains(&self, p: P2) -> bool {
        p[0] >= self.min[0] && p[0] <= self.max[0] && p[1] >= self.min[1] && p[1] <= self.max[1]
    }

    /// Whether the interiors of two boxes share some area.
    pub fn overlaps(&self, o: &Rect) -> bool {
        self.min[0] < o.max[0] && o.min[0] < self.max[0] && self.min[1] < o.max[1] && o.min[1] < self.max[1]
    }

    /// The area two boxes share, m².
    pub fn overlap_area(&self, o: &Rect) -> f32 {
        let w = self.max[0].min(o.max[0]) - self.min[0].max(o.min[0]);
        let h = self.max[1].min(o.max[1]) - self.min[1].max(o.min[1]);
        w.max(0.0) * h.max(0.0)
    }

    pub fn area(&self) -> f32 {
        (self.max[0] - self.min[0]) * (self.max[1] - self.min[1])
    }

    /// Whether `o` lies inside this box whole.
    pub fn contains_rect(&self, o: &Rect) -> bool {
        self.contains(o.min) && self.contains(o.max)
    }

    pub fn inflate(&self, r: f32) -> Rect {
        Rect { min: [self.min[0] - r, self.min[1] - r], max: [self.max[0] + r, self.max[1] + r] }
    }

    pub fn corners(&self) -> [P2; 4] {
        [self.min, [self.max[0], self.min[1]], self.max, [self.min[0], self.max[1]]]
    }

    /// The point of the box nearest to `p` (p itself when inside).
    pub fn closest(&self, p: P2) -> P2 {
        [p[0].clamp(self.min[0], self.max[0]), p[1].clamp(self.min[1], self.max[1])]
    }

    /// Whether the open segment a→b passes through the box's interior (with a small
    /// tolerance, so grazing an edge does not count).
    pub fn blocks(&self, a: P2, b: P2) -> bool {
        self.inflate(-1e-3).entry(a, b).is_some()
    }

    /// Distance along a→b (as a fraction) at which the segment enters the box, if it does.
    pub fn entry(&self, a: P2, b: P2) -> Option<f32> {
        let (mut t0, mut t1) = (0.0f32, 1.0f32);
        let d = sub(b, a);
        for k in 0..2 {
            if d[k].abs() < 1e-9 {
                if a[k] < self.min[k] || a[k] > self.max[k] {
                    return None;
                }
            } else {
                let (mut ta, mut tb) = ((self.min[k] - a[k]) / d[k], (self.max[k] - a[k]) / d[k]);
                if ta > tb {
                    std::mem::swap(&mut ta, &mut tb);
                }
                t0 = t0.max(ta);
                t1 = t1.min(tb);
                if t0 > t1 {
                    return None;
                }
            }
        }
        Some(t0)
    }
}

/// Distance along a→b (fraction) at which the segment first comes within `r` of `c`.
pub fn circle_entry(a: P2, b: P2, c: P2, r: f32) -> Option<f32> {
    let d = sub(b, a);
    let f = sub(a, c);
    let (qa, qb, qc) =
        (d[0] * d[0] + d[1] * d[1], 2.0 * (f[0] * d[0] + f[1] * d[1]), f[0] * f[0] + f[1] * f[1] - r * r);
    let disc = qb * qb - 4.0 * qa * qc;
    if qa < 1e-12 || disc < 0.0 {
        return None;
    }
    let t = (-qb - disc.sqrt()) / (2.0 * qa);
    (0.0..=1.0).contains(&t).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_and_boxes() {
        let r = Rect { min: [1.0, 1.0], max: [2.0, 2.0] };
        assert!(r.blocks([0.0, 1.5], [3.0, 1.5]));
        assert!(!r.blocks([0.0, 0.5], [3.0, 0.5]));
        assert!(!r.blocks([0.0, 1.0], [3.0, 1.0]), "grazing an edge is not blocking");
        assert!((r.entry([0.0, 1.5], [4.0, 1.5]).unwrap() - 0.25).abs() < 1e-6);
        assert!((circle_entry([0.0, 0.0], [4.0, 0.0], [2.0, 0.0], 1.0).unwrap() - 0.25).abs() < 1e-6);
        assert!(circle_entry([0.0, 2.0], [4.0, 2.0], [2.0, 0.0], 1.0).is_none());
    }
}

//! The way a person walks to each station round what stands in the way.
//!
//! The relation rows measure a station's distance and bearing along the straight line
//! from the worker. A worker whose goal lies behind a rack walks to the rack's corner
//! first, and along that leg the straight-line bearing of its goal points into the rack
//! while a station it happens to walk towards looks like the goal. A set whose rows
//! read routes (`"row": "route_facing"` in its manifest) measures every station along
//! the shortest path round the obstacles instead: [`Obstacles::route_targets`] puts
//! each station in the direction of its route's first leg, as far away as the whole
//! route is long, and the relation and facing blocks are computed against those
//! points, so their closing speed is the rate at which the walk to the station shrinks
//! and their bearings say whether the worker heads down that route.
//!
//! Obstacles are axis-aligned footprints on the floor, grown by a person's clearance;
//! the shortest path runs over their corners (a visibility graph, as people cut
//! corners). Where the worker or a station stands inside a grown footprint (a noisy
//! track, a station's objects against a rack), that footprint does not block the legs
//! that start or end there.

use spwi_proto::NUM_CLASSES;

/// How far a walking person keeps from an obstacle's edge, metres (body radius and a
/// margin): footprints grow by this before routes are planned round them.
pub const CLEARANCE: f32 = 0.35;

/// An axis-aligned box on the floor: its lower and upper corners, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Footprint {
    pub min: [f32; 2],
    pub max: [f32; 2],
}

impl Footprint {
    fn grow(self, r: f32) -> Footprint {
        Footprint { min: [self.min[0] - r, self.min[1] - r], max: [self.max[0] + r, self.max[1] + r] }
    }

    fn contains(&self, p: [f32; 2]) -> bool {
        (0..2).all(|k| p[k] > self.min[k] && p[k] < self.max[k])
    }

    /// Whether the segment a→b passes through the interior (grazing an edge or a corner
    /// does not count: routes run along them).
    fn blocks(&self, a: [f32; 2], b: [f32; 2]) -> bool {
        let inner = self.grow(-1e-3);
        let (mut t0, mut t1) = (0.0f32, 1.0f32);
        for k in 0..2 {
            let d = b[k] - a[k];
            if d.abs() < 1e-9 {
                if a[k] <= inner.min[k] || a[k] >= inner.max[k] {
                    return false;
                }
                continue;
            }
            let (mut lo, mut hi) = ((inner.min[k] - a[k]) / d, (inner.max[k] - a[k]) / d);
            if lo > hi {
                std::mem::swap(&mut lo, &mut hi);
            }
            t0 = t0.max(lo);
            t1 = t1.min(hi);
            if t0 >= t1 {
                return false;
            }
        }
        true
    }

    fn corners(&self) -> [[f32; 2]; 4] {
        [self.min, [self.max[0], self.min[1]], self.max, [self.min[0], self.max[1]]]
    }
}

/// The obstacles a robot knows on its floor, grown by [`CLEARANCE`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Obstacles {
    grown: Vec<Footprint>,
}

fn dist(a: [f32; 2], b: [f32; 2]) -> f32 {
    (b[0] - a[0]).hypot(b[1] - a[1])
}

impl Obstacles {
    pub fn new(footprints: impl IntoIterator<Item = Footprint>) -> Self {
        Obstacles { grown: footprints.into_iter().map(|f| f.grow(CLEARANCE)).collect() }
    }

    pub fn is_empty(&self) -> bool {
        self.grown.is_empty()
    }

    /// Whether the leg a→b is free: no grown footprint that holds neither end blocks it.
    fn clear(&self, a: [f32; 2], b: [f32; 2]) -> bool {
        !self.grown.iter().any(|f| f.blocks(a, b) && !f.contains(a) && !f.contains(b))
    }

    /// Every station of `stations` as the worker at `from` would walk to it: a point in
    /// the direction of its route's first leg, as far from `from` as the route is long
    /// (the station itself when the way is straight or no route exists).
    pub fn route_targets(
        &self,
        from: [f32; 2],
        stations: &[Option<[f32; 2]>; NUM_CLASSES],
    ) -> [Option<[f32; 2]>; NUM_CLASSES] {
        if stations.iter().flatten().all(|&s| self.clear(from, s)) {
            return *stations;
        }
        // Nodes: the worker, the stations, then the grown footprints' corners that lie
        // outside every footprint (pushed out a little, so legs along an edge are clear).
        let mut nodes = vec![from];
        nodes.extend(stations.iter().map(|s| s.unwrap_or(from)));
        for f in &self.grown {
            for c in f.grow(0.05).corners() {
                if !self.grown.iter().any(|g| g.contains(c)) {
                    nodes.push(c);
                }
            }
        }
        // Dijkstra from the worker over the visibility graph (a few dozen nodes).
        let n = nodes.len();
        let (mut best, mut first, mut done) = (vec![f32::INFINITY; n], vec![usize::MAX; n], vec![false; n]);
        best[0] = 0.0;
        while let Some(u) =
            (0..n).filter(|&i| !done[i] && best[i].is_finite()).min_by(|&a, &b| best[a].total_cmp(&best[b]))
        {
            done[u] = true;
            let is_station = (1..=NUM_CLASSES).contains(&u);
            if is_station {
                continue; // a route may end at a station, not pass through it
            }
            for v in 1..n {
                if done[v] || !self.clear(nodes[u], nodes[v]) {
                    continue;
                }
                let d = best[u] + dist(nodes[u], nodes[v]);
                if d < best[v] {
                    best[v] = d;
                    first[v] = if u == 0 { v } else { first[u] };
                }
            }
        }
        let mut out = *stations;
        for (s, target) in out.iter_mut().enumerate() {
            if target.is_none() {
                continue;
            }
            let k = s + 1;
            let leg = first[k];
            if leg == usize::MAX || leg == k {
                continue; // straight, or no way round: the station itself
            }
            let (to, length) = (nodes[leg], best[k]);
            let d = dist(from, to);
            if d > 1e-3 {
                *target = Some([from[0] + (to[0] - from[0]) / d * length, from[1] + (to[1] - from[1]) / d * length]);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rack() -> Obstacles {
        // A 2 m x 4 m rack between x = 4 and 6, y = -2 and 2.
        Obstacles::new([Footprint { min: [4.0, -2.0], max: [6.0, 2.0] }])
    }

    #[test]
    fn a_station_in_plain_view_stays_where_it_is() {
        let stations = [Some([10.0, 8.0]), None, Some([-3.0, 0.0]), Some([3.0, 0.0])];
        assert_eq!(rack().route_targets([0.0, 0.0], &stations), stations);
        assert_eq!(Obstacles::default().route_targets([0.0, 0.0], &stations), stations);
    }

    #[test]
    fn a_station_behind_a_rack_lies_towards_the_corner_the_walk_rounds_and_as_far_as_the_walk() {
        let stations = [Some([10.0, -0.5]), None, None, Some([-3.0, 0.0])];
        let out = rack().route_targets([0.0, 0.0], &stations);
        let t = out[0].unwrap();
        // The worker rounds the rack's lower corners (y = -2.4): the nearer side.
        let corner = [4.0 - CLEARANCE - 0.05, -2.0 - CLEARANCE - 0.05];
        let far = [6.0 + CLEARANCE + 0.05, -2.0 - CLEARANCE - 0.05];
        let length = dist([0.0, 0.0], corner) + dist(corner, far) + dist(far, [10.0, -0.5]);
        assert!((dist([0.0, 0.0], t) - length).abs() < 1e-3, "{t:?}: {} against {length}", dist([0.0, 0.0], t));
        let (a, b) = (t[1].atan2(t[0]), corner[1].atan2(corner[0]));
        assert!((a - b).abs() < 1e-4, "towards the corner: {a} against {b}");
        assert_eq!(out[3], stations[3], "the station in view is untouched");
        assert_eq!(out[1], None);
    }

    #[test]
    fn a_worker_or_station_inside_a_grown_footprint_is_not_walled_in() {
        // The worker stands 0.2 m from the rack's face, inside its clearance.
        let stations = [Some([3.8, 6.0]), None, None, None];
        let out = rack().route_targets([3.8, 0.0], &stations);
        assert_eq!(out, stations, "the leg along the face is free");
        // A station whose objects stand against the rack is reached straight.
        let against = [Some([6.2, 0.0]), None, None, None];
        let out = rack().route_targets([10.0, 0.0], &against);
        assert_eq!(out, against);
    }

    #[test]
    fn the_route_round_two_racks_takes_the_gap_between_them() {
        let two = Obstacles::new([
            Footprint { min: [4.0, -6.0], max: [6.0, -0.5] },
            Footprint { min: [4.0, 1.5], max: [6.0, 8.0] },
        ]);
        // The gap at y = -0.5 .. 1.5 is 2 m wide, 1.3 m once grown: the route goes through.
        let stations = [Some([10.0, 0.5]), None, None, None];
        let out = two.route_targets([0.0, 0.5], &stations);
        assert_eq!(out, stations, "straight through the gap");
        // From beside the upper rack, its lower end and the gap are nearer than its top.
        let stations = [Some([10.0, 3.0]), None, None, None];
        let t = two.route_targets([0.0, 3.0], &stations)[0].unwrap();
        let corner = [4.0 - CLEARANCE - 0.05, 1.5 - CLEARANCE - 0.05];
        let length = 2.0 * dist([0.0, 3.0], corner) + 2.0 + 2.0 * (CLEARANCE + 0.05);
        assert!(t[1] < 3.0, "down towards the gap: {t:?}");
        assert!((dist([0.0, 3.0], t) - length).abs() < 1e-3, "{t:?}");
    }
}

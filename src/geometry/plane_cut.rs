//! Where a plane cuts the lumen surface: the closed loops of the cut near a point, and the 2D
//! queries a cross-section needs on one of them (inside, depth, first wall along a ray).
//!
//! A closed, manifold surface cut by a plane gives closed loops, whatever the lumen's shape: a
//! ray from a point inside a loop always leaves it. That is why a section taken from the cut
//! closes wherever the lumen does (a 90 % stenosis, an eccentric plaque, a plane leaning through
//! a narrowing), where rays of a fixed reach from the centerline may not.

use crate::geometry::surface::LumenSurface;
use nalgebra::{Point3, Vector2, Vector3};
use std::collections::HashMap;

/// One closed loop of a plane's cut through the surface. Segment `i` runs from `points[i]` to
/// `points[i + 1]` (the last back to the first) across triangle `triangles[i]`; `plane` holds
/// the same points in the plane's 2D coordinates.
#[derive(Debug, Clone)]
pub struct CutLoop {
    pub points: Vec<Point3<f64>>,
    pub plane: Vec<Vector2<f64>>,
    pub triangles: Vec<u32>,
}

/// A plane: its point, and the two unit axes spanning it (its 2D coordinates).
#[derive(Debug, Clone, Copy)]
pub struct Plane {
    pub origin: Point3<f64>,
    pub x: Vector3<f64>,
    pub y: Vector3<f64>,
}

impl Plane {
    pub fn normal(&self) -> Vector3<f64> {
        self.x.cross(&self.y)
    }
    pub fn to_2d(&self, p: &Point3<f64>) -> Vector2<f64> {
        let d = p - self.origin;
        Vector2::new(d.dot(&self.x), d.dot(&self.y))
    }
    pub fn to_3d(&self, q: &Vector2<f64>) -> Point3<f64> {
        self.origin + self.x * q.x + self.y * q.y
    }
}

/// The closed loops where `plane` cuts the surface within the box of half-width `reach` about
/// its origin. Chains that leave the box, or end at the surface's border (an open vessel end,
/// a hole), are not loops and are left out. A vertex on the plane counts as above it, so every
/// crossing lies on an edge whose ends are on either side and neighbouring triangles share it.
pub fn plane_loops(surface: &LumenSurface, plane: &Plane, reach: f64) -> Vec<CutLoop> {
    let n = plane.normal();
    let side = |v: u32| (surface.vertices[v as usize] - plane.origin).dot(&n);
    // Each crossing triangle's segment, as the two edges it joins (vertex pairs, low first).
    let mut segments: Vec<(u32, [(u32, u32); 2])> = vec![];
    for t in surface.triangles_near_plane(&plane.origin, &n, reach) {
        let tri = surface.triangles[t as usize];
        let above = tri.map(|v| side(v) >= 0.0);
        let crossing: Vec<(u32, u32)> = (0..3)
            .filter(|&k| above[k] != above[(k + 1) % 3])
            .map(|k| {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                (a.min(b), a.max(b))
            })
            .collect();
        if let [e0, e1] = crossing[..] {
            segments.push((t, [e0, e1]));
        }
    }
    let mut by_edge: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (i, (_, edges)) in segments.iter().enumerate() {
        for e in edges {
            by_edge.entry(*e).or_default().push(i);
        }
    }
    let crossing_point = |(a, b): (u32, u32)| {
        let (pa, pb) = (surface.vertices[a as usize], surface.vertices[b as usize]);
        let (da, db) = (side(a), side(b));
        pa + (pb - pa) * (da / (da - db))
    };
    let mut used = vec![false; segments.len()];
    let mut loops = vec![];
    for start in 0..segments.len() {
        if used[start] {
            continue;
        }
        if let Some(chain) = follow_chain(start, &segments, &by_edge, &mut used) {
            let points: Vec<Point3<f64>> = chain.iter().map(|&(_, e)| crossing_point(e)).collect();
            let plane_points = points.iter().map(|p| plane.to_2d(p)).collect();
            let triangles = chain.iter().map(|&(s, _)| segments[s].0).collect();
            loops.push(CutLoop { points, plane: plane_points, triangles });
        }
    }
    loops
}

/// Follows segments from `start` through their shared edges; the chain's segments with the
/// edge each starts from, when it comes back to `start` (a loop).
fn follow_chain(
    start: usize,
    segments: &[(u32, [(u32, u32); 2])],
    by_edge: &HashMap<(u32, u32), Vec<usize>>,
    used: &mut [bool],
) -> Option<Vec<(usize, (u32, u32))>> {
    let mut chain = vec![];
    let (mut current, mut entry) = (start, segments[start].1[0]);
    loop {
        used[current] = true;
        chain.push((current, entry));
        let [e0, e1] = segments[current].1;
        let exit = if e0 == entry { e1 } else { e0 };
        let next = by_edge[&exit].iter().copied().find(|&s| s != current && (!used[s] || s == start));
        match next {
            Some(s) if s == start => return Some(chain),
            Some(s) => (current, entry) = (s, exit),
            None => return None,
        }
    }
}

impl CutLoop {
    /// Twice the signed area enclosed (positive counter-clockwise in the plane's coordinates).
    pub fn signed_area(&self) -> f64 {
        let p = &self.plane;
        (0..p.len()).map(|i| p[i].perp(&p[(i + 1) % p.len()])).sum::<f64>() * 0.5
    }

    /// Whether `q` lies inside the loop (non-zero winding).
    pub fn contains(&self, q: &Vector2<f64>) -> bool {
        let p = &self.plane;
        let mut winding = 0i32;
        for i in 0..p.len() {
            let (a, b) = (p[i] - q, p[(i + 1) % p.len()] - q);
            if (a.y <= 0.0) != (b.y <= 0.0) {
                let left = a.perp(&b) > 0.0;
                match (a.y <= 0.0, left) {
                    (true, true) => winding += 1,
                    (false, false) => winding -= 1,
                    _ => {}
                }
            }
        }
        winding != 0
    }

    /// Distance from `q` to the loop.
    pub fn distance(&self, q: &Vector2<f64>) -> f64 {
        let p = &self.plane;
        (0..p.len())
            .map(|i| {
                let (a, b) = (p[i], p[(i + 1) % p.len()]);
                let ab = b - a;
                let t = ((q - a).dot(&ab) / ab.norm_squared().max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
                (a + ab * t - q).norm()
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// The first point of the loop along the ray `q + t dir` (t > 0): its distance t, the
    /// segment and the fraction along it. From a point inside the loop there always is one.
    pub fn first_hit(&self, q: &Vector2<f64>, dir: &Vector2<f64>) -> Option<(f64, usize, f64)> {
        let p = &self.plane;
        let mut best: Option<(f64, usize, f64)> = None;
        for i in 0..p.len() {
            let (a, b) = (p[i], p[(i + 1) % p.len()]);
            let ab = b - a;
            let den = dir.perp(&ab);
            if den == 0.0 {
                continue;
            }
            let aq = a - q;
            let t = aq.perp(&ab) / den;
            let u = aq.perp(dir) / den;
            if t > 0.0 && (0.0..=1.0).contains(&u) && best.is_none_or(|(bt, _, _)| t < bt) {
                best = Some((t, i, u));
            }
        }
        best
    }

    /// The surface point at fraction `u` along segment `i`.
    pub fn point_on(&self, i: usize, u: f64) -> Point3<f64> {
        let (a, b) = (self.points[i], self.points[(i + 1) % self.points.len()]);
        a + (b - a) * u
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// A closed cylinder along z: radius r, from z = 0 to z = h, with fan caps.
    fn cylinder(r: f64, h: f64, around: usize, rings: usize) -> LumenSurface {
        LumenSurface::new(&crate::testing::capped_tube_surface(r, h, around, rings)).unwrap()
    }

    fn plane_at(z: f64, tilt: f64) -> Plane {
        let x = Vector3::new(tilt.cos(), 0.0, tilt.sin());
        Plane { origin: Point3::new(0.0, 0.0, z), x, y: Vector3::y() }
    }

    #[test]
    fn a_square_cut_of_a_cylinder_is_one_loop_on_its_wall() {
        let s = cylinder(2.0, 10.0, 48, 10);
        let loops = plane_loops(&s, &plane_at(5.3, 0.0), 5.0);
        assert_eq!(loops.len(), 1);
        let l = &loops[0];
        // Each quad of the wall is two triangles: the cut crosses its upright edge and its diagonal.
        assert_eq!(l.points.len(), 96);
        for p in &l.points {
            assert!((p.z - 5.3).abs() < 1e-12);
            let rho = (p.x * p.x + p.y * p.y).sqrt();
            assert!(rho <= 2.0 + 1e-12 && rho > 2.0 * (std::f64::consts::PI / 48.0).cos() - 1e-12);
        }
        assert!(l.contains(&Vector2::zeros()));
        assert!(!l.contains(&Vector2::new(2.5, 0.0)));
        let area = l.signed_area().abs();
        assert!((area - std::f64::consts::PI * 4.0).abs() < 0.02 * area, "{area}");
        let depth = l.distance(&Vector2::zeros());
        assert!(depth > 1.98 && depth <= 2.0, "{depth}");
        for k in 0..12 {
            let a = k as f64 * 0.5;
            let (t, i, u) = l.first_hit(&Vector2::new(0.3, -0.2), &Vector2::new(a.cos(), a.sin())).unwrap();
            let p = l.point_on(i, u);
            assert!(((p.x - 0.3) - t * a.cos()).abs() < 1e-9 && ((p.y + 0.2) - t * a.sin()).abs() < 1e-9);
        }
    }

    #[test]
    fn a_leaning_plane_gives_an_ellipse_and_a_cut_through_the_cap_or_beyond_the_box_none() {
        let s = cylinder(2.0, 10.0, 64, 20);
        let tilt = 0.6_f64;
        let loops = plane_loops(&s, &plane_at(5.0, tilt), 6.0);
        assert_eq!(loops.len(), 1);
        let far = loops[0].first_hit(&Vector2::zeros(), &Vector2::x()).unwrap().0;
        assert!((far - 2.0 / tilt.cos()).abs() < 0.01, "{far}");
        // The box is too small for the loop: the chain leaves it and is no loop.
        assert!(plane_loops(&s, &plane_at(5.0, tilt), 1.5).is_empty());
        // A plane along the axis crosses both caps: one loop, through the caps.
        let along = Plane { origin: Point3::new(0.0, 0.0, 5.0), x: Vector3::x(), y: Vector3::z() };
        assert_eq!(plane_loops(&s, &along, 20.0).len(), 1);
    }

    #[test]
    fn an_open_tube_cut_through_its_opening_gives_no_loop() {
        let s = cylinder(2.0, 10.0, 32, 10);
        // Drop the top cap: the tube is open at z = 10.
        let keep: Vec<[u32; 3]> =
            s.triangles.iter().copied().filter(|t| !t.contains(&(s.vertices.len() as u32 - 1))).collect();
        let open = LumenSurface::from_parts(s.vertices.clone(), keep, PathBuf::from("open")).unwrap();
        let through = Plane { origin: Point3::new(0.0, 0.0, 9.0), x: Vector3::new(0.6, 0.0, 0.8), y: Vector3::y() };
        assert!(plane_loops(&open, &through, 20.0).is_empty());
        assert_eq!(plane_loops(&open, &plane_at(5.0, 0.0), 5.0).len(), 1);
    }
}

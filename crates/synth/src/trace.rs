//! Ray geometry for the handful of shapes a stage needs. A flat list with bounding boxes is
//! plenty for a few dozen objects.

use std::ops::{Add, Mul, Neg, Sub};

use super::rig::VirtualStage;

/// A 3-vector in metres (or a direction).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct V3 {
    pub x: f32,
    pub y: f32,
    pub z: f32,
}

impl V3 {
    pub const fn new(x: f32, y: f32, z: f32) -> V3 {
        V3 { x, y, z }
    }
    pub fn from(a: [f32; 3]) -> V3 {
        V3::new(a[0], a[1], a[2])
    }
    pub fn dot(self, o: V3) -> f32 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    pub fn cross(self, o: V3) -> V3 {
        V3::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    pub fn norm(self) -> V3 {
        self * (1.0 / self.dot(self).sqrt())
    }
}

impl Add for V3 {
    type Output = V3;
    fn add(self, o: V3) -> V3 {
        V3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl Sub for V3 {
    type Output = V3;
    fn sub(self, o: V3) -> V3 {
        V3::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
impl Mul<f32> for V3 {
    type Output = V3;
    fn mul(self, s: f32) -> V3 {
        V3::new(self.x * s, self.y * s, self.z * s)
    }
}
impl Neg for V3 {
    type Output = V3;
    fn neg(self) -> V3 {
        V3::new(-self.x, -self.y, -self.z)
    }
}

/// Two unit vectors perpendicular to `n` and to each other.
pub(crate) fn orthonormal(n: V3) -> (V3, V3) {
    let a = if n.x.abs() < 0.9 {
        V3::new(1.0, 0.0, 0.0)
    } else {
        V3::new(0.0, 1.0, 0.0)
    };
    let u = n.cross(a).norm();
    (u, n.cross(u))
}

/// Shortest distance along a ray that still counts as a hit, to keep a surface from
/// shadowing itself.
const EPS: f32 = 1e-3;

#[derive(Debug, Clone, Copy)]
enum Shape {
    /// Rectangle in the plane `axis = at`, spanning `lo..hi` in the other two axes.
    Rect {
        axis: usize,
        at: f32,
        lo: V3,
        hi: V3,
    },
    /// Concave quarter cylinder along x (the cyc cove): axis at (y, z) = (cy, cz), surface
    /// where y <= cy and z >= cz.
    Cove {
        cy: f32,
        cz: f32,
        r: f32,
        x0: f32,
        x1: f32,
    },
    /// Box with centre `c`, half sizes `h`, turned about y by an angle of cosine `cs`, sine `sn`.
    Cuboid {
        c: V3,
        h: V3,
        cs: f32,
        sn: f32,
    },
    /// Upright capped cylinder standing on `base`.
    Cylinder {
        base: V3,
        r: f32,
        h: f32,
    },
    Sphere {
        c: V3,
        r: f32,
    },
}

#[derive(Debug, Clone, Copy)]
struct Object {
    shape: Shape,
    albedo: [f32; 3],
    lo: V3,
    hi: V3,
}

/// Where a ray meets the scene: position, unit normal facing the ray's origin, reflectance.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Surface {
    pub p: V3,
    pub n: V3,
    pub albedo: [f32; 3],
}

/// Everything that can be hit or cast a shadow.
pub(crate) struct Geometry {
    objects: Vec<Object>,
}

impl Geometry {
    /// Builds the floor, cyc, legs and props of a checked rig.
    pub fn new(rig: &VirtualStage) -> Geometry {
        let s = &rig.stage;
        let hw = s.width / 2.0;
        let mut objects = Vec::new();
        let mut push = |shape: Shape, albedo: [f32; 3]| {
            let (lo, hi) = bounds(&shape);
            objects.push(Object {
                shape,
                albedo,
                lo,
                hi,
            });
        };
        let cove = s.cyc.as_ref().map_or(0.0, |c| c.cove);
        let floor_end = s.depth - cove;
        push(
            Shape::Rect {
                axis: 1,
                at: 0.0,
                lo: V3::new(-hw, 0.0, 0.0),
                hi: V3::new(hw, 0.0, floor_end),
            },
            s.albedo,
        );
        if let Some(c) = &s.cyc {
            push(
                Shape::Rect {
                    axis: 2,
                    at: s.depth,
                    lo: V3::new(-hw, cove, s.depth),
                    hi: V3::new(hw, c.height, s.depth),
                },
                c.albedo,
            );
            if cove > 0.0 {
                push(
                    Shape::Cove {
                        cy: cove,
                        cz: floor_end,
                        r: cove,
                        x0: -hw,
                        x1: hw,
                    },
                    c.albedo,
                );
            }
        }
        if let Some(l) = &s.legs {
            for k in 0..l.pairs {
                let z = s.depth * (k as f32 + 0.5) / l.pairs as f32;
                for side in [-1.0, 1.0] {
                    let c = V3::new(side * (hw - l.width / 2.0), l.height / 2.0, z);
                    let h = V3::new(l.width / 2.0, l.height / 2.0, 0.02);
                    push(
                        Shape::Cuboid {
                            c,
                            h,
                            cs: 1.0,
                            sn: 0.0,
                        },
                        l.albedo,
                    );
                }
            }
        }
        for b in &rig.boxes {
            let h = V3::from(b.size) * 0.5;
            let c = V3::from(b.position) + V3::new(0.0, h.y, 0.0);
            let (sn, cs) = b.yaw.to_radians().sin_cos();
            push(Shape::Cuboid { c, h, cs, sn }, b.albedo);
        }
        for c in &rig.cylinders {
            let shape = Shape::Cylinder {
                base: V3::from(c.position),
                r: c.radius,
                h: c.height,
            };
            push(shape, c.albedo);
        }
        for s in &rig.spheres {
            let shape = Shape::Sphere {
                c: V3::from(s.position),
                r: s.radius,
            };
            push(shape, s.albedo);
        }
        Geometry { objects }
    }

    /// The nearest surface along the ray `o + t d` (d unit), if any.
    pub fn hit(&self, o: V3, d: V3) -> Option<Surface> {
        let inv = V3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
        let mut best: Option<(f32, V3, [f32; 3])> = None;
        for ob in &self.objects {
            let tmax = best.map_or(f32::INFINITY, |b| b.0);
            if !slab(o, inv, ob.lo, ob.hi, tmax) {
                continue;
            }
            if let Some((t, n)) = intersect(&ob.shape, o, d, tmax) {
                best = Some((t, n, ob.albedo));
            }
        }
        best.map(|(t, n, albedo)| Surface {
            p: o + d * t,
            n: if n.dot(d) > 0.0 { -n } else { n },
            albedo,
        })
    }

    /// True if anything blocks the ray `o + t d` (d unit) before distance `dist`.
    pub fn blocked(&self, o: V3, d: V3, dist: f32) -> bool {
        let inv = V3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
        let tmax = dist - EPS;
        self.objects.iter().any(|ob| {
            slab(o, inv, ob.lo, ob.hi, tmax) && intersect(&ob.shape, o, d, tmax).is_some()
        })
    }
}

/// Axis-aligned bounds of a shape, padded so flat shapes have some thickness.
fn bounds(s: &Shape) -> (V3, V3) {
    let pad = V3::new(EPS, EPS, EPS);
    let (lo, hi) = match *s {
        Shape::Rect { lo, hi, .. } => (lo, hi),
        Shape::Cove { cy, cz, r, x0, x1 } => (V3::new(x0, cy - r, cz), V3::new(x1, cy, cz + r)),
        Shape::Cuboid { c, h, cs, sn } => {
            let ex = (h.x * cs).abs() + (h.z * sn).abs();
            let ez = (h.x * sn).abs() + (h.z * cs).abs();
            let e = V3::new(ex, h.y, ez);
            (c - e, c + e)
        }
        Shape::Cylinder { base, r, h } => (base - V3::new(r, 0.0, r), base + V3::new(r, h, r)),
        Shape::Sphere { c, r } => (c - V3::new(r, r, r), c + V3::new(r, r, r)),
    };
    (lo - pad, hi + pad)
}

/// Whether the ray can meet the box `lo..hi` between EPS and `tmax`.
fn slab(o: V3, inv: V3, lo: V3, hi: V3, tmax: f32) -> bool {
    let (mut t0, mut t1) = (0.0f32, tmax);
    for (o, inv, lo, hi) in [
        (o.x, inv.x, lo.x, hi.x),
        (o.y, inv.y, lo.y, hi.y),
        (o.z, inv.z, lo.z, hi.z),
    ] {
        let a = (lo - o) * inv;
        let b = (hi - o) * inv;
        // NaN (a ray in the plane of a face) compares false and leaves the interval alone.
        let (near, far) = if a < b { (a, b) } else { (b, a) };
        if near > t0 {
            t0 = near;
        }
        if far < t1 {
            t1 = far;
        }
    }
    t0 <= t1
}

fn comp(v: V3, axis: usize) -> f32 {
    match axis {
        0 => v.x,
        1 => v.y,
        _ => v.z,
    }
}

/// Nearest hit in (EPS, tmax) with its (unoriented) unit normal.
fn intersect(s: &Shape, o: V3, d: V3, tmax: f32) -> Option<(f32, V3)> {
    match *s {
        Shape::Rect { axis, at, lo, hi } => {
            let dn = comp(d, axis);
            if dn == 0.0 {
                return None;
            }
            let t = (at - comp(o, axis)) / dn;
            if !(t > EPS && t < tmax) {
                return None;
            }
            let p = o + d * t;
            let inside = (0..3)
                .filter(|&a| a != axis)
                .all(|a| comp(p, a) >= comp(lo, a) && comp(p, a) <= comp(hi, a));
            let n = match axis {
                0 => V3::new(1.0, 0.0, 0.0),
                1 => V3::new(0.0, 1.0, 0.0),
                _ => V3::new(0.0, 0.0, 1.0),
            };
            inside.then_some((t, n))
        }
        Shape::Cove { cy, cz, r, x0, x1 } => {
            let (oy, oz) = (o.y - cy, o.z - cz);
            let a = d.y * d.y + d.z * d.z;
            if a < 1e-12 {
                return None;
            }
            let b = oy * d.y + oz * d.z;
            let c = oy * oy + oz * oz - r * r;
            let disc = b * b - a * c;
            if disc < 0.0 {
                return None;
            }
            let sq = disc.sqrt();
            for t in [(-b - sq) / a, (-b + sq) / a] {
                if t > EPS && t < tmax {
                    let p = o + d * t;
                    if p.y <= cy && p.z >= cz && p.x >= x0 && p.x <= x1 {
                        return Some((t, V3::new(0.0, cy - p.y, cz - p.z) * (1.0 / r)));
                    }
                }
            }
            None
        }
        Shape::Cuboid { c, h, cs, sn } => {
            // Into the box's frame: rotate by -yaw about y.
            let rel = o - c;
            let lo_ = V3::new(cs * rel.x - sn * rel.z, rel.y, sn * rel.x + cs * rel.z);
            let ld = V3::new(cs * d.x - sn * d.z, d.y, sn * d.x + cs * d.z);
            let (mut t0, mut t1) = (f32::NEG_INFINITY, f32::INFINITY);
            let (mut n0, mut n1) = (0usize, 0usize);
            for a in 0..3 {
                let (oa, da, ha) = (comp(lo_, a), comp(ld, a), comp(h, a));
                if da.abs() < 1e-12 {
                    if oa.abs() > ha {
                        return None;
                    }
                    continue;
                }
                let ta = (-ha - oa) / da;
                let tb = (ha - oa) / da;
                let (near, far) = if ta < tb { (ta, tb) } else { (tb, ta) };
                if near > t0 {
                    t0 = near;
                    n0 = a;
                }
                if far < t1 {
                    t1 = far;
                    n1 = a;
                }
            }
            if t0 > t1 {
                return None;
            }
            let (t, a) = if t0 > EPS { (t0, n0) } else { (t1, n1) };
            if !(t > EPS && t < tmax) {
                return None;
            }
            let ln = match a {
                0 => V3::new(1.0, 0.0, 0.0),
                1 => V3::new(0.0, 1.0, 0.0),
                _ => V3::new(0.0, 0.0, 1.0),
            };
            // Back to world: rotate by +yaw.
            Some((
                t,
                V3::new(cs * ln.x + sn * ln.z, ln.y, -sn * ln.x + cs * ln.z),
            ))
        }
        Shape::Cylinder { base, r, h } => {
            let mut best: Option<(f32, V3)> = None;
            let (ox, oz) = (o.x - base.x, o.z - base.z);
            let a = d.x * d.x + d.z * d.z;
            if a > 1e-12 {
                let b = ox * d.x + oz * d.z;
                let c = ox * ox + oz * oz - r * r;
                let disc = b * b - a * c;
                if disc >= 0.0 {
                    let sq = disc.sqrt();
                    for t in [(-b - sq) / a, (-b + sq) / a] {
                        let y = o.y + d.y * t - base.y;
                        if t > EPS && t < tmax && (0.0..=h).contains(&y) {
                            let p = o + d * t;
                            best = Some((t, V3::new(p.x - base.x, 0.0, p.z - base.z).norm()));
                            break;
                        }
                    }
                }
            }
            if d.y != 0.0 {
                for cap in [base.y, base.y + h] {
                    let t = (cap - o.y) / d.y;
                    let lim = best.map_or(tmax, |b| b.0);
                    if t > EPS && t < lim {
                        let p = o + d * t;
                        let (dx, dz) = (p.x - base.x, p.z - base.z);
                        if dx * dx + dz * dz <= r * r {
                            best = Some((t, V3::new(0.0, 1.0, 0.0)));
                        }
                    }
                }
            }
            best
        }
        Shape::Sphere { c, r } => {
            let oc = o - c;
            let b = oc.dot(d);
            let disc = b * b - (oc.dot(oc) - r * r);
            if disc < 0.0 {
                return None;
            }
            let sq = disc.sqrt();
            [-b - sq, -b + sq]
                .into_iter()
                .find(|&t| t > EPS && t < tmax)
                .map(|t| (t, (o + d * t - c) * (1.0 / r)))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turned_box_bounds_contain_its_corners() {
        let (sn, cs) = 30f32.to_radians().sin_cos();
        let s = Shape::Cuboid {
            c: V3::new(1.0, 0.5, 2.0),
            h: V3::new(1.0, 0.5, 0.25),
            cs,
            sn,
        };
        let (lo, hi) = bounds(&s);
        for &(x, z) in &[(1.0, 0.25), (1.0, -0.25), (-1.0, 0.25), (-1.0, -0.25)] {
            let w = V3::new(cs * x + sn * z + 1.0, 0.5, -sn * x + cs * z + 2.0);
            let inside = [(w.x, lo.x, hi.x), (w.y, lo.y, hi.y), (w.z, lo.z, hi.z)]
                .iter()
                .all(|&(v, l, h)| v >= l && v <= h);
            assert!(inside, "corner {w:?} outside {lo:?}..{hi:?}");
        }
    }

    #[test]
    fn ray_hits_turned_box_face_with_outward_normal() {
        let s = Shape::Cuboid {
            c: V3::new(0.0, 0.0, 5.0),
            h: V3::new(1.0, 1.0, 1.0),
            cs: 1.0,
            sn: 0.0,
        };
        let (t, n) =
            intersect(&s, V3::new(0.0, 0.0, 0.0), V3::new(0.0, 0.0, 1.0), 100.0).expect("hit");
        assert!((t - 4.0).abs() < 1e-5);
        assert!((n.z.abs() - 1.0).abs() < 1e-5);
    }
}

//! Colour by the emitters: a requested colour becomes emitter levels (0..1) by solving in
//! linear light with each emitter's CIE XYZ at full (docs/dmx.md, "Colour by the emitters").
//!
//! Mixing is additive, so emitter levels `l` give the XYZ `Σ l_k E_k`. [`solve`] finds the
//! levels that reproduce the target's chromaticity with the most light (the largest
//! luminance), then, when several do (four or more emitters, some of whose chromaticities
//! lie on one line, or two of one colour), the one with the least drive (smallest `Σ l²`),
//! which spreads the light over every emitter that can give it. A target the emitters
//! cannot reach is first moved to the nearest chromaticity they can, in CIE 1976 u'v'.
//! The solve is plain `f64` arithmetic in a fixed order on fixed-size arrays: no
//! allocation, no randomness, the same bits on every run.

pub mod colour;
pub mod model;

pub use model::ColourModel;

use colour::{xyz_to_linear_srgb, xyz_to_uv};

/// The most emitters a solve handles; emitters past it are ignored (no level), so profiles
/// must refuse more. No fixture type comes near: the widest LED engines have 7 or 8 colours.
pub const MAX_EMITTERS: usize = 16;

/// Within this distance (u'v') of the emitters' gamut a chromaticity counts as inside.
const INSIDE: f64 = 1e-12;
/// A chromaticity inside the gamut but within this distance (u'v', far below any visible
/// difference) of its edge is put on the edge, and one this close to an emitter's on that
/// emitter's: so near, the most-light programme's dual optimum lies near infinity, where
/// rounding cancels it to nonsense (a red with a 1e-8 trace of blue solved to black).
const EDGE: f64 = 1e-7;
/// Two chromaticity directions whose sine is below this are parallel.
const PARALLEL: f64 = 1e-9;
/// An emitter whose chromaticity is within this (relative) of the target's has it.
const SAME: f64 = 1e-12;
/// A reduced cost within this (relative) of zero leaves an emitter free to trade.
const TIE: f64 = 1e-9;

/// The levels of one solve and what they make.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solution {
    levels: [f64; MAX_EMITTERS],
    len: usize,
    /// The CIE XYZ the levels make (in the emitters' units): what the preview should show.
    pub reached: [f64; 3],
    /// How far (CIE 1976 u'v' distance) the target's chromaticity was moved to bring it
    /// into the emitters' gamut; 0 when it was inside.
    pub shift: f64,
}

impl Solution {
    /// The level (0..1) of each emitter, in the order they were given.
    pub fn levels(&self) -> &[f64] {
        &self.levels[..self.len]
    }

    /// [`Solution::reached`] as linear sRGB, unclamped: a wide-gamut fixture's saturated
    /// colours fall outside 0..1 (even below 0), and the caller decides how to show them.
    pub fn reached_linear_srgb(&self) -> [f64; 3] {
        xyz_to_linear_srgb(self.reached)
    }

    /// Whether the target was inside the emitters' gamut (reached without a shift).
    pub fn in_gamut(&self) -> bool {
        self.shift == 0.0
    }

    /// The same colour at `intensity` (clamped to 0..1, NaN as 0) of the most light: levels
    /// and reached colour scaled alike, what a fixture without a dimmer sends. With a
    /// dimmer, the emitters take [`Solution::levels`] (the colour at its most light) and
    /// the dimmer takes the intensity.
    pub fn at(&self, intensity: f64) -> Solution {
        let k = if intensity.is_nan() {
            0.0
        } else {
            intensity.clamp(0.0, 1.0)
        };
        Solution {
            levels: self.levels.map(|v| v * k),
            reached: self.reached.map(|v| v * k),
            ..*self
        }
    }
}

/// The emitter levels that make the chromaticity of `target` (CIE XYZ; its luminance is
/// ignored, intensity is [`Solution::at`]'s) from emitters whose XYZ at full are
/// `emitters`, with the most light.
///
/// - The levels (0..1, one per emitter) maximise the luminance `Σ l_k Y_k` subject to the
///   mix having the target's chromaticity: a linear programme solved exactly through its
///   dual (see the docs). Among equal-light solutions the one with the least `Σ l_k²`.
/// - A target outside the emitters' gamut (the convex hull of their u'v') is moved to the
///   nearest point of it in u'v'; [`Solution::shift`] says how far.
/// - Black (no chromaticity: X + 15Y + 3Z not positive), a non-finite target, or no usable
///   emitter gives all zeros. An emitter that is not finite or has no positive Y stays at
///   0. One emitter, or several of one colour, works (they all go to full).
pub fn solve(emitters: &[[f64; 3]], target: [f64; 3]) -> Solution {
    let len = emitters.len().min(MAX_EMITTERS);
    let mut solution = Solution {
        levels: [0.0; MAX_EMITTERS],
        len,
        reached: [0.0; 3],
        shift: 0.0,
    };
    let mut live = [0usize; MAX_EMITTERS];
    let mut uv = [[0.0; 2]; MAX_EMITTERS];
    let mut n = 0;
    for (k, e) in emitters[..len].iter().enumerate() {
        if e.iter().all(|v| v.is_finite())
            && e[1] > 0.0
            && let Some(p) = xyz_to_uv(*e)
        {
            live[n] = k;
            uv[n] = p;
            n += 1;
        }
    }
    let wanted = xyz_to_uv(target).filter(|_| target.iter().all(|v| v.is_finite()));
    let Some(wanted) = wanted.filter(|_| n > 0) else {
        return solution;
    };
    let (c, shift) = nearest_in_gamut(&uv[..n], wanted);
    // A hair from an emitter's own chromaticity is that emitter's (see [`EDGE`]).
    let c = uv[..n]
        .iter()
        .copied()
        .find(|p| norm(sub(c, *p)) < EDGE)
        .unwrap_or(c);
    solution.shift = shift;
    // The chromaticity constraint Σ l_k g_k = 0, with g_k = (4X - u D, 9Y - v D) and
    // D = X + 15Y + 3Z: the mix's u' = Σ l 4X / Σ l D is u (and v' likewise).
    let mut g = [[0.0; 2]; MAX_EMITTERS];
    let mut y = [0.0; MAX_EMITTERS];
    for i in 0..n {
        let [big_x, big_y, big_z] = emitters[live[i]];
        let d = big_x + 15.0 * big_y + 3.0 * big_z;
        g[i] = [4.0 * big_x - c[0] * d, 9.0 * big_y - c[1] * d];
        if norm(g[i]) <= SAME * d {
            g[i] = [0.0; 2];
        }
        y[i] = big_y;
    }
    let mut l = [0.0; MAX_EMITTERS];
    most_light(&g[..n], &y[..n], &mut l[..n]);
    for i in 0..n {
        solution.levels[live[i]] = l[i];
    }
    for (level, e) in solution.levels[..len].iter().zip(emitters) {
        if *level > 0.0 {
            for (r, v) in solution.reached.iter_mut().zip(e) {
                *r += level * v;
            }
        }
    }
    solution
}

fn norm(v: [f64; 2]) -> f64 {
    (v[0] * v[0] + v[1] * v[1]).sqrt()
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// The z of the cross product: `|a| |b| sin(a to b)`.
fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// The nearest point to `c` (u'v') of the convex hull of `points`, and its distance: `c`
/// itself and 0 when inside (within [`INSIDE`]), put on the edge when within [`EDGE`] of
/// it (still reported as no shift).
fn nearest_in_gamut(points: &[[f64; 2]], c: [f64; 2]) -> ([f64; 2], f64) {
    let mut hull = [[0.0; 2]; 2 * MAX_EMITTERS];
    let h = convex_hull(points, &mut hull);
    let hull = &hull[..h];
    let nearest_on = |a: [f64; 2], b: [f64; 2]| {
        let ab = sub(b, a);
        let len2 = dot(ab, ab);
        let t = if len2 > 0.0 {
            (dot(sub(c, a), ab) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let q = [a[0] + t * ab[0], a[1] + t * ab[1]];
        (q, norm(sub(c, q)))
    };
    let mut best = nearest_on(hull[0], hull[1 % h]);
    for i in 1..h {
        let candidate = nearest_on(hull[i], hull[(i + 1) % h]);
        if candidate.1 < best.1 {
            best = candidate;
        }
    }
    // Counter-clockwise: inside is left of (or on) every edge.
    let inside = h >= 3
        && (0..h).all(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % h]);
            cross(sub(b, a), sub(c, a)) >= -INSIDE * norm(sub(b, a))
        });
    if inside {
        return (if best.1 < EDGE { best.0 } else { c }, 0.0);
    }
    if best.1 <= INSIDE { (c, 0.0) } else { best }
}

/// Andrew's monotone chain: the hull's corners counter-clockwise into `out`, returning how
/// many (1 for coincident points, 2 for collinear ones). `points` is not empty.
fn convex_hull(points: &[[f64; 2]], out: &mut [[f64; 2]; 2 * MAX_EMITTERS]) -> usize {
    let mut order: [usize; MAX_EMITTERS] = std::array::from_fn(|i| i);
    let order = &mut order[..points.len()];
    order.sort_unstable_by(|&a, &b| {
        let (p, q) = (points[a], points[b]);
        p[0].total_cmp(&q[0])
            .then(p[1].total_cmp(&q[1]))
            .then(a.cmp(&b))
    });
    let turns_left = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| cross(sub(a, o), sub(b, o)) > 0.0;
    let mut k = 0;
    for &i in order.iter() {
        while k >= 2 && !turns_left(out[k - 2], out[k - 1], points[i]) {
            k -= 1;
        }
        out[k] = points[i];
        k += 1;
    }
    let lower = k + 1;
    for &i in order.iter().rev().skip(1) {
        while k >= lower && !turns_left(out[k - 2], out[k - 1], points[i]) {
            k -= 1;
        }
        out[k] = points[i];
        k += 1;
    }
    // The chain ends where it began; coincident points leave one corner.
    let k = (k - 1).max(1);
    if k == 2 && out[0] == out[1] { 1 } else { k }
}

/// The levels `l` (0..1) maximising `Σ l_k y_k` subject to `Σ l_k g_k = 0`, the least
/// `Σ l²` of them when several tie.
///
/// The dual of this programme is to minimise `F(λ) = Σ_k max(0, y_k - λ·g_k)` over
/// λ in the plane, a convex piecewise-linear function whose minimum (for a feasible target)
/// lies at a crossing of two of the lines `λ·g_k = y_k`: all crossings are tried (n(n-1)/2
/// of them, each evaluated in n steps). At the best one, complementary slackness fixes
/// every emitter whose reduced cost `y_k - λ·g_k` is positive at 1 and negative at 0; the
/// ones on their line (normally two) share what remains, which every way of sharing gives
/// the same light.
fn most_light(g: &[[f64; 2]], y: &[f64], l: &mut [f64]) {
    let n = g.len();
    let dual = |lambda: [f64; 2]| -> f64 {
        g.iter()
            .zip(y)
            .map(|(gk, yk)| (yk - dot(lambda, *gk)).max(0.0))
            .sum()
    };
    let mut best: Option<(f64, [f64; 2])> = None;
    for i in 0..n {
        for j in i + 1..n {
            let det = cross(g[i], g[j]);
            if det.abs() <= PARALLEL * norm(g[i]) * norm(g[j]) {
                continue;
            }
            let lambda = [
                (y[i] * g[j][1] - y[j] * g[i][1]) / det,
                (g[i][0] * y[j] - g[j][0] * y[i]) / det,
            ];
            let f = dual(lambda);
            if best.is_none_or(|(b, _)| f < b) {
                best = Some((f, lambda));
            }
        }
    }
    let lambda = match best {
        Some((_, lambda)) => lambda,
        None => along_one_line(g, y, &dual),
    };
    let mut free = [0usize; MAX_EMITTERS];
    let mut m = 0;
    let mut rest = [0.0; 2];
    let size = norm(lambda);
    for k in 0..n {
        let reduced = y[k] - dot(lambda, g[k]);
        let tol = TIE * (y[k] + size * norm(g[k]));
        if reduced > tol {
            l[k] = 1.0;
            rest = sub(rest, g[k]);
        } else if reduced < -tol {
            l[k] = 0.0;
        } else {
            free[m] = k;
            m += 1;
        }
    }
    share(&free[..m], g, rest, l);
}

/// [`most_light`]'s dual when every `g_k` is parallel (the emitters' chromaticities on one
/// line through the target's, or all at it): λ along that line, at the best breakpoint
/// (λ = 0, so every emitter full, when all are at the target's chromaticity).
fn along_one_line(g: &[[f64; 2]], y: &[f64], dual: &dyn Fn([f64; 2]) -> f64) -> [f64; 2] {
    let longest = g
        .iter()
        .copied()
        .fold([0.0; 2], |a, b| if norm(b) > norm(a) { b } else { a });
    let size = norm(longest);
    if size == 0.0 {
        return [0.0; 2];
    }
    let e = [longest[0] / size, longest[1] / size];
    let mut best: Option<(f64, [f64; 2])> = None;
    for (gk, yk) in g.iter().zip(y) {
        let a = dot(*gk, e);
        if a.abs() > PARALLEL * size {
            let lambda = [e[0] * yk / a, e[1] * yk / a];
            let f = dual(lambda);
            if best.is_none_or(|(b, _)| f < b) {
                best = Some((f, lambda));
            }
        }
    }
    best.map_or([0.0; 2], |(_, lambda)| lambda)
}

/// Levels (0..1) for the emitters `free` so that `Σ l_k g_k = rest`, with the least
/// `Σ l_k²`: unique, so the choice among equal-light solutions is deterministic.
fn share(free: &[usize], g: &[[f64; 2]], rest: [f64; 2], l: &mut [f64]) {
    match *free {
        [] => {}
        [k] => {
            let gg = dot(g[k], g[k]);
            l[k] = if gg > 0.0 {
                (dot(g[k], rest) / gg).clamp(0.0, 1.0)
            } else {
                0.0
            };
        }
        [i, j] if cross(g[i], g[j]).abs() > PARALLEL * norm(g[i]) * norm(g[j]) => {
            let det = cross(g[i], g[j]);
            l[i] = (cross(rest, g[j]) / det).clamp(0.0, 1.0);
            l[j] = (cross(g[i], rest) / det).clamp(0.0, 1.0);
        }
        _ => least_drive(free, g, rest, l),
    }
}

/// The smoothed clamp's integral: `φ(s) = ∫ clamp(s, 0, 1)`, convex.
fn phi(s: f64) -> f64 {
    if s <= 0.0 {
        0.0
    } else if s < 1.0 {
        0.5 * s * s
    } else {
        s - 0.5
    }
}

/// The minimum of `½ Σ l_k²` over `0 <= l_k <= 1` with `Σ l_k g_k = rest` (k in `free`).
///
/// Its dual: `l_k = clamp(μ·g_k, 0, 1)` for the μ minimising the convex, once
/// differentiable `ψ(μ) = Σ φ(μ·g_k) - μ·rest`, found by Newton's method with the
/// generalised Hessian (`Σ g gᵀ` over the emitters strictly inside 0..1) and a halving
/// line search; ψ is quadratic between the lines where an emitter reaches 0 or 1, so once
/// the emitters at their bounds are the right ones, one step lands exactly. `rest` is
/// first projected onto the span of the `g_k` (rounding may leave it a little outside),
/// and a tiny ridge keeps the Hessian invertible.
fn least_drive(free: &[usize], g: &[[f64; 2]], rest: [f64; 2], l: &mut [f64]) {
    let gram = |pick: &dyn Fn(f64) -> bool, mu: [f64; 2]| {
        let mut m = [0.0; 3];
        for &k in free {
            if pick(dot(mu, g[k])) {
                m[0] += g[k][0] * g[k][0];
                m[1] += g[k][0] * g[k][1];
                m[2] += g[k][1] * g[k][1];
            }
        }
        m
    };
    let m = gram(&|_| true, [0.0; 2]);
    let half = 0.5 * (m[0] + m[2]);
    let disc = (0.25 * (m[0] - m[2]).powi(2) + m[1] * m[1]).sqrt();
    let (top, bottom) = (half + disc, half - disc);
    if top <= 0.0 {
        for &k in free {
            l[k] = 0.0;
        }
        return;
    }
    let mut b = rest;
    if bottom <= 1e-12 * top {
        // The g_k are parallel: only rest's part along them can be made.
        let e = if m[1] != 0.0 {
            [top - m[2], m[1]]
        } else if m[0] >= m[2] {
            [1.0, 0.0]
        } else {
            [0.0, 1.0]
        };
        let e = [e[0] / norm(e), e[1] / norm(e)];
        let along = dot(b, e);
        b = [along * e[0], along * e[1]];
    }
    let ridge = 1e-13 * top;
    let solve2 = |m: [f64; 3], v: [f64; 2]| {
        let (a, c, d) = (m[0] + ridge, m[1], m[2] + ridge);
        let det = a * d - c * c;
        [(d * v[0] - c * v[1]) / det, (a * v[1] - c * v[0]) / det]
    };
    let psi = |mu: [f64; 2]| -> f64 {
        free.iter().map(|&k| phi(dot(mu, g[k]))).sum::<f64>() - dot(mu, b)
            + 0.5 * ridge * dot(mu, mu)
    };
    let gradient = |mu: [f64; 2]| {
        let mut s = [ridge * mu[0] - b[0], ridge * mu[1] - b[1]];
        for &k in free {
            let v = dot(mu, g[k]).clamp(0.0, 1.0);
            s[0] += v * g[k][0];
            s[1] += v * g[k][1];
        }
        s
    };
    let scale = norm(b) + free.iter().map(|&k| norm(g[k])).sum::<f64>();
    // Start at the unconstrained least drive: the answer when no level leaves 0..1.
    let mut mu = solve2(m, b);
    for _ in 0..64 {
        let grad = gradient(mu);
        if norm(grad) <= 1e-15 * scale {
            break;
        }
        let h = gram(&|s| s > 0.0 && s < 1.0, mu);
        let step = solve2(h, grad);
        let d = [-step[0], -step[1]];
        let (here, slope) = (psi(mu), dot(grad, d));
        let mut t = 1.0;
        while t > 1e-12 && psi([mu[0] + t * d[0], mu[1] + t * d[1]]) > here + 1e-4 * t * slope {
            t *= 0.5;
        }
        let next = [mu[0] + t * d[0], mu[1] + t * d[1]];
        if next == mu {
            break;
        }
        mu = next;
    }
    for &k in free {
        l[k] = dot(mu, g[k]).clamp(0.0, 1.0);
    }
}

#[cfg(test)]
mod tests;

//! Lighting: direct light from a soft-edged spot with hard shadows, plus one diffuse bounce
//! gathered from virtual point lights placed where the beam lands.

use std::f32::consts::PI;
use visobjd_scene::srgb::srgb_to_linear;

use rayon::prelude::*;

use super::rig::{Spotlight, VirtualStage};
use super::trace::{Geometry, Surface, V3, orthonormal};

/// Subpixel sample positions (rotated grid): cheap antialiasing, identical on every run.
const SUBPIXELS: [(f32, f32); 4] = [
    (0.375, 0.125),
    (0.875, 0.375),
    (0.125, 0.625),
    (0.625, 0.875),
];

/// Virtual point lights per light for the bounce. Each subpixel gathers from every fourth,
/// so a pixel sees all of them for the price of a quarter.
const BOUNCE_SAMPLES: usize = 64;

/// Bounce distances are clamped to this (squared, m^2) so a virtual light next to a corner
/// does not make a hot spot.
const BOUNCE_MIN_DIST2: f32 = 0.25;

/// The camera's view of the stage, traced once and shared by every light.
pub(crate) struct Renderer {
    geometry: Geometry,
    /// `SUBPIXELS.len()` entries per pixel, row-major.
    view: Vec<Option<Surface>>,
    scale: f32,
}

/// A light reduced to what shading needs.
struct Spot {
    pos: V3,
    axis: V3,
    cos_beam: f32,
    cos_field: f32,
    half_beam: f32,
    half_field: f32,
    /// Intensity on the axis times the gel's linear transmission.
    rgb: [f32; 3],
}

impl Spot {
    /// `l` pointing along `direction` (any length above 0).
    fn new(l: &Spotlight, direction: [f32; 3]) -> Spot {
        let half_beam = l.beam.to_radians() / 2.0;
        let half_field = l.field.to_radians() / 2.0;
        let gel = l.gel.unwrap_or([1.0; 3]).map(srgb_to_linear);
        Spot {
            pos: V3::from(l.position),
            axis: V3::from(direction).norm(),
            cos_beam: half_beam.cos(),
            cos_field: half_field.cos(),
            half_beam,
            half_field,
            rgb: gel.map(|g| g * l.intensity),
        }
    }

    /// Relative intensity towards unit direction `d` from the lamp: 1 inside the beam,
    /// smoothstep down to 0 at the field edge.
    fn profile(&self, d: V3) -> f32 {
        let c = self.axis.dot(d);
        if c <= self.cos_field {
            0.0
        } else if c >= self.cos_beam {
            1.0
        } else {
            let x =
                (c.clamp(-1.0, 1.0).acos() - self.half_beam) / (self.half_field - self.half_beam);
            let x = x.clamp(0.0, 1.0);
            1.0 - x * x * (3.0 - 2.0 * x)
        }
    }
}

/// A patch lit by the beam, re-emitting diffusely: position, normal, reflected flux.
struct Vpl {
    p: V3,
    n: V3,
    flux: [f32; 3],
}

impl Renderer {
    /// Traces the camera rays of a checked rig.
    pub fn new(rig: &VirtualStage) -> Renderer {
        let geometry = Geometry::new(rig);
        let (w, h) = (rig.width as usize, rig.height as usize);
        let cam = &rig.camera;
        let eye = V3::from(cam.position);
        let fwd = (V3::from(cam.look_at) - eye).norm();
        let right = fwd.cross(V3::new(0.0, 1.0, 0.0)).norm();
        let up = right.cross(fwd);
        let th = (cam.fov.to_radians() / 2.0).tan();
        let tw = th * w as f32 / h as f32;
        let view = (0..w * h)
            .into_par_iter()
            .flat_map_iter(|i| {
                let (px, py) = ((i % w) as f32, (i / w) as f32);
                let g = &geometry;
                SUBPIXELS.iter().map(move |&(sx, sy)| {
                    let u = 2.0 * (px + sx) / w as f32 - 1.0;
                    let v = 1.0 - 2.0 * (py + sy) / h as f32;
                    g.hit(eye, (fwd + right * (u * tw) + up * (v * th)).norm())
                })
            })
            .collect();
        Renderer {
            geometry,
            view,
            scale: rig.exposure.exp2(),
        }
    }

    /// Linear RGB radiance (times the exposure scale) of the stage lit by `light` alone,
    /// pointing along `direction`, row-major.
    pub fn render(&self, light: &Spotlight, direction: [f32; 3]) -> Vec<[f32; 3]> {
        let spot = Spot::new(light, direction);
        let vpls = self.bounce_lights(&spot);
        let n = SUBPIXELS.len();
        // Averaging the subpixels and dividing by pi (Lambert) folded into one factor.
        let k = self.scale / (n as f32 * PI);
        self.view
            .par_chunks(n)
            .map(|px| {
                let mut sum = [0.0f32; 3];
                for (j, s) in px.iter().enumerate() {
                    let Some(s) = s else { continue };
                    let mut e = self.direct(&spot, s);
                    // Interleaved: subpixel j gathers virtual lights j, j+n, ..., weighted n.
                    for v in vpls.iter().skip(j).step_by(n) {
                        let b = self.bounce(v, s) * n as f32;
                        for (e, f) in e.iter_mut().zip(v.flux) {
                            *e += f * b;
                        }
                    }
                    for ((sum, a), e) in sum.iter_mut().zip(s.albedo).zip(e) {
                        *sum += a * e;
                    }
                }
                sum.map(|v| v * k)
            })
            .collect()
    }

    /// Irradiance at `s` straight from the lamp: inverse square, cosine, cone, shadow.
    fn direct(&self, spot: &Spot, s: &Surface) -> [f32; 3] {
        let to = spot.pos - s.p;
        let d2 = to.dot(to);
        let d = d2.sqrt();
        let wi = to * (1.0 / d);
        let cos = s.n.dot(wi);
        if cos <= 0.0 {
            return [0.0; 3];
        }
        let f = spot.profile(-wi);
        if f == 0.0 || self.geometry.blocked(s.p, wi, d) {
            return [0.0; 3];
        }
        let g = f * cos / d2;
        spot.rgb.map(|i| i * g)
    }

    /// Geometry term from a virtual light to `s`: cosines over clamped distance squared, over
    /// pi (the virtual light is a Lambertian emitter), zero when hidden.
    fn bounce(&self, v: &Vpl, s: &Surface) -> f32 {
        let to = v.p - s.p;
        let d2 = to.dot(to);
        let d = d2.sqrt();
        if d < 1e-4 {
            return 0.0;
        }
        let wi = to * (1.0 / d);
        let cr = s.n.dot(wi);
        let ce = -v.n.dot(wi);
        if cr <= 0.0 || ce <= 0.0 || self.geometry.blocked(s.p, wi, d) {
            return 0.0;
        }
        cr * ce / (PI * d2.max(BOUNCE_MIN_DIST2))
    }

    /// Shoots the beam as equal-solid-angle rays (a Fibonacci spiral over the field cone) and
    /// keeps a reflected-flux virtual light where each lands.
    fn bounce_lights(&self, spot: &Spot) -> Vec<Vpl> {
        let (u, w) = orthonormal(spot.axis);
        let n = BOUNCE_SAMPLES;
        let cap = 1.0 - spot.cos_field;
        let d_omega = 2.0 * PI * cap / n as f32;
        let golden = PI * (3.0 - 5f32.sqrt());
        (0..n)
            .filter_map(|k| {
                let ct = 1.0 - cap * (k as f32 + 0.5) / n as f32;
                let st = (1.0 - ct * ct).max(0.0).sqrt();
                let (sp, cp) = (golden * k as f32).sin_cos();
                let d = (spot.axis * ct + u * (st * cp) + w * (st * sp)).norm();
                let f = spot.profile(d) * d_omega;
                if f == 0.0 {
                    return None;
                }
                let s = self.geometry.hit(spot.pos, d)?;
                let flux = [0, 1, 2].map(|c| spot.rgb[c] * f * s.albedo[c]);
                Some(Vpl {
                    p: s.p,
                    n: s.n,
                    flux,
                })
            })
            .collect()
    }
}

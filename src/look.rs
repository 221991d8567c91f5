//! A look: an intensity and a colour for every light of a scene.
//!
//! Everything downstream (the compositor, DMX, saved look files) reads the same
//! [`Look`], so what the gallery shows is what the stage is told to do.

use serde::{Deserialize, Serialize};

use crate::color::srgb_to_linear;

/// One light's setting. `color` is sRGB 0..1 with the brightness carried by
/// `intensity`; lights without colour keep white.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Level {
    /// Fraction of the fixture's full output, 0..1.
    pub intensity: f32,
    /// sRGB colour, 0..1 per channel.
    pub color: [f32; 3],
}

impl Level {
    /// A light that is off and white: the state of every light missing from a look file.
    pub const OFF: Level = Level {
        intensity: 0.0,
        color: [1.0, 1.0, 1.0],
    };

    /// The linear RGB multiplier this level applies to the light's basis image. The
    /// compositor and the DMX mapping both use it, so preview and stage agree.
    pub fn multiplier(&self) -> [f32; 3] {
        let c = self.color.map(srgb_to_linear);
        [
            c[0] * self.intensity,
            c[1] * self.intensity,
            c[2] * self.intensity,
        ]
    }
}

/// One [`Level`] per light, indexed like `Scene::lights` (channel order).
#[derive(Debug, Clone, PartialEq)]
pub struct Look {
    /// The levels, one per scene light.
    pub levels: Vec<Level>,
}

impl Look {
    /// Every light off: the default base look.
    pub fn off(lights: usize) -> Look {
        Look {
            levels: vec![Level::OFF; lights],
        }
    }
}

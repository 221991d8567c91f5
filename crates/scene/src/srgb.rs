//! The sRGB transfer functions: looks carry colours as designers pick them (sRGB), and
//! everything that mixes light converts them to linear light first.

/// sRGB-encoded value (0..1) to linear light.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear light (clamped to 0..1) to sRGB-encoded 0..1 (computed in f64, so full-value
/// colours round-trip to exactly 1.0).
pub fn linear_to_srgb(v: f32) -> f32 {
    linear_to_srgb_f64(f64::from(v.clamp(0.0, 1.0))) as f32
}

/// The sRGB encoding in f64 (no clamp): [`linear_to_srgb`], and the reference the
/// compositor's fast encoder is fitted and tested against.
pub fn linear_to_srgb_f64(v: f64) -> f64 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trips() {
        for i in 0..=255 {
            let v = i as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-5);
        }
        assert_eq!(linear_to_srgb(1.0), 1.0);
        assert_eq!(linear_to_srgb(3.0), 1.0);
        assert_eq!(linear_to_srgb(-1.0), 0.0);
    }
}

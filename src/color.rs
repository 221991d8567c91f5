//! Colour science shared by objectives, the compositor and the gallery: sRGB transfer
//! functions and CIELAB (D65), so every stage measures colour the same way.

/// sRGB-encoded value (0..1) to linear light.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear light (clamped to 0..1) to sRGB-encoded 0..1.
pub fn linear_to_srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v >= 1.0 {
        1.0 // exact, so full-value colours round-trip to 1.0
    } else if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// CIELAB (D65 white) of a linear-light RGB colour: L* in 0..100.
pub fn linear_to_lab(rgb: [f32; 3]) -> [f32; 3] {
    let [r, g, b] = rgb;
    let x = (0.412_456_4 * r + 0.357_576_1 * g + 0.180_437_5 * b) / 0.950_47;
    let y = 0.212_672_9 * r + 0.715_152_2 * g + 0.072_175 * b;
    let z = (0.019_333_9 * r + 0.119_192 * g + 0.950_304_1 * b) / 1.088_83;
    let (fx, fy, fz) = (lab_f(x), lab_f(y), lab_f(z));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// CIELAB of an sRGB-encoded colour (0..1 per channel).
pub fn srgb_to_lab(rgb: [f32; 3]) -> [f32; 3] {
    linear_to_lab(rgb.map(srgb_to_linear))
}

/// CIE L* (0..100) of a linear luminance Y (0..1 of white).
pub fn lightness(y: f32) -> f32 {
    116.0 * lab_f(y) - 16.0
}

/// Relative luminance (Y) of linear sRGB.
pub fn luminance(rgb: [f32; 3]) -> f32 {
    0.212_672_9 * rgb[0] + 0.715_152_2 * rgb[1] + 0.072_175 * rgb[2]
}

/// The CIELAB companding function, with the linear segment near black.
fn lab_f(t: f32) -> f32 {
    const DELTA: f32 = 6.0 / 29.0;
    if t > DELTA * DELTA * DELTA {
        t.cbrt()
    } else {
        t / (3.0 * DELTA * DELTA) + 4.0 / 29.0
    }
}

/// CIE76 colour difference.
pub fn delta_e(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// 8-bit sRGB to linear, as a table: decoding reference pixels is then a lookup.
pub fn srgb8_to_linear_table() -> &'static [f32; 256] {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)))
}

/// Resolution of [`encode_srgb8`]'s table: fine enough that every 8-bit code is reachable
/// and the result matches exact encoding to within one code.
const ENCODE_STEPS: usize = 1 << 14;

/// Linear light to 8-bit sRGB through a table (clamps to 0..1): the compositor's hot path.
#[inline]
pub fn encode_srgb8(v: f32) -> u8 {
    static TABLE: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    let table = TABLE.get_or_init(|| {
        (0..=ENCODE_STEPS)
            .map(|i| (linear_to_srgb(i as f32 / ENCODE_STEPS as f32) * 255.0).round() as u8)
            .collect()
    });
    // NaN and negatives clamp to 0 (`as usize` saturates).
    let i = (v * ENCODE_STEPS as f32 + 0.5) as usize;
    table[i.min(ENCODE_STEPS)]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference values from Bruce Lindbloom's calculator (sRGB, D65, no adaptation).
    #[test]
    fn srgb_to_lab_matches_published_values() {
        let cases: [([f32; 3], [f32; 3]); 6] = [
            ([1.0, 1.0, 1.0], [100.0, 0.0, 0.0]),
            ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
            ([1.0, 0.0, 0.0], [53.2408, 80.0925, 67.2032]),
            ([0.0, 1.0, 0.0], [87.7347, -86.1827, 83.1793]),
            ([0.0, 0.0, 1.0], [32.2970, 79.1875, -107.8602]),
            (
                [119.0 / 255.0, 119.0 / 255.0, 119.0 / 255.0],
                [50.0, 0.0, 0.0],
            ),
        ];
        for (rgb, want) in cases {
            let got = srgb_to_lab(rgb);
            for k in 0..3 {
                assert!(
                    (got[k] - want[k]).abs() < 0.05 + if k == 0 { 0.0 } else { 0.1 },
                    "{rgb:?}: got {got:?}, want {want:?}"
                );
            }
        }
    }

    #[test]
    fn srgb_round_trips() {
        for i in 0..=255 {
            let v = i as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-5);
            assert_eq!(encode_srgb8(srgb8_to_linear_table()[i]), i as u8);
        }
        assert_eq!(encode_srgb8(f32::NAN), 0);
        assert_eq!(encode_srgb8(-3.0), 0);
        assert_eq!(encode_srgb8(7.0), 255);
    }
}

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

/// [`linear_to_lab`] for a strip of planar pixels (clamped to 0..1 first), written as the
/// strip's L, a and b planes into `lab` (`3 * n` long): the gallery's proxy conversion. A
/// fast cube root keeps it within 1e-3 Delta-E of the exact conversion, and the loop
/// vectorises (AVX-512 or AVX2 when the CPU has them; the result is the same bit for bit
/// either way).
pub fn linear_to_lab_planar(rgb: [&[f32]; 3], lab: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if is_x86_feature_detected!("avx512f") {
        // SAFETY: AVX-512F was just detected.
        return unsafe { lab_planar_avx512(rgb, lab) };
    } else if is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 was just detected.
        return unsafe { lab_planar_avx2(rgb, lab) };
    }
    lab_planar(rgb, lab);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn lab_planar_avx512(rgb: [&[f32]; 3], lab: &mut [f32]) {
    lab_planar(rgb, lab);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn lab_planar_avx2(rgb: [&[f32]; 3], lab: &mut [f32]) {
    lab_planar(rgb, lab);
}

#[inline(always)]
fn lab_planar(rgb: [&[f32]; 3], lab: &mut [f32]) {
    let n = lab.len() / 3;
    let (l_out, rest) = lab.split_at_mut(n);
    let (a_out, b_out) = rest.split_at_mut(n);
    let (r, g, b) = (&rgb[0][..n], &rgb[1][..n], &rgb[2][..n]);
    for i in 0..n {
        let (r, g, b) = (
            r[i].clamp(0.0, 1.0),
            g[i].clamp(0.0, 1.0),
            b[i].clamp(0.0, 1.0),
        );
        let x = (0.412_456_4 * r + 0.357_576_1 * g + 0.180_437_5 * b) * (1.0 / 0.950_47);
        let y = 0.212_672_9 * r + 0.715_152_2 * g + 0.072_175 * b;
        let z = (0.019_333_9 * r + 0.119_192 * g + 0.950_304_1 * b) * (1.0 / 1.088_83);
        let (fx, fy, fz) = (lab_f_fast(x), lab_f_fast(y), lab_f_fast(z));
        l_out[i] = 116.0 * fy - 16.0;
        a_out[i] = 500.0 * (fx - fy);
        b_out[i] = 200.0 * (fy - fz);
    }
}

/// [`lab_f`] with [`fast_cbrt`], branch-free so it vectorises.
#[inline(always)]
fn lab_f_fast(t: f32) -> f32 {
    const DELTA: f32 = 6.0 / 29.0;
    let linear = t * (1.0 / (3.0 * DELTA * DELTA)) + 4.0 / 29.0;
    let root = fast_cbrt(t);
    if t > DELTA * DELTA * DELTA {
        root
    } else {
        linear
    }
}

/// Cube root of a finite non-negative `x` (about 4e-7 relative error), with no division
/// or branch so it vectorises cheaply: an exponent-thirding bit trick guesses x^(-1/3) to
/// 3.5%, three division-free Newton steps refine it, and x r^2 is the root. 10-20x faster
/// than `f32::cbrt` in a loop.
#[inline(always)]
pub fn fast_cbrt(x: f32) -> f32 {
    let x = x.max(1e-30);
    let mut r = f32::from_bits(0x54a2_3000 - x.to_bits() / 3);
    for _ in 0..3 {
        r *= (4.0 - x * (r * r * r)) * (1.0 / 3.0);
    }
    x * (r * r)
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

/// [`encode_srgb8`]'s table: entry i is the code of linear i / ENCODE_STEPS.
fn encode_table() -> &'static [u8] {
    static TABLE: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        (0..=ENCODE_STEPS)
            .map(|i| (linear_to_srgb(i as f32 / ENCODE_STEPS as f32) * 255.0).round() as u8)
            .collect()
    })
}

/// Linear light to 8-bit sRGB through a table (clamps to 0..1): the compositor's hot path.
#[inline]
pub fn encode_srgb8(v: f32) -> u8 {
    encode_with(encode_table(), v)
}

#[inline(always)]
fn encode_with(table: &[u8], v: f32) -> u8 {
    // NaN and negatives clamp to 0 (`as usize` saturates).
    let i = (v * ENCODE_STEPS as f32 + 0.5) as usize;
    table[i.min(ENCODE_STEPS)]
}

/// [`encode_srgb8`] of planar `[R, G, B]` samples into interleaved `out` (`3 * n` long):
/// table indices are computed in a vectorisable pass, then looked up.
pub fn encode_srgb8_planar(rgb: [&[f32]; 3], out: &mut [u8]) {
    const CHUNK: usize = 64;
    let table: &[u8; ENCODE_STEPS + 1] = encode_table()
        .try_into()
        .expect("the table has ENCODE_STEPS + 1 entries");
    for (c, px) in out.chunks_mut(3 * CHUNK).enumerate() {
        let n = px.len() / 3;
        let mut idx = [[0u32; CHUNK]; 3];
        for (idx, plane) in idx.iter_mut().zip(rgb) {
            for (i, &v) in idx.iter_mut().zip(&plane[c * CHUNK..c * CHUNK + n]) {
                // max() maps NaN to 0, as encode_srgb8's saturating cast does; clamp()
                // would keep NaN.
                #[allow(clippy::manual_clamp)]
                let t = v.max(0.0).min(1.0) * ENCODE_STEPS as f32 + 0.5;
                // SAFETY: t is finite and in 0.5..=ENCODE_STEPS + 0.5, so it fits a u32;
                // the unchecked cast lets the loop vectorise.
                *i = unsafe { t.to_int_unchecked::<u32>() };
            }
        }
        for (i, px) in px.chunks_exact_mut(3).enumerate() {
            for (o, idx) in px.iter_mut().zip(&idx) {
                *o = table[(idx[i] as usize).min(ENCODE_STEPS)];
            }
        }
    }
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

    #[test]
    fn fast_lab_is_within_a_thousandth_of_delta_e() {
        let mut worst = 0.0f32;
        let steps = 40;
        for ri in 0..=steps {
            for gi in 0..=steps {
                let n = steps + 1;
                let r = vec![ri as f32 / steps as f32; n];
                let g = vec![(gi as f32 / steps as f32).powi(3); n];
                let b: Vec<f32> = (0..n).map(|k| (k as f32 / steps as f32).powi(2)).collect();
                let mut lab = vec![0.0; 3 * n];
                linear_to_lab_planar([&r, &g, &b], &mut lab);
                for k in 0..n {
                    let want = linear_to_lab([r[k], g[k], b[k]]);
                    let got = [lab[k], lab[n + k], lab[2 * n + k]];
                    worst = worst.max(delta_e(got, want));
                }
            }
        }
        assert!(worst < 1e-3, "worst Delta-E {worst}");
        for x in [1e-6f32, 0.008, 0.3, 1.0, 1.2] {
            assert!((fast_cbrt(x) - x.cbrt()).abs() <= 1e-6 * x.cbrt(), "{x}");
        }
    }

    #[test]
    fn planar_encoding_matches_per_sample_encoding() {
        let r: Vec<f32> = (0..300).map(|i| i as f32 / 250.0 - 0.1).collect();
        let g: Vec<f32> = r.iter().map(|v| v * v).collect();
        let b: Vec<f32> = r.iter().rev().copied().collect();
        let mut out = vec![0u8; 900];
        encode_srgb8_planar([&r, &g, &b], &mut out);
        for i in 0..300 {
            assert_eq!(out[3 * i..3 * i + 3], [r[i], g[i], b[i]].map(encode_srgb8));
        }
    }
}

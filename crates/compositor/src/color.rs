//! Colour science shared by objectives, the compositor and the gallery: CIELAB (D65) and
//! the fast sRGB encoders, so every stage measures colour the same way (the scalar sRGB
//! transfer functions are the scene model's, [`visobjd_scene::srgb`]; the sRGB-to-XYZ
//! matrix and the white are the emitter solve's, [`visobjd_scene::emitter::colour`], here
//! in `f32` for speed).

use visobjd_scene::emitter::colour::{D65, SRGB_TO_XYZ};
use visobjd_scene::srgb::{linear_to_srgb_f64, srgb_to_linear};

#[cfg(target_arch = "x86_64")]
use crate::cpu::{Avx2Fma, Avx512F};

/// A row of [`SRGB_TO_XYZ`] in `f32` (each entry has 7 decimals, so these are the `f32`
/// values of the published decimals).
const fn xyz_row(r: usize) -> [f32; 3] {
    let row = SRGB_TO_XYZ[r];
    [row[0] as f32, row[1] as f32, row[2] as f32]
}

/// The rows of the linear sRGB to XYZ matrix.
const X: [f32; 3] = xyz_row(0);
const Y: [f32; 3] = xyz_row(1);
const Z: [f32; 3] = xyz_row(2);
/// The D65 white's X and Z (its Y is 1).
const XN: f32 = D65[0] as f32;
const ZN: f32 = D65[2] as f32;

/// CIELAB (D65 white) of a linear-light RGB colour: L* in 0..100.
pub fn linear_to_lab(rgb: [f32; 3]) -> [f32; 3] {
    let [r, g, b] = rgb;
    let x = (X[0] * r + X[1] * g + X[2] * b) / XN;
    let y = Y[0] * r + Y[1] * g + Y[2] * b;
    let z = (Z[0] * r + Z[1] * g + Z[2] * b) / ZN;
    let (fx, fy, fz) = (lab_f(x), lab_f(y), lab_f(z));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// [`linear_to_lab`] for a strip of planar pixels (clamped to 0..1 first), written as the
/// strip's L, a and b planes into `lab` (`3 * n` long): the gallery's proxy conversion. A
/// fast cube root keeps it within 1e-3 Delta-E of the exact conversion, and the loop
/// vectorises (AVX-512 or AVX2 + FMA when the CPU has them; those two give the same result
/// bit for bit).
pub fn linear_to_lab_planar(rgb: [&[f32]; 3], lab: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if let Some(t) = Avx512F::detect() {
        // SAFETY: the token exists, so the CPU has AVX-512F and FMA.
        return unsafe { lab_planar_avx512(t, rgb, lab) };
    } else if let Some(t) = Avx2Fma::detect() {
        // SAFETY: the token exists, so the CPU has AVX2 and FMA.
        return unsafe { lab_planar_avx2(t, rgb, lab) };
    }
    lab_planar::<{ cfg!(target_feature = "fma") }>(rgb, lab);
}

/// The token is the caller's proof of the features.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma")]
fn lab_planar_avx512(_: Avx512F, rgb: [&[f32]; 3], lab: &mut [f32]) {
    lab_planar::<true>(rgb, lab);
}

/// The token is the caller's proof of the features.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn lab_planar_avx2(_: Avx2Fma, rgb: [&[f32]; 3], lab: &mut [f32]) {
    lab_planar::<true>(rgb, lab);
}

#[inline(always)]
fn lab_planar<const FMA: bool>(rgb: [&[f32]; 3], lab: &mut [f32]) {
    let n = lab.len() / 3;
    let (l_out, rest) = lab.split_at_mut(n);
    let (a_out, b_out) = rest.split_at_mut(n);
    // Every slice exactly n long: with no bounds check left in the loop, it vectorises
    // without a scalar epilogue (which took a whole vector's worth of a 96-pixel strip).
    let b_out = &mut b_out[..n];
    let (r, g, b) = (&rgb[0][..n], &rgb[1][..n], &rgb[2][..n]);
    // The XYZ matrix's rows, X and Z already divided by the white point's.
    let (x, z) = (X.map(|k| k / XN), Z.map(|k| k / ZN));
    let row = |k: [f32; 3], r, g, b: f32| madd::<FMA>(r, k[0], madd::<FMA>(g, k[1], b * k[2]));
    for i in 0..n {
        let (r, g, b) = (
            r[i].clamp(0.0, 1.0),
            g[i].clamp(0.0, 1.0),
            b[i].clamp(0.0, 1.0),
        );
        let fx = lab_f_fast::<FMA>(row(x, r, g, b));
        let fy = lab_f_fast::<FMA>(row(Y, r, g, b));
        let fz = lab_f_fast::<FMA>(row(z, r, g, b));
        l_out[i] = madd::<FMA>(116.0, fy, -16.0);
        a_out[i] = 500.0 * (fx - fy);
        b_out[i] = 200.0 * (fy - fz);
    }
}

/// `a * b + c`, fused (one instruction, one rounding) if `FMA`: the SIMD paths have it, and
/// without it `mul_add` would be a slow library call.
#[inline(always)]
fn madd<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA { a.mul_add(b, c) } else { a * b + c }
}

/// [`lab_f`] with [`cbrt_approx`], branch-free so it vectorises.
#[inline(always)]
fn lab_f_fast<const FMA: bool>(t: f32) -> f32 {
    const DELTA: f32 = 6.0 / 29.0;
    let linear = madd::<FMA>(t, 1.0 / (3.0 * DELTA * DELTA), 4.0 / 29.0);
    // t may be -0.0 (from a -0.0 input), for which cbrt_approx gives NaN, but that lane
    // takes the linear branch.
    let root = cbrt_approx::<FMA>(t);
    if t > DELTA * DELTA * DELTA {
        root
    } else {
        linear
    }
}

/// Cube root of a finite non-negative `x` (within about 2e-7 relative for 0, -0 and normal
/// `x`; see `cbrt_approx`). 10-20x faster than `f32::cbrt` in a loop.
#[inline(always)]
pub fn fast_cbrt(x: f32) -> f32 {
    // abs() maps -0.0 to +0.0, which cbrt_approx needs.
    cbrt_approx::<{ cfg!(target_feature = "fma") }>(x.abs())
}

/// Cube root of +0.0 or a normal positive `x`, with no division or branch so it vectorises
/// cheaply (12 vector instructions with FMA). An exponent-thirding bit trick guesses
/// r ~ x^(-1/3) to 3.5%; then x^(1/3) = x r^2 (1 - h)^(-2/3) with h = 1 - x r^3, and the
/// last factor is a degree-5 polynomial in h (a Chebyshev fit, 2e-8 relative on the
/// trick's range of h). That one step does the work of three Newton steps.
#[inline(always)]
fn cbrt_approx<const FMA: bool>(x: f32) -> f32 {
    // The guess's bits are K - bits(x) / 3, the division done in floats (a convert and an
    // FMA; rounding the bits to 24 bits moves the guess by about 1e-5).
    let guess = madd::<FMA>(x.to_bits() as i32 as f32, -1.0 / 3.0, 0x54a2_3000 as f32);
    // SAFETY: whatever x's bits, guess is finite and within K +- 2^31 / 3, inside i32.
    let r = f32::from_bits(unsafe { guess.to_int_unchecked::<i32>() } as u32);
    // h from the rounded x r^2, so that rounding is (to first order) undone by p(h).
    let xr2 = x * (r * r);
    let h = madd::<FMA>(-xr2, r, 1.0);
    // (1 - h)^(-2/3) on -0.1065..0.1 (the guess is within 3.5%, so h is within that).
    const C: [f32; 6] = [
        0.420_792_63,
        0.459_022_77,
        0.493_885_55,
        0.555_530_4,
        0.666_666_5,
        1.0,
    ];
    let p = C[1..].iter().fold(C[0], |p, &c| madd::<FMA>(p, h, c));
    xr2 * p
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
    Y[0] * rgb[0] + Y[1] * rgb[1] + Y[2] * rgb[2]
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

/// The encoder works on a 16-bit key of each value: its float bits shifted right by 11
/// (arithmetically), less those of 2^-16 (below which every code is 0: 255 x 12.92 x 2^-16
/// = 0.05), clamped to 0..=65535. For 2^-16..1 the key is 4 bits of octave, 1 of half
/// octave and 11 of position within the half octave; negative values clamp to 0, and values
/// from 1 up (infinity and positive NaN too) to 65535.
const KEY_BASE: u32 = 0x3780_0000;

/// The encoder's table: per half octave s (the key's top 5 bits), a quadratic in the
/// position t = the key rotated left by 5 within 16 bits (in 1/65536ths: the key's low 11
/// bits, then s, which the fit allows for), with the code x 256 + 128 as value:
/// `y = c0 + t * (c1 - t * n2)` in 16-bit fixed point, whose high byte is the code.
/// Rows are `[c0, c1, n2]` (sRGB is concave, so the quadratic term is subtracted and every
/// intermediate stays within 0..65536). 16-bit lanes do twice the work of 32-bit ones per
/// instruction: thumbnails were 2-5% faster than with a float cubic per half octave (within
/// 0.003 codes) in same-run measurements.
struct EncodeTable {
    /// `[c0, c1, n2][s]`, for 16-bit table lookups.
    words: [[u16; 32]; 3],
    /// The same as 32-bit lanes, for encoders that work in them.
    dwords: [[u32; 32]; 3],
}

/// [`EncodeTable`], fitted once: through 3 Chebyshev nodes per half octave, aimed at the
/// middle of each key's range of values, in f64, then rounded. The result is within 0.04
/// codes of exact sRGB (the tests check every key).
fn encode_table() -> &'static EncodeTable {
    static TABLE: std::sync::OnceLock<EncodeTable> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut words = [[0u16; 32]; 3];
        for s in 0..32u32 {
            let lo = f64::from(f32::from_bits(KEY_BASE + (s << 22)));
            let hi = f64::from(f32::from_bits(KEY_BASE + ((s + 1) << 22)));
            // Code x 256 + 128 at position t, aimed half a key into the key's range.
            let y = |t: f64| {
                let x = t - f64::from(s) / 65536.0 + 0.5 / 2048.0;
                256.0 * 255.0 * linear_to_srgb_f64(lo + x * (hi - lo)) + 128.0
            };
            let nodes: [f64; 3] = std::array::from_fn(|k| {
                0.5 + 0.5 * ((2 * k + 1) as f64 * std::f64::consts::PI / 6.0).cos()
            });
            let [a0, a1, a2] = interpolate(nodes, nodes.map(y));
            // The outer high-half multiply rounds down: +0.5 on c0 centres it.
            let coefficients = [a0 + 0.5, a1, -a2];
            for (row, c) in words.iter_mut().zip(coefficients) {
                row[s as usize] = c.round().clamp(0.0, 65535.0) as u16;
            }
        }
        let dwords = words.map(|row| row.map(u32::from));
        EncodeTable { words, dwords }
    })
}

/// The encoder's key of `v` (see [`KEY_BASE`]).
fn encode_key(v: f32) -> u32 {
    // The shift comes first, so negative values (sign bit set) stay negative.
    (((v.to_bits() as i32) >> 11) - (KEY_BASE >> 11) as i32).clamp(0, 65535) as u32
}

/// The code of a key, in the 16-bit fixed point every SIMD path computes.
fn code_of_key(key: u32, table: &EncodeTable) -> u8 {
    (fixed_point(key, table)[1] >> 8) as u8
}

/// The quadratic of a key as `[c1 - t * n2, y]`, in 32 bits (wrapping), so the tests can
/// check that neither leaves the 16 bits the SIMD lanes have.
fn fixed_point(key: u32, table: &EncodeTable) -> [u32; 2] {
    let [c0, c1, n2] = table.dwords.map(|row| row[(key >> 11) as usize]);
    let t = ((key << 5) | (key >> 11)) & 0xFFFF;
    let y1 = c1.wrapping_sub((t * n2) >> 16);
    [y1, c0.wrapping_add((t * y1) >> 16)]
}

/// Coefficients (constant term first) of the polynomial through N points: Gauss-Jordan on
/// the Vandermonde system, with partial pivoting.
fn interpolate<const N: usize>(x: [f64; N], mut y: [f64; N]) -> [f64; N] {
    let mut m: [[f64; N]; N] =
        std::array::from_fn(|r| std::array::from_fn(|k| x[r].powi(k as i32)));
    for col in 0..N {
        let pivot = (col..N)
            .max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))
            .unwrap_or(col);
        m.swap(col, pivot);
        y.swap(col, pivot);
        for r in (0..N).filter(|&r| r != col) {
            let f = m[r][col] / m[col][col];
            let pivot_row = m[col];
            for (a, p) in m[r].iter_mut().zip(pivot_row) {
                *a -= f * p;
            }
            y[r] -= f * y[col];
        }
    }
    std::array::from_fn(|k| y[k] / m[k][k])
}

/// Linear light (clamped to 0..1) to 8-bit sRGB, rounded to nearest: exact but within 0.04
/// codes of a rounding tie. Negative values and negative NaN give 0, positive NaN 255. The
/// compositor's hot path: every SIMD path of [`encode_srgb8_planar`] does the same integer
/// arithmetic, so gives the same codes.
#[inline]
pub fn encode_srgb8(v: f32) -> u8 {
    code_of_key(encode_key(v), encode_table())
}

/// [`encode_srgb8`] of planar `[R, G, B]` samples into interleaved `out` (`3 * n` long),
/// the same codes bit for bit, 32, 16 or 8 pixels at a time with AVX-512 (VBMI and VBMI2),
/// AVX-512 or AVX2.
pub fn encode_srgb8_planar(rgb: [&[f32]; 3], out: &mut [u8]) {
    let n = out.len() / 3;
    let rgb = rgb.map(|p| &p[..n]);
    #[cfg(target_arch = "x86_64")]
    let done = x86::encode(rgb, out);
    #[cfg(not(target_arch = "x86_64"))]
    let done = 0;
    let table = encode_table();
    for (i, px) in out.chunks_exact_mut(3).enumerate().skip(done) {
        for (o, plane) in px.iter_mut().zip(rgb) {
            *o = code_of_key(encode_key(plane[i]), table);
        }
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) use x86::Vbmi;

/// The SIMD encoders: each does whole vectors of pixels and returns how many it did.
#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    use super::{KEY_BASE, encode_table};
    use crate::cpu::{Avx2Fma, Avx512F, NonTemporal};

    /// The widest encoder this CPU runs; returns the pixels it did.
    pub(super) fn encode(rgb: [&[f32]; 3], out: &mut [u8]) -> usize {
        static BEST: std::sync::OnceLock<Option<Encoder>> = std::sync::OnceLock::new();
        match BEST.get_or_init(|| encoders().first().copied()) {
            Some(encoder) => encoder.encode(rgb, out),
            None => 0,
        }
    }

    /// A SIMD encoder, with the token of its features: only made where the CPU has them.
    #[derive(Clone, Copy)]
    #[allow(
        clippy::large_enum_variant,
        reason = "one lives in a static and is used by reference; a Vbmi is the table it loads"
    )]
    pub(super) enum Encoder {
        Vbmi(Vbmi),
        Avx512(Avx512F),
        Avx2(Avx2Fma),
    }

    impl Encoder {
        /// Pixels per vector.
        #[cfg(test)]
        pub(super) fn lanes(self) -> usize {
            match self {
                Encoder::Vbmi(_) => 32,
                Encoder::Avx512(_) => 16,
                Encoder::Avx2(_) => 8,
            }
        }

        /// Encodes whole vectors of pixels into `out`; returns how many it did.
        pub(super) fn encode(&self, rgb: [&[f32]; 3], out: &mut [u8]) -> usize {
            match *self {
                // SAFETY: the Vbmi exists, so the CPU has AVX-512 F, BW, VBMI and VBMI2.
                Encoder::Vbmi(ref vbmi) => unsafe { encode_avx512_vbmi(vbmi, rgb, out) },
                // SAFETY: the token exists, so the CPU has AVX-512F.
                Encoder::Avx512(t) => unsafe { encode_avx512(t, rgb, out) },
                // SAFETY: the token exists, so the CPU has AVX2.
                Encoder::Avx2(t) => unsafe { encode_avx2(t, rgb, out) },
            }
        }
    }

    /// Every SIMD encoder this CPU runs, widest first.
    pub(super) fn encoders() -> Vec<Encoder> {
        [
            Vbmi::new().map(Encoder::Vbmi),
            Avx512F::detect().map(Encoder::Avx512),
            Avx2Fma::detect().map(Encoder::Avx2),
        ]
        .into_iter()
        .flatten()
        .collect()
    }

    /// The byte of value v's code (0..32) in [`Vbmi::words`]: `vpackusdw` packs per
    /// 128-bit lane, so word j holds value 4 (j / 8) + j % 8 for j % 8 < 4, else that + 12,
    /// and a code is its word's high byte.
    const fn code_byte(v: usize) -> u8 {
        (2 * (8 * (v % 16 / 4) + v % 4 + 4 * (v / 16)) + 1) as u8
    }

    /// The indices of the two byte permutes that make output bytes 64j..64j + 64 of
    /// interleaved RGB (byte m is pixel m / 3's channel m % 3) from codes in
    /// [`Vbmi::words`]' order, 32 pixels a register: the first picks red and green (from a
    /// red and a green register), the second keeps those and picks blue (from a blue
    /// register). Bytes past the 32 pixels are left 0.
    const fn interleave_index(j: usize, blue: bool) -> [u8; 64] {
        let mut idx = [0u8; 64];
        let mut k = 0;
        while k < 64 && (64 * j + k) / 3 < 32 {
            let (p, c) = ((64 * j + k) / 3, (64 * j + k) % 3);
            let byte = code_byte(p);
            idx[k] = match (blue, c) {
                (false, 0) => byte,
                (false, 1) => 64 + byte,
                (false, _) => 0,
                (true, 2) => 64 + byte,
                (true, _) => k as u8,
            };
            k += 1;
        }
        idx
    }

    /// The encoder with AVX-512 VBMI, and proof that the CPU has AVX-512 F, BW, VBMI and
    /// VBMI2: one is only made where it does. It holds the table in registers. Its methods
    /// are always inlined (which functions with target features cannot be), so they compile
    /// into callers that enable those features, the render's kernel among them.
    #[derive(Clone, Copy)]
    pub(crate) struct Vbmi {
        rows: [__m512i; 3],
        base: __m512i,
        /// Byte k of two [`Vbmi::words`] (k < 32 from the first): where value k's code is
        /// (see [`code_byte`]).
        bytes: __m512i,
    }

    impl Vbmi {
        /// Loads the table; `None` if the CPU lacks one of the features.
        pub(crate) fn new() -> Option<Vbmi> {
            let have = is_x86_feature_detected!("avx512f")
                && is_x86_feature_detected!("avx512bw")
                && is_x86_feature_detected!("avx512vbmi")
                && is_x86_feature_detected!("avx512vbmi2");
            // SAFETY: the features were just detected.
            have.then(|| unsafe { Vbmi::load() })
        }

        #[target_feature(enable = "avx512f,avx512bw,avx512vbmi,avx512vbmi2")]
        fn load() -> Vbmi {
            const fn code_bytes() -> [u8; 64] {
                let mut idx = [0u8; 64];
                let mut k = 0;
                while k < 64 {
                    idx[k] = code_byte(k % 32) + 64 * (k / 32) as u8;
                    k += 1;
                }
                idx
            }
            const BYTES: [u8; 64] = code_bytes();
            // SAFETY: each table row is 32 words (64 bytes), the index 64 bytes.
            unsafe {
                Vbmi {
                    rows: encode_table()
                        .words
                        .map(|row| _mm512_loadu_si512(row.as_ptr().cast())),
                    base: _mm512_set1_epi32((KEY_BASE >> 11) as i32),
                    bytes: _mm512_loadu_si512(BYTES.as_ptr().cast()),
                }
            }
        }

        /// The codes of 32 values (`a` then `b`, as float bits), each the high byte of a
        /// word, in `vpackusdw`'s order (see [`code_byte`]).
        #[inline(always)]
        fn words(self, a: __m512i, b: __m512i) -> __m512i {
            // SAFETY: a Vbmi exists only where the CPU has the features.
            unsafe {
                let a = _mm512_sub_epi32(_mm512_srai_epi32::<11>(a), self.base);
                let b = _mm512_sub_epi32(_mm512_srai_epi32::<11>(b), self.base);
                let key = _mm512_packus_epi32(a, b);
                // The key rotated left by 5 is t with s in its low 5 bits, which are all
                // a 32-word permute reads of its index.
                let t = _mm512_shrdi_epi16::<11>(key, key);
                let [c0, c1, n2] = self.rows.map(|row| _mm512_permutexvar_epi16(t, row));
                let y1 = _mm512_sub_epi16(c1, _mm512_mulhi_epu16(t, n2));
                _mm512_add_epi16(c0, _mm512_mulhi_epu16(t, y1))
            }
        }

        /// [`Vbmi::words`] of `plane[i..i + 32]`.
        ///
        /// # Safety
        /// `i + 32 <= plane.len()`.
        #[inline(always)]
        unsafe fn load_words(self, plane: &[f32], i: usize) -> __m512i {
            debug_assert!(i + 32 <= plane.len());
            // SAFETY: the caller guarantees the bounds; a Vbmi, the features.
            unsafe {
                let a = _mm512_loadu_si512(plane.as_ptr().add(i).cast());
                let b = _mm512_loadu_si512(plane.as_ptr().add(i + 16).cast());
                self.words(a, b)
            }
        }

        /// The codes of 96 linear values, in order, in registers: codes 0..64, then 64..96
        /// in the low half of the second (its high half is not codes).
        #[inline(always)]
        fn codes(self, values: &[__m512; 6]) -> [__m512i; 2] {
            // SAFETY: a Vbmi exists only where the CPU has the features.
            unsafe {
                let v = values.map(|v| _mm512_castps_si512(v));
                let [a, b, c] = [
                    self.words(v[0], v[1]),
                    self.words(v[2], v[3]),
                    self.words(v[4], v[5]),
                ];
                [
                    _mm512_permutex2var_epi8(a, self.bytes, b),
                    _mm512_permutexvar_epi8(self.bytes, c),
                ]
            }
        }

        /// The codes of 96 linear values, in order.
        #[inline(always)]
        pub(crate) fn plane(self, values: &[__m512; 6], plane: &mut [u8; 96]) {
            let [ab, c] = self.codes(values);
            // SAFETY: a Vbmi exists only where the CPU has the features; the stores are
            // bytes 0..64 and 64..96 of the plane.
            unsafe {
                _mm512_storeu_si512(plane.as_mut_ptr().cast(), ab);
                _mm256_storeu_si256(plane.as_mut_ptr().add(64).cast(), _mm512_castsi512_si256(c));
            }
        }

        /// Interleaves planes of 96 red and green codes with the codes of 96 blue values,
        /// encoded here from the registers that hold them (so blue never goes through
        /// memory: 1.5-2% faster renders), into RGB pixels: the first
        /// `min(out.len(), 288)` bytes of `out`. Per 64 bytes, one single-table byte
        /// permute per channel, each filling that channel's bytes; then a two-table one per
        /// cache line realigns those bytes to `out`'s lines, so every line wholly inside
        /// `out` is written by one non-temporal store. A line written whole need not be read
        /// from memory first: for 100 thumbnails at 44 lights that read was 12% of the
        /// render, and the thumbnails are read much later anyway. The lines at the ends,
        /// which neighbouring strips share, are written normally.
        ///
        /// The line stores are fenced when `nt`'s scope ends: a fence here, per candidate and
        /// strip, would cost more than the stores save.
        #[inline(always)]
        pub(crate) fn stream_interleaved(
            self,
            _: &NonTemporal,
            planes: [&[u8; 96]; 2],
            blue: &[__m512; 6],
            out: &mut [u8],
        ) {
            // Byte k of output bytes 64j..64j + 64 is pixel (64j + k) / 3's channel
            // (j + k) % 3 (64 is 1 mod 3), from the half's registers of 64 pixels.
            const PIXEL: [[u8; 64]; 3] = {
                let mut idx = [[0u8; 64]; 3];
                let mut m = 0;
                while m < 3 * 64 {
                    idx[m / 64][m % 64] = (m / 3 % 64) as u8;
                    m += 1;
                }
                idx
            };
            // LANES[m]: lanes k with k % 3 == m.
            const LANES: [u64; 3] = {
                let mut lanes = [0u64; 3];
                let mut k = 0;
                while k < 64 {
                    lanes[k % 3] |= 1 << k;
                    k += 1;
                }
                lanes
            };
            const IOTA: [u8; 64] = {
                let mut iota = [0u8; 64];
                let mut k = 0;
                while k < 64 {
                    iota[k] = k as u8;
                    k += 1;
                }
                iota
            };
            let n = out.len().min(288);
            if n == 0 {
                return;
            }
            // SAFETY: a Vbmi exists only where the CPU has the features. The loads are bytes
            // px..px + 64 of a 96-byte plane, or at 64 its last 32, and 64-byte tables. Each
            // store writes only bytes of out[..n]: a stream store a whole line inside it
            // (64-byte aligned, as it needs), a masked store the line's bytes inside it.
            unsafe {
                // bytes[j]: output bytes 64j..64j + 64 (those from n on are never stored);
                // pixels 0..64 make bytes 0..192, pixels 64..96 bytes 192..288.
                let mut bytes = [_mm512_setzero_si512(); 6];
                let blue_codes = self.codes(blue);
                for (half, (px, load)) in [(0, !0u64), (64, 0xFFFF_FFFF)].into_iter().enumerate() {
                    // Loads written out: `.map` with a closure is not reliably inlined
                    // here, and a call per candidate spilled the vectors (12% slower).
                    let r = _mm512_maskz_loadu_epi8(load, planes[0].as_ptr().add(px).cast());
                    let g = _mm512_maskz_loadu_epi8(load, planes[1].as_ptr().add(px).cast());
                    let b = blue_codes[half];
                    // One single-table permute per channel, each filling its lanes: on
                    // this Sapphire Rapids a two-table permute takes two cycles of port 5,
                    // a single one one, so three cost less than two (renders 1-2% faster).
                    for (j, idx) in PIXEL.iter().enumerate().take(3 - half) {
                        let idx = _mm512_loadu_si512(idx.as_ptr().cast());
                        let v = _mm512_maskz_permutexvar_epi8(LANES[(3 - j) % 3], idx, r);
                        let v = _mm512_mask_permutexvar_epi8(v, LANES[(4 - j) % 3], idx, g);
                        bytes[3 * half + j] =
                            _mm512_mask_permutexvar_epi8(v, LANES[(5 - j) % 3], idx, b);
                    }
                }
                // Line l holds output bytes 64l - off.. : byte k is byte 64 - off + k of
                // the pair (bytes[l - 1], bytes[l]).
                let off = out.as_ptr() as usize % 64;
                let realign = _mm512_add_epi8(
                    _mm512_loadu_si512(IOTA.as_ptr().cast()),
                    _mm512_set1_epi8((64 - off) as i8),
                );
                let mut prev = _mm512_setzero_si512();
                for (l, &next) in bytes.iter().enumerate().take((off + n).div_ceil(64)) {
                    let line = _mm512_permutex2var_epi8(prev, realign, next);
                    prev = next;
                    let (lo, hi) = ((64 * l).max(off), (64 * l + 64).min(off + n));
                    let at = out.as_mut_ptr().add(lo - off);
                    if hi - lo == 64 {
                        _mm512_stream_si512(at.cast(), line);
                    } else {
                        let start = lo - 64 * l;
                        let mask = (!0u64 >> (64 - (hi - lo))) << start;
                        _mm512_mask_storeu_epi8(at.wrapping_sub(start).cast(), mask, line);
                    }
                }
            }
        }
    }

    /// With VBMI: 32 pixels at a time in 16-bit lanes, two byte permutes per 64 bytes out.
    #[target_feature(enable = "avx512f,avx512bw,avx512vbmi,avx512vbmi2")]
    fn encode_avx512_vbmi(vbmi: &Vbmi, rgb: [&[f32]; 3], out: &mut [u8]) -> usize {
        let vbmi = *vbmi;
        const INDEX: [[[u8; 64]; 2]; 2] = [
            [interleave_index(0, false), interleave_index(0, true)],
            [interleave_index(1, false), interleave_index(1, true)],
        ];
        let n = rgb.iter().fold(out.len() / 3, |n, p| n.min(p.len())) / 32 * 32;
        // SAFETY: each index is 64 bytes.
        let [[rg_lo, b_lo], [rg_hi, b_hi]] =
            INDEX.map(|h| h.map(|i| unsafe { _mm512_loadu_si512(i.as_ptr().cast()) }));
        for i in (0..n).step_by(32) {
            // SAFETY: i + 32 <= n <= every plane's length; the features are this function's.
            let [r, g, b] = unsafe {
                [
                    vbmi.load_words(rgb[0], i),
                    vbmi.load_words(rgb[1], i),
                    vbmi.load_words(rgb[2], i),
                ]
            };
            let lo = _mm512_permutex2var_epi8(_mm512_permutex2var_epi8(r, rg_lo, g), b_lo, b);
            let hi = _mm512_permutex2var_epi8(_mm512_permutex2var_epi8(r, rg_hi, g), b_hi, b);
            // SAFETY: the 96 bytes stored are out[3i..3i + 96], inside out.
            unsafe {
                _mm512_storeu_si512(out.as_mut_ptr().add(3 * i).cast(), lo);
                _mm512_mask_storeu_epi8(
                    out.as_mut_ptr().add(3 * i + 64).cast(),
                    u32::MAX.into(),
                    hi,
                );
            }
        }
        n
    }

    /// The 16-bit arithmetic in 32-bit lanes (16 of them), the table read with two-table
    /// permutes; codes land in the low byte of each lane.
    #[target_feature(enable = "avx512f")]
    fn codes_avx512(table: &[[__m512i; 2]; 3], plane: &[f32], i: usize) -> __m512i {
        assert!(i + 16 <= plane.len());
        // SAFETY: lanes i..i + 16 of `plane` are inside (asserted).
        let bits = unsafe { _mm512_loadu_si512(plane.as_ptr().add(i).cast()) };
        let key = _mm512_sub_epi32(
            _mm512_srai_epi32::<11>(bits),
            _mm512_set1_epi32((KEY_BASE >> 11) as i32),
        );
        let key = _mm512_min_epi32(
            _mm512_max_epi32(key, _mm512_setzero_si512()),
            _mm512_set1_epi32(0xFFFF),
        );
        let s = _mm512_srli_epi32::<11>(key);
        // (key << 5 & 0xFFFF) | s, in one ternary-logic instruction (A & B | C is 0xEA).
        let t = _mm512_ternarylogic_epi32::<0xEA>(
            _mm512_slli_epi32::<5>(key),
            _mm512_set1_epi32(0xFFFF),
            s,
        );
        let [c0, c1, n2] = table.map(|[lo, hi]| _mm512_permutex2var_epi32(lo, s, hi));
        let high = |a, b| _mm512_srli_epi32::<16>(_mm512_mullo_epi32(a, b));
        let y1 = _mm512_sub_epi32(c1, high(t, n2));
        _mm512_srli_epi32::<8>(_mm512_add_epi32(c0, high(t, y1)))
    }

    /// Without VBMI a pixel's codes are first one word [R, G, B, 0]; the 3 out words of each
    /// group of 4 pixels p are then p[m] >> 8m | p[m + 1] << (24 - 8m) for m = 0, 1, 2: two
    /// permutes and two variable shifts for a whole vector, and a masked store of 3/4 of it.
    #[target_feature(enable = "avx512f")]
    fn encode_avx512(_: Avx512F, rgb: [&[f32]; 3], out: &mut [u8]) -> usize {
        let n = rgb.iter().fold(out.len() / 3, |n, p| n.min(p.len())) / 16 * 16;
        // SAFETY: each table row holds 32 dwords: lanes 0..16 and 16..32 are inside.
        let table = encode_table()
            .dwords
            .map(|row| unsafe { [0, 16].map(|o| _mm512_loadu_si512(row.as_ptr().add(o).cast())) });
        let lo = _mm512_setr_epi32(0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, 0, 0, 0, 0);
        let hi = _mm512_add_epi32(lo, _mm512_set1_epi32(1));
        let right = _mm512_setr_epi32(0, 8, 16, 0, 8, 16, 0, 8, 16, 0, 8, 16, 0, 0, 0, 0);
        let left = _mm512_sub_epi32(_mm512_set1_epi32(24), right);
        for i in (0..n).step_by(16) {
            let [r, g, b] = rgb.map(|plane| codes_avx512(&table, plane, i));
            let px = _mm512_or_si512(
                r,
                _mm512_or_si512(_mm512_slli_epi32::<8>(g), _mm512_slli_epi32::<16>(b)),
            );
            let words = _mm512_or_si512(
                _mm512_srlv_epi32(_mm512_permutexvar_epi32(lo, px), right),
                _mm512_sllv_epi32(_mm512_permutexvar_epi32(hi, px), left),
            );
            // SAFETY: the 12 words stored are out[3i..3i + 48], inside out.
            unsafe { _mm512_mask_storeu_epi32(out.as_mut_ptr().add(3 * i).cast(), 0xFFF, words) };
        }
        n
    }

    /// 8 lanes of the 32-bit arithmetic; AVX2 has no two-table permute, so the table is
    /// gathered (it is in cache).
    #[target_feature(enable = "avx2")]
    fn encode_avx2(_: Avx2Fma, rgb: [&[f32]; 3], out: &mut [u8]) -> usize {
        let n = rgb.iter().fold(out.len() / 3, |n, p| n.min(p.len())) / 8 * 8;
        let table = &encode_table().dwords;
        let code = |plane: &[f32], i: usize| {
            assert!(i + 8 <= plane.len());
            // SAFETY: lanes i..i + 8 of `plane` are inside (asserted).
            let bits = unsafe { _mm256_loadu_si256(plane.as_ptr().add(i).cast()) };
            let key = _mm256_sub_epi32(
                _mm256_srai_epi32::<11>(bits),
                _mm256_set1_epi32((KEY_BASE >> 11) as i32),
            );
            let key = _mm256_min_epi32(
                _mm256_max_epi32(key, _mm256_setzero_si256()),
                _mm256_set1_epi32(0xFFFF),
            );
            let s = _mm256_srli_epi32::<11>(key);
            let t = _mm256_or_si256(
                _mm256_and_si256(_mm256_slli_epi32::<5>(key), _mm256_set1_epi32(0xFFFF)),
                s,
            );
            // SAFETY: s is in 0..32, and each table row holds 32 dwords.
            let [c0, c1, n2] =
                table.map(|row| unsafe { _mm256_i32gather_epi32::<4>(row.as_ptr().cast(), s) });
            let high = |a, b| _mm256_srli_epi32::<16>(_mm256_mullo_epi32(a, b));
            let y1 = _mm256_sub_epi32(c1, high(t, n2));
            _mm256_srli_epi32::<8>(_mm256_add_epi32(c0, high(t, y1)))
        };
        let lo = _mm256_setr_epi32(0, 1, 2, 4, 5, 6, 0, 0);
        let hi = _mm256_add_epi32(lo, _mm256_set1_epi32(1));
        let right = _mm256_setr_epi32(0, 8, 16, 0, 8, 16, 0, 0);
        let left = _mm256_sub_epi32(_mm256_set1_epi32(24), right);
        let six = _mm256_setr_epi32(-1, -1, -1, -1, -1, -1, 0, 0);
        for i in (0..n).step_by(8) {
            let gb = _mm256_or_si256(
                _mm256_slli_epi32::<8>(code(rgb[1], i)),
                _mm256_slli_epi32::<16>(code(rgb[2], i)),
            );
            let px = _mm256_or_si256(code(rgb[0], i), gb);
            let words = _mm256_or_si256(
                _mm256_srlv_epi32(_mm256_permutevar8x32_epi32(px, lo), right),
                _mm256_sllv_epi32(_mm256_permutevar8x32_epi32(px, hi), left),
            );
            // SAFETY: the 6 words stored are out[3i..3i + 24], inside out.
            unsafe { _mm256_maskstore_epi32(out.as_mut_ptr().add(3 * i).cast(), six, words) };
        }
        n
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

    /// The shared matrix and white in `f32` are bit for bit the published decimals (what
    /// this module used before they were shared), so no Lab value moved.
    #[test]
    fn shared_constants_are_the_published_f32_values() {
        let published: [[f32; 3]; 3] = [
            [0.412_456_4, 0.357_576_1, 0.180_437_5],
            [0.212_672_9, 0.715_152_2, 0.072_175],
            [0.019_333_9, 0.119_192, 0.950_304_1],
        ];
        assert_eq!([X, Y, Z], published);
        assert_eq!((XN, ZN), (0.950_47, 1.088_83));
    }

    #[test]
    fn srgb8_round_trips() {
        for i in 0..=255 {
            assert_eq!(encode_srgb8(srgb8_to_linear_table()[i]), i as u8);
        }
    }

    #[test]
    fn fast_lab_is_within_a_thousandth_of_delta_e() {
        // Checks one path; those with FMA must also give the portable FMA path's bits.
        type Path<'a> = &'a dyn Fn([&[f32]; 3], &mut [f32]);
        let check = |name: &str, fused: bool, path: Path| {
            let mut worst = 0.0f32;
            let steps = 40;
            for ri in 0..=steps {
                for gi in 0..=steps {
                    let n = steps + 1;
                    let r = vec![ri as f32 / steps as f32; n];
                    let g = vec![(gi as f32 / steps as f32).powi(3); n];
                    let b: Vec<f32> = (0..n).map(|k| (k as f32 / steps as f32).powi(2)).collect();
                    let mut lab = vec![0.0; 3 * n];
                    path([&r, &g, &b], &mut lab);
                    for k in 0..n {
                        let want = linear_to_lab([r[k], g[k], b[k]]);
                        let got = [lab[k], lab[n + k], lab[2 * n + k]];
                        worst = worst.max(delta_e(got, want));
                    }
                    if fused {
                        let mut want = vec![0.0; 3 * n];
                        lab_planar::<true>([&r, &g, &b], &mut want);
                        assert_eq!(lab, want, "{name}");
                    }
                }
            }
            assert!(worst < 1e-3, "{name}: worst Delta-E {worst}");
        };
        check("dispatched", false, &linear_to_lab_planar);
        check("portable", false, &lab_planar::<false>);
        #[cfg(target_arch = "x86_64")]
        {
            match Avx512F::detect() {
                // SAFETY: the token exists, so the CPU has AVX-512F and FMA.
                Some(t) => check("avx512", true, &|rgb, lab| unsafe {
                    lab_planar_avx512(t, rgb, lab)
                }),
                None => eprintln!("note: this CPU lacks AVX-512F; its path is not checked"),
            }
            match Avx2Fma::detect() {
                // SAFETY: the token exists, so the CPU has AVX2 and FMA.
                Some(t) => check("avx2", true, &|rgb, lab| unsafe {
                    lab_planar_avx2(t, rgb, lab)
                }),
                None => eprintln!("note: this CPU lacks AVX2 or FMA; its path is not checked"),
            }
        }
        for x in [1e-6f32, 0.008, 0.3, 1.0, 1.2] {
            assert!((fast_cbrt(x) - x.cbrt()).abs() <= 1e-6 * x.cbrt(), "{x}");
        }
        assert_eq!(fast_cbrt(0.0), 0.0);
        assert_eq!(fast_cbrt(-0.0), 0.0);
        // Every exponent residue and mantissa region, fused or not.
        for i in 0..100_000 {
            let x = 2f32.powf(-14.0 + 16.0 * i as f32 / 100_000.0);
            let want = (x as f64).cbrt();
            for got in [cbrt_approx::<false>(x), cbrt_approx::<true>(x)] {
                assert!((got as f64 / want - 1.0).abs() < 2.5e-7, "{x}: {got}");
            }
        }
    }

    /// How far the encoder may stray from 255 x sRGB(v), in codes, beyond rounding.
    const ENCODE_TOLERANCE: f64 = 0.04;

    /// Every key, at both ends of its range of values (sRGB is monotonic, so the ends bound
    /// it): the code is exact sRGB rounding unless the exact value is within the tolerance
    /// of a tie, and then one of the two codes beside it. Out-of-range values clamp.
    #[test]
    fn encoding_rounds_exact_srgb() {
        let table = encode_table();
        let bits = |key: u32| (key + (KEY_BASE >> 11)) << 11;
        let mut near_ties = 0;
        for key in 0..=65535u32 {
            let got = f64::from(code_of_key(key, table));
            let first = f32::from_bits(bits(key));
            let last = f32::from_bits(bits(key) + 2047).min(1.0);
            for v in [first, last] {
                assert_eq!(encode_key(v), key, "{v}");
                let exact = 255.0 * linear_to_srgb_f64(f64::from(v));
                if (exact.fract() - 0.5).abs() < ENCODE_TOLERANCE {
                    near_ties += 1;
                    assert!(
                        (got - exact).abs() < 0.5 + ENCODE_TOLERANCE,
                        "key {key} ({v}): {got} for {exact}"
                    );
                } else {
                    assert_eq!(got, exact.round(), "key {key} ({v}): exact {exact}");
                }
            }
        }
        // The keys' ranges are fine enough for ties to fall in them (the test can fail).
        assert!(near_ties > 100, "{near_ties}");
        // The SIMD paths compute in 16-bit lanes: no intermediate may leave 0..65536.
        for key in 0..=65535u32 {
            let [y1, y] = fixed_point(key, table);
            assert!(y1 < 65536 && y < 65536, "key {key}: {y1} {y}");
        }
        let below = [
            0.0,
            -0.0,
            -1.0,
            1e-6,
            -f32::NAN,
            f32::NEG_INFINITY,
            f32::MIN_POSITIVE,
        ];
        for v in below {
            assert_eq!(encode_srgb8(v), 0, "{v}");
        }
        for v in [1.0, 1.000_001, 7.0, f32::INFINITY, f32::MAX, f32::NAN] {
            assert_eq!(encode_srgb8(v), 255, "{v}");
        }
    }

    #[test]
    fn planar_encoding_matches_per_sample_encoding() {
        let special = [
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -0.0,
            -1e-6,
            1.0,
            1.000_001,
            7.0,
            f32::MIN_POSITIVE,
        ];
        let sample = |i: usize| match i % 5 {
            3 => special[i / 5 % special.len()],
            _ => i as f32 / 250.0 - 0.1,
        };
        // Both ends of every half octave and a few floats either side, as one long strip.
        let first = KEY_BASE >> 22;
        let sweep: Vec<f32> = (first..=first + 32)
            .flat_map(|h| (0..8).map(move |d| f32::from_bits((h << 22) + d - 4)))
            .collect();
        let lengths = (0..=70).chain([95, 96, 97, 300, 1000, sweep.len()]);
        for n in lengths {
            let r: Vec<f32> = if n == sweep.len() {
                sweep.clone()
            } else {
                (0..n).map(sample).collect()
            };
            let g: Vec<f32> = r.iter().map(|v| v * v).collect();
            let b: Vec<f32> = r.iter().rev().copied().collect();
            let want: Vec<u8> = (0..n)
                .flat_map(|i| [r[i], g[i], b[i]].map(encode_srgb8))
                .collect();
            let mut out = vec![0u8; 3 * n];
            encode_srgb8_planar([&r, &g, &b], &mut out);
            assert_eq!(out, want, "{n} pixels");
            // Each SIMD path on its own: its whole vectors, and not a byte past them.
            #[cfg(target_arch = "x86_64")]
            for encoder in x86::encoders() {
                let lanes = encoder.lanes();
                let mut out = vec![0xA5u8; 3 * n];
                let done = encoder.encode([&r, &g, &b], &mut out);
                assert_eq!(done, n / lanes * lanes);
                assert_eq!(
                    out[..3 * done],
                    want[..3 * done],
                    "{n} pixels, {lanes} lanes"
                );
                assert!(out[3 * done..].iter().all(|&o| o == 0xA5));
            }
        }
    }

    /// The streamed interleave at every offset of `out` within a cache line and lengths
    /// around every vector and line boundary: exactly `out`'s bytes, in order, and not a
    /// byte either side (the compositor's outputs sit at whatever alignment they were
    /// allocated at).
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn streamed_interleave_writes_its_bytes_and_no_others_at_any_alignment() {
        #[target_feature(enable = "avx512f,avx512bw,avx512vbmi,avx512vbmi2")]
        fn stream(vbmi: Vbmi, planes: [&[u8; 96]; 2], blue: &[f32; 96], out: &mut [u8]) {
            let blue = std::array::from_fn(|j| {
                // SAFETY: lanes 16j..16j + 16 of 96 are inside; the features are enabled.
                unsafe { std::arch::x86_64::_mm512_loadu_ps(blue.as_ptr().add(16 * j)) }
            });
            // The scope fences before the test reads `out`.
            crate::cpu::non_temporal(|nt| vbmi.stream_interleaved(nt, planes, &blue, out));
        }
        #[repr(align(64))]
        struct Lines([u8; 512]);
        let Some(vbmi) = Vbmi::new() else {
            eprintln!("skipped: this CPU lacks AVX-512 VBMI");
            return;
        };
        let planes: [[u8; 96]; 2] =
            std::array::from_fn(|c| std::array::from_fn(|p| (7 * p + 100 * c) as u8));
        // Blue as values whose codes differ from pixel to pixel and span 0..255.
        let blue: [f32; 96] = std::array::from_fn(|p| ((p * 37) % 96) as f32 / 95.0);
        let codes = [planes[0], planes[1], blue.map(encode_srgb8)];
        let lengths = [
            1, 2, 3, 31, 32, 63, 64, 65, 127, 128, 191, 192, 193, 255, 256, 287, 288,
        ];
        for off in 0..64 {
            for n in lengths {
                let mut buf = Lines([0xEE; 512]);
                let start = 64 + off;
                // SAFETY: the Vbmi exists, so the CPU has the features.
                unsafe {
                    stream(
                        vbmi,
                        [&planes[0], &planes[1]],
                        &blue,
                        &mut buf.0[start..start + n],
                    )
                };
                for (i, &got) in buf.0.iter().enumerate() {
                    let want = match i.checked_sub(start) {
                        Some(k) if k < n => codes[k % 3][k / 3],
                        _ => 0xEE,
                    };
                    assert_eq!(got, want, "offset {off}, {n} bytes: byte {i}");
                }
            }
        }
    }
}

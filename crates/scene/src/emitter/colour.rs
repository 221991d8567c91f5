//! The colour science the emitter solve and its users share, in `f64`: linear sRGB (D65)
//! and CIE XYZ, xyY, CIE 1976 u'v', CIELAB (D65) and the CIEDE2000 difference.
//!
//! XYZ is relative: Y = 1 is the white of linear sRGB (1, 1, 1). The compositor's fast
//! `f32` CIELAB uses the same matrix ([`SRGB_TO_XYZ`]) and white ([`D65`]).

/// Linear sRGB to CIE XYZ (rows X, Y, Z), IEC 61966-2-1 primaries and D65 white, as Bruce
/// Lindbloom tabulates it; its rows sum to [`D65`].
pub const SRGB_TO_XYZ: [[f64; 3]; 3] = [
    [0.412_456_4, 0.357_576_1, 0.180_437_5],
    [0.212_672_9, 0.715_152_2, 0.072_175],
    [0.019_333_9, 0.119_192, 0.950_304_1],
];

/// CIE XYZ to linear sRGB: the exact inverse of [`SRGB_TO_XYZ`] (computed, not rounded
/// separately, so a round trip returns the colour to within rounding).
pub const XYZ_TO_SRGB: [[f64; 3]; 3] = invert(SRGB_TO_XYZ);

/// The D65 white point's XYZ with Y = 1 (the sum of [`SRGB_TO_XYZ`]'s rows).
pub const D65: [f64; 3] = [0.950_47, 1.0, 1.088_83];

/// The 2x2 minor of `m` on rows `r0`, `r1` and columns `c0`, `c1`.
const fn minor(m: &[[f64; 3]; 3], r0: usize, c0: usize, r1: usize, c1: usize) -> f64 {
    m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
}

/// The inverse of a non-singular 3x3 matrix, by its adjugate.
const fn invert(m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let cof = [
        [
            minor(&m, 1, 1, 2, 2),
            minor(&m, 1, 2, 2, 0),
            minor(&m, 1, 0, 2, 1),
        ],
        [
            minor(&m, 2, 1, 0, 2),
            minor(&m, 2, 2, 0, 0),
            minor(&m, 2, 0, 0, 1),
        ],
        [
            minor(&m, 0, 1, 1, 2),
            minor(&m, 0, 2, 1, 0),
            minor(&m, 0, 0, 1, 1),
        ],
    ];
    let det = m[0][0] * cof[0][0] + m[0][1] * cof[0][1] + m[0][2] * cof[0][2];
    // The inverse is the transposed cofactor matrix over the determinant.
    [
        [cof[0][0] / det, cof[1][0] / det, cof[2][0] / det],
        [cof[0][1] / det, cof[1][1] / det, cof[2][1] / det],
        [cof[0][2] / det, cof[1][2] / det, cof[2][2] / det],
    ]
}

/// `m` times the column vector `v`.
pub fn mul(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    m.map(|row| row[0] * v[0] + row[1] * v[1] + row[2] * v[2])
}

/// CIE XYZ of a linear sRGB colour.
pub fn linear_srgb_to_xyz(rgb: [f64; 3]) -> [f64; 3] {
    mul(&SRGB_TO_XYZ, rgb)
}

/// Linear sRGB of a CIE XYZ colour; components fall outside 0..1 (even below 0) for
/// colours outside sRGB's gamut: not clamped, so the caller decides.
pub fn xyz_to_linear_srgb(xyz: [f64; 3]) -> [f64; 3] {
    mul(&XYZ_TO_SRGB, xyz)
}

/// CIE XYZ of chromaticity `x`, `y` at luminance `big_y` (how GDTF gives an emitter's
/// colour); a `y` that is not positive gives black, since no such light exists.
pub fn xyy_to_xyz(x: f64, y: f64, big_y: f64) -> [f64; 3] {
    if y > 0.0 && y.is_finite() {
        [x * big_y / y, big_y, (1.0 - x - y) * big_y / y]
    } else {
        [0.0; 3]
    }
}

/// CIE 1976 UCS chromaticity (u', v') of an XYZ colour, or `None` when it has none (black,
/// or a denominator X + 15Y + 3Z that is not positive and finite).
pub fn xyz_to_uv(xyz: [f64; 3]) -> Option<[f64; 2]> {
    let d = xyz[0] + 15.0 * xyz[1] + 3.0 * xyz[2];
    (d > 0.0 && d.is_finite()).then(|| [4.0 * xyz[0] / d, 9.0 * xyz[1] / d])
}

/// CIELAB (D65 white at Y = 1) of an XYZ colour: L* 0..100 for Y 0..1.
pub fn xyz_to_lab(xyz: [f64; 3]) -> [f64; 3] {
    let [fx, fy, fz] = [0, 1, 2].map(|k| lab_f(xyz[k] / D65[k]));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// The CIELAB companding function (CIE 15), with its linear segment near black.
pub fn lab_f(t: f64) -> f64 {
    const DELTA: f64 = 6.0 / 29.0;
    if t > DELTA * DELTA * DELTA {
        t.cbrt()
    } else {
        t / (3.0 * DELTA * DELTA) + 4.0 / 29.0
    }
}

/// The CIEDE2000 colour difference of two CIELAB colours (kL = kC = kH = 1), as CIE
/// 142-2001 defines it and Sharma, Wu and Dalal (Color Res. Appl. 30(1), 2005) spell out:
/// their equations are numbered in the comments. About 1 is a just-noticeable difference.
pub fn ciede2000(lab1: [f64; 3], lab2: [f64; 3]) -> f64 {
    let [l1, a1, b1] = lab1;
    let [l2, a2, b2] = lab2;
    const P25_7: f64 = 6_103_515_625.0; // 25^7
    // (2)-(6): a' stretched by G for neutral colours, then C' and h' (degrees, 0..360).
    let c_mean = 0.5 * (a1.hypot(b1) + a2.hypot(b2));
    let g = 0.5 * (1.0 - (c_mean.powi(7) / (c_mean.powi(7) + P25_7)).sqrt());
    let (a1p, a2p) = ((1.0 + g) * a1, (1.0 + g) * a2);
    let (c1p, c2p) = (a1p.hypot(b1), a2p.hypot(b2));
    let hue = |b: f64, a: f64| {
        if a == 0.0 && b == 0.0 {
            0.0
        } else {
            b.atan2(a).to_degrees().rem_euclid(360.0)
        }
    };
    let (h1p, h2p) = (hue(b1, a1p), hue(b2, a2p));
    // (8)-(10): the differences; a neutral colour has no hue difference.
    let dl = l2 - l1;
    let dc = c2p - c1p;
    let chromatic = c1p * c2p != 0.0;
    let dh = if !chromatic {
        0.0
    } else if h2p - h1p > 180.0 {
        h2p - h1p - 360.0
    } else if h2p - h1p < -180.0 {
        h2p - h1p + 360.0
    } else {
        h2p - h1p
    };
    let dh_big = 2.0 * (c1p * c2p).sqrt() * (0.5 * dh).to_radians().sin();
    // (12)-(14): the means, the hue mean taken the short way round the circle.
    let l_mean = 0.5 * (l1 + l2);
    let cp_mean = 0.5 * (c1p + c2p);
    let h_mean = if !chromatic {
        h1p + h2p
    } else if (h1p - h2p).abs() <= 180.0 {
        0.5 * (h1p + h2p)
    } else if h1p + h2p < 360.0 {
        0.5 * (h1p + h2p + 360.0)
    } else {
        0.5 * (h1p + h2p - 360.0)
    };
    // (15)-(22): the weights and the rotation term for blues.
    let cos = |deg: f64| deg.to_radians().cos();
    let t =
        1.0 - 0.17 * cos(h_mean - 30.0) + 0.24 * cos(2.0 * h_mean) + 0.32 * cos(3.0 * h_mean + 6.0)
            - 0.20 * cos(4.0 * h_mean - 63.0);
    let d_theta = 30.0 * (-((h_mean - 275.0) / 25.0).powi(2)).exp();
    let r_c = 2.0 * (cp_mean.powi(7) / (cp_mean.powi(7) + P25_7)).sqrt();
    let l50 = (l_mean - 50.0).powi(2);
    let s_l = 1.0 + 0.015 * l50 / (20.0 + l50).sqrt();
    let s_c = 1.0 + 0.045 * cp_mean;
    let s_h = 1.0 + 0.015 * cp_mean * t;
    let r_t = -(2.0 * d_theta).to_radians().sin() * r_c;
    let (tl, tc, th) = (dl / s_l, dc / s_c, dh_big / s_h);
    (tl * tl + tc * tc + th * th + r_t * tc * th)
        .max(0.0)
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 34 pairs of Sharma, Wu and Dalal (2005), Table 1: L1 a1 b1, L2 a2 b2, ΔE00 to
    /// four decimals. They cover the hue-mean and hue-difference wrap-arounds, neutral
    /// colours and the blue rotation term.
    const SHARMA: [[f64; 7]; 34] = [
        [50.0, 2.6772, -79.7751, 50.0, 0.0, -82.7485, 2.0425],
        [50.0, 3.1571, -77.2803, 50.0, 0.0, -82.7485, 2.8615],
        [50.0, 2.8361, -74.0200, 50.0, 0.0, -82.7485, 3.4412],
        [50.0, -1.3802, -84.2814, 50.0, 0.0, -82.7485, 1.0000],
        [50.0, -1.1848, -84.8006, 50.0, 0.0, -82.7485, 1.0000],
        [50.0, -0.9009, -85.5211, 50.0, 0.0, -82.7485, 1.0000],
        [50.0, 0.0, 0.0, 50.0, -1.0, 2.0, 2.3669],
        [50.0, -1.0, 2.0, 50.0, 0.0, 0.0, 2.3669],
        [50.0, 2.4900, -0.0010, 50.0, -2.4900, 0.0009, 7.1792],
        [50.0, 2.4900, -0.0010, 50.0, -2.4900, 0.0010, 7.1792],
        [50.0, 2.4900, -0.0010, 50.0, -2.4900, 0.0011, 7.2195],
        [50.0, 2.4900, -0.0010, 50.0, -2.4900, 0.0012, 7.2195],
        [50.0, -0.0010, 2.4900, 50.0, 0.0009, -2.4900, 4.8045],
        [50.0, -0.0010, 2.4900, 50.0, 0.0010, -2.4900, 4.8045],
        [50.0, -0.0010, 2.4900, 50.0, 0.0011, -2.4900, 4.7461],
        [50.0, 2.5, 0.0, 50.0, 0.0, -2.5, 4.3065],
        [50.0, 2.5, 0.0, 73.0, 25.0, -18.0, 27.1492],
        [50.0, 2.5, 0.0, 61.0, -5.0, 29.0, 22.8977],
        [50.0, 2.5, 0.0, 56.0, -27.0, -3.0, 31.9030],
        [50.0, 2.5, 0.0, 58.0, 24.0, 15.0, 19.4535],
        [50.0, 2.5, 0.0, 50.0, 3.1736, 0.5854, 1.0000],
        [50.0, 2.5, 0.0, 50.0, 3.2972, 0.0, 1.0000],
        [50.0, 2.5, 0.0, 50.0, 1.8634, 0.5757, 1.0000],
        [50.0, 2.5, 0.0, 50.0, 3.2592, 0.3350, 1.0000],
        [
            60.2574, -34.0099, 36.2677, 60.4626, -34.1751, 39.4387, 1.2644,
        ],
        [
            63.0109, -31.0961, -5.8663, 62.8187, -29.7946, -4.0864, 1.2630,
        ],
        [61.2901, 3.7196, -5.3901, 61.4292, 2.2480, -4.9620, 1.8731],
        [35.0831, -44.1164, 3.7933, 35.0232, -40.0716, 1.5901, 1.8645],
        [
            22.7233, 20.0904, -46.6940, 23.0331, 14.9730, -42.5619, 2.0373,
        ],
        [36.4612, 47.8580, 18.3852, 36.2715, 50.5065, 21.2231, 1.4146],
        [90.8027, -2.0831, 1.4410, 91.1528, -1.6435, 0.0447, 1.4441],
        [90.9257, -0.5406, -0.9208, 88.6381, -0.8985, -0.7239, 1.5381],
        [6.7747, -0.2908, -2.4247, 5.8714, -0.0985, -2.2286, 0.6377],
        [2.0776, 0.0795, -1.1350, 0.9033, -0.0636, -0.5514, 0.9082],
    ];

    #[test]
    fn ciede2000_matches_sharma_wu_dalal_both_ways_round() {
        for (i, p) in SHARMA.iter().enumerate() {
            let (a, b) = ([p[0], p[1], p[2]], [p[3], p[4], p[5]]);
            for (x, y) in [(a, b), (b, a)] {
                let got = ciede2000(x, y);
                assert!(
                    (got - p[6]).abs() < 5e-5,
                    "pair {}: {got}, want {}",
                    i + 1,
                    p[6]
                );
            }
        }
        assert_eq!(ciede2000([50.0, 10.0, -3.0], [50.0, 10.0, -3.0]), 0.0);
    }

    #[test]
    fn matrices_are_inverse_and_white_is_d65() {
        for c in 0..3 {
            let product = mul(&SRGB_TO_XYZ, XYZ_TO_SRGB.map(|row| row[c]));
            for (r, p) in product.iter().enumerate() {
                assert!(
                    (p - f64::from(u8::from(r == c))).abs() < 1e-12,
                    "{r} {c}: {p}"
                );
            }
        }
        // The published rows are rounded to 7 decimals: Y's sum to 1.0000001.
        let white = linear_srgb_to_xyz([1.0; 3]);
        for k in 0..3 {
            assert!((white[k] - D65[k]).abs() < 2e-7, "{white:?}");
        }
        // Lindbloom's published inverse, to its 7 decimals.
        assert!((XYZ_TO_SRGB[0][0] - 3.240_454_2).abs() < 1e-6);
        assert!((XYZ_TO_SRGB[1][1] - 1.876_010_8).abs() < 1e-6);
        assert!((XYZ_TO_SRGB[2][2] - 1.057_225_2).abs() < 1e-6);
    }

    #[test]
    fn chromaticities_of_known_colours() {
        // D65 is x 0.3127, y 0.3290 (CIE 15), u' 0.1978, v' 0.4683.
        let d65 = xyy_to_xyz(0.3127, 0.3290, 1.0);
        assert!((d65[0] - D65[0]).abs() < 5e-4 && (d65[2] - D65[2]).abs() < 5e-4);
        let [u, v] = xyz_to_uv(D65).unwrap_or_default();
        assert!(
            (u - 0.1978).abs() < 1e-4 && (v - 0.4683).abs() < 1e-4,
            "{u} {v}"
        );
        assert_eq!(xyz_to_uv([0.0; 3]), None);
        assert_eq!(xyy_to_xyz(0.3, 0.0, 1.0), [0.0; 3]);
        // sRGB red is x 0.64, y 0.33.
        let red = linear_srgb_to_xyz([1.0, 0.0, 0.0]);
        let s: f64 = red.iter().sum();
        assert!((red[0] / s - 0.64).abs() < 1e-4 && (red[1] / s - 0.33).abs() < 1e-4);
        // Lab: white is (100, 0, 0); sRGB red is (53.2408, 80.0925, 67.2032) (Lindbloom).
        let w = xyz_to_lab(D65);
        assert!((w[0] - 100.0).abs() < 1e-9 && w[1].abs() < 1e-9 && w[2].abs() < 1e-9);
        let r = xyz_to_lab(red);
        for (g, want) in r.iter().zip([53.2408, 80.0925, 67.2032]) {
            assert!((g - want).abs() < 2e-3, "{r:?}");
        }
    }
}

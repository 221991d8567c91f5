//! Area (box) downsampling: every source pixel contributes by the fraction of it that lies
//! inside each destination pixel, so the mean is preserved and a non-integer factor is
//! handled without aliasing or bias.

use rayon::prelude::*;

use crate::Radiance;

/// Size of a `width`-wide version of a `w x h` image: height from the aspect, rounded;
/// never upscaled; at least 1x1. The same rule as the compositor's, so a merge at the
/// scene's working width has the size the compositor expects.
pub fn scaled_size(w: usize, h: usize, width: usize) -> (usize, usize) {
    if width >= w || width == 0 {
        return (w, h);
    }
    let height = ((h as f64 * width as f64 / w as f64).round() as usize).max(1);
    (width, height)
}

/// Taps of an `n -> m` area resample: for each destination index, `(source, weight)` pairs
/// whose weights sum to 1. Overlaps are computed in integer units of `1/(n*m)`, so integer
/// factors give exact box averages.
pub(crate) fn taps(n: usize, m: usize) -> Vec<Vec<(usize, f32)>> {
    (0..m)
        .map(|i| {
            // Destination i spans [i*n, (i+1)*n) and source j spans [j*m, (j+1)*m).
            let (a, b) = (i * n, (i + 1) * n);
            (a / m..b.div_ceil(m))
                .filter_map(|j| {
                    let overlap = b.min((j + 1) * m).saturating_sub(a.max(j * m));
                    (overlap > 0).then(|| (j, (overlap as f64 / n as f64) as f32))
                })
                .collect()
        })
        .collect()
}

/// The destination index whose area holds the start of source index `j` (each source row
/// is "owned" by exactly one destination row, for counting).
pub(crate) fn owner(j: usize, n: usize, m: usize) -> usize {
    j * m / n
}

/// Adds `weight x` the horizontal resample of `row` into `acc`.
pub(crate) fn add_row(
    row: &[[f32; 3]],
    xs: &[Vec<(usize, f32)>],
    weight: f32,
    acc: &mut [[f32; 3]],
) {
    for (out, taps) in acc.iter_mut().zip(xs) {
        let mut s = [0.0f32; 3];
        for &(j, wx) in taps {
            let p = row[j];
            s[0] += p[0] * wx;
            s[1] += p[1] * wx;
            s[2] += p[2] * wx;
        }
        out[0] += s[0] * weight;
        out[1] += s[1] * weight;
        out[2] += s[2] * weight;
    }
}

/// Area-downsamples `img` to `width` pixels wide (height from the aspect, see
/// [`scaled_size`]). [`crate::merge`] does this on the fly; this is for images merged at
/// full resolution.
pub fn downsample(img: &Radiance, width: usize) -> Radiance {
    let (w, h) = (img.width, img.height);
    let (nw, nh) = scaled_size(w, h, width);
    if (nw, nh) == (w, h) {
        return img.clone();
    }
    let xs = taps(w, nw);
    let ys = taps(h, nh);
    let mut pixels = vec![[0.0f32; 3]; nw * nh];
    pixels
        .par_chunks_mut(nw)
        .zip(ys.par_iter())
        .for_each(|(out, rows)| {
            for &(y, wy) in rows {
                add_row(&img.pixels[y * w..(y + 1) * w], &xs, wy, out);
            }
        });
    Radiance {
        width: nw,
        height: nh,
        pixels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn taps_sum_to_one_and_cover_every_source_equally() {
        for (n, m) in [(12, 4), (6000, 480), (4000, 320), (7, 3), (5, 5)] {
            let t = taps(n, m);
            let mut per_src = vec![0.0f64; n];
            for row in &t {
                let s: f64 = row.iter().map(|&(_, w)| f64::from(w)).sum();
                assert!((s - 1.0).abs() < 1e-6, "{n}->{m}: {s}");
                for &(j, w) in row {
                    per_src[j] += f64::from(w);
                }
            }
            for v in per_src {
                assert!((v - m as f64 / n as f64).abs() < 1e-6);
            }
        }
    }
}

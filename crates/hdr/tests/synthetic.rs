//! The merge against synthetic ground truth: a known radiance map through a simulated
//! camera (raw: black level, shot and read noise, 14-bit clipping; JPEG: filmic tone curve,
//! 8-bit rounding), EXIF times off by 3%.

mod common;

use common::*;
use rand::SeedableRng;
use visobjd_hdr::*;

const W: usize = 600;
const H: usize = 400;
const FRAMES: usize = 7;
const BASE: f64 = 1e-3;

struct Shot<T> {
    truth: Vec<f64>,
    exif: Vec<f64>,
    data: Vec<Vec<T>>,
}

fn raw_shot(map: &[[f32; 3]], seed: u64) -> Shot<u16> {
    let (truth, exif) = bracket_times(FRAMES, BASE);
    let data = truth
        .iter()
        .enumerate()
        .map(|(k, &t)| raw_frame(map, W, t, seed * 100 + k as u64))
        .collect();
    Shot { truth, exif, data }
}

fn jpeg_shot(map: &[[f32; 3]], seed: u64) -> Shot<u8> {
    let (truth, exif) = bracket_times(FRAMES, BASE);
    let data = truth
        .iter()
        .enumerate()
        .map(|(k, &t)| jpeg_frame(map, W, t, seed * 100 + k as u64))
        .collect();
    Shot { truth, exif, data }
}

fn raw_frames(s: &Shot<u16>) -> Vec<BracketFrame<'_>> {
    raw_frames_of(&s.data, &s.exif, W, H)
}

fn jpeg_frames(s: &Shot<u8>) -> Vec<BracketFrame<'_>> {
    jpeg_frames_of(&s.data, &s.exif, W, H)
}

fn full_res() -> MergeSettings {
    MergeSettings {
        width: None,
        ..MergeSettings::default()
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Relative errors of `got` against `truth` over samples above the noise floor (at least
/// 1% of full scale in the longest frame) and unclipped in the shortest.
fn rel_errors(got: &Radiance, truth: &[[f32; 3]], t_max: f64, t_min: f64, scale: f64) -> Vec<f64> {
    got.pixels
        .iter()
        .zip(truth)
        .flat_map(|(g, t)| (0..3).map(move |c| (f64::from(g[c]) * scale, f64::from(t[c]))))
        .filter(|&(_, t)| t * t_max >= 0.01 && t * t_min < 0.8)
        .map(|(g, t)| (g - t).abs() / t)
        .collect()
}

fn recovered_response(s: &Shot<u8>) -> Response {
    let mut rng = Rng::seed_from_u64(7);
    Response::recover(&jpeg_frames(s), &mut rng).expect("response")
}

#[test]
fn recovered_response_has_the_true_shape() {
    let map = radiance_map(W, H, false);
    let shot = jpeg_shot(&map, 1);
    let r = recovered_response(&shot);
    for c in 0..3 {
        let norm_r = f64::from(r.curves[c][200]);
        let norm_t = true_g(200);
        let mut worst = 0.0f64;
        for z in 16..=240u8 {
            let got = f64::from(r.curves[c][usize::from(z)]) / norm_r;
            let want = true_g(z) / norm_t;
            worst = worst.max((got - want).abs() / want);
        }
        assert!(worst < 0.03, "channel {c}: worst relative error {worst}");
        // Against a plain gamma 2.2 with no shoulder, the shape must be distinguishable.
        let gamma_only = (0.5f64).powf(2.2) / (200.0f64 / 255.0).powf(2.2);
        let got = f64::from(r.curves[c][128]) / norm_r;
        assert!((got - true_g(128) / norm_t).abs() < (gamma_only - true_g(128) / norm_t).abs());
    }
}

#[test]
fn response_round_trips_through_json_and_rejects_damage() {
    let r = Response::linear();
    let json = serde_json::to_string(&r).unwrap();
    let back: Response = serde_json::from_str(&json).unwrap();
    assert_eq!(back, r);
    back.validate().unwrap();
    let mut bad = r.clone();
    bad.curves[1].truncate(200);
    assert!(matches!(bad.validate(), Err(HdrError::BadResponse)));
    let mut bad = r;
    bad.curves[0][100] = 2.0;
    assert!(matches!(bad.validate(), Err(HdrError::BadResponse)));
}

#[test]
fn raw_merge_is_within_2_percent_and_fits_the_true_ratios() {
    let map = radiance_map(W, H, false);
    let shot = raw_shot(&map, 2);
    let m = merge(&raw_frames(&shot), None, &full_res()).unwrap();
    let errs = rel_errors(&m.radiance, &map, shot.truth[6], shot.truth[0], 1.0);
    let med = median(errs.clone());
    assert!(
        errs.len() > W * H,
        "too few samples above the floor: {}",
        errs.len()
    );
    assert!(med < 0.02, "median relative error {med}");
    check_ratios(&m, &shot.truth);
    assert_eq!(m.clipped_everywhere, 0);
}

#[test]
fn jpeg_merge_is_within_2_percent_and_fits_the_true_ratios() {
    let map = radiance_map(W, H, false);
    let cal = jpeg_shot(&map, 3);
    let r = recovered_response(&cal);
    let shot = jpeg_shot(&map, 4);
    let m = merge(&jpeg_frames(&shot), Some(&r), &full_res()).unwrap();
    // The response is known up to its full-scale value: compare after one global factor.
    let pairs: Vec<f64> = m
        .radiance
        .pixels
        .iter()
        .zip(&map)
        .filter(|(_, t)| f64::from(t[1]) * shot.truth[3] > 0.05)
        .map(|(g, t)| f64::from(t[1]) / f64::from(g[1]))
        .collect();
    let scale = median(pairs);
    let errs = rel_errors(&m.radiance, &map, shot.truth[6], shot.truth[0], scale);
    let med = median(errs);
    assert!(med < 0.02, "median relative error {med} (scale {scale})");
    check_ratios(&m, &shot.truth);
}

/// Fitted ratios within 0.5% of the truth while EXIF is off by 3%.
fn check_ratios(m: &Merged, truth: &[f64]) {
    assert_eq!(m.reference, 3);
    for (k, e) in m.exposures.iter().enumerate() {
        let want = truth[k] / truth[3];
        let fit_err = (e.fitted_ratio - want).abs() / want;
        let nominal_err = (e.nominal_ratio - want).abs() / want;
        assert!(
            fit_err < 0.005,
            "frame {k}: fitted {} true {want}",
            e.fitted_ratio
        );
        if k != 3 {
            assert!(
                nominal_err > 0.025,
                "frame {k}: the test needs EXIF to be off"
            );
            assert!(e.samples > 0, "frame {k} kept its EXIF ratio");
        }
    }
}

#[test]
fn pixels_clipped_in_every_frame_are_counted_and_are_a_lower_bound() {
    let map = radiance_map(W, H, true);
    let shot = raw_shot(&map, 5);
    let m = merge(&raw_frames(&shot), None, &full_res()).unwrap();
    let shortest = &shot.data[0];
    let expected = shortest
        .chunks_exact(3)
        .filter(|p| p.iter().any(|&v| v >= WHITE))
        .count();
    assert!(expected > 50, "the map must blow some pixels: {expected}");
    assert_eq!(m.clipped_everywhere, expected);
    for (g, t) in m.radiance.pixels.iter().zip(&map) {
        for c in 0..3 {
            if f64::from(t[c]) * shot.truth[0] >= 1.0 {
                assert!(g[c] <= t[c] && g[c] > 0.0);
            }
        }
    }
    // JPEG too.
    let jshot = jpeg_shot(&map, 6);
    let jm = merge(&jpeg_frames(&jshot), Some(&Response::linear()), &full_res()).unwrap();
    let jexpected = jshot.data[0]
        .chunks_exact(3)
        .filter(|p| p.iter().any(|&v| v >= 250))
        .count();
    assert_eq!(jm.clipped_everywhere, jexpected);
}

#[test]
fn merging_at_the_working_width_equals_merging_then_downsampling() {
    let map = radiance_map(W, H, true);
    let shot = raw_shot(&map, 8);
    let frames = raw_frames(&shot);
    let full = merge(&frames, None, &full_res()).unwrap();
    let small = merge(
        &frames,
        None,
        &MergeSettings {
            width: Some(240),
            ..MergeSettings::default()
        },
    )
    .unwrap();
    assert_eq!((small.radiance.width, small.radiance.height), (240, 160));
    assert_eq!(small.clipped_everywhere, full.clipped_everywhere);
    let after = downsample(&full.radiance, 240);
    for (a, b) in small.radiance.pixels.iter().zip(&after.pixels) {
        for c in 0..3 {
            assert!(
                (a[c] - b[c]).abs() <= 1e-4 * b[c].abs().max(1e-3),
                "{a:?} vs {b:?}"
            );
        }
    }
}

fn merged_raw(map: &[[f32; 3]], seed: u64) -> Radiance {
    let shot = raw_shot(map, seed);
    merge(
        &raw_frames(&shot),
        None,
        &MergeSettings {
            width: Some(300),
            ..MergeSettings::default()
        },
    )
    .unwrap()
    .radiance
}

/// Ambient: a dim wash; the light: a pool on top of it.
fn with_pool(ambient: &[[f32; 3]], strength: f32) -> Vec<[f32; 3]> {
    ambient
        .iter()
        .enumerate()
        .map(|(i, a)| {
            let (x, y) = ((i % W) as f32 / W as f32, (i / W) as f32 / H as f32);
            let d2 = ((x - 0.5).powi(2) + (y - 0.5).powi(2)) / 0.02;
            let k = strength * (-d2).exp();
            [a[0] + k, a[1] + k, a[2] + k * 0.8]
        })
        .collect()
}

#[test]
fn ambient_is_subtracted_and_drift_and_dead_lights_are_reported() {
    let ambient: Vec<[f32; 3]> = radiance_map(W, H, false)
        .iter()
        .map(|p| p.map(|v| v * 0.05))
        .collect();
    let amb1 = merged_raw(&ambient, 10);
    let amb2 = merged_raw(&ambient, 11);

    // Subtraction recovers the pool.
    let lit = with_pool(&ambient, 1.0);
    let light = merged_raw(&lit, 12);
    let pool = subtract_ambient(&light, &amb1).unwrap();
    let truth = downsample(
        &Radiance {
            width: W,
            height: H,
            pixels: with_pool(&vec![[0.0; 3]; W * H], 1.0),
        },
        300,
    );
    let errs: Vec<f64> = pool
        .pixels
        .iter()
        .zip(&truth.pixels)
        .filter(|(_, t)| t[1] > 0.1)
        .map(|(g, t)| f64::from((g[1] - t[1]).abs() / t[1]))
        .collect();
    assert!(errs.len() > 1000);
    assert!(median(errs) < 0.02);
    assert!(pool.pixels.iter().flatten().all(|&v| v >= 0.0));

    // Drift: a third merge of the same ambient agrees with the first beyond the noise two
    // merges of it show; a 10% brighter one does not.
    let amb3 = merged_raw(&ambient, 15);
    let same = ambient_drift(&amb1, &amb2, &amb3).unwrap();
    assert!(same.relative < 0.02, "{same:?}");
    assert!(same.mean_change.abs() < 0.005, "{same:?}");
    let brighter: Vec<[f32; 3]> = ambient.iter().map(|p| p.map(|v| v * 1.1)).collect();
    let drifted = ambient_drift(&amb1, &amb2, &merged_raw(&brighter, 13)).unwrap();
    assert!((drifted.mean_change - 0.1).abs() < 0.01, "{drifted:?}");
    assert!(drifted.relative > 0.05, "{drifted:?}");
    // A dark stage: an ambient of nothing but noise has not drifted.
    let dark = vec![[0.0f32; 3]; W * H];
    let (d1, d2, d3) = (
        merged_raw(&dark, 16),
        merged_raw(&dark, 17),
        merged_raw(&dark, 18),
    );
    let noise = ambient_drift(&d1, &d2, &d3).unwrap();
    assert!(noise.relative < 0.05, "{noise:?}");
    // ... and one where a work light came on before the end has.
    let lit = ambient_drift(&d1, &d2, &merged_raw(&with_pool(&dark, 0.01), 19)).unwrap();
    assert!(lit.relative > 0.05, "{lit:?}");

    // A light that adds nothing is flagged; a dim one (1% of the ambient's bright end,
    // in a pool) is not; the bright one neither.
    let dead = light_test(&amb2, &amb1).unwrap();
    assert!(!dead.shows_light, "{dead:?}");
    let dim = light_test(&merged_raw(&with_pool(&ambient, 0.002), 14), &amb1).unwrap();
    assert!(dim.shows_light, "{dim:?}");
    let bright = light_test(&light, &amb1).unwrap();
    assert!(
        bright.shows_light && bright.lit_pixels > dim.lit_pixels,
        "{bright:?}"
    );
}

#[test]
fn bracket_choice_covers_the_range() {
    let map = radiance_map(W, H, false);
    // Camera shutter speeds in third stops, 1/8000 s to 30 s.
    let choices: Vec<f64> = (0..=48).map(|k| 30.0 / 2f64.powf(k as f64 / 3.0)).collect();
    let meter_t = 1.0 / 1000.0;
    let meter = raw_frame(&map, W, meter_t, 20);
    let frame = BracketFrame {
        width: W,
        height: H,
        exposure: exif(meter_t),
        pixels: Pixels::Raw {
            values: &meter,
            black: BLACK,
            white: WHITE,
        },
    };
    let s = BracketSettings::default();
    let b = propose_bracket(&frame, None, &choices, &s).unwrap();
    assert!(!b.meter_clipped);
    let (short, long) = (b.times[0], *b.times.last().unwrap());
    // The brightest true radiance fits under the headroom in the shortest frame...
    let brightest = map.iter().flatten().fold(0.0f32, |a, &v| a.max(v)) as f64;
    assert!(brightest * short <= s.headroom * 1.02, "{b:?}");
    // ...and the next longer choice would not (the shortest is not needlessly short).
    let next = choices
        .iter()
        .copied()
        .filter(|&c| c > short)
        .fold(f64::MAX, f64::min);
    assert!(brightest * next > s.headroom * 0.98, "{b:?}");
    // Steps of at most 2 stops, ascending, all from the choices.
    for p in b.times.windows(2) {
        assert!(p[1] > p[0] && p[1] / p[0] <= 4.0 * (1.0 + 1e-9), "{b:?}");
    }
    assert!(b.times.iter().all(|t| choices.contains(t)));
    // The longest lifts the useful (5th percentile of noticeably lit) pixels to 5%.
    let mut lit: Vec<f64> = map
        .iter()
        .map(|p| p.iter().fold(0.0f32, |a, &v| a.max(v)) as f64)
        .filter(|&e| e >= 0.01 * brightest)
        .collect();
    lit.sort_by(f64::total_cmp);
    let p5 = lit[(lit.len() - 1) / 20];
    assert!(p5 * long >= 0.045, "useful {p5} x {long}: {b:?}");
    // Shooting it: nothing clipped everywhere, everything lit well exposed somewhere.
    let data: Vec<Vec<u16>> = b
        .times
        .iter()
        .enumerate()
        .map(|(k, &t)| raw_frame(&map, W, t, 30 + k as u64))
        .collect();
    let frames = raw_frames_of(&data, &b.times, W, H);
    let m = merge(&frames, None, &full_res()).unwrap();
    assert_eq!(m.clipped_everywhere, 0);
    // Clipped meter: flagged, starts at the shortest choice.
    let clipped_meter = raw_frame(&map, W, 0.1, 21);
    let b2 = propose_bracket(
        &BracketFrame {
            exposure: exif(0.1),
            pixels: Pixels::Raw {
                values: &clipped_meter,
                black: BLACK,
                white: WHITE,
            },
            ..frame
        },
        None,
        &choices,
        &s,
    )
    .unwrap();
    assert!(b2.meter_clipped);
    assert_eq!(
        b2.times[0],
        choices.iter().copied().fold(f64::MAX, f64::min)
    );
}

#[test]
fn downsample_preserves_the_mean_and_handles_non_integer_factors() {
    let mut rng = Rng::seed_from_u64(3);
    use rand::RngExt;
    let (w, h) = (37, 23);
    let img = Radiance {
        width: w,
        height: h,
        pixels: (0..w * h)
            .map(|_| {
                [
                    rng.random::<f32>(),
                    rng.random::<f32>() * 10.0,
                    rng.random::<f32>(),
                ]
            })
            .collect(),
    };
    let small = downsample(&img, 10); // factor 3.7
    assert_eq!((small.width, small.height), (10, 6));
    // Mean per area: the image's mean is preserved when the aspect scale matches; check
    // the exact property along x (single row images) and the mean for an exact fit.
    let row = Radiance {
        width: 3,
        height: 1,
        pixels: vec![[1.0; 3], [2.0; 3], [4.0; 3]],
    };
    let two = downsample(&row, 2);
    assert!((two.pixels[0][0] - (1.0 + 1.0) / 1.5).abs() < 1e-6);
    assert!((two.pixels[1][0] - (1.0 + 4.0) / 1.5).abs() < 1e-6);
    let exact = Radiance {
        width: 74,
        height: 46,
        pixels: (0..74 * 46)
            .map(|i| [(i % 7) as f32, (i % 13) as f32 * 0.5, (i % 3) as f32])
            .collect(),
    };
    let half = downsample(&exact, 20); // 3.7 both ways: 74/20 = 46/12.43.. -> 20x12
    let scale_x = 74.0 / half.width as f64;
    let scale_y = 46.0 / half.height as f64;
    // Each destination pixel is the area average, so the sums relate by the area ratio.
    let sum_src: f64 = exact.pixels.iter().flatten().map(|&v| f64::from(v)).sum();
    let sum_dst: f64 = half.pixels.iter().flatten().map(|&v| f64::from(v)).sum();
    assert!((sum_dst * scale_x * scale_y - sum_src).abs() / sum_src < 1e-5);
    assert!((half.mean() - exact.mean()).abs() / exact.mean() < 1e-5);
    // Integer factor: every output is the 4x4 box mean.
    let quarter = downsample(&exact, 74 / 2);
    assert_eq!((quarter.width, quarter.height), (37, 23));
    for y in 0..23 {
        for x in 0..37 {
            let mut s = 0.0f64;
            for dy in 0..2 {
                for dx in 0..2 {
                    s += f64::from(exact.pixels[(2 * y + dy) * 74 + 2 * x + dx][1]);
                }
            }
            assert!((f64::from(quarter.pixels[y * 37 + x][1]) - s / 4.0).abs() < 1e-5);
        }
    }
    assert!((quarter.mean() - exact.mean()).abs() / exact.mean() < 1e-6);
    let _ = small;
}

#[test]
fn the_exr_reads_back() {
    let img = Radiance {
        width: 5,
        height: 3,
        pixels: (0..15)
            .map(|i| [i as f32 * 0.25, 1.0 / (i + 1) as f32, 100.0 + i as f32])
            .collect(),
    };
    let dir = std::env::temp_dir().join(format!("visobjd-hdr-test-{}", std::process::id()));
    let path = dir.join("basis").join("017.exr");
    write_exr(&path, &img).unwrap();
    let read = exr::prelude::read_first_rgba_layer_from_file(
        &path,
        |size, _| vec![[0.0f32; 3]; size.0 * size.1],
        |px: &mut Vec<[f32; 3]>, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.1 * 5 + pos.0] = [r, g, b];
        },
    )
    .unwrap();
    let layer = &read.layer_data;
    assert_eq!((layer.size.0, layer.size.1), (5, 3));
    for (a, b) in layer.channel_data.pixels.iter().zip(&img.pixels) {
        for c in 0..3 {
            assert!((a[c] - b[c]).abs() <= b[c].abs() * 1e-3, "{a:?} vs {b:?}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let a = vec![0u16; 30];
    let b = vec![0u16; 27];
    let f = |v: &'static [u16]| BracketFrame {
        width: 5,
        height: 2,
        exposure: exif(0.01),
        pixels: Pixels::Raw {
            values: v,
            black: 10,
            white: 1000,
        },
    };
    let a: &'static [u16] = a.leak();
    let b: &'static [u16] = b.leak();
    assert!(matches!(
        merge(&[f(a), f(b)], None, &full_res()),
        Err(HdrError::PixelCount { frame: 1, .. })
    ));
    assert!(matches!(
        merge(&[], None, &full_res()),
        Err(HdrError::NoFrames)
    ));
    let codes = vec![0u8; 30];
    let j = BracketFrame {
        width: 5,
        height: 2,
        exposure: exif(0.01),
        pixels: Pixels::Jpeg(&codes),
    };
    assert!(matches!(
        merge(&[j], None, &full_res()),
        Err(HdrError::NoResponse)
    ));
    assert!(matches!(
        merge(&[f(a), j], None, &full_res()),
        Err(HdrError::MixedKinds { .. })
    ));
    let mut bad = f(a);
    bad.exposure.seconds = 0.0;
    assert!(matches!(
        merge(&[bad], None, &full_res()),
        Err(HdrError::BadExposure { .. })
    ));
}

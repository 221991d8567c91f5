//! Reference statistics on images with known answers.

use visobjd_compositor::color::srgb_to_lab;
use visobjd_method::objective::{Region, analyze};

fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) -> image::RgbImage {
    image::RgbImage::from_fn(w, h, |x, y| image::Rgb(f(x, y)))
}

#[test]
fn flat_grey_has_no_keys_and_its_own_lightness() {
    let a = analyze(&image(64, 48, |_, _| [119, 119, 119]), Region::FULL, 5);
    let l = srgb_to_lab([119.0 / 255.0; 3])[0];
    assert!((a.stats.mean_l - l).abs() < 1e-3, "{:?}", a.stats);
    assert!((a.stats.key_l - l).abs() < 1e-3, "{:?}", a.stats);
    assert_eq!(
        a.stats.bright, 0.0,
        "a flat image has no pixel above its mean"
    );
    assert_eq!(a.palette.len(), 1, "one colour, one palette entry");
    assert!((a.palette[0].weight - 1.0).abs() < 1e-6);
}

#[test]
fn half_black_half_white() {
    let a = analyze(
        &image(100, 40, |x, _| if x < 50 { [0; 3] } else { [255; 3] }),
        Region::FULL,
        5,
    );
    assert!((a.stats.mean_l - 50.0).abs() < 0.01, "{:?}", a.stats);
    assert!((a.stats.key_l - 100.0).abs() < 0.01, "{:?}", a.stats);
    assert!((a.stats.bright - 0.5).abs() < 1e-6, "{:?}", a.stats);
}

#[test]
fn key_is_the_exact_top_fifteen_percent() {
    // 100 pixels, L* rising; the brightest 15 are the last 15 columns.
    let a = analyze(&image(100, 1, |x, _| [(x * 2) as u8; 3]), Region::FULL, 3);
    let want: f32 = (85..100)
        .map(|x| srgb_to_lab([(x * 2) as f32 / 255.0; 3])[0])
        .sum::<f32>()
        / 15.0;
    assert!(
        (a.stats.key_l - want).abs() < 1e-3,
        "{} vs {want}",
        a.stats.key_l
    );
}

#[test]
fn two_colour_image_gives_a_seventy_thirty_palette() {
    let orange = [240, 120, 20];
    let blue = [20, 60, 200];
    let a = analyze(
        &image(100, 50, |x, _| if x < 70 { orange } else { blue }),
        Region::FULL,
        5,
    );
    assert_eq!(a.palette.len(), 2, "{:?}", a.palette);
    assert!((a.palette[0].weight - 0.7).abs() < 0.02, "{:?}", a.palette);
    assert!((a.palette[1].weight - 0.3).abs() < 0.02, "{:?}", a.palette);
    let close = |c: [f32; 3], want: [u8; 3]| {
        c.iter()
            .zip(want)
            .all(|(a, b)| (a * 255.0 - f32::from(b)).abs() < 1.5)
    };
    assert!(close(a.palette[0].color, orange), "{:?}", a.palette[0]);
    assert!(close(a.palette[1].color, blue), "{:?}", a.palette[1]);
}

#[test]
fn palette_is_deterministic_and_weights_sum_to_one() {
    let img = image(90, 60, |x, y| {
        [(x * 3) as u8, (y * 4) as u8, ((x * y) % 251) as u8]
    });
    let a = analyze(&img, Region::FULL, 5);
    let b = analyze(&img, Region::FULL, 5);
    assert_eq!(a, b);
    assert_eq!(a.palette.len(), 5);
    let total: f32 = a.palette.iter().map(|p| p.weight).sum();
    assert!((total - 1.0).abs() < 1e-4);
}

#[test]
fn crop_analyses_only_that_part() {
    let img = image(100, 40, |x, _| if x < 50 { [0; 3] } else { [255; 3] });
    let right = analyze(&img, Region::new(0.5, 0.0, 1.0, 1.0).unwrap(), 5);
    assert!(
        (right.stats.mean_l - 100.0).abs() < 0.01,
        "{:?}",
        right.stats
    );
}

#[test]
fn regions_are_validated() {
    assert!(Region::parse("0.5,0,0.5,1").is_err(), "x0 >= x1");
    assert!(Region::parse("0,0.6,1,0.2").is_err(), "y0 >= y1");
    assert!(Region::parse("0,0,1.5,1").is_err(), "outside 0..1");
    assert!(Region::parse("0,0,1").is_err(), "three numbers");
    assert!(Region::parse("0,0,NaN,1").is_err(), "NaN");
    assert_eq!(
        Region::parse("0, 0, 0.5, 1").unwrap(),
        Region::new(0.0, 0.0, 0.5, 1.0).unwrap()
    );
}

#[test]
fn pixel_spans_hold_exactly_the_pixels_whose_centres_are_inside() {
    for (x0, y0, x1, y1) in [
        (0.0, 0.0, 1.0, 1.0),
        (0.0, 0.0, 0.25, 1.0),
        (0.3, 0.6, 0.7, 0.9),
        (0.51, 0.02, 0.52, 0.03),
        (0.9, 0.9, 1.0, 1.0),
    ] {
        let region = Region::new(x0, y0, x1, y1).unwrap();
        for (w, h) in [(128, 72), (40, 20), (7, 3)] {
            let (xs, ys) = region.pixel_spans(w, h);
            for y in 0..h {
                for x in 0..w {
                    let (cx, cy) = ((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
                    assert_eq!(
                        xs.contains(&x) && ys.contains(&y),
                        cx >= x0 && cx < x1 && cy >= y0 && cy < y1,
                        "{region:?} on {w}x{h} at ({x}, {y})"
                    );
                }
            }
        }
    }
}

#[test]
fn a_record_of_any_analysis_reads_back_and_one_not_finite_is_refused() {
    use visobjd_method::objective::{Aspects, Objective, ObjectiveRecord};
    for img in [
        image(40, 20, |_, _| [255; 3]),
        image(40, 20, |_, _| [0; 3]),
        image(40, 20, |x, y| [(x * 6) as u8, (y * 12) as u8, 255]),
    ] {
        let o = Objective {
            image: "a.png".into(),
            aspects: Aspects::Both,
            region: Region::FULL,
            analysis: analyze(&img, Region::FULL, 5),
        };
        let record = ObjectiveRecord::from(&o);
        assert_eq!(record.to_objective(), Ok(o));
        let mut bad = record.clone();
        bad.key_l = f32::INFINITY;
        assert_eq!(
            bad.to_objective(),
            Err("key_l inf is not a finite number".into())
        );
        let mut bad = record.clone();
        bad.palette[0].weight = f32::NAN;
        assert_eq!(
            bad.to_objective(),
            Err("palette weight 1 NaN is not a finite number".into())
        );
        let mut bad = record;
        bad.palette[0].weight = 2.0;
        assert_eq!(
            bad.to_objective(),
            Err("palette weight 1 2 is outside 0..1".into())
        );
    }
}

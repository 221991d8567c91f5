//! Times reading one bracket of seven 24-megapixel shots (6000x4000) as capture reads
//! them: Bayer DNGs through `rawler` and the block average, and JPEGs through `image`.
//! The merge of the decoded frames is timed by `visobjd-hdr`'s `merge_bench`.
//! Run: `cargo run --release -p visobjd-capture --example decode_bench`.

use std::time::Instant;

use visobjd_capture::{decode, sim};

const W: usize = 6000;
const H: usize = 4000;
const FRAMES: usize = 7;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::temp_dir().join(format!("visobjd-decode-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    // A smooth stage-like picture: a lit pool fading to dark, in three colours.
    let sensor: Vec<[f32; 3]> = (0..H)
        .flat_map(|y| (0..W).map(move |x| (x, y)))
        .map(|(x, y)| {
            let dx = x as f32 / W as f32 - 0.5;
            let dy = y as f32 / H as f32 - 0.6;
            let v = (-(dx * dx + dy * dy) * 8.0).exp();
            [v, 0.8 * v, 0.6 * v]
        })
        .collect();
    let rgb: Vec<u8> = sensor
        .iter()
        .flat_map(|p| p.map(|v| (v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0) as u8))
        .collect();
    let mut raws = Vec::new();
    let mut jpegs = Vec::new();
    for i in 0..FRAMES {
        let seconds = 0.01 * f64::from(1u32 << i);
        let raw = dir.join(format!("{i}.dng"));
        sim::write_raw(&raw, W, H, &sensor, seconds)?;
        let jpeg = dir.join(format!("{i}.jpg"));
        sim::write_jpeg(&jpeg, W, H, &rgb, seconds)?;
        raws.push((raw, seconds));
        jpegs.push((jpeg, seconds));
    }
    for (label, files) in [("raw (DNG)", &raws), ("JPEG", &jpegs)] {
        let mut best = f64::INFINITY;
        for _ in 0..3 {
            let t = Instant::now();
            for (path, seconds) in files {
                let exposure = visobjd_hdr::Exposure {
                    seconds: *seconds,
                    iso: 100.0,
                    f_number: 8.0,
                };
                std::hint::black_box(decode::load(path, exposure)?);
            }
            best = best.min(t.elapsed().as_secs_f64());
        }
        println!("{label}: {FRAMES} frames of {W}x{H} read in {best:.2} s (best of 3)");
    }
    std::fs::remove_dir_all(&dir)?;
    Ok(())
}

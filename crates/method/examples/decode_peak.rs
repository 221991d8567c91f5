//! Measures a reference decode: `decode_peak make W H FILE` writes a 16-bit RGBA PNG (a
//! smooth gradient: small on disk), `decode_peak FILE` decodes it as an objective's
//! reference is and prints the time and the process's peak resident memory (VmHWM).

use std::time::Instant;

fn vm_hwm() -> String {
    std::fs::read_to_string("/proc/self/status")
        .unwrap_or_default()
        .lines()
        .find(|l| l.starts_with("VmHWM"))
        .map(|l| l.split_whitespace().skip(1).collect::<Vec<_>>().join(" "))
        .unwrap_or_default()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("make") {
        use image::ImageEncoder;
        let (w, h): (u32, u32) = (args[1].parse().unwrap(), args[2].parse().unwrap());
        let mut px = Vec::with_capacity(w as usize * h as usize * 8);
        for y in 0..h {
            for x in 0..w {
                for v in [
                    (u64::from(x) * 65535 / u64::from(w)) as u16,
                    (u64::from(y) * 65535 / u64::from(h)) as u16,
                    20000u16,
                    65535u16,
                ] {
                    px.extend(v.to_ne_bytes());
                }
            }
        }
        let file = std::io::BufWriter::new(std::fs::File::create(&args[3]).unwrap());
        image::codecs::png::PngEncoder::new_with_quality(
            file,
            image::codecs::png::CompressionType::Best,
            image::codecs::png::FilterType::Sub,
        )
        .write_image(&px, w, h, image::ExtendedColorType::Rgba16)
        .unwrap();
        return;
    }
    let path = std::path::Path::new(&args[0]);
    let before = vm_hwm();
    let t = Instant::now();
    let got = visobjd_method::objective::decode_reference(path);
    let ms = t.elapsed().as_secs_f64() * 1000.0;
    match got {
        Ok(img) => {
            println!(
                "decoded {}x{} in {ms:.0} ms, VmHWM {}",
                img.width(),
                img.height(),
                vm_hwm()
            );
            let t = Instant::now();
            let a = visobjd_method::objective::analyze(
                &img,
                visobjd_method::objective::Region::FULL,
                5,
            );
            println!(
                "analysed in {:.0} ms (mean L* {:.1})",
                t.elapsed().as_secs_f64() * 1000.0,
                a.stats.mean_l
            );
        }
        Err(e) => println!("refused in {ms:.0} ms: {e}"),
    }
    println!("VmHWM before {before}, after {}", vm_hwm());
}

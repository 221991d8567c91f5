//! The memory a reference decode takes, counted by this test binary's allocator (its own
//! process, one test, so nothing else allocates meanwhile): a 64-megapixel 16-bit RGBA PNG
//! (512 MB at its own depth) and a 64-megapixel JPEG both decode within
//! [`DECODE_LIMIT`], at little more than the 8-bit image itself.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use visobjd_method::objective::{DECODE_LIMIT, decode_reference};

/// The system allocator, counting the bytes held and the most held since [`reset`].
struct Counting;

static HELD: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call is passed to the system allocator unchanged; only counters are added.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract, passed on.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let held = HELD.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(held, Ordering::Relaxed);
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract, passed on.
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            let held = HELD.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(held, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract, passed on.
        unsafe { System.dealloc(p, layout) };
        HELD.fetch_sub(layout.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: the caller's contract, passed on.
        let q = unsafe { System.realloc(p, layout, new_size) };
        if !q.is_null() {
            // Counted as held at once, old and new, as a moving realloc holds them.
            let held = HELD.fetch_add(new_size, Ordering::Relaxed) + new_size;
            PEAK.fetch_max(held, Ordering::Relaxed);
            HELD.fetch_sub(layout.size(), Ordering::Relaxed);
        }
        q
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The most bytes `f` held at once beyond what was held before it.
fn peak_of<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let before = HELD.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    let out = f();
    (out, PEAK.load(Ordering::Relaxed) - before)
}

const SIDE: u32 = 8000;
const MIB: usize = 1 << 20;

#[test]
fn a_64_megapixel_decode_stays_within_the_bound() {
    let dir = std::env::temp_dir().join(format!("visobjd-decode-memory-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("mkdir");
    let image_bytes = 3 * (SIDE as usize).pow(2);

    let png = dir.join("big16.png");
    visobjd_testkit::png16(&png, SIDE, SIDE);
    let (img, peak) = peak_of(|| decode_reference(&png).expect("the PNG decodes"));
    assert_eq!(img.dimensions(), (SIDE, SIDE));
    assert_eq!(img.get_pixel(1000, 2000).0, [31, 62, 78]);
    drop(img);
    println!("16-bit PNG: peak {} MiB", peak / MIB);
    assert!(peak as u64 <= DECODE_LIMIT, "{} MiB", peak / MIB);
    // The 8-bit image and a few rows: never the 512 MB of 16-bit RGBA.
    assert!(peak <= image_bytes + 2 * MIB, "{} MiB", peak / MIB);

    let jpeg = dir.join("big.jpg");
    {
        let pixels: Vec<u8> = (0..image_bytes).map(|i| (i % 251) as u8).collect();
        let file = std::io::BufWriter::new(std::fs::File::create(&jpeg).expect("create"));
        image::ImageEncoder::write_image(
            image::codecs::jpeg::JpegEncoder::new_with_quality(file, 50),
            &pixels,
            SIDE,
            SIDE,
            image::ExtendedColorType::Rgb8,
        )
        .expect("encode");
    }
    let file = std::fs::metadata(&jpeg).expect("jpeg").len() as usize;
    let (img, peak) = peak_of(|| decode_reference(&jpeg).expect("the JPEG decodes"));
    assert_eq!(img.dimensions(), (SIDE, SIDE));
    drop(img);
    println!("JPEG ({} MiB file): peak {} MiB", file / MIB, peak / MIB);
    assert!(peak as u64 <= DECODE_LIMIT, "{} MiB", peak / MIB);
    // The file, the image, and the decoder's rows.
    assert!(peak <= file + image_bytes + 4 * MIB, "{} MiB", peak / MIB);
    let _ = std::fs::remove_dir_all(&dir);
}

//! `visobjd bench`: measures this machine's FLOP bound and, in the same run, every row of
//! the performance targets (issue 5), so ratios are comparable even on a busy machine.

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use rand::{RngExt, SeedableRng};

use visobjd_compositor::render::{Kernel, composite_clamped, composite_srgb8, weights};
use visobjd_dmx::{Output, OutputConfig, SacnDest};
use visobjd_method::objective::{Aspects, Objective, Region, analyze, decode_reference};
use visobjd_method::sampler::{Constraints, Spread};
use visobjd_method::stage::{GenerateRequest, Stage, THUMB_WIDTH};
use visobjd_scene::look::{Level, Look};

/// Arguments of `bench`.
#[derive(clap::Args)]
pub struct Args {
    /// Fewer repetitions (about 4x faster, noisier).
    #[arg(long)]
    quick: bool,
    /// The demo scene folder (the small rig's rows).
    #[arg(long, default_value = "scenes/demo")]
    scene: PathBuf,
}

type Rng = rand::rngs::Xoshiro256PlusPlus;

/// Lights, size and universes of the synthetic large scene.
const BIG: (usize, usize, usize, u16) = (267, 640, 360, 16);

/// Runs `bench`.
pub fn run(args: Args) -> anyhow::Result<()> {
    // As the daemon runs them, so the DMX row measures the same priorities.
    super::start_compute_pool();
    let reps = if args.quick { 3 } else { 10 };
    let kernel = Kernel::detect();
    println!(
        "visobjd bench: {} threads, kernel {kernel:?}, {}",
        rayon::current_num_threads(),
        cpu_model()
    );
    // The machine's bound is the fastest FMA loop of the run: the host is shared, and a
    // loop measured while a neighbour competes would flatter every ratio.
    let mut bound = flop_bound(kernel);
    println!(
        "FLOP bound at the start (FMA loop, all threads): {:.1} GFLOP/s",
        bound / 1e9
    );

    // The large scene first, so its load and resident memory are not mixed with the demo's.
    let dir = std::env::temp_dir().join(format!("visobjd-bench-{}", std::process::id()));
    let written = write_big_scene(&dir)?;
    let rss_before = rss_bytes();
    let started = Instant::now();
    let big = Arc::new(Stage::load(&dir, THUMB_WIDTH).context("loading the synthetic scene")?);
    let load_s = started.elapsed().as_secs_f64();
    let rss = rss_bytes();
    let kept = big.proxy.bytes() + big.thumbs.bytes();
    let demo = Arc::new(
        Stage::load(&args.scene, THUMB_WIDTH)
            .with_context(|| format!("{}: cannot load", args.scene.display()))?,
    );
    let objective = objective(&args.scene)?;
    let small = demo.scene.lights.len().to_string();
    let small = small.as_str();

    // Compositor rows, to be set against the run's bound once it is known. Every kernel
    // this CPU runs, the dispatched one last: its thumbnail row is the one with a target
    // (what a generate renders), its linear-float row is for comparison.
    // Kernels come only from their checked constructors: one this CPU lacks is `None`.
    let kernels = Kernel::all();
    for (name, k) in kernels {
        if k.is_none() && !args.quick {
            println!("note: this CPU lacks the {name} kernel; its rows are skipped");
        }
    }
    let mut compositor_rows = Vec::new();
    for (name, stage) in [(small, &demo), ("267", &big)] {
        let others = kernels
            .into_iter()
            .filter_map(|(_, k)| k)
            .filter(|k| *k != kernel);
        let runs = others
            .filter(|_| !args.quick)
            .map(|k| (k, Product::Thumbnails))
            .chain([(kernel, Product::Thumbnails), (kernel, Product::Linear)]);
        for (k, product) in runs {
            let name = format!(
                "compositor [{k:?}], {name} lights, {}x{}, 100 {}",
                stage.thumbs.width,
                stage.thumbs.height,
                product.describe()
            );
            let target = (k == kernel && product == Product::Thumbnails).then_some(0.6);
            compositor_rows.push((name, Compositor::new(stage, k, product), target));
        }
    }
    // One render of each row a round, each after an FMA loop: a row's renders and the
    // bound's loops are spread over the same seconds, so a quiet spell of the host reaches
    // both alike.
    let mut out = Outputs::default();
    for (_, row, _) in &mut compositor_rows {
        row.render(&mut out); // warm-up: page faults, panels
    }
    for _ in 0..reps {
        for (_, row, _) in &mut compositor_rows {
            bound = bound.max(fma_rate(kernel));
            row.sample(&mut out);
        }
    }
    drop(out);
    let compositor_rows: Vec<_> = compositor_rows
        .into_iter()
        .map(|(name, mut row, target)| (name, row.rates(), target))
        .collect();
    let mut rows = Vec::new();
    for (name, stage, target) in [(small, &demo, 15.0), ("267", &big, 40.0)] {
        let (ms, cpu_ms) = generate_ms(stage, &objective, reps * 2, Duration::ZERO);
        rows.push(Row::at_most(
            format!("/vo/generate 100 -> 12 + thumbs, {name} lights ({cpu_ms:.0} ms CPU)"),
            ms,
            "ms",
            target,
        ));
    }
    // As a designer clicks: after half a second idle, a CPU that clocks down when idle
    // starts the generate slow. For information: the target is the row above.
    let (ms, cpu_ms) = generate_ms(&demo, &objective, reps, Duration::from_millis(500));
    rows.push(Row {
        target: None,
        ..Row::at_most(
            format!("  the same, each after 0.5 s idle ({cpu_ms:.0} ms CPU)"),
            ms,
            "ms",
            15.0,
        )
    });
    rows.push(movers::row(&dir, &objective, reps * 2)?);
    rows.push(steer::row(&demo, &objective, reps));
    rows.push(Row::at_most(
        format!("scene load, {} lights at {}x{}", BIG.0, BIG.1, BIG.2),
        load_s,
        "s",
        3.0,
    ));
    rows.push(parse_row(if args.quick { 2 } else { 5 })?);
    rows.push(Row::at_most(
        format!(
            "resident memory, {} MB of basis kept (was {} MB before load)",
            kept >> 20,
            rss_before >> 20
        ),
        (rss >> 20) as f64,
        "MB",
        (1.2 * kept as f64 / (1 << 20) as f64) + 60.0,
    ));
    let (p99, period) = dmx_p99(&big, &dir, &objective, if args.quick { 2.0 } else { 4.0 })?;
    rows.push(Row::at_most(
        format!(
            "DMX p99 frame interval, {} universes, period {period:.2} ms",
            BIG.3
        ),
        p99,
        "ms",
        period + 2.0,
    ));
    let drag_s = if args.quick { 3.0 } else { 10.0 };
    for (name, stage, scene, target) in [
        (small, &demo, args.scene.as_path(), 50.0),
        ("267", &big, dir.as_path(), 20.0),
    ] {
        let d = drag::run(Arc::clone(stage), scene, &args.scene.join("refs"), drag_s)?;
        rows.extend(d.rows(name, drag_s, target));
    }
    drop(big);
    let _ = std::fs::remove_dir_all(&dir);
    bound = bound.max(flop_bound(kernel));
    let compositor_rows = compositor_rows
        .into_iter()
        .map(|(name, (best, median), target)| Row {
            name,
            value: best / 1e9,
            unit: "GFLOP/s",
            ratio: best / bound,
            target,
            more: true,
            note: format!("median {:.2}", median / bound),
        });
    let rows: Vec<Row> = compositor_rows.chain(rows).collect();
    println!(
        "FLOP bound, the fastest of the run: {:.1} GFLOP/s\n",
        bound / 1e9
    );

    println!(
        "{:<72} {:>16} {:>6} {:>7}",
        "measure", "value", "ratio", "target"
    );
    for r in &rows {
        let verdict = match r.target {
            Some(t) if (r.ratio >= t) == r.more => "ok",
            Some(_) => "MISSED",
            None => "",
        };
        let target = r.target.map_or(String::new(), |t| {
            format!("{}{t:.2}", if r.more { ">=" } else { "<=" })
        });
        let line = format!(
            "{:<72} {:>16} {:>6.2} {target:>7} {verdict:<6} {}",
            r.name,
            format!("{:.2} {}", r.value, r.unit),
            r.ratio,
            r.note,
        );
        println!("{}", line.trim_end());
    }
    println!(
        "(ratio: compositor rows, the fastest of {reps} renders to the FLOP bound, the fastest \
         FMA loop of the run: both best cases, as contention on a shared host only slows \
         either, taken over the same seconds (the renders one a round, each after an FMA \
         loop, plus loops at the start and the end); the median render's ratio beside them. \
         The others to their limit)"
    );
    println!(
        "(drag rows: a client sends /vo/explore 1, {} region updates a second for {drag_s} s, \
         then /vo/explore 0, to a daemon in this process (OSC over UDP on loopback, sACN to a \
         local socket); galleries are the /vo/generated pushes its subscription received, \
         against the target; the lockstep client beside them sets the region and waits for \
         each /vo/generate. The DMX gap is the largest interval between one universe's \
         packets during the drag, against two periods; pings go every {} ms from another \
         socket)",
        drag::UPDATES_HZ,
        drag::PING_EVERY.as_millis()
    );
    println!("\n(the synthetic scene: {written} EXR files, {load_s:.2} s to load)");
    Ok(())
}

mod drag;
mod movers;
mod steer;

/// One line of the report.
struct Row {
    name: String,
    value: f64,
    unit: &'static str,
    /// Value over its bound (compositor) or limit (the rest).
    ratio: f64,
    /// Required ratio, if the row has a target.
    target: Option<f64>,
    /// Whether the ratio must be at least (else at most) the target.
    more: bool,
    /// Printed after the verdict.
    note: String,
}

impl Row {
    /// A row that must stay at or under `limit`.
    fn at_most(name: String, value: f64, unit: &'static str, limit: f64) -> Row {
        Row {
            name,
            value,
            unit,
            ratio: value / limit,
            target: Some(1.0),
            more: false,
            note: String::new(),
        }
    }
}

fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into())
}

/// Resident set size from /proc/self/status (0 where there is none).
fn rss_bytes() -> usize {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<usize>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}

/// Best of three FMA loops: the bound at the start and the end of the run.
fn flop_bound(kernel: Kernel) -> f64 {
    (0..3).map(|_| fma_rate(kernel)).fold(0.0, f64::max)
}

/// Floating-point operations per second of independent FMA chains on every rayon thread
/// at the kernel's vector width (about 35 ms).
fn fma_rate(kernel: Kernel) -> f64 {
    const ITERS: u64 = 20_000_000;
    let started = Instant::now();
    let flops: u64 = rayon::broadcast(|_| fma_loop(kernel, ITERS)).iter().sum();
    flops as f64 / started.elapsed().as_secs_f64()
}

/// Runs `iters` rounds of 12 independent FMA chains; returns the flops done.
fn fma_loop(kernel: Kernel, iters: u64) -> u64 {
    match kernel {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the token exists, so the CPU has AVX-512F.
        Kernel::Avx512(t) => unsafe { peak::avx512(t, iters) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the token exists, so the CPU has AVX2 and FMA.
        Kernel::Avx2(t) => unsafe { peak::avx2(t, iters) },
        _ => {
            let mut acc = [1.0f32; 48];
            for _ in 0..iters / 4 {
                for a in &mut acc {
                    *a = *a * 0.999_999 + 1e-7;
                }
            }
            std::hint::black_box(acc);
            iters / 4 * 48 * 2
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod peak {
    use std::arch::x86_64::*;

    use visobjd_compositor::cpu::{Avx2Fma, Avx512F};

    /// 12 chains are more than latency x throughput of any current FMA unit.
    const CHAINS: usize = 12;

    /// The token is the caller's proof of the feature.
    #[target_feature(enable = "avx512f")]
    pub(super) fn avx512(_: Avx512F, iters: u64) -> u64 {
        let (m, a) = (_mm512_set1_ps(0.999_999), _mm512_set1_ps(1e-7));
        let mut c = [_mm512_set1_ps(1.0); CHAINS];
        for _ in 0..iters {
            for c in &mut c {
                *c = _mm512_fmadd_ps(*c, m, a);
            }
        }
        std::hint::black_box(c);
        iters * (CHAINS * 16 * 2) as u64
    }

    /// The token is the caller's proof of the features.
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn avx2(_: Avx2Fma, iters: u64) -> u64 {
        let (m, a) = (_mm256_set1_ps(0.999_999), _mm256_set1_ps(1e-7));
        let mut c = [_mm256_set1_ps(1.0); CHAINS];
        for _ in 0..iters {
            for c in &mut c {
                *c = _mm256_fmadd_ps(*c, m, a);
            }
        }
        std::hint::black_box(c);
        iters * (CHAINS * 8 * 2) as u64
    }
}

/// What the compositor's output is turned into.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Product {
    /// 8-bit sRGB, as gallery thumbnails are rendered.
    Thumbnails,
    /// Linear RGB clamped to 0..1, as 32-bit floats (four times the bytes to write).
    Linear,
}

impl Product {
    fn describe(self) -> &'static str {
        match self {
            Product::Thumbnails => "8-bit sRGB thumbnails",
            Product::Linear => "linear float images",
        }
    }
}

/// Output buffers, shared by the compositor rows: 100 thumbnails or linear images.
#[derive(Default)]
struct Outputs {
    bytes: Vec<Vec<u8>>,
    floats: Vec<Vec<f32>>,
}

/// One compositor row: 100 random candidates of a stage, rendered by one kernel to one
/// product, and the times of its renders.
struct Compositor<'a> {
    stage: &'a Stage,
    kernel: Kernel,
    product: Product,
    weights: Vec<Vec<[f32; 3]>>,
    times: Vec<f64>,
}

impl<'a> Compositor<'a> {
    fn new(stage: &'a Stage, kernel: Kernel, product: Product) -> Self {
        let lights = stage.thumbs.lights;
        let mut rng = Rng::seed_from_u64(7);
        let looks: Vec<Look> = (0..100)
            .map(|_| Look {
                levels: (0..lights)
                    .map(|_| Level {
                        intensity: rng.random(),
                        color: [rng.random(), rng.random(), rng.random()],
                        position: None,
                    })
                    .collect(),
            })
            .collect();
        let refs: Vec<&Look> = looks.iter().collect();
        Compositor {
            stage,
            kernel,
            product,
            weights: weights(&stage.thumbs, &refs, stage.gain),
            times: Vec::new(),
        }
    }

    fn render(&self, out: &mut Outputs) {
        let basis = &self.stage.thumbs;
        let len = basis.pixels() * 3;
        match self.product {
            Product::Thumbnails => {
                fit(&mut out.bytes, self.weights.len(), len);
                composite_srgb8(self.kernel, basis, &self.weights, &mut out.bytes);
            }
            Product::Linear => {
                fit(&mut out.floats, self.weights.len(), len);
                composite_clamped(self.kernel, basis, &self.weights, &mut out.floats);
            }
        }
    }

    /// Times one render.
    fn sample(&mut self, out: &mut Outputs) {
        let started = Instant::now();
        self.render(out);
        self.times.push(started.elapsed().as_secs_f64());
    }

    /// FLOP rates of the fastest render, the measure of what the code can do on a shared
    /// host, and of the median one.
    fn rates(&mut self) -> (f64, f64) {
        let basis = &self.stage.thumbs;
        let flops = 2.0 * 3.0 * (basis.lights * basis.pixels() * self.weights.len()) as f64;
        // median() sorts the times, so the fastest is then the first.
        let median = median(&mut self.times);
        (flops / self.times[0], flops / median)
    }
}

/// Makes `bufs` `n` buffers of `len`: rows of the same size share them as they are.
fn fit<T: Default + Clone>(bufs: &mut Vec<Vec<T>>, n: usize, len: usize) {
    bufs.resize_with(n, Vec::new);
    for b in bufs {
        b.resize(len, T::default());
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// An objective from the first reference image of the demo scene.
fn objective(scene: &Path) -> anyhow::Result<Objective> {
    let mut refs: Vec<PathBuf> = std::fs::read_dir(scene.join("refs"))
        .with_context(|| format!("{}: no refs folder", scene.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    refs.sort();
    let path = refs.first().context("no reference PNG in the demo scene")?;
    let img = decode_reference(path).map_err(anyhow::Error::msg)?;
    Ok(Objective {
        image: path.display().to_string(),
        aspects: Aspects::Both,
        region: Region::FULL,
        analysis: analyze(&img, Region::FULL, 5),
    })
}

/// One generate as the daemon runs it: 100 candidates into 12 entries, thumbnails included.
fn generate_once(stage: &Stage, objective: &Objective, seed: u64) -> f64 {
    let base = Look::off(stage.scene.lights.len());
    let started = Instant::now();
    let g = stage.generate(
        &GenerateRequest {
            objectives: std::slice::from_ref(objective),
            constraints: &Constraints::none(&stage.rig),
            base: &base,
            spread: Spread::default(),
            count: 100,
            clusters: 12,
            steer: None,
        },
        &mut Rng::seed_from_u64(seed),
    );
    std::hint::black_box(&g);
    started.elapsed().as_secs_f64() * 1000.0
}

/// Median wall time of `runs` generates, each after `pause` idle, and the mean CPU time
/// (all threads) they used: on a shared machine the second says how much of the first was
/// waiting for a core.
fn generate_ms(stage: &Stage, objective: &Objective, runs: usize, pause: Duration) -> (f64, f64) {
    generate_once(stage, objective, 999); // warm-up
    let cpu = cpu_ms();
    let mut ms: Vec<f64> = (1..=runs as u64)
        .map(|seed| {
            std::thread::sleep(pause);
            generate_once(stage, objective, seed)
        })
        .collect();
    let cpu = (cpu_ms() - cpu) / runs as f64;
    (median(&mut ms), cpu)
}

/// CPU time of this process so far (user + system, all threads), from /proc/self/stat.
fn cpu_ms() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the parenthesised command name; utime and stime are the 12th and 13th,
    // in clock ticks (100 per second on Linux).
    let fields: Vec<f64> = stat
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .skip(11)
        .take(2)
        .filter_map(|f| f.parse().ok())
        .collect();
    fields.iter().sum::<f64>() * 10.0
}

/// Lights of the small and the large scene.toml of the parse row.
const PARSE: (usize, usize) = (1000, 16000);

/// The parse row: `Scene::parse`'s time per light at 16,000 lights over its time per light
/// at 1,000, each the best of `reps` parses taken in turns (so a busy spell of the host
/// slows both alike): a step that grows with lights x groups shows as a ratio far above 1
/// (it read 18-19 when group names were looked up in a list); linear reads about 1.1 on a
/// quiet host, up to 2 on a busy one, so the target is 3. Each light is its own group, as
/// an imported rig's ungrouped fixtures are, and the profiles alternate.
fn parse_row(reps: usize) -> anyhow::Result<Row> {
    let dir = Path::new("bench-parse");
    let texts = [scene_toml(PARSE.0), scene_toml(PARSE.1)];
    let mut best = [f64::INFINITY; 2];
    for _ in 0..reps {
        for (text, best) in texts.iter().zip(&mut best) {
            let started = Instant::now();
            let scene = visobjd_scene::Scene::parse(dir, text)?;
            *best = best.min(started.elapsed().as_secs_f64());
            std::hint::black_box(scene);
        }
    }
    let (small, large) = (best[0] / PARSE.0 as f64, best[1] / PARSE.1 as f64);
    Ok(Row {
        name: format!(
            "scene.toml parse, time per light at {} over {} ({:.1} us at {})",
            PARSE.1,
            PARSE.0,
            small * 1e6,
            PARSE.0
        ),
        value: large * 1e6,
        unit: "us",
        ratio: large / small,
        target: Some(3.0),
        more: false,
        note: String::new(),
    })
}

/// The scene.toml of `lights` ungrouped lights (each its own group), 128 to a universe.
fn scene_toml(lights: usize) -> String {
    let mut toml = String::from("name = \"bench, parse\"\n");
    for i in 0..lights {
        let profile = if i % 2 == 0 { "dimmer" } else { "irgb" };
        toml += &format!(
            "[[light]]\nchannel = {}\nbasis = \"basis/{:05}.exr\"\nprofile = \"{profile}\"\n\
             universe = {}\naddress = {}\n",
            i + 1,
            i + 1,
            i / 128 + 1,
            (i % 128) * 4 + 1
        );
    }
    toml
}

/// Writes the synthetic scene: smooth coloured spots over a dim wash, one per light,
/// spread over `BIG.3` universes. Returns the number of basis images.
fn write_big_scene(dir: &Path) -> anyhow::Result<usize> {
    use rayon::prelude::*;
    let (lights, w, h, universes) = BIG;
    std::fs::create_dir_all(dir.join("basis"))?;
    let per_universe = lights.div_ceil(universes as usize);
    let mut toml = String::from("name = \"bench, synthetic\"\n");
    for i in 0..lights {
        toml += &format!(
            "[[light]]\nchannel = {}\nbasis = \"basis/{:03}.exr\"\nprofile = \"irgb\"\n\
             universe = {}\naddress = {}\n",
            i + 1,
            i + 1,
            i / per_universe + 1,
            (i % per_universe) * 4 + 1
        );
    }
    std::fs::write(dir.join("scene.toml"), toml)?;
    (0..lights).into_par_iter().try_for_each(|i| {
        spot_image(&dir.join(format!("basis/{:03}.exr", i + 1)), w, h, i as u64)
    })?;
    Ok(lights)
}

/// Writes a smooth coloured spot over a dim wash, placed, sized and tinted by `seed`: a
/// synthetic light's basis image.
fn spot_image(path: &Path, w: usize, h: usize, seed: u64) -> anyhow::Result<()> {
    let mut rng = Rng::seed_from_u64(seed);
    let (cx, cy) = (
        rng.random::<f32>() * w as f32,
        rng.random::<f32>() * h as f32,
    );
    let radius = (0.05 + 0.2 * rng.random::<f32>()) * w as f32;
    let tint: [f32; 3] = std::array::from_fn(|_| 0.3 + 0.7 * rng.random::<f32>());
    exr::prelude::write_rgb_file(path, w, h, |x, y| {
        let d2 = ((x as f32 - cx).powi(2) + (y as f32 - cy).powi(2)) / (radius * radius);
        let v = 0.01 + 0.5 * (-d2).exp();
        (v * tint[0], v * tint[1], v * tint[2])
    })
    .with_context(|| format!("{}: cannot write", path.display()))
}

/// Runs back-to-back generates for `seconds` while an `Output` sends the scene's universes
/// by sACN to a local socket; returns the p99 interval between one universe's packets and
/// the period, in ms.
fn dmx_p99(
    stage: &Stage,
    dir: &Path,
    objective: &Objective,
    seconds: f64,
) -> anyhow::Result<(f64, f64)> {
    let receiver = UdpSocket::bind("127.0.0.1:0")?;
    receiver.set_read_timeout(Some(Duration::from_millis(100)))?;
    let config = OutputConfig {
        sacn: vec![SacnDest {
            port: receiver.local_addr()?.port(),
            ..SacnDest::default()
        }],
        ..OutputConfig::default()
    };
    let period = 1000.0 / f64::from(config.rate_hz);
    let patch = visobjd_dmx::patch::Patch::new(&stage.scene);
    let output = Output::start(&config, patch, dir, Look::off(stage.scene.lights.len()))?;
    let stop = std::sync::atomic::AtomicBool::new(false);
    let arrivals = std::thread::scope(|s| {
        let listener = s.spawn(|| {
            let mut buf = [0u8; 1024];
            let mut arrivals = Vec::new();
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                if let Ok(n) = receiver.recv(&mut buf)
                    // E1.31 data packets carry the universe at bytes 113..115.
                    && n > 115
                    && u16::from_be_bytes([buf[113], buf[114]]) == 1
                {
                    // The kernel's receive time: this thread competes for the cores with
                    // the generates, and its own lateness is not the sender's.
                    arrivals.push(visobjd_dmx::kernel_arrival(&receiver, Instant::now()));
                }
            }
            arrivals
        });
        let started = Instant::now();
        let mut seed = 1;
        while started.elapsed().as_secs_f64() < seconds {
            generate_once(stage, objective, seed);
            seed += 1;
        }
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
        listener.join().expect("listener thread")
    });
    output.shutdown();
    let mut gaps: Vec<f64> = arrivals
        .windows(2)
        .map(|w| (w[1] - w[0]).as_secs_f64() * 1000.0)
        .collect();
    anyhow::ensure!(
        gaps.len() > 10,
        "only {} sACN packets arrived",
        arrivals.len()
    );
    gaps.sort_by(f64::total_cmp);
    Ok((gaps[(gaps.len() * 99) / 100], period))
}

//! The CPU compositor: a look relights the basis images (paper 5.1).
//!
//! A render is `out[pixel] = gain * sum over lights of multiplier[light] * basis[light][pixel]`
//! per channel, so rendering C candidates is a matrix product (C x lights) x (lights x
//! pixels) per channel. The batched compositor cuts the pixels into strips of [`STRIP`]
//! (the basis is stored strip by strip), and for each strip runs a register-blocked
//! micro-kernel (4 candidates x 96 pixels) over chunks of lights small enough to stay in L1,
//! for every block of candidates before the next chunk: the basis is read from memory once
//! per batch, each chunk from L1 once per block, and the FMA units stay busy. The kernel is
//! picked at run time ([`Kernel::detect`]): AVX-512, AVX2+FMA, or portable code. Thumbnails
//! ([`composite_srgb8`]) are encoded to sRGB inside the AVX-512 kernel where the CPU has
//! VBMI, as each channel's sums become final.

use half::f16;
use half::slice::HalfFloatSliceExt;
use rayon::prelude::*;

use crate::basis::{BasisImages, Panel};
use crate::color::encode_srgb8_planar;
use crate::cpu::{Avx2Fma, Avx512F, NonTemporal, non_temporal};
use visobjd_scene::look::Look;

/// Pixels per strip: six 16-lane AVX-512 vectors, the width of the register block.
pub const STRIP: usize = 96;
/// Candidates per register block.
const MR: usize = 4;
/// Strips per parallel task at most: enough work to hide rayon's overhead.
const TASK_STRIPS: usize = 8;

/// One light's strip of one channel.
type Row = [f32; STRIP];

/// A row on cache-line boundaries (384 bytes is six lines), so no load of the kernel
/// straddles two lines.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct Line(Row);

// A line adds no padding to its row: the cast in `rows_mut` relies on it.
const _: () = assert!(size_of::<Line>() == size_of::<Row>());

impl Line {
    /// The lines as the kernel's plain rows.
    fn rows_mut(lines: &mut [Line]) -> &mut [Row] {
        // SAFETY: `Line` is a `repr(C)` wrapper of one `Row` with no padding (asserted above),
        // so a slice of lines is laid out exactly as a slice of rows.
        unsafe { std::slice::from_raw_parts_mut(lines.as_mut_ptr().cast::<Row>(), lines.len()) }
    }
}

/// A register block's sums in memory: carried from one chunk of lights to the next, and
/// what the candidates are emitted from.
type Acc = [[f32; STRIP]; MR];

/// A register block's sRGB codes of one channel: a plane of STRIP bytes per candidate.
type Codes = [[u8; STRIP]; MR];

/// Linear gain of an exposure in stops.
pub fn exposure_gain(stops: f32) -> f32 {
    stops.exp2()
}

/// Per-image linear RGB multipliers of each look, times `gain`: `weights[c][i]` for every
/// image of `basis`, computed once per look so the kernels only multiply and add. A light
/// captured at white only weighs its white image by its colour model's multiplier
/// ([`BasisImages::colours`]); one captured per emitter weighs each emitter's image by the
/// level the colour solve sends that emitter (times the intensity), and its white image by
/// 0, so the preview is the sum of what the camera saw of each emitter. A moving light
/// weighs only the image of the position the look puts it in.
pub fn weights(basis: &BasisImages, looks: &[&Look], gain: f32) -> Vec<Vec<[f32; 3]>> {
    looks
        .par_iter()
        .map(|look| {
            let mut w = vec![[0.0; 3]; basis.images];
            for (l, ((lv, colour), emitters)) in look
                .levels
                .iter()
                .zip(&basis.colours)
                .zip(&basis.emitter_images)
                .enumerate()
            {
                match emitters {
                    None => w[basis.image_of(l, lv)] = colour.multiplier(lv).map(|m| m * gain),
                    Some(first) if lv.intensity > 0.0 => {
                        let k = lv.intensity * gain;
                        for (wi, level) in
                            w[*first..].iter_mut().zip(colour.solve(lv.color).levels())
                        {
                            *wi = [*level as f32 * k; 3];
                        }
                    }
                    Some(_) => {}
                }
            }
            w
        })
        .collect()
}

/// A micro-kernel implementation; all compute the same sums (FMA or not), to within 1e-4
/// of [`render_reference`].
///
/// The SIMD variants carry the token of their CPU features ([`crate::cpu`]), which only
/// that token's `detect` makes: no safe code can choose a kernel this CPU does not run. Get
/// one from [`Kernel::detect`], [`Kernel::all`], or as `Kernel::Avx512(token)`. (This is
/// why there is no constant list of every kernel, nor a `supported()` to ask: a kernel
/// value is itself the answer.)
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    /// Plain Rust the compiler vectorises for the baseline target: runs anywhere.
    Portable,
    /// 256-bit AVX2 with FMA (x86-64 from about 2013).
    Avx2(Avx2Fma),
    /// 512-bit AVX-512F (Zen 4, Intel server parts).
    Avx512(Avx512F),
}

impl Kernel {
    /// The widest kernel this CPU runs.
    pub fn detect() -> Kernel {
        Kernel::all()
            .into_iter()
            .rev()
            .find_map(|(_, k)| k)
            .unwrap_or(Kernel::Portable)
    }

    /// Every kernel by name, slowest first, each `None` where this CPU lacks its features
    /// (for tests and the benchmark, which compare the paths and note the ones skipped).
    pub fn all() -> [(&'static str, Option<Kernel>); 3] {
        [
            ("Portable", Some(Kernel::Portable)),
            ("Avx2", Avx2Fma::detect().map(Kernel::Avx2)),
            ("Avx512", Avx512F::detect().map(Kernel::Avx512)),
        ]
    }

    /// The kernel's name, as [`Kernel::all`] gives it.
    pub fn name(self) -> &'static str {
        match self {
            Kernel::Portable => "Portable",
            Kernel::Avx2(_) => "Avx2",
            Kernel::Avx512(_) => "Avx512",
        }
    }

    /// Computes one register block's sums into `acc` (see [`Call`]).
    fn block(self, call: Call, acc: &mut Acc) {
        match self {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: the token exists, so the CPU has AVX-512F.
            Kernel::Avx512(t) => unsafe { x86::block_avx512(t, call, acc) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: the token exists, so the CPU has AVX2 and FMA.
            Kernel::Avx2(t) => unsafe { x86::block_avx2(t, call, acc) },
            _ => block_portable(call, acc),
        }
    }
}

/// The name alone: the tokens say nothing more.
impl std::fmt::Debug for Kernel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One kernel call: `acc[r][p] = sum over active l of w[l][r] * b[l][p]`, added to the
/// stored sums if `add` (an earlier chunk's), else from zero. The kernel also asks for the
/// cache lines of `ahead` (its share of the next strip's panel), so memory streams in under
/// the arithmetic.
#[derive(Clone, Copy)]
struct Call<'a> {
    /// The block's weights over the chunk's lights, `[light][candidate]`.
    w: &'a [[f32; MR]],
    /// The chunk's rows of the strip's panel.
    b: &'a [Row],
    /// The lights of the chunk that contribute to the block (weights not all zero).
    active: &'a [u32],
    add: bool,
    ahead: Ahead,
}

/// Cache lines to prefetch: `lines` lines from `start`. A prefetch is only a hint and never
/// faults, so the address needs no validity guarantee.
#[derive(Clone, Copy)]
struct Ahead {
    start: *const u8,
    lines: usize,
}

impl Ahead {
    /// Asks for every line.
    #[inline(always)]
    fn touch_all(self) {
        #[cfg(target_arch = "x86_64")]
        for i in 0..self.lines {
            use std::arch::x86_64::{_MM_HINT_T1, _mm_prefetch};
            // SAFETY: prefetching is a hint with no effect on memory safety; the address
            // (computed with wrapping arithmetic) is inside the next strip's panel anyway.
            unsafe { _mm_prefetch::<_MM_HINT_T1>(self.start.wrapping_add(64 * i).cast()) };
        }
    }
}

impl Call<'_> {
    /// Calls `light` with the row and weights of every contributing light. When they all
    /// contribute it walks the rows in order: with no index to load and check, the loop's
    /// few scalar instructions leave the FMA ports to the FMAs (5-15% faster than the
    /// indexed loop in same-run measurements).
    #[inline(always)]
    fn for_each_light(self, mut light: impl FnMut(&Row, &[f32; MR])) {
        let Call { w, b, active, .. } = self;
        if active.len() == b.len() {
            for (row, ws) in b.iter().zip(w) {
                light(row, ws);
            }
        } else {
            for &l in active {
                light(&b[l as usize], &w[l as usize]);
            }
        }
    }
}

fn block_portable(call: Call, acc: &mut Acc) {
    if !call.add {
        for a in acc.iter_mut() {
            a.fill(0.0);
        }
    }
    call.for_each_light(|row, ws| {
        for (a, &k) in acc.iter_mut().zip(ws) {
            for (a, &v) in a.iter_mut().zip(row) {
                *a += k * v;
            }
        }
    });
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    use half::f16;

    use super::{Acc, Call, Codes, MR, STRIP};
    use crate::color::Vbmi;
    use crate::cpu::{Avx2Fma, Avx512F, NonTemporal};

    /// Zmm vectors per row.
    const V: usize = STRIP / 16;

    /// 4 candidates x 96 pixels in 24 zmm accumulators; per light 6 loads, 4 broadcasts,
    /// 24 FMAs. The sums are left in registers for the caller to store or encode (always
    /// inlined, which a function with target features cannot be: 24 registers returned
    /// through memory would undo the point).
    ///
    /// # Safety
    /// The CPU must have AVX-512F.
    #[inline(always)]
    unsafe fn sums_avx512(call: Call, acc: &Acc) -> [[__m512; V]; MR] {
        // SAFETY: the caller guarantees AVX-512F; the loads are in bounds (noted at each).
        unsafe {
            let mut c = [[_mm512_setzero_ps(); V]; MR];
            if call.add {
                for (c, a) in c.iter_mut().zip(acc.iter()) {
                    for (j, c) in c.iter_mut().enumerate() {
                        // `a` holds STRIP floats; lanes 16j..16j+16 are inside.
                        *c = _mm512_loadu_ps(a.as_ptr().add(16 * j));
                    }
                }
            }
            call.ahead.touch_all();
            call.for_each_light(|row, ws| {
                let mut v = [_mm512_setzero_ps(); V];
                for (j, v) in v.iter_mut().enumerate() {
                    // `row` holds STRIP = 16 * V floats; lanes 16j..16j+16 are inside.
                    *v = _mm512_loadu_ps(row.as_ptr().add(16 * j));
                }
                for (c, &k) in c.iter_mut().zip(ws) {
                    let k = _mm512_set1_ps(k);
                    for (c, &v) in c.iter_mut().zip(&v) {
                        *c = _mm512_fmadd_ps(k, v, *c);
                    }
                }
            });
            c
        }
    }

    /// The register block with its sums stored to `acc`. The token is the caller's proof
    /// of the features.
    #[target_feature(enable = "avx512f")]
    pub(super) fn block_avx512(_: Avx512F, call: Call, acc: &mut Acc) {
        // SAFETY: this function's features include AVX-512F.
        let c = unsafe { sums_avx512(call, acc) };
        for (a, c) in acc.iter_mut().zip(&c) {
            for (j, &c) in c.iter().enumerate() {
                // SAFETY: `a` holds STRIP floats; lanes 16j..16j+16 are inside.
                unsafe { _mm512_storeu_ps(a.as_mut_ptr().add(16 * j), c) };
            }
        }
    }

    /// The register block with its sums encoded to sRGB codes straight from the registers,
    /// one plane of STRIP bytes per candidate: the sums never go to memory, and the planes
    /// (a quarter of their bytes) stay in L1 until the block's blue is done.
    #[target_feature(enable = "avx512f,avx512bw,avx512vbmi,avx512vbmi2")]
    pub(super) fn codes_avx512(call: Call, acc: &Acc, vbmi: Vbmi, codes: &mut Codes) {
        // SAFETY: this function's features include AVX-512F.
        let c = unsafe { sums_avx512(call, acc) };
        // Written out, not a loop over the candidates: the compiler then keeps the sums in
        // registers rather than storing all 24 to the stack to index them (2% faster).
        let [p0, p1, p2, p3] = codes;
        vbmi.plane(&c[0], p0);
        vbmi.plane(&c[1], p1);
        vbmi.plane(&c[2], p2);
        vbmi.plane(&c[3], p3);
    }

    /// The register block's blue sums encoded straight from the registers and interleaved
    /// with its red and green code planes into each candidate's output's `local` bytes,
    /// whole cache lines with non-temporal stores (fenced when `nt`'s scope ends).
    #[target_feature(enable = "avx512f,avx512bw,avx512vbmi,avx512vbmi2")]
    pub(super) fn emit_avx512(
        call: Call,
        acc: &Acc,
        vbmi: Vbmi,
        nt: &NonTemporal,
        codes: &[Codes; 2],
        outs: &mut [&mut [u8]],
        local: std::ops::Range<usize>,
    ) {
        // SAFETY: this function's features include AVX-512F.
        let c = unsafe { sums_avx512(call, acc) };
        // The loop stores the sums to the stack once, each then read by the instruction
        // that uses it: written out per candidate (a macro, the sums left in registers) it
        // measured the same, and with a closure the closure was called, not inlined.
        for (r, out) in outs.iter_mut().enumerate() {
            let planes = [&codes[0][r], &codes[1][r]];
            vbmi.stream_interleaved(nt, planes, &c[r], &mut out[local.clone()]);
        }
    }

    /// Four passes of 4 candidates x 24 pixels (12 ymm accumulators of 16 registers).
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn block_avx2(_: Avx2Fma, call: Call, acc: &mut Acc) {
        const V: usize = 3;
        const PARTS: usize = STRIP / (8 * V);
        call.ahead.touch_all();
        for part in 0..PARTS {
            let off = part * 8 * V;
            let mut c = [[_mm256_setzero_ps(); V]; MR];
            if call.add {
                for (c, a) in c.iter_mut().zip(acc.iter()) {
                    for (j, c) in c.iter_mut().enumerate() {
                        // SAFETY: off + 8 * V <= STRIP floats of `a`.
                        *c = unsafe { _mm256_loadu_ps(a.as_ptr().add(off + 8 * j)) };
                    }
                }
            }
            call.for_each_light(|row, ws| {
                let row = &row[off..off + 8 * V];
                let mut v = [_mm256_setzero_ps(); V];
                for (j, v) in v.iter_mut().enumerate() {
                    // SAFETY: `row` holds 8 * V floats; lanes 8j..8j+8 are inside.
                    *v = unsafe { _mm256_loadu_ps(row.as_ptr().add(8 * j)) };
                }
                for (c, &k) in c.iter_mut().zip(ws) {
                    let k = _mm256_set1_ps(k);
                    for (c, &v) in c.iter_mut().zip(&v) {
                        *c = _mm256_fmadd_ps(k, v, *c);
                    }
                }
            });
            for (a, c) in acc.iter_mut().zip(&c) {
                let a = &mut a[off..off + 8 * V];
                for (j, &c) in c.iter().enumerate() {
                    // SAFETY: `a` holds 8 * V floats; lanes 8j..8j+8 are inside.
                    unsafe { _mm256_storeu_ps(a.as_mut_ptr().add(8 * j), c) };
                }
            }
        }
    }

    /// Half to single precision, 16 lanes at a time.
    #[target_feature(enable = "avx512f")]
    pub(super) fn widen_avx512(_: Avx512F, src: &[f16], dst: &mut [f32]) {
        assert_eq!(src.len(), dst.len());
        let n = src.len() / 16 * 16;
        for i in (0..n).step_by(16) {
            // SAFETY: i + 16 <= n <= both lengths; `f16` is a transparent u16, so 16 of them
            // are one unaligned 256-bit load.
            unsafe {
                let h = _mm256_loadu_si256(src.as_ptr().add(i).cast());
                _mm512_storeu_ps(dst.as_mut_ptr().add(i), _mm512_cvtph_ps(h));
            }
        }
        for (d, s) in dst[n..].iter_mut().zip(&src[n..]) {
            *d = s.to_f32();
        }
    }

    /// Where interleaved element k (pixel k / 3, channel k % 3) of output vector `j` comes
    /// from: first from R (0..16) or G (16..32) of its pixel group, then B (16..32) is laid
    /// over the blue slots (the others keep their lane).
    const fn interleave_index(j: usize, blue: bool) -> [i32; 16] {
        let mut idx = [0i32; 16];
        let mut lane = 0;
        while lane < 16 {
            let k = 16 * j + lane;
            let (p, c) = ((k / 3) as i32, k % 3);
            idx[lane] = match (blue, c) {
                (false, 0) => p,
                (false, 1) => 16 + p,
                (false, _) => 0,
                (true, 2) => 16 + p,
                (true, _) => lane as i32,
            };
            lane += 1;
        }
        idx
    }

    /// Clamps 16-pixel groups of planar RGB to 0..1 and interleaves them into `out`, with
    /// two permutes per output vector; returns the pixels done (the rest is left to the
    /// caller).
    #[target_feature(enable = "avx512f")]
    pub(super) fn interleave_clamped_avx512(
        _: Avx512F,
        rgb: [&[f32]; 3],
        out: &mut [f32],
    ) -> usize {
        const RG: [[i32; 16]; 3] = [
            interleave_index(0, false),
            interleave_index(1, false),
            interleave_index(2, false),
        ];
        const B: [[i32; 16]; 3] = [
            interleave_index(0, true),
            interleave_index(1, true),
            interleave_index(2, true),
        ];
        let n = (out.len() / 3)
            .min(rgb[0].len())
            .min(rgb[1].len())
            .min(rgb[2].len());
        let groups = n / 16;
        let (zero, one) = (_mm512_setzero_ps(), _mm512_set1_ps(1.0));
        for g in 0..groups {
            let mut v = [zero; 3];
            for (v, plane) in v.iter_mut().zip(rgb) {
                // SAFETY: 16 * g + 16 <= n <= plane.len().
                let x = unsafe { _mm512_loadu_ps(plane.as_ptr().add(16 * g)) };
                // NaN would become 0 here (clamp keeps it); basis and weights are finite.
                *v = _mm512_min_ps(_mm512_max_ps(x, zero), one);
            }
            for j in 0..3 {
                // SAFETY: the index tables are compile-time constants, read by value.
                let (rg, b) = unsafe {
                    (
                        _mm512_loadu_si512(RG[j].as_ptr().cast()),
                        _mm512_loadu_si512(B[j].as_ptr().cast()),
                    )
                };
                let t = _mm512_permutex2var_ps(v[0], rg, v[1]);
                let o = _mm512_permutex2var_ps(t, b, v[2]);
                // SAFETY: 48 * g + 16 * j + 16 <= 3 * n <= out.len().
                unsafe { _mm512_storeu_ps(out.as_mut_ptr().add(48 * g + 16 * j), o) };
            }
        }
        groups * 16
    }

    /// Copies `src` into `dst`, the middle of `dst` (aligned to `LANES` floats) with
    /// `store`, a non-temporal store of `LANES` floats: outputs written once and read much
    /// later should not evict the basis panel. The ends are copied normally (a neighbouring
    /// strip owns the rest of their cache lines). The stores are fenced when `nt`'s scope
    /// ends.
    ///
    /// # Safety
    /// `store(d, s)` must be sound wherever `d` is aligned to `LANES` floats and `LANES`
    /// floats are writable at `d` and readable at `s`.
    #[inline(always)]
    unsafe fn stream_lanes<const LANES: usize>(
        _: &NonTemporal,
        dst: &mut [f32],
        src: &[f32],
        store: impl Fn(*mut f32, *const f32),
    ) {
        let n = dst.len().min(src.len());
        let head = dst.as_ptr().align_offset(4 * LANES).min(n);
        let body = head + (n - head) / LANES * LANES;
        dst[..head].copy_from_slice(&src[..head]);
        for i in (head..body).step_by(LANES) {
            // i + LANES <= body <= n, both slices hold n floats, and `dst + i` is aligned
            // (i - head is a multiple of LANES floats): `store`'s contract holds.
            store(dst[i..].as_mut_ptr(), src[i..].as_ptr());
        }
        dst[body..n].copy_from_slice(&src[body..n]);
    }

    /// [`stream_lanes`] with 16-byte SSE stores (baseline x86-64).
    pub(super) fn stream_copy(nt: &NonTemporal, dst: &mut [f32], src: &[f32]) {
        // SAFETY: `_mm_stream_ps` needs the 16-byte alignment stream_lanes::<4> gives, and 4
        // floats each side, which it guarantees.
        unsafe { stream_lanes::<4>(nt, dst, src, |d, s| _mm_stream_ps(d, _mm_loadu_ps(s))) }
    }

    /// [`stream_lanes`] a whole cache line per store: a quarter of the SSE stores.
    #[target_feature(enable = "avx512f")]
    pub(super) fn stream_copy_avx512(_: Avx512F, nt: &NonTemporal, dst: &mut [f32], src: &[f32]) {
        // SAFETY: `_mm512_stream_ps` needs the 64-byte alignment stream_lanes::<16> gives,
        // and 16 floats each side, which it guarantees; AVX-512F is this function's.
        unsafe { stream_lanes::<16>(nt, dst, src, |d, s| _mm512_stream_ps(d, _mm512_loadu_ps(s))) }
    }
}

/// Converts a half-float panel to f32 (exactly: every half is an f32), with the widest
/// conversion the kernel's CPU level has.
fn widen(kernel: Kernel, src: &[f16], dst: &mut [Row]) {
    let dst = dst.as_flattened_mut();
    match kernel {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the token exists, so the CPU has AVX-512F.
        Kernel::Avx512(t) => unsafe { x86::widen_avx512(t, src, dst) },
        _ => src.convert_to_f32_slice(dst),
    }
}

/// Renders every look of `weights` into its output (interleaved RGB, `pixels * 3` long),
/// converting each linear value with `encode` (sRGB bytes for thumbnails, clamped floats
/// for the gallery's proxy).
pub fn composite<O: Send>(
    basis: &BasisImages,
    weights: &[Vec<[f32; 3]>],
    outputs: &mut [Vec<O>],
    encode: impl Fn(f32) -> O + Sync,
) {
    composite_with(Kernel::detect(), basis, weights, outputs, |rgb, out| {
        for (i, px) in out.chunks_exact_mut(3).enumerate() {
            px[0] = encode(rgb[0][i]);
            px[1] = encode(rgb[1][i]);
            px[2] = encode(rgb[2][i]);
        }
    });
}

/// Renders linear RGB clamped to 0..1 (interleaved), with the clamp fused into the store
/// and non-temporal stores where the CPU has them: the fastest way to get floats out.
pub fn composite_clamped(
    kernel: Kernel,
    basis: &BasisImages,
    weights: &[Vec<[f32; 3]>],
    outputs: &mut [Vec<f32>],
) {
    emit_chunked(
        kernel,
        basis,
        weights,
        outputs,
        CHUNK_LIGHTS,
        |rgb, out, nt| {
            let mut buf = [0.0f32; STRIP * 3];
            let n = out.len() / 3;
            let mut done = 0;
            #[cfg(target_arch = "x86_64")]
            if let Kernel::Avx512(t) = kernel {
                // SAFETY: the token exists, so the CPU has AVX-512F.
                done = unsafe { x86::interleave_clamped_avx512(t, rgb, &mut buf[..n * 3]) };
            }
            for (i, px) in buf[..n * 3].chunks_exact_mut(3).enumerate().skip(done) {
                px[0] = rgb[0][i].clamp(0.0, 1.0);
                px[1] = rgb[1][i].clamp(0.0, 1.0);
                px[2] = rgb[2][i].clamp(0.0, 1.0);
            }
            #[cfg(target_arch = "x86_64")]
            if let Kernel::Avx512(t) = kernel {
                // SAFETY: as above.
                unsafe { x86::stream_copy_avx512(t, nt, out, &buf) };
            } else {
                x86::stream_copy(nt, out, &buf);
            }
            #[cfg(not(target_arch = "x86_64"))]
            {
                let _ = nt;
                out.copy_from_slice(&buf[..out.len()]);
            }
        },
    );
}

/// The batched compositor with an explicit kernel: renders every look of `weights`, and
/// hands each candidate's strip (`[R, G, B]` planes, one value per pixel) to `emit`
/// together with the strip's part of that candidate's output (`3 * pixels` long).
///
/// Panics if an output is not `pixels * 3` long.
pub fn composite_with<O: Send>(
    kernel: Kernel,
    basis: &BasisImages,
    weights: &[Vec<[f32; 3]>],
    outputs: &mut [Vec<O>],
    emit: impl Fn([&[f32]; 3], &mut [O]) + Sync,
) {
    composite_chunked(kernel, basis, weights, outputs, CHUNK_LIGHTS, emit);
}

/// Renders 8-bit sRGB (interleaved), the same bytes as [`composite_with`] and
/// [`encode_srgb8_planar`]. With AVX-512 VBMI the kernel encodes each channel's sums as
/// soon as they are final, straight from its registers, and a block's candidates are
/// interleaved from those code planes: the sums never go through memory.
pub fn composite_srgb8(
    kernel: Kernel,
    basis: &BasisImages,
    weights: &[Vec<[f32; 3]>],
    outputs: &mut [Vec<u8>],
) {
    composite_srgb8_chunked(kernel, basis, weights, outputs, CHUNK_LIGHTS);
}

/// [`composite_srgb8`] with the lights cut into chunks of `chunk` (tests use small ones).
fn composite_srgb8_chunked(
    kernel: Kernel,
    basis: &BasisImages,
    weights: &[Vec<[f32; 3]>],
    outputs: &mut [Vec<u8>],
    chunk: usize,
) {
    #[cfg(target_arch = "x86_64")]
    if let Kernel::Avx512(_) = kernel
        && let Some(vbmi) = crate::color::Vbmi::new()
    {
        return run(kernel, basis, weights, outputs, chunk, |last| {
            let (ch, acc) = (last.ch, &last.sums[last.ch]);
            if ch < 2 {
                // SAFETY: the Vbmi exists, so the CPU has AVX-512 F, BW, VBMI and VBMI2.
                unsafe { x86::codes_avx512(last.call, acc, vbmi, &mut last.codes[ch]) };
            } else {
                let Last {
                    call,
                    codes,
                    outs,
                    local,
                    nt,
                    ..
                } = last;
                // SAFETY: as above.
                unsafe { x86::emit_avx512(call, acc, vbmi, nt, codes, outs, local) };
            }
        });
    }
    composite_chunked(kernel, basis, weights, outputs, chunk, encode_srgb8_planar);
}

/// Lights per chunk of a strip's panel: 64 x 96 floats (24 KB) stay in L1 while every
/// register block runs over them; the sums of a larger rig are carried from chunk to chunk
/// in memory (GEMM's K-blocking; the sums, 4.5 KB a block of 4 candidates, sit in L2).
const CHUNK_LIGHTS: usize = 64;

/// [`composite_with`] with the lights cut into chunks of `chunk` (tests use small ones).
fn composite_chunked<O: Send>(
    kernel: Kernel,
    basis: &BasisImages,
    weights: &[Vec<[f32; 3]>],
    outputs: &mut [Vec<O>],
    chunk: usize,
    emit: impl Fn([&[f32]; 3], &mut [O]) + Sync,
) {
    emit_chunked(kernel, basis, weights, outputs, chunk, |rgb, out, _| {
        emit(rgb, out)
    });
}

/// [`composite_chunked`] whose `emit` may also stream its output (it is handed the task's
/// [`NonTemporal`] scope).
fn emit_chunked<O: Send>(
    kernel: Kernel,
    basis: &BasisImages,
    weights: &[Vec<[f32; 3]>],
    outputs: &mut [Vec<O>],
    chunk: usize,
    emit: impl Fn([&[f32]; 3], &mut [O], &NonTemporal) + Sync,
) {
    run(kernel, basis, weights, outputs, chunk, |last| {
        let ch = last.ch;
        let acc = &mut last.sums[ch];
        kernel.block(last.call, acc);
        // The block's sums are final after its blue: its candidates are emitted now,
        // while the blue sums are still in L1.
        if ch == 2 {
            let len = last.local.len() / 3;
            for (r, out) in last.outs.iter_mut().enumerate() {
                let rgb = std::array::from_fn(|ch| &last.sums[ch][r][..len]);
                emit(rgb, &mut out[last.local.clone()], last.nt);
            }
        }
    });
}

/// A register block's last kernel call for one channel (its sums are final after it),
/// which the render's `finish` makes and turns into output.
struct Last<'a, 'o, O> {
    call: Call<'a>,
    ch: usize,
    /// The block's sums per channel.
    sums: &'a mut [Acc; 3],
    /// For renders that encode in the kernel: the block's red and green code planes (blue
    /// is interleaved with them straight from the registers).
    // Only the x86-64 in-kernel encoding reads them.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    codes: &'a mut [Codes; 2],
    /// The block's candidates' outputs, of which this strip is `local`.
    outs: &'a mut [&'o mut [O]],
    local: std::ops::Range<usize>,
    /// The task's scope for non-temporal stores into `outs` (fenced when the task ends).
    nt: &'a NonTemporal,
}

/// The batched compositor's loop: every call but a block's last of a channel stores its
/// sums; the last is `finish`'s.
fn run<O: Send>(
    kernel: Kernel,
    basis: &BasisImages,
    weights: &[Vec<[f32; 3]>],
    outputs: &mut [Vec<O>],
    chunk: usize,
    finish: impl Fn(Last<'_, '_, O>) + Sync,
) {
    let pixels = basis.pixels();
    assert!(outputs.iter().all(|o| o.len() == pixels * 3));
    assert!(weights.iter().all(|w| w.len() >= basis.images));
    let cands = weights.len().min(outputs.len());
    if cands == 0 || pixels == 0 || basis.images == 0 {
        return;
    }
    let plan = Plan::new(kernel, basis, &weights[..cands], chunk);
    let threads = rayon::current_num_threads().max(1);
    let task_strips = (basis.strips() / (8 * threads)).clamp(1, TASK_STRIPS);
    let task_px = task_strips * STRIP;
    let mut tasks: Vec<Vec<&mut [O]>> = (0..pixels.div_ceil(task_px))
        .map(|_| Vec::with_capacity(cands))
        .collect();
    for out in outputs.iter_mut().take(cands) {
        for (t, chunk) in out.chunks_mut(task_px * 3).enumerate() {
            tasks[t].push(chunk);
        }
    }
    tasks.into_par_iter().enumerate().for_each(|(t, mut outs)| {
        // The task's non-temporal stores are fenced as its scope ends, on its thread, before
        // rayon's join hands the outputs back.
        non_temporal(|nt| {
            SCRATCH.with_borrow_mut(|scratch| {
                scratch.fit(&plan);
                for start in (t * task_px..pixels.min((t + 1) * task_px)).step_by(STRIP) {
                    let local = start - t * task_px;
                    let len = (pixels - start).min(STRIP);
                    plan.strip(
                        start / STRIP,
                        scratch,
                        nt,
                        &mut outs,
                        local * 3..(local + len) * 3,
                        &finish,
                    );
                }
            })
        });
        // A task is at most a millisecond or so: offering the CPU between tasks lets a
        // thread that just woke (the DMX clock) run now rather than when the scheduler's
        // slice ends, which measurably cuts late frames during generates (~1 us per task).
        std::thread::yield_now();
    });
}

/// What every strip of a render shares: the weights packed per register block, and the
/// lights cut into chunks.
struct Plan<'a> {
    kernel: Kernel,
    basis: &'a BasisImages,
    blocks: usize,
    /// Chunks of lights, of near-equal size: 267 lights are 4 chunks of 54 and one of 51,
    /// not 4 of 64 and one of 11 whose per-call overhead would outweigh its work.
    chunks: Vec<std::ops::Range<usize>>,
    /// The longest chunk, in lights.
    size: usize,
    /// Weights per channel and block of MR candidates, `[light][candidate]` (missing
    /// candidates weigh 0).
    packed: Vec<Vec<[f32; MR]>>,
    /// Per channel and block, and per chunk, the lights (numbered within the chunk) that
    /// contribute at all.
    active: Vec<Vec<Vec<u32>>>,
    /// Per channel and chunk, the lights any block reads, when that is not all of them:
    /// only these rows of a half-float chunk are widened (a mover holding many positions
    /// leaves most of its images unread by a few thumbnails).
    read: Vec<Vec<Option<Vec<u32>>>>,
}

impl<'a> Plan<'a> {
    /// The plan for rendering `weights` (one per candidate) from `basis`, the lights cut
    /// into chunks of at most `chunk`.
    fn new(
        kernel: Kernel,
        basis: &'a BasisImages,
        weights: &[Vec<[f32; 3]>],
        chunk: usize,
    ) -> Self {
        let lights = basis.images;
        let blocks = weights.len().div_ceil(MR);
        let size = lights.div_ceil(lights.div_ceil(chunk.max(1)));
        let chunks: Vec<std::ops::Range<usize>> = (0..lights)
            .step_by(size)
            .map(|l| l..(l + size).min(lights))
            .collect();
        let packed: Vec<Vec<[f32; MR]>> = (0..3 * blocks)
            .map(|i| {
                let (ch, blk) = (i / blocks, i % blocks);
                (0..lights)
                    .map(|l| {
                        std::array::from_fn(|r| weights.get(blk * MR + r).map_or(0.0, |w| w[l][ch]))
                    })
                    .collect()
            })
            .collect();
        let active: Vec<Vec<Vec<u32>>> = packed
            .iter()
            .map(|w| {
                chunks
                    .iter()
                    .map(|c| {
                        (0..c.len() as u32)
                            .filter(|&l| w[c.start + l as usize] != [0.0; MR])
                            .collect()
                    })
                    .collect()
            })
            .collect();
        let read = (0..3)
            .map(|ch| {
                chunks
                    .iter()
                    .enumerate()
                    .map(|(k, c)| {
                        let mut any = vec![false; c.len()];
                        for blk in 0..blocks {
                            for &l in &active[ch * blocks + blk][k] {
                                any[l as usize] = true;
                            }
                        }
                        let rows: Vec<u32> =
                            (0..c.len() as u32).filter(|&l| any[l as usize]).collect();
                        (rows.len() < c.len()).then_some(rows)
                    })
                    .collect()
            })
            .collect();
        Plan {
            read,
            kernel,
            basis,
            blocks,
            chunks,
            size,
            packed,
            active,
        }
    }

    /// Renders strip `strip` into the `local` bytes of the outputs (one per candidate).
    fn strip<O>(
        &self,
        strip: usize,
        scratch: &mut Scratch,
        nt: &NonTemporal,
        outs: &mut [&mut [O]],
        local: std::ops::Range<usize>,
        finish: &impl Fn(Last<'_, '_, O>),
    ) {
        let Plan {
            kernel,
            basis,
            blocks,
            ref chunks,
            ..
        } = *self;
        let lights = basis.images;
        let Scratch { panel, sums, codes } = scratch;
        let src = basis.panel(strip);
        // The next strip's panel is prefetched, its lines shared out over this strip's
        // kernel calls.
        let next = match (strip + 1 < basis.strips()).then(|| basis.panel(strip + 1)) {
            Some(Panel::Single(p)) => (p.as_ptr().cast::<u8>(), size_of_val(p)),
            Some(Panel::Half(p)) => (p.as_ptr().cast::<u8>(), size_of_val(p)),
            None => (std::ptr::null(), 0),
        };
        let lines = next.1.div_ceil(64);
        let per_call = lines.div_ceil(blocks * 3 * chunks.len());
        let mut issued = 0;
        for ch in 0..3 {
            for (k, range) in chunks.iter().enumerate() {
                let rows = ch * lights + range.start..ch * lights + range.end;
                // A half-float chunk is widened just before the blocks that read it, so its
                // floats are written to and read from L1. Widening the whole strip first
                // (50 KB at 44 lights) sent them through L2: 3% slower at 44 and 267 lights
                // in same-run measurements.
                let b: &[Row] = match src {
                    Panel::Single(p) => &p.as_chunks().0[rows],
                    Panel::Half(p) => {
                        let dst = &mut Line::rows_mut(panel)[..range.len()];
                        match &self.read[ch][k] {
                            None => widen(kernel, &p[rows.start * STRIP..rows.end * STRIP], dst),
                            Some(read) => {
                                for &l in read {
                                    let at = (rows.start + l as usize) * STRIP;
                                    let row = std::slice::from_mut(&mut dst[l as usize]);
                                    widen(kernel, &p[at..at + STRIP], row);
                                }
                            }
                        }
                        dst
                    }
                };
                for blk in 0..blocks {
                    let i = ch * blocks + blk;
                    let ahead = Ahead {
                        start: next.0.wrapping_add(issued * per_call * 64),
                        lines: per_call.min(lines.saturating_sub(issued * per_call)),
                    };
                    issued += 1;
                    let call = Call {
                        w: &self.packed[i][range.clone()],
                        b,
                        active: &self.active[i][k],
                        add: k > 0,
                        ahead,
                    };
                    if k + 1 < chunks.len() {
                        kernel.block(call, &mut sums[blk][ch]);
                        continue;
                    }
                    let cs = blk * MR..(blk * MR + MR).min(outs.len());
                    finish(Last {
                        call,
                        ch,
                        sums: &mut sums[blk],
                        codes: &mut codes[blk],
                        outs: &mut outs[cs],
                        local: local.clone(),
                        nt,
                    });
                }
            }
        }
    }
}

/// A thread's working memory, kept between renders (allocating and zeroing it per task
/// showed in profiles).
struct Scratch {
    /// One chunk of a panel, widened from half floats.
    panel: Vec<Line>,
    /// Every register block's sums per channel.
    sums: Vec<[Acc; 3]>,
    /// For renders that encode in the kernel: every register block's red and green code
    /// planes, kept until its blue is done (19 KB a strip, in L1).
    codes: Vec<[Codes; 2]>,
}

impl Scratch {
    /// Sizes the buffers for `plan`'s renders.
    fn fit(&mut self, plan: &Plan) {
        self.sums.resize(plan.blocks, [[[0.0; STRIP]; MR]; 3]);
        self.codes.resize(plan.blocks, [[[0; STRIP]; MR]; 2]);
        self.panel.resize(plan.size, Line([0.0; STRIP]));
    }
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = const {
        std::cell::RefCell::new(Scratch {
            panel: Vec::new(),
            sums: Vec::new(),
            codes: Vec::new(),
        })
    };
}

/// `n` zeroed output buffers of `len`, zeroed on all threads (the allocator usually hands
/// back recycled memory, so zeroing is a real memset that showed up in profiles).
pub fn zeroed_outputs<O: Default + Clone + Send>(n: usize, len: usize) -> Vec<Vec<O>> {
    (0..n)
        .into_par_iter()
        .map(|_| vec![O::default(); len])
        .collect()
}

/// Renders looks to 8-bit sRGB images.
pub fn render_srgb8(basis: &BasisImages, looks: &[&Look], gain: f32) -> Vec<image::RgbImage> {
    let w = weights(basis, looks, gain);
    let mut outs = zeroed_outputs(looks.len(), basis.pixels() * 3);
    composite_srgb8(Kernel::detect(), basis, &w, &mut outs);
    outs.into_iter()
        .map(|buf| {
            image::RgbImage::from_raw(basis.width as u32, basis.height as u32, buf)
                .expect("buffer sized width * height * 3 above")
        })
        .collect()
}

/// The scalar reference: one look, one pixel at a time, in the obvious order. Fast paths
/// are tested against it.
pub fn render_reference(basis: &BasisImages, look: &Look, gain: f32) -> Vec<f32> {
    let mut out = vec![0.0f32; basis.pixels() * 3];
    let mut add = |image: usize, m: [f32; 3]| {
        for ch in 0..3 {
            for (p, &v) in basis.plane(ch, image).iter().enumerate() {
                out[p * 3 + ch] += gain * m[ch] * v;
            }
        }
    };
    for (l, (lv, colour)) in look.levels.iter().zip(&basis.colours).enumerate() {
        match basis.emitter_images[l] {
            None => add(basis.image_of(l, lv), colour.multiplier(lv)),
            Some(first) => {
                for (k, level) in colour.solve(lv.color).levels().iter().enumerate() {
                    add(first + k, [*level as f32 * lv.intensity; 3]);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::basis::Precision;
    use visobjd_scene::emitter::ColourModel;
    use visobjd_scene::look::Level;

    /// 7 lights over a 37x11 image (pixels not a multiple of the strip), HDR values up to 4.
    fn planes() -> (usize, usize, usize, Vec<f32>) {
        let (w, h, lights) = (37, 11, 7);
        let planes = (0..3 * lights * w * h)
            .map(|i| ((i * 7919) % 1000) as f32 / 250.0)
            .collect();
        (w, h, lights, planes)
    }

    /// 21 looks: several register blocks, the last one partial;
    /// light 2 off in all but the last.
    fn looks(lights: usize) -> Vec<Look> {
        (0..21)
            .map(|k| Look {
                levels: (0..lights)
                    .map(|l| Level {
                        intensity: if l == 2 && k < 20 {
                            0.0
                        } else {
                            ((k * 31 + l * 17) % 100) as f32 / 100.0
                        },
                        color: [0.9, ((k + l) % 5) as f32 / 5.0, 0.4],
                        position: None,
                    })
                    .collect(),
            })
            .collect()
    }

    /// Checks a kernel with every light in one chunk and with the lights cut into chunks
    /// of 3 (7 lights: a partial last chunk; light 2 contributes in one block only).
    fn check(kernel: Kernel, precision: Precision) {
        for chunk in [CHUNK_LIGHTS, 3] {
            check_chunked(kernel, precision, chunk);
        }
    }

    fn check_chunked(kernel: Kernel, precision: Precision, chunk: usize) {
        let (w, h, lights, planes) = planes();
        let basis = BasisImages::from_planes(w, h, lights, &planes, precision);
        let looks = looks(lights);
        let refs: Vec<&Look> = looks.iter().collect();
        let wts = weights(&basis, &refs, 0.7);
        let mut raw: Vec<Vec<f32>> = looks.iter().map(|_| vec![0.0; w * h * 3]).collect();
        composite_chunked(kernel, &basis, &wts, &mut raw, chunk, |rgb, out| {
            for (i, px) in out.chunks_exact_mut(3).enumerate() {
                px.copy_from_slice(&[rgb[0][i], rgb[1][i], rgb[2][i]]);
            }
        });
        let mut clamped: Vec<Vec<f32>> = looks.iter().map(|_| vec![0.0; w * h * 3]).collect();
        composite_clamped(kernel, &basis, &wts, &mut clamped);
        for (k, look) in looks.iter().enumerate() {
            let want = render_reference(&basis, look, 0.7);
            for (i, &v) in want.iter().enumerate() {
                assert!(
                    (raw[k][i] - v).abs() <= 1e-4 * v.max(1.0),
                    "{kernel:?} {precision:?} chunk {chunk} look {k} sample {i}: {} vs {v}",
                    raw[k][i]
                );
                assert!((clamped[k][i] - v.clamp(0.0, 1.0)).abs() <= 1e-4);
            }
        }
    }

    /// Light 1 (`rgb`) captured per emitter as well: its red, green and blue images are its
    /// white image's R, G and B planes alone, which is what the sRGB primaries it is
    /// modelled with show. Every kernel's preview, mixing them by the solved levels, is the
    /// white-only preview of the same looks.
    #[test]
    fn per_emitter_images_mix_by_the_solved_levels() {
        let (w, h, lights, planes) = planes();
        let pixels = w * h;
        let images = lights + 3;
        let mut more = vec![0.0f32; 3 * images * pixels];
        for ch in 0..3 {
            for i in 0..images {
                let src = if i < lights { i } else { 1 };
                if i < lights || i - lights == ch {
                    let from = (ch * lights + src) * pixels;
                    let to = (ch * images + i) * pixels;
                    more[to..to + pixels].copy_from_slice(&planes[from..from + pixels]);
                }
            }
        }
        let rgb = ColourModel::new(&visobjd_scene::profile::Profile::built_in("rgb").expect("rgb"));
        let mut white = BasisImages::from_planes(w, h, lights, &planes, Precision::Single);
        white.colours[1] = rgb.clone();
        let mut split = BasisImages::from_planes(w, h, images, &more, Precision::Single);
        split.lights = lights;
        split.colours.truncate(lights);
        split.colours[1] = rgb;
        split.emitter_images = vec![None; lights];
        split.emitter_images[1] = Some(lights);
        let looks = looks(lights);
        let refs: Vec<&Look> = looks.iter().collect();
        let wts = weights(&split, &refs, 0.7);
        for (name, kernel) in Kernel::all() {
            let Some(kernel) = kernel else { continue };
            let mut raw: Vec<Vec<f32>> = looks.iter().map(|_| vec![0.0; pixels * 3]).collect();
            composite_with(kernel, &split, &wts, &mut raw, |rgb, out| {
                for (i, px) in out.chunks_exact_mut(3).enumerate() {
                    px.copy_from_slice(&[rgb[0][i], rgb[1][i], rgb[2][i]]);
                }
            });
            for (k, look) in looks.iter().enumerate() {
                let want = render_reference(&white, look, 0.7);
                let reference = render_reference(&split, look, 0.7);
                for (i, &v) in want.iter().enumerate() {
                    for got in [raw[k][i], reference[i]] {
                        assert!(
                            (got - v).abs() <= 1e-4 * v.max(1.0),
                            "{name} look {k} sample {i}: {got} vs {v}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn every_kernel_matches_the_scalar_reference() {
        for (name, kernel) in Kernel::all() {
            let Some(kernel) = kernel else {
                eprintln!("note: {name} does not run on this CPU; its test is skipped");
                continue;
            };
            check(kernel, Precision::Single);
            check(kernel, Precision::Half);
        }
    }

    /// The sRGB encoding inside the AVX-512 kernel (CPUs with VBMI) gives the bytes of the
    /// generic compositor with the planar encoder, with one chunk and several, across the
    /// whole curve (gains from dark to overexposed). Elsewhere `composite_srgb8` is that
    /// generic compositor, so there is nothing to compare.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn srgb8_render_matches_the_planar_encoder() {
        let (Some(t), Some(_)) = (Avx512F::detect(), crate::color::Vbmi::new()) else {
            eprintln!("note: this CPU lacks AVX-512 VBMI; the in-kernel encoding is not tested");
            return;
        };
        let kernel = Kernel::Avx512(t);
        let (w, h, lights, planes) = planes();
        let looks = looks(lights);
        let refs: Vec<&Look> = looks.iter().collect();
        for precision in [Precision::Single, Precision::Half] {
            let basis = BasisImages::from_planes(w, h, lights, &planes, precision);
            for gain in [0.004, 0.05, 0.7] {
                let wts = weights(&basis, &refs, gain);
                for chunk in [CHUNK_LIGHTS, 3] {
                    let mut want = zeroed_outputs(looks.len(), w * h * 3);
                    composite_chunked(kernel, &basis, &wts, &mut want, chunk, encode_srgb8_planar);
                    let mut got = zeroed_outputs(looks.len(), w * h * 3);
                    composite_srgb8_chunked(kernel, &basis, &wts, &mut got, chunk);
                    for (k, (got, want)) in got.iter().zip(&want).enumerate() {
                        if let Some(i) = (0..got.len()).find(|&i| got[i] != want[i]) {
                            panic!(
                                "{precision:?} gain {gain} chunk {chunk} look {k} byte {i}: {} vs {}",
                                got[i], want[i]
                            );
                        }
                    }
                    let distinct = want
                        .iter()
                        .flatten()
                        .collect::<std::collections::BTreeSet<_>>();
                    assert!(
                        distinct.len() > 40,
                        "gain {gain}: only {} codes",
                        distinct.len()
                    );
                }
            }
        }
    }

    #[test]
    fn half_storage_stays_within_half_float_precision_of_single() {
        let (w, h, lights, planes) = planes();
        let single = BasisImages::from_planes(w, h, lights, &planes, Precision::Single);
        let half = BasisImages::from_planes(w, h, lights, &planes, Precision::Half);
        assert_eq!(half.bytes() * 2, single.bytes());
        for look in looks(lights) {
            let a = render_reference(&single, &look, 1.0);
            let b = render_reference(&half, &look, 1.0);
            for (a, b) in a.iter().zip(&b) {
                assert!((a - b).abs() <= 1e-3 * a.max(1.0), "{a} vs {b}");
            }
        }
    }

    /// Four lights over the seven images of [`planes`]: light 1 a mover holding images 1
    /// and 5, light 3 one holding 3, 4 and 6 (a mover's images are not contiguous), light
    /// 2 a mover with one position. Every kernel, with the images in one chunk or cut
    /// into several, renders what the reference does.
    #[test]
    fn movers_weigh_the_image_of_their_position_alone() {
        let (w, h, images, planes) = planes();
        let lights = 4;
        for precision in [Precision::Single, Precision::Half] {
            let mut basis = BasisImages::from_planes(w, h, images, &planes, precision);
            basis.lights = lights;
            basis.colours.truncate(lights);
            basis.emitter_images.truncate(lights);
            basis.positions = vec![Vec::new(); lights];
            basis.positions[1] = vec![(10, 1), (20, 5)];
            basis.positions[3] = vec![(1, 3), (2, 4), (3, 6)];
            basis.positions[2] = vec![(7, 2)];
            let mut looks = looks(lights);
            for (k, look) in looks.iter_mut().enumerate() {
                look.levels[1].position = [None, Some(20), Some(10), Some(99)][k % 4];
                look.levels[3].position = Some(1 + (k as u32 * 7) % 3);
                look.levels[2].position = Some(7);
            }
            looks[5].levels[3].intensity = 0.0;
            let refs: Vec<&Look> = looks.iter().collect();
            let wts = weights(&basis, &refs, 0.7);
            for (name, kernel) in Kernel::all() {
                let Some(kernel) = kernel else { continue };
                for chunk in [CHUNK_LIGHTS, 3, 1] {
                    let mut raw: Vec<Vec<f32>> =
                        looks.iter().map(|_| vec![0.0; w * h * 3]).collect();
                    composite_chunked(kernel, &basis, &wts, &mut raw, chunk, |rgb, out| {
                        for (i, px) in out.chunks_exact_mut(3).enumerate() {
                            px.copy_from_slice(&[rgb[0][i], rgb[1][i], rgb[2][i]]);
                        }
                    });
                    for (k, look) in looks.iter().enumerate() {
                        let want = render_reference(&basis, look, 0.7);
                        for (i, &v) in want.iter().enumerate() {
                            assert!(
                                (raw[k][i] - v).abs() <= 1e-4 * v.max(1.0),
                                "{name} {precision:?} chunk {chunk} look {k} sample {i}: {} vs {v}",
                                raw[k][i]
                            );
                        }
                    }
                }
            }
            // The reference itself takes the position's image: palette 2 puts light 3
            // on image 4.
            let mut alone = Look::off(lights);
            alone.levels[3] = Level {
                intensity: 1.0,
                color: [1.0; 3],
                position: Some(2),
            };
            let got = render_reference(&basis, &alone, 1.0);
            assert_eq!(got[0], basis.plane(0, 4)[0], "image 4's first red sample");
            assert_ne!(basis.plane(0, 4)[0], basis.plane(0, 3)[0]);
        }
    }
}

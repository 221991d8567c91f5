//! The design gallery (paper 4.5): candidates drawn one after another and clustered in a
//! streaming fashion with a falling threshold, so diverse entries appear quickly.
//!
//! Distances are mean per-pixel CIELAB Delta-E (76) between small proxy renders, computed
//! by the same pipeline for candidates and representatives.

use rand::Rng;
use rayon::prelude::*;

use crate::sampler::Plan;
use crate::steer::Steer;
use visobjd_compositor::basis::BasisImages;
use visobjd_compositor::color::linear_to_lab_planar;
#[cfg(target_arch = "x86_64")]
use visobjd_compositor::cpu::{Avx2Fma, Avx512F};
use visobjd_compositor::render::{Kernel, STRIP, composite_with, weights, zeroed_outputs};
use visobjd_scene::look::Look;

/// Width of the proxy renders distances are measured on: "small", as docs/method.md says (the
/// prototype's were 100x100). 96 x 54 on a 16:9 stage has a third fewer pixels to render,
/// convert and compare than 120 px wide, and the gallery phase of a generate takes about
/// two thirds of the time.
pub const PROXY_WIDTH: usize = 96;

/// The largest seed: seeds travel as OSC int32 (a console macro, TouchOSC, `/vo/generated`),
/// so every seed (the daemon's, the offline `gallery`'s, a random one) lies in
/// `0..=MAX_SEED` and any gallery can be replayed live with its seed.
pub const MAX_SEED: u64 = i32::MAX as u64;

/// Starting threshold, in Delta-E units.
pub const START_THRESHOLD: f32 = 20.0;
/// The threshold never falls below this.
pub const MIN_THRESHOLD: f32 = 0.1;
/// Candidates drawn at most, per candidate asked for, before a generate gives up.
pub const DRAWS_PER_CANDIDATE: usize = 20;

/// What happened to an offered candidate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Too close to an entry: rejected, and the threshold fell.
    Rejected,
    /// Kept, as a member of entry `k` (0-based); a new entry if it is its first member.
    Accepted(usize),
}

/// The streaming clustering state (docs/method.md, "Gallery").
#[derive(Debug, Clone)]
pub struct Clustering {
    clusters: usize,
    threshold: f32,
    rejections: u32,
    /// Lab proxies of the representatives, one per entry.
    reps: Vec<Vec<f32>>,
    /// Accepted candidate numbers (0-based, in acceptance order) per entry, representative first.
    entries: Vec<Vec<usize>>,
    accepted: usize,
}

impl Clustering {
    /// At most `clusters` entries.
    pub fn new(clusters: usize) -> Clustering {
        Clustering {
            clusters: clusters.max(1),
            threshold: START_THRESHOLD,
            rejections: 0,
            reps: Vec::new(),
            entries: Vec::new(),
            accepted: 0,
        }
    }

    /// Offers the next candidate's Lab proxy. A candidate closer than the threshold to the
    /// nearest representative is rejected and lowers the threshold to
    /// 20 / (1 + 0.1 * rejections); otherwise it is accepted: as a new entry while fewer
    /// than `clusters` exist, else as a member of its nearest entry.
    pub fn offer(&mut self, lab: &[f32]) -> Decision {
        let distances: Vec<f32> = self.reps.iter().map(|r| mean_delta_e(r, lab)).collect();
        self.offer_measured(lab, &distances)
    }

    /// [`Clustering::offer`] with the distances to the first representatives already
    /// measured (`known[k]` to entry k), so a batch can measure them in parallel; the rest
    /// are measured here.
    fn offer_measured(&mut self, lab: &[f32], known: &[f32]) -> Decision {
        let nearest = known
            .iter()
            .copied()
            .chain(
                self.reps[known.len()..]
                    .iter()
                    .map(|r| mean_delta_e(r, lab)),
            )
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((_, d)) = nearest
            && d < self.threshold
        {
            self.rejections += 1;
            self.threshold =
                (START_THRESHOLD / (1.0 + 0.1 * self.rejections as f32)).max(MIN_THRESHOLD);
            return Decision::Rejected;
        }
        let n = self.accepted;
        self.accepted += 1;
        match nearest {
            Some((k, _)) if self.reps.len() >= self.clusters => {
                self.entries[k].push(n);
                Decision::Accepted(k)
            }
            _ => {
                self.reps.push(lab.to_vec());
                self.entries.push(vec![n]);
                Decision::Accepted(self.entries.len() - 1)
            }
        }
    }

    /// Candidates accepted so far.
    pub fn accepted(&self) -> usize {
        self.accepted
    }

    /// The current threshold.
    pub fn threshold(&self) -> f32 {
        self.threshold
    }

    /// Accepted candidate numbers per entry, representative first.
    pub fn entries(&self) -> &[Vec<usize>] {
        &self.entries
    }
}

/// Mean per-pixel Delta-E 76 between two Lab proxies from [`lab_proxies`].
///
/// The sum runs in 16 fixed lanes, so it vectorises and gives the same value on every CPU.
pub fn mean_delta_e(a: &[f32], b: &[f32]) -> f32 {
    #[cfg(target_arch = "x86_64")]
    if let Some(t) = Avx512F::detect() {
        // SAFETY: the token exists, so the CPU has AVX-512F.
        return unsafe { mean_delta_e_avx512(t, a, b) };
    } else if let Some(t) = Avx2Fma::detect() {
        // SAFETY: the token exists, so the CPU has AVX2.
        return unsafe { mean_delta_e_avx2(t, a, b) };
    }
    mean_delta_e_lanes(a, b)
}

/// The token is the caller's proof of the feature.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn mean_delta_e_avx512(_: Avx512F, a: &[f32], b: &[f32]) -> f32 {
    mean_delta_e_lanes(a, b)
}

/// The token (AVX2 with FMA, which every AVX2 CPU has) is the caller's proof of AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn mean_delta_e_avx2(_: Avx2Fma, a: &[f32], b: &[f32]) -> f32 {
    mean_delta_e_lanes(a, b)
}

#[inline(always)]
fn mean_delta_e_lanes(a: &[f32], b: &[f32]) -> f32 {
    const LANES: usize = 16;
    let mut lanes = [0.0f32; LANES];
    let mut n = 0;
    for (p, q) in a.chunks(3 * STRIP).zip(b.chunks(3 * STRIP)) {
        let len = p.len().min(q.len()) / 3;
        n += len;
        let (pl, pa, pb) = (&p[..len], &p[len..2 * len], &p[2 * len..3 * len]);
        let (ql, qa, qb) = (&q[..len], &q[len..2 * len], &q[2 * len..3 * len]);
        let de = |pl: f32, pa: f32, pb: f32, ql: f32, qa: f32, qb: f32| {
            let (dl, da, db) = (pl - ql, pa - qa, pb - qb);
            (dl * dl + da * da + db * db).sqrt()
        };
        // Whole groups of 16 as fixed-size arrays, so the compiler sees no bounds to check.
        let (cl, ca, cb) = (
            pl.as_chunks::<LANES>(),
            pa.as_chunks::<LANES>(),
            pb.as_chunks::<LANES>(),
        );
        let (dl, da, db) = (
            ql.as_chunks::<LANES>(),
            qa.as_chunks::<LANES>(),
            qb.as_chunks::<LANES>(),
        );
        for (((((x, y), z), u), v), w) in
            cl.0.iter()
                .zip(ca.0)
                .zip(cb.0)
                .zip(dl.0)
                .zip(da.0)
                .zip(db.0)
        {
            for k in 0..LANES {
                lanes[k] += de(x[k], y[k], z[k], u[k], v[k], w[k]);
            }
        }
        let tails =
            cl.1.iter()
                .zip(ca.1)
                .zip(cb.1)
                .zip(dl.1)
                .zip(da.1)
                .zip(db.1);
        for ((((((x, y), z), u), v), w), lane) in tails.zip(&mut lanes) {
            *lane += de(*x, *y, *z, *u, *v, *w);
        }
    }
    lanes.iter().sum::<f32>() / n.max(1) as f32
}

/// Renders looks at proxy size and converts to Lab: what distances are measured on. The
/// layout is the compositor's: per strip of [`STRIP`] pixels, the strip's L, a and b planes.
pub fn lab_proxies(proxy: &BasisImages, looks: &[&Look], gain: f32) -> Vec<Vec<f32>> {
    let w = weights(proxy, looks, gain);
    let mut outs = zeroed_outputs(looks.len(), proxy.pixels() * 3);
    composite_with(Kernel::detect(), proxy, &w, &mut outs, linear_to_lab_planar);
    outs
}

/// The outcome of a generate.
#[derive(Debug, Clone)]
pub struct Generation {
    /// Accepted candidates in acceptance order (candidate index = position).
    pub candidates: Vec<Look>,
    /// Candidate indices per entry, representative first.
    pub entries: Vec<Vec<usize>>,
    /// Threshold when it finished.
    pub threshold: f32,
    /// Candidates drawn, kept or rejected.
    pub draws: usize,
    /// True if the draw bound ran out before `count` candidates were accepted.
    pub exhausted: bool,
    /// Candidates the preference model turned down (0 unless steered).
    pub turned_down: usize,
    /// Colour-only objectives (indices in request order) that took their reference's
    /// intensity too, the base leaving their lights dark ([`Plan::lit_for_color`]).
    pub lit_for_color: Vec<usize>,
    /// Thumbnails of the representatives, one per entry, so the gallery can be shown as
    /// soon as it exists (filled by [`crate::stage::Stage::generate`]; members' thumbnails
    /// are rendered on demand with [`crate::stage::Stage::thumbnails`]).
    /// Shared and never changed once made, so a reader (the web gallery) takes them
    /// without copying and without holding the session.
    pub thumbnails: std::sync::Arc<[image::RgbImage]>,
}

impl Generation {
    /// What a user should be told about this gallery besides its size, one sentence each:
    /// colour-only objectives that had to set intensity too, and a gallery with no light in
    /// it. `objectives` are the request's, in its order.
    pub fn notes(&self, objectives: &[crate::objective::Objective]) -> Vec<String> {
        let mut notes: Vec<String> = self
            .lit_for_color
            .iter()
            .filter_map(|&i| objectives.get(i))
            .map(|o| {
                format!(
                    "{} asks for colour only, and the base look leaves the lights it colours dark: \
                     their intensity follows the reference too (give them a level first to keep \
                     your own, or set its aspects to both)",
                    o.image
                )
            })
            .collect();
        let dark = |look: &Look| look.levels.iter().all(|l| l.intensity <= 0.0);
        if self.candidates.iter().all(dark) {
            notes.push(
                "every candidate is dark: the objectives reach no light they may raise (each is \
                 locked, held off or outside every region); unlock a group, widen a region or \
                 give the base look some light"
                    .into(),
            );
        }
        notes
    }
}

/// Candidates are sampled and proxied in batches of at most this many; the decisions are
/// still taken one by one in draw order, so the result is that of a pure stream.
const BATCH: usize = 64;

/// How many candidates a generate accepts and how many entries it makes at most.
#[derive(Debug, Clone, Copy)]
pub struct Size {
    /// Candidates to accept (N).
    pub count: usize,
    /// Entries at most (c).
    pub clusters: usize,
}

/// Draws candidates from `plan` until `size.count` are accepted into at most
/// `size.clusters` entries (or `count * DRAWS_PER_CANDIDATE` draws), measuring distances on
/// `proxy`; and runs `reps` on the entries' representatives in parallel with the rest of
/// the drawing. Representatives never change once chosen (they are the first `clusters`
/// candidates accepted), so their thumbnails can be rendered while the remaining candidates
/// are still being decided: a 44-light generate takes about 5-10% less time. If fewer
/// entries form, `reps` runs at the end.
///
/// `progress` is told how much of the drawing is done (0..=1), from work done, never from a
/// clock, so a seed and inputs give the same sequence every time: before each batch is
/// drawn, the larger of the share of candidates accepted and the share of draws allowed
/// used, and 1 once the drawing ends (`reps` may still be running then). It is called on
/// whichever thread draws, never concurrently, at most once a batch.
#[allow(clippy::too_many_arguments)]
pub fn generate<T: Send>(
    plan: &Plan,
    base: &Look,
    proxy: &BasisImages,
    gain: f32,
    size: Size,
    rng: &mut (impl Rng + Send),
    steering: Option<(&mut Steer, &[bool])>,
    reps: impl FnOnce(&[&Look]) -> T + Send,
    progress: &mut (dyn FnMut(f32) + Send),
) -> (Generation, T) {
    let mut drawing = Drawing {
        plan,
        base,
        steering,
        proxy,
        gain,
        count: size.count,
        max_draws: size.count * DRAWS_PER_CANDIDATE,
        clustering: Clustering::new(size.clusters),
        candidates: Vec::with_capacity(size.count),
        draws: 0,
        batch: Batch::default(),
        rng,
        progress,
    };
    let clusters = drawing.clustering.clusters;
    while drawing.clustering.entries.len() < clusters && drawing.decide_next() {}
    let chosen: Vec<Look> = drawing
        .clustering
        .entries
        .iter()
        .map(|e| drawing.candidates[e[0]].clone())
        .collect();
    let (out, ()) = rayon::join(
        || reps(&chosen.iter().collect::<Vec<_>>()),
        || {
            while drawing.decide_next() {}
            (drawing.progress)(1.0);
        },
    );
    let Drawing {
        clustering,
        candidates,
        draws,
        steering,
        ..
    } = drawing;
    let generation = Generation {
        turned_down: steering.map_or(0, |(s, _)| s.turned_down()),
        exhausted: candidates.len() < size.count,
        lit_for_color: plan.lit_for_color().to_vec(),
        candidates,
        entries: clustering.entries().to_vec(),
        threshold: clustering.threshold(),
        draws,
        thumbnails: std::sync::Arc::new([]),
    };
    (generation, out)
}

/// A generate's drawing in progress: candidates are sampled and proxied a batch at a time,
/// and decided one by one in draw order.
struct Drawing<'a, R> {
    plan: &'a Plan,
    base: &'a Look,
    /// The steering by ratings, and the lights the constraints keep.
    steering: Option<(&'a mut Steer, &'a [bool])>,
    proxy: &'a BasisImages,
    gain: f32,
    count: usize,
    max_draws: usize,
    clustering: Clustering,
    candidates: Vec<Look>,
    draws: usize,
    batch: Batch,
    rng: &'a mut R,
    progress: &'a mut (dyn FnMut(f32) + Send),
}

/// The batch being decided: its looks not yet decided, and every look's Lab proxy and
/// distances to the representatives known when it was measured.
#[derive(Default)]
struct Batch {
    looks: std::vec::IntoIter<Look>,
    labs: Vec<Vec<f32>>,
    known: Vec<Vec<f32>>,
}

impl<R: Rng> Drawing<'_, R> {
    /// Decides the next candidate, drawing a new batch when the last is used up. False once
    /// `count` are accepted or the draws ran out (the rest of a batch is then dropped).
    fn decide_next(&mut self) -> bool {
        if self.candidates.len() >= self.count {
            return false;
        }
        if self.batch.looks.len() == 0 {
            if self.draws >= self.max_draws {
                return false;
            }
            self.draw_batch();
        }
        // The look's place in its batch: how many were decided before it.
        let i = self.batch.labs.len() - self.batch.looks.len();
        let Some(look) = self.batch.looks.next() else {
            return false;
        };
        let Batch { labs, known, .. } = &mut self.batch;
        self.draws += 1;
        let entries = self.clustering.entries.len();
        let decision = self.clustering.offer_measured(&labs[i], &known[i]);
        if self.clustering.entries.len() > entries {
            // The rest of the batch is measured against the new representative at once, in
            // parallel.
            let rep = &self.clustering.reps[entries];
            known[i + 1..]
                .par_iter_mut()
                .zip(&labs[i + 1..])
                .for_each(|(d, lab)| d.push(mean_delta_e(rep, lab)));
        }
        if decision != Decision::Rejected {
            self.candidates.push(look);
        }
        true
    }

    /// How much of the drawing is done: the share of the candidates accepted or of the
    /// draws allowed, whichever is further (a generate ends at either bound).
    fn done(&self) -> f32 {
        let accepted = self.candidates.len() as f32 / self.count.max(1) as f32;
        let drawn = self.draws as f32 / self.max_draws.max(1) as f32;
        accepted.max(drawn).min(1.0)
    }

    /// Samples the next batch, renders its Lab proxies and measures its distances to every
    /// representative that exists now, in parallel; reports the work done before it.
    fn draw_batch(&mut self) {
        let done = self.done();
        (self.progress)(done);
        let want = (self.count - self.candidates.len())
            .clamp(1, BATCH)
            .min(self.max_draws - self.draws);
        let (plan, base) = (self.plan, self.base);
        let looks: Vec<Look> = (0..want)
            .map(|_| match &mut self.steering {
                Some((steer, kept)) => steer.draw(self.rng, kept, |r| plan.sample(base, r)),
                None => plan.sample(base, self.rng),
            })
            .collect();
        let refs: Vec<&Look> = looks.iter().collect();
        let labs = lab_proxies(self.proxy, &refs, self.gain);
        let reps = &self.clustering.reps;
        let known = labs
            .par_iter()
            .map(|lab| reps.iter().map(|r| mean_delta_e(r, lab)).collect())
            .collect();
        self.batch = Batch {
            looks: looks.into_iter(),
            labs,
            known,
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A proxy of `pixels` pixels with Lab values spread over -100..100.
    fn proxy(pixels: usize, seed: u64) -> Vec<f32> {
        let mut s = seed;
        (0..3 * pixels)
            .map(|_| {
                s = s
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                (s >> 40) as f32 / (1u64 << 24) as f32 * 200.0 - 100.0
            })
            .collect()
    }

    #[test]
    fn mean_delta_e_matches_an_f64_reference_and_every_path() {
        // Whole strips, a partial last strip, and groups that are not whole 16s.
        for pixels in [0, 1, 17, STRIP, 8160, 8160 + 37] {
            let (a, b) = (proxy(pixels, 1), proxy(pixels, 2));
            let mut sum = 0.0f64;
            for (p, q) in a.chunks(3 * STRIP).zip(b.chunks(3 * STRIP)) {
                let len = p.len() / 3;
                for i in 0..len {
                    let d = |k: usize| p[k * len + i] as f64 - q[k * len + i] as f64;
                    sum += (d(0).powi(2) + d(1).powi(2) + d(2).powi(2)).sqrt();
                }
            }
            let want = sum / pixels.max(1) as f64;
            let got = mean_delta_e(&a, &b);
            assert!(
                (got as f64 - want).abs() <= 1e-5 * want,
                "{pixels} pixels: {got} vs {want}"
            );
            // The same value on every CPU.
            assert_eq!(got.to_bits(), mean_delta_e_lanes(&a, &b).to_bits());
            #[cfg(target_arch = "x86_64")]
            match Avx2Fma::detect() {
                Some(t) => {
                    // SAFETY: the token exists, so the CPU has AVX2.
                    let avx2 = unsafe { mean_delta_e_avx2(t, &a, &b) };
                    assert_eq!(got.to_bits(), avx2.to_bits());
                }
                None => eprintln!("note: this CPU lacks AVX2; its path is not compared"),
            }
            assert_eq!(mean_delta_e(&a, &a), 0.0);
        }
    }
}

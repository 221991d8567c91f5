//! The design gallery (paper 4.5): candidates drawn one after another and clustered in a
//! streaming fashion with a falling threshold, so diverse entries appear quickly.
//!
//! Distances are mean per-pixel CIELAB Delta-E (76) between small proxy renders, computed
//! by the same pipeline for candidates and representatives.

use rand::Rng;

use crate::basis::BasisImages;
use crate::color::linear_to_lab;
use crate::look::Look;
use crate::render::{composite, weights};
use crate::sampler::Plan;

/// Width of the proxy renders distances are measured on.
pub const PROXY_WIDTH: usize = 120;
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

/// The streaming clustering state (algorithm.md, "Gallery").
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
        let nearest = self
            .reps
            .iter()
            .map(|r| mean_delta_e(r, lab))
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

/// Mean per-pixel Delta-E 76 between two Lab images (interleaved L, a, b).
pub fn mean_delta_e(a: &[f32], b: &[f32]) -> f32 {
    let n = (a.len() / 3).max(1);
    let sum: f32 = a
        .chunks_exact(3)
        .zip(b.chunks_exact(3))
        .map(|(p, q)| {
            let (dl, da, db) = (p[0] - q[0], p[1] - q[1], p[2] - q[2]);
            (dl * dl + da * da + db * db).sqrt()
        })
        .sum();
    sum / n as f32
}

/// Renders looks at proxy size and converts to Lab: what distances are measured on.
pub fn lab_proxies(proxy: &BasisImages, looks: &[&Look], gain: f32) -> Vec<Vec<f32>> {
    let w = weights(looks, gain);
    let mut outs: Vec<Vec<f32>> = looks
        .iter()
        .map(|_| vec![0.0; proxy.pixels() * 3])
        .collect();
    composite(proxy, &w, &mut outs, |v| v.clamp(0.0, 1.0));
    for out in &mut outs {
        for px in out.chunks_exact_mut(3) {
            let lab = linear_to_lab([px[0], px[1], px[2]]);
            px.copy_from_slice(&lab);
        }
    }
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
}

/// Candidates are sampled and proxied in batches of at most this many; the decisions are
/// still taken one by one in draw order, so the result is that of a pure stream.
const BATCH: usize = 64;

/// Draws candidates from `plan` until `count` are accepted into at most `clusters` entries
/// (or `count * DRAWS_PER_CANDIDATE` draws), measuring distances on `proxy`.
pub fn generate(
    plan: &Plan,
    base: &Look,
    proxy: &BasisImages,
    gain: f32,
    count: usize,
    clusters: usize,
    rng: &mut impl Rng,
) -> Generation {
    let mut clustering = Clustering::new(clusters);
    let mut candidates = Vec::with_capacity(count);
    let max_draws = count * DRAWS_PER_CANDIDATE;
    let mut draws = 0;
    while candidates.len() < count && draws < max_draws {
        let want = (count - candidates.len())
            .clamp(1, BATCH)
            .min(max_draws - draws);
        let batch: Vec<Look> = (0..want).map(|_| plan.sample(base, rng)).collect();
        let refs: Vec<&Look> = batch.iter().collect();
        let labs = lab_proxies(proxy, &refs, gain);
        for (look, lab) in batch.into_iter().zip(labs) {
            draws += 1;
            if clustering.offer(&lab) != Decision::Rejected {
                candidates.push(look);
                if candidates.len() == count {
                    break;
                }
            }
        }
    }
    Generation {
        exhausted: candidates.len() < count,
        candidates,
        entries: clustering.entries().to_vec(),
        threshold: clustering.threshold(),
        draws,
    }
}

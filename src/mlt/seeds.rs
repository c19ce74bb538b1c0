//! Seeds and normalisation: from the bootstrap's weighted candidates to each chain's seed, the
//! normalisation b, and how large the bootstrap must be.
//!
//! Input: per group (the path depth k in MMLT; one group in PSSMLT) one weight per bootstrap
//! sample, zeros included: the luminance of the sample's contribution (in MMLT, of its
//! MIS-weighted connections of that depth). A negative, NaN or infinite weight counts as 0 everywhere here.
//!
//! # Bootstrap size
//!
//! b_k is the mean weight of group k, estimated from N_k samples with sample variance s_k^2, so
//! b = sum_k b_k has the relative standard error
//!
//! ```text
//!     r_b = sqrt(sum_k s_k^2 / N_k) / b        (one group: r_b = (s / b) / sqrt(N)).
//! ```
//!
//! It is a scale error on the whole image that no number of mutations reduces. The image's own
//! noise at M mutations per pixel: the chains deposit one unit of target per mutation, spread
//! in proportion to luminance, so a pixel of average luminance receives the equivalent of M
//! unit deposits, and its relative standard error is about 1 / sqrt(M) when successive states
//! are independent (correlated chains have fewer effective samples and more noise, so this is
//! the smallest image noise to expect). Keeping b's error a fraction kappa of it,
//!
//! ```text
//!     r_b <= kappa / sqrt(M)   <=>   N >= M (s / b)^2 / kappa^2     (one group),
//!     N_k >= M sum_j s_j^2 / (kappa^2 b^2)                         (groups of equal N),
//! ```
//!
//! the bootstrap grows linearly with the mutations per pixel, with the squared coefficient of
//! variation of one bootstrap weight as the constant. kappa = `BOOTSTRAP_NOISE_FRACTION` = 1/2:
//! the squared scale error is then at most a quarter of an average pixel's variance (MSE up by
//! at most 25%). E.g. pbrt-v4's defaults, M = 100 and N = 100000 per depth, suffice while
//! s / b <= 15.8. The sample variance of a heavy-tailed weight is itself noisy and low until
//! the rare large weights are seen, hence a floor of `MIN_BOOTSTRAP_SAMPLES` per group.
//! (Separately, keep at least ~16 non-zero candidates per chain, or chains duplicate seeds.)

use super::chains::ChainStates;
use crate::sampling::{SampleKey, mix64};

/// kappa: b's relative standard error is kept below this fraction of the image's.
pub const BOOTSTRAP_NOISE_FRACTION: f64 = 0.5;
/// No verdict on the bootstrap size from fewer samples per group than this.
pub const MIN_BOOTSTRAP_SAMPLES: usize = 1024;

/// Separates the resampling offsets from every other use of the seed.
const SEED_DOMAIN: u64 = 0x6d6c_745f_7365_6564;

/// A weight as the seed selection uses it: non-negative and finite, else 0.
#[inline]
pub fn usable_weight(w: f32) -> f64 {
    if w.is_finite() && w > 0.0 {
        w as f64
    } else {
        0.0
    }
}

/// b_k: the mean weight per bootstrap sample of one group (0 for an empty group).
pub fn group_normalisation(weights: &[f32]) -> f64 {
    if weights.is_empty() {
        return 0.0;
    }
    weights.iter().map(|&w| usable_weight(w)).sum::<f64>() / weights.len() as f64
}

/// Splits `total` items among groups in proportion to `shares` by largest remainder: each group
/// gets the floor of its quota, and the items left go to the largest fractional parts (ties to
/// the lower index). Deterministic, sums to `total`, within 1 of proportional, unlike
/// multinomial draws whose per-group error is a scale error per depth that mutations never
/// remove. A group with a positive share but a quota under 1 still gets one item when there
/// are enough (else its whole contribution would be missing from the image), taken from the
/// group with the most items above its quota. All zero (or empty) shares: all zero.
pub fn allocate_largest_remainder(shares: &[f64], total: usize, out: &mut Vec<usize>) {
    out.clear();
    let share = |s: f64| if s.is_finite() && s > 0.0 { s } else { 0.0 };
    let sum: f64 = shares.iter().map(|&s| share(s)).sum();
    if sum <= 0.0 {
        out.resize(shares.len(), 0);
        return;
    }
    let quota: Vec<f64> = shares
        .iter()
        .map(|&s| share(s) / sum * total as f64)
        .collect();
    out.extend(quota.iter().map(|&q| (q.floor() as usize).min(total)));
    let given: usize = out.iter().sum();
    let mut order: Vec<usize> = (0..shares.len()).collect();
    // Largest fractional part first; stable, so ties keep index order.
    order.sort_by(|&a, &b| {
        let fa = quota[a] - quota[a].floor();
        let fb = quota[b] - quota[b].floor();
        fb.total_cmp(&fa)
    });
    for &g in order.iter().take(total.saturating_sub(given)) {
        out[g] += 1;
    }
    let positive = quota.iter().filter(|&&q| q > 0.0).count();
    if positive <= total {
        for g in 0..shares.len() {
            if quota[g] > 0.0 && out[g] == 0 {
                let donor = (0..shares.len())
                    .filter(|&d| out[d] >= 2)
                    .max_by(|&a, &b| {
                        (out[a] as f64 - quota[a]).total_cmp(&(out[b] as f64 - quota[b]))
                    })
                    .expect("a group with two items exists while groups <= items");
                out[donor] -= 1;
                out[g] = 1;
            }
        }
    }
}

/// Systematic (stratified) resampling: appends to `out` the indices of `count` candidates drawn
/// in proportion to `weights`, at positions (j + offset) / count of the total weight for
/// j = 0..count, `offset` in [0, 1). Candidate i is picked floor or ceil of count w_i / W
/// times (never a zero-weight one); indices come out non-decreasing. Nothing if W = 0.
pub fn resample_stratified(weights: &[f32], count: usize, offset: f64, out: &mut Vec<u32>) {
    let total: f64 = weights.iter().map(|&w| usable_weight(w)).sum();
    if total <= 0.0 || count == 0 {
        return;
    }
    let last_positive = weights
        .iter()
        .rposition(|&w| usable_weight(w) > 0.0)
        .expect("a positive weight");
    let (mut i, mut below) = (0usize, 0.0f64);
    for j in 0..count {
        let position = (j as f64 + offset) / count as f64 * total;
        // Skip candidates whose range [below, below + w) ends at or before the position.
        while i < last_positive && below + usable_weight(weights[i]) <= position {
            below += usable_weight(weights[i]);
            i += 1;
        }
        out.push(i as u32);
    }
}

/// Where each chain starts: its group and its candidate (index into its group's weights),
/// chains of a group consecutive, groups in order.
#[derive(Clone, Debug, PartialEq)]
pub struct SeedSelection {
    /// b_k per group.
    pub normalisation: Vec<f64>,
    pub chains_per_group: Vec<usize>,
    pub group: Vec<u32>,
    pub candidate: Vec<u32>,
}

impl SeedSelection {
    /// b = sum_k b_k: the image's mean target (luminance) per pixel.
    pub fn total_normalisation(&self) -> f64 {
        self.normalisation.iter().sum()
    }

    /// Per group, the number of distinct seeds its chains start from. Far fewer seeds than
    /// chains means correlated chains (they start on the same path): a sign that the
    /// bootstrap found little light, or that one heavy evaluation took a group's whole share.
    pub fn distinct_seeds(&self) -> Vec<usize> {
        let mut pairs: Vec<(u32, u32)> = self
            .group
            .iter()
            .copied()
            .zip(self.candidate.iter().copied())
            .collect();
        pairs.sort_unstable();
        pairs.dedup();
        let mut seeds = vec![0; self.chains_per_group.len()];
        for (g, _) in pairs {
            seeds[g as usize] += 1;
        }
        seeds
    }

    /// The factor on every splat of group `group`'s chains: 1 / chains_k. With it, group k's
    /// splat sums x pixels / steps per chain are its image in units of b_k (each step deposits
    /// one unit of target per group in all), which `Normalisation` scales at the end.
    pub fn splat_scale(&self, group: usize) -> f64 {
        match self.chains_per_group[group] {
            0 => 0.0,
            n => 1.0 / n as f64,
        }
    }

    /// Writes each chain's group and splat scale. (Replaying the seeds' vectors into
    /// `chains.current` and evaluating them is the renderer's part.)
    pub fn apply(&self, chains: &mut ChainStates) {
        assert_eq!(chains.chains(), self.group.len(), "one seed per chain");
        for (i, &g) in self.group.iter().enumerate() {
            chains.group[i] = g;
            chains.splat_scale[i] = self.splat_scale(g as usize) as f32;
        }
    }
}

/// The running estimate of every b_k: the mean target of group k over its bootstrap
/// evaluations and over every large step its chains have proposed since (a large step is a
/// fresh uniform vector, so its target is one more independent sample of b_k: Kelemen et
/// al.'s estimator). The image is scaled by it when it is developed, so one heavy bootstrap
/// evaluation is averaged away as the render goes on instead of frozen into the image.
/// Sums are f64 added in chain order, so the estimate is the same for any thread count.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Normalisation {
    /// Per group, the sum of the usable targets seen.
    pub sums: Vec<f64>,
    /// Per group, how many targets were seen (zeros included).
    pub counts: Vec<u64>,
    /// How many of them were large steps.
    pub large_steps: u64,
}

impl Normalisation {
    /// The estimate from the bootstrap's weights alone.
    pub fn from_bootstrap(groups: &[&[f32]]) -> Normalisation {
        Normalisation {
            sums: groups
                .iter()
                .map(|w| w.iter().map(|&x| usable_weight(x)).sum())
                .collect(),
            counts: groups.iter().map(|w| w.len() as u64).collect(),
            large_steps: 0,
        }
    }

    /// Adds the targets of one step's large steps, per group: `(sum, count)` each.
    pub fn add_large_steps(&mut self, per_group: &[(f64, u64)]) {
        for (g, &(sum, count)) in per_group.iter().enumerate() {
            self.sums[g] += sum;
            self.counts[g] += count;
            self.large_steps += count;
        }
    }

    /// b_k (0 for a group with no samples).
    pub fn group(&self, group: usize) -> f64 {
        match self.counts[group] {
            0 => 0.0,
            n => self.sums[group] / n as f64,
        }
    }

    /// b = sum of b_k.
    pub fn total(&self) -> f64 {
        (0..self.sums.len()).map(|g| self.group(g)).sum()
    }
}

/// Seeds for `chains` chains from the bootstrap's groups: b_k per group, chains per group in
/// proportion to b_k by largest remainder, and within a group stratified resampling by weight
/// with one offset per group from the hash of (seed, group). None when every weight is 0.
pub fn select_seeds(groups: &[&[f32]], chains: usize, seed: u64) -> Option<SeedSelection> {
    let normalisation: Vec<f64> = groups.iter().map(|w| group_normalisation(w)).collect();
    if normalisation.iter().sum::<f64>() <= 0.0 {
        return None;
    }
    let mut chains_per_group = Vec::new();
    allocate_largest_remainder(&normalisation, chains, &mut chains_per_group);
    let (mut group, mut candidate) = (Vec::with_capacity(chains), Vec::with_capacity(chains));
    let key_seed = mix64(seed ^ SEED_DOMAIN);
    for (g, (&weights, &n)) in groups.iter().zip(&chains_per_group).enumerate() {
        let offset = SampleKey::new(key_seed, g as u64, 0).get(0) as f64;
        resample_stratified(weights, n, offset, &mut candidate);
        group.resize(candidate.len(), g as u32);
    }
    Some(SeedSelection {
        normalisation,
        chains_per_group,
        group,
        candidate,
    })
}

/// b and its relative standard error from the bootstrap's weights so far.
#[derive(Clone, Debug, PartialEq)]
pub struct BootstrapError {
    /// b = sum_k b_k.
    pub normalisation: f64,
    /// r_b = sqrt(sum_k s_k^2 / N_k) / b (infinite while b = 0).
    pub relative_standard_error: f64,
    /// sum_k s_k^2, the per-sample variances (for the samples still needed).
    pub variance_sum: f64,
    /// The fewest samples of any group.
    pub min_samples: usize,
}

/// b's estimate and relative standard error (see the module docs).
pub fn bootstrap_error(groups: &[&[f32]]) -> BootstrapError {
    use rayon::prelude::*;
    // Each group's mean and variance in parallel (each summed in order, so the same bits
    // for any thread count), combined in group order: the automatic bootstrap computes
    // this after every wave over every weight so far.
    let stats: Vec<(usize, f64, f64)> = groups
        .par_iter()
        .with_max_len(1)
        .map(|weights| {
            let n = weights.len();
            if n == 0 {
                return (0, 0.0, 0.0);
            }
            let mean = group_normalisation(weights);
            let variance = if n > 1 {
                weights
                    .iter()
                    .map(|&w| (usable_weight(w) - mean).powi(2))
                    .sum::<f64>()
                    / (n - 1) as f64
            } else {
                0.0
            };
            (n, mean, variance)
        })
        .collect();
    let (mut b, mut var_of_mean, mut variance_sum) = (0.0, 0.0, 0.0);
    let mut min_samples = usize::MAX;
    for (n, mean, variance) in stats {
        min_samples = min_samples.min(n);
        if n == 0 {
            continue;
        }
        b += mean;
        var_of_mean += variance / n as f64;
        variance_sum += variance;
    }
    let relative_standard_error = if b > 0.0 {
        var_of_mean.sqrt() / b
    } else {
        f64::INFINITY
    };
    BootstrapError {
        normalisation: b,
        relative_standard_error,
        variance_sum,
        min_samples: if groups.is_empty() { 0 } else { min_samples },
    }
}

/// Samples per group the bootstrap needs for `mutations_per_pixel` (the rule in the module
/// docs, at the variances seen so far, at least `MIN_BOOTSTRAP_SAMPLES`); None while b = 0.
pub fn bootstrap_samples_needed(groups: &[&[f32]], mutations_per_pixel: f64) -> Option<usize> {
    let e = bootstrap_error(groups);
    if e.normalisation <= 0.0 {
        return None;
    }
    let kappa = BOOTSTRAP_NOISE_FRACTION;
    let needed = mutations_per_pixel * e.variance_sum / (kappa * e.normalisation).powi(2);
    Some((needed.ceil() as usize).max(MIN_BOOTSTRAP_SAMPLES))
}

/// Whether the bootstrap must draw more samples before `mutations_per_pixel` mutations per pixel:
/// true while any group has fewer than `MIN_BOOTSTRAP_SAMPLES`, while b = 0 (the caller caps
/// the bootstrap: a black scene never gets a positive b), or while
/// r_b > `BOOTSTRAP_NOISE_FRACTION` / sqrt(mutations_per_pixel).
pub fn needs_more_bootstrap(groups: &[&[f32]], mutations_per_pixel: f64) -> bool {
    let e = bootstrap_error(groups);
    e.min_samples < MIN_BOOTSTRAP_SAMPLES
        || e.normalisation <= 0.0
        || e.relative_standard_error
            > BOOTSTRAP_NOISE_FRACTION / mutations_per_pixel.max(1.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn uniform(seed: u64, i: u64) -> f64 {
        SampleKey::new(seed, i, 0).get(0) as f64
    }

    #[test]
    fn largest_remainder_sums_to_the_total_within_one_of_proportional() {
        let mut out = Vec::new();
        for case in 0..200u64 {
            let groups = 1 + (case % 9) as usize;
            let total = 1 + (mix64(case) % 5000) as usize;
            let shares: Vec<f64> = (0..groups)
                .map(|g| 0.05 + uniform(case, g as u64).powi(2) * 10.0)
                .collect();
            allocate_largest_remainder(&shares, total, &mut out);
            assert_eq!(out.iter().sum::<usize>(), total, "case {case}");
            let sum: f64 = shares.iter().sum();
            let quotas: Vec<f64> = shares.iter().map(|s| s / sum * total as f64).collect();
            // A quota below one gets its guaranteed item (when there are enough), which may
            // push its donor past 1 from proportional: check the bound when no quota is below 1.
            let guaranteed = quotas.iter().any(|&q| q < 1.0) && groups <= total;
            for (g, (&n, &quota)) in out.iter().zip(&quotas).enumerate() {
                if guaranteed {
                    assert!(n >= 1, "case {case} group {g}");
                } else {
                    assert!(
                        (n as f64 - quota).abs() < 1.0,
                        "case {case} group {g}: {n} vs {quota}"
                    );
                }
            }
        }
        // Exact quotas are met exactly; ties go to the lower index.
        allocate_largest_remainder(&[1.0, 2.0, 1.0], 8, &mut out);
        assert_eq!(out, [2, 4, 2]);
        allocate_largest_remainder(&[1.0, 1.0, 1.0], 4, &mut out);
        assert_eq!(out, [2, 1, 1]);
        allocate_largest_remainder(&[0.0, f64::NAN, 0.0], 4, &mut out);
        assert_eq!(out, [0, 0, 0]);
    }

    #[test]
    fn largest_remainder_gives_every_positive_group_a_chain() {
        let mut out = Vec::new();
        allocate_largest_remainder(&[1000.0, 1e-6, 0.0, 1.0], 100, &mut out);
        assert_eq!(out.iter().sum::<usize>(), 100);
        assert_eq!(out[1], 1);
        assert_eq!(out[2], 0);
        assert_eq!(out[3], 1);
    }

    #[test]
    fn stratified_resampling_picks_in_proportion() {
        for k in 0..16 {
            let offset = k as f64 / 16.0;
            let mut out = Vec::new();
            resample_stratified(&[1.0, 0.0, 3.0], 4, offset, &mut out);
            assert_eq!(out, [0, 2, 2, 2], "offset {offset}");
        }
        // Zero-weight candidates at the ends and non-finite weights are never picked.
        let weights = [0.0, 2.0, f32::NAN, 0.0, 6.0, -1.0, 0.0];
        let mut out = Vec::new();
        resample_stratified(&weights, 8, 0.999_999, &mut out);
        assert_eq!(out, [1, 1, 4, 4, 4, 4, 4, 4]);
        out.clear();
        resample_stratified(&[0.0, 0.0], 3, 0.5, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn seeds_follow_b_per_group() {
        // Group 0: b = 1; group 1: b = 3 (weights zero for most samples); group 2: nothing.
        let g0 = vec![1.0f32; 100];
        let mut g1 = vec![0.0f32; 100];
        g1[10] = 100.0;
        g1[50] = 200.0;
        let g2 = vec![0.0f32; 100];
        let s = select_seeds(&[&g0, &g1, &g2], 40, 5).expect("b > 0");
        assert_eq!(s.normalisation, [1.0, 3.0, 0.0]);
        assert_eq!(s.chains_per_group, [10, 30, 0]);
        assert_eq!(s.group.len(), 40);
        let picks = |c: u32| s.candidate[10..].iter().filter(|&&x| x == c).count();
        assert_eq!((picks(10), picks(50)), (10, 20));
        assert!(s.group[..10].iter().all(|&g| g == 0));
        assert_eq!(s.splat_scale(1), 1.0 / 30.0);
        assert_eq!(s.total_normalisation(), 4.0);
        let mut chains = ChainStates::new(40, 1, 1, 0);
        s.apply(&mut chains);
        assert_eq!(chains.group[39], 1);
        assert_eq!(chains.splat_scale[0], 0.1);
        // The running b_k starts at the bootstrap's and takes large steps in.
        let mut b = Normalisation::from_bootstrap(&[&g0, &g1, &g2]);
        assert_eq!((b.group(0), b.group(1), b.total()), (1.0, 3.0, 4.0));
        b.add_large_steps(&[(0.0, 0), (100.0, 100), (0.0, 0)]);
        assert_eq!((b.group(1), b.large_steps), (2.0, 100));
        assert!(select_seeds(&[&g2], 4, 5).is_none());
    }

    /// The predicted relative standard error matches the scatter of b over independent
    /// bootstraps, and the size rule follows N = M (s / b)^2 / kappa^2.
    #[test]
    fn bootstrap_error_matches_its_scatter_and_sets_the_size() {
        // A heavy target: weight 50 with probability 1/100, else 0.5 (s / b about 4.8).
        let weight = |u: f64| if u < 0.01 { 50.0f32 } else { 0.5 };
        let (n, trials) = (4000usize, 400u64);
        let mut bs = Vec::new();
        let mut predicted = 0.0;
        let mut weights = vec![0.0f32; n];
        for t in 0..trials {
            for (i, w) in weights.iter_mut().enumerate() {
                *w = weight(uniform(100 + t, i as u64));
            }
            let e = bootstrap_error(&[&weights]);
            bs.push(e.normalisation);
            predicted += e.relative_standard_error / trials as f64;
        }
        let mean = bs.iter().sum::<f64>() / trials as f64;
        let sd = (bs.iter().map(|b| (b - mean).powi(2)).sum::<f64>() / (trials - 1) as f64).sqrt();
        let observed = sd / mean;
        assert!(
            (predicted / observed - 1.0).abs() < 0.15,
            "predicted {predicted}, observed {observed}"
        );

        // Exact mean and variance of this weight: b = 0.995, s^2 = 0.01 * 0.99 * 49.5^2.
        let (b, s2) = (0.995f64, 0.01 * 0.99 * 49.5f64.powi(2));
        let m = 64.0;
        let rule = m * s2 / (BOOTSTRAP_NOISE_FRACTION * b).powi(2);
        let needed = bootstrap_samples_needed(&[&weights], m).expect("b > 0") as f64;
        assert!((needed / rule - 1.0).abs() < 0.25, "{needed} vs {rule}");
        // 4000 samples are too few for 64 mutations per pixel (rule ~ 6100) but enough for 16.
        assert!(needs_more_bootstrap(&[&weights], m));
        assert!(!needs_more_bootstrap(&[&weights], 16.0));
        // Constant weights: no variance, only the floor applies; none at all: always more.
        let flat = vec![1.0f32; MIN_BOOTSTRAP_SAMPLES];
        assert!(!needs_more_bootstrap(&[&flat, &flat], 1e6));
        assert!(needs_more_bootstrap(&[&flat[..10]], 1.0));
        assert!(needs_more_bootstrap(&[&vec![0.0; 5000]], 1.0));
        assert_eq!(
            bootstrap_samples_needed(&[&flat], 1e6),
            Some(MIN_BOOTSTRAP_SAMPLES)
        );
    }
}

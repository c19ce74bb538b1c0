//! The kernel's acceptance tests on a toy target: a piecewise-constant RGB image of 16 x 16
//! cells on the unit square (luminance 1 to 100), the primary-sample vector being the point
//! (x, y) and the "pixel" its cell of an 8 x 8 grid.

use super::*;
use crate::math::luminance;
use crate::sampling::{SampleKey, mix64};
use glam::{DVec3, Vec3};
use rayon::prelude::*;

const FINE: usize = 16;
const COARSE: usize = 8;
const CELLS: usize = COARSE * COARSE;
/// Chi-square critical value for 63 degrees of freedom at p = 1e-4 (from the regularised
/// incomplete gamma function): a correct kernel fails once in 10^4 seeds.
const CHI2_CRITICAL_63_DOF: f64 = 113.5;

struct Toy {
    /// RGB per fine cell, x-major: cell (i, j) at i * FINE + j.
    colour: Vec<Vec3>,
    /// Cumulative luminance over fine cells, for exact samples.
    cdf: Vec<f64>,
    /// b: the integral of the luminance over the unit square.
    b: f64,
    /// Exact probability of each coarse cell under the target.
    cell_probability: Vec<f64>,
    /// Exact integral of the RGB over each coarse cell.
    cell_integral: Vec<DVec3>,
}

impl Toy {
    fn new() -> Toy {
        let mut colour = Vec::with_capacity(FINE * FINE);
        for i in 0..FINE {
            for j in 0..FINE {
                let mut v = 1.0 + (i + 2 * j) as f32 / 45.0;
                if (3..=4).contains(&i) && (4..=5).contains(&j) {
                    v = 100.0; // a bright block across a coarse cell boundary
                }
                if (9..=12).contains(&i) && j == 11 {
                    v = 40.0; // a streak
                }
                if (i, j) == (14, 2) {
                    v = 100.0; // an isolated bright cell
                }
                let tint = Vec3::new(
                    1.0 + 0.5 * (i as f32).sin(),
                    1.0,
                    1.0 + 0.5 * (j as f32).cos(),
                );
                colour.push(tint * (v / luminance(tint)));
            }
        }
        let area = 1.0 / (FINE * FINE) as f64;
        let mut cdf = Vec::with_capacity(colour.len());
        let mut sum = 0.0;
        let mut cell_probability = vec![0.0; CELLS];
        let mut cell_integral = vec![DVec3::ZERO; CELLS];
        for (k, &c) in colour.iter().enumerate() {
            let l = luminance(c) as f64;
            sum += l;
            cdf.push(sum);
            let cell = coarse_cell(k / FINE, k % FINE);
            cell_probability[cell] += l;
            cell_integral[cell] += c.as_dvec3() * area;
        }
        for p in &mut cell_probability {
            *p /= sum;
        }
        Toy {
            colour,
            cdf,
            b: sum * area,
            cell_probability,
            cell_integral,
        }
    }

    /// The point's coarse cell and RGB.
    fn eval(&self, x: f32, y: f32) -> (u32, Vec3) {
        let i = ((x * FINE as f32) as usize).min(FINE - 1);
        let j = ((y * FINE as f32) as usize).min(FINE - 1);
        (coarse_cell(i, j) as u32, self.colour[i * FINE + j])
    }

    /// An exact sample of the target (density proportional to luminance).
    fn sample(&self, key: SampleKey) -> (f32, f32) {
        let total = *self.cdf.last().unwrap();
        let u = key.get(0) as f64 * total;
        let k = self
            .cdf
            .partition_point(|&c| c <= u)
            .min(self.cdf.len() - 1);
        let (i, j) = (k / FINE, k % FINE);
        let x = (i as f32 + key.get(1)) / FINE as f32;
        let y = (j as f32 + key.get(2)) / FINE as f32;
        (x.min(1.0 - f32::EPSILON), y.min(1.0 - f32::EPSILON))
    }
}

fn coarse_cell(i: usize, j: usize) -> usize {
    (i * COARSE / FINE) * COARSE + j * COARSE / FINE
}

#[derive(Clone, Copy, PartialEq)]
enum Kernel {
    Correct,
    /// The negative control: small steps only ever move up (|dv| kept, sign dropped), a
    /// non-symmetric proposal whose Hastings correction is omitted.
    DriftWithoutHastings,
}

struct ToyRun {
    chains: ChainStates,
    initial_cells: Vec<u32>,
    counters: MltCounters,
    /// Splat sums per coarse cell, over all steps.
    film: Vec<DVec3>,
    /// Sum over all splats of their luminance.
    deposited: f64,
    /// A hash of every splat's bits in emission order.
    splat_hash: u64,
}

impl ToyRun {
    fn final_cells(&self) -> Vec<u32> {
        (0..self.chains.chains())
            .map(|i| self.chains.current_contributions.pixel[i])
            .collect()
    }
}

fn evaluate_proposals(toy: &Toy, chains: &mut ChainStates) {
    let (xs, ys) = (chains.proposal.column(0), chains.proposal.column(1));
    chains
        .proposal_contributions
        .par_chunks_mut()
        .for_each(|mut chunk| {
            for local in 0..chunk.len() {
                let i = chunk.first_chain + local;
                let (cell, colour) = toy.eval(xs[i], ys[i]);
                chunk.set_single(local, cell, colour);
            }
        });
}

/// `chains` chains started from exact samples of the toy, run `steps` steps.
fn run_toy(
    toy: &Toy,
    n: usize,
    steps: u64,
    settings: &MutationSettings,
    seed: u64,
    kernel: Kernel,
    splat_scale: f32,
) -> ToyRun {
    let mut chains = ChainStates::new(n, 2, 1, 0);
    let mut initial_cells = Vec::with_capacity(n);
    for i in 0..n {
        let (x, y) = toy.sample(SampleKey::new(mix64(seed ^ 0x5eed), i as u64, 0));
        chains.current.set(i, 0, x);
        chains.current.set(i, 1, y);
        let (cell, colour) = toy.eval(x, y);
        chains.current_contributions.set_single(i, cell, colour);
        chains.splat_scale[i] = splat_scale;
        initial_cells.push(cell);
    }
    let mut splats = ChainSplats::new();
    let mut counters = MltCounters::default();
    let mut film = vec![DVec3::ZERO; CELLS];
    let (mut deposited, mut splat_hash) = (0.0, 0u64);
    for step in 0..steps {
        propose_mutations(&mut chains, settings, seed, step);
        if kernel == Kernel::DriftWithoutHastings {
            for d in 0..2 {
                for i in 0..n {
                    if !chains.large_step[i] {
                        let x = chains.current.get(i, d);
                        let dv = wrapped_difference(chains.proposal.get(i, d), x);
                        chains.proposal.set(i, d, wrap_unit(x + dv.abs()));
                    }
                }
            }
        }
        evaluate_proposals(toy, &mut chains);
        counters += accept_or_reject(&mut chains);
        splat_expected_values(&chains, &mut splats, 0);
        for s in splats.iter() {
            film[s.pixel as usize] += s.value.as_dvec3();
            deposited += luminance(s.value) as f64;
            let bits = [
                s.pixel,
                s.value.x.to_bits(),
                s.value.y.to_bits(),
                s.value.z.to_bits(),
            ];
            for b in bits {
                splat_hash = mix64(splat_hash ^ b as u64);
            }
        }
        commit_accepted(&mut chains);
    }
    ToyRun {
        chains,
        initial_cells,
        counters,
        film,
        deposited,
        splat_hash,
    }
}

fn wrapped_difference(y: f32, x: f32) -> f32 {
    let d = y - x;
    d - (d + 0.5).floor()
}

/// Pearson's chi-square of the chains' cells against the target's cell probabilities.
fn chi_square(toy: &Toy, cells: &[u32]) -> f64 {
    let mut observed = vec![0u64; CELLS];
    for &c in cells {
        observed[c as usize] += 1;
    }
    let n = cells.len() as f64;
    observed
        .iter()
        .zip(&toy.cell_probability)
        .map(|(&o, &p)| (o as f64 - n * p).powi(2) / (n * p))
        .sum()
}

const CHAINS: usize = 4096;
const STEPS: u64 = 300;

#[test]
fn toy_expected_cell_counts_are_large_enough_for_chi_square() {
    let toy = Toy::new();
    let smallest = toy.cell_probability.iter().cloned().fold(1.0, f64::min);
    assert!(
        smallest * CHAINS as f64 > 10.0,
        "{}",
        smallest * CHAINS as f64
    );
    let ratio = toy
        .colour
        .iter()
        .map(|&c| luminance(c))
        .fold(0.0f32, f32::max)
        / toy
            .colour
            .iter()
            .map(|&c| luminance(c))
            .fold(f32::MAX, f32::min);
    assert!((99.0..=101.0).contains(&ratio), "dynamic range {ratio}");
}

/// Chains started from exact samples stay distributed as the target: the states of 4096
/// independent chains after 300 steps pass a chi-square test over 8 x 8 cells, for both small
/// steps. The chains must also have moved (else any kernel that never moves would pass).
#[test]
fn chain_states_follow_the_target_chi_square() {
    let toy = Toy::new();
    for (name, settings, seed) in [
        ("pssmlt (Kelemen)", MutationSettings::PSSMLT, 11),
        ("mmlt (wrapped normal)", MutationSettings::MMLT, 12),
    ] {
        let run = run_toy(&toy, CHAINS, STEPS, &settings, seed, Kernel::Correct, 1.0);
        let cells = run.final_cells();
        let chi2 = chi_square(&toy, &cells);
        let moved = cells
            .iter()
            .zip(&run.initial_cells)
            .filter(|(a, b)| a != b)
            .count() as f64
            / CHAINS as f64;
        let c = run.counters;
        eprintln!(
            "{name}: chi2 = {chi2:.1} (63 dof, critical {CHI2_CRITICAL_63_DOF}), moved {moved:.3}, \
             acceptance {:.3} (large {:.3}, small {:.3})",
            c.acceptance_rate(),
            c.large_accepted as f64 / c.large_proposed as f64,
            c.small_accepted as f64 / c.small_proposed as f64,
        );
        assert!(chi2 < CHI2_CRITICAL_63_DOF, "{name}: chi2 = {chi2}");
        assert!(
            moved > 0.5,
            "{name}: only {moved} of the chains changed cell"
        );
        assert_eq!(c.steps, CHAINS as u64 * STEPS);
        assert!(c.large_accepted > 0 && c.small_accepted > 0);
    }
}

/// The negative control: the same test with small steps that only move up (Hastings
/// correction omitted) must fail, so the chi-square test has power against a broken kernel.
#[test]
fn broken_kernel_fails_the_chi_square_test() {
    let toy = Toy::new();
    for (name, settings, seed) in [
        ("pssmlt (Kelemen)", MutationSettings::PSSMLT, 11),
        ("mmlt (wrapped normal)", MutationSettings::MMLT, 12),
    ] {
        let run = run_toy(
            &toy,
            CHAINS,
            STEPS,
            &settings,
            seed,
            Kernel::DriftWithoutHastings,
            1.0,
        );
        let chi2 = chi_square(&toy, &run.final_cells());
        eprintln!("{name}, drift without Hastings correction: chi2 = {chi2:.1}");
        assert!(
            chi2 > CHI2_CRITICAL_63_DOF,
            "{name}: broken kernel passed, chi2 = {chi2}"
        );
    }
}

/// The expected-value estimator with b from the exact normaliser: splat sums / steps, with
/// each chain's splat scale b / chains, equal the target's cell integrals within statistical
/// tolerance. 64 independent runs of 64 chains give the standard errors.
#[test]
fn expected_values_estimate_the_cell_integrals() {
    let toy = Toy::new();
    let (runs, n, steps) = (64usize, 64usize, 200u64);
    let settings = MutationSettings::PSSMLT;
    let scale = (toy.b / n as f64) as f32;
    let estimates: Vec<Vec<DVec3>> = (0..runs)
        .map(|r| {
            let run = run_toy(
                &toy,
                n,
                steps,
                &settings,
                1000 + r as u64,
                Kernel::Correct,
                scale,
            );
            run.film.iter().map(|&s| s / steps as f64).collect()
        })
        .collect();
    let (mut worst, mut total_estimate, mut total_exact) = (0.0f64, DVec3::ZERO, DVec3::ZERO);
    for cell in 0..CELLS {
        let mean = estimates.iter().map(|e| e[cell]).sum::<DVec3>() / runs as f64;
        let var = estimates
            .iter()
            .map(|e| (e[cell] - mean) * (e[cell] - mean))
            .sum::<DVec3>()
            / (runs - 1) as f64;
        let standard_error = (var / runs as f64).sqrt();
        let exact = toy.cell_integral[cell];
        let z = ((mean - exact) / standard_error).abs();
        worst = worst.max(z.max_element());
        total_estimate += mean;
        total_exact += exact;
        assert!(
            z.max_element() < 5.0,
            "cell {cell}: {mean} vs {exact}, z = {z}"
        );
    }
    let relative = ((total_estimate - total_exact) / total_exact)
        .abs()
        .max_element();
    eprintln!(
        "expected values: worst |z| over 64 cells x RGB = {worst:.2}, total off by {relative:.2e}"
    );
    // The total luminance is b exactly (each step deposits one unit times b / chains).
    assert!(
        (luminance(total_estimate.as_vec3()) as f64 / toy.b - 1.0).abs() < 1e-4,
        "{total_estimate} vs b = {}",
        toy.b
    );
}

/// With splat scale 1, every chain step deposits exactly one unit of luminance, whatever it
/// decides: the splats' luminance sums to the number of chain steps.
#[test]
fn each_step_deposits_one_unit_of_luminance() {
    let toy = Toy::new();
    for settings in [MutationSettings::PSSMLT, MutationSettings::MMLT] {
        let run = run_toy(&toy, 1500, 50, &settings, 3, Kernel::Correct, 1.0);
        let steps = run.counters.steps as f64;
        assert_eq!(steps, 1500.0 * 50.0);
        assert!(
            (run.deposited / steps - 1.0).abs() < 1e-6,
            "{} vs {steps}",
            run.deposited
        );
    }
}

/// Chains, counters and every splat are bit-identical for 1, 2 and 3 threads (2600 chains:
/// three chunks, the last partial).
#[test]
fn results_are_bit_identical_for_any_thread_count() -> Result<(), rayon::ThreadPoolBuildError> {
    let toy = Toy::new();
    let mut results = Vec::new();
    for threads in [1, 2, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()?;
        let run = pool.install(|| {
            run_toy(
                &toy,
                2600,
                40,
                &MutationSettings::PSSMLT,
                8,
                Kernel::Correct,
                0.5,
            )
        });
        results.push(run);
    }
    let first = &results[0];
    for other in &results[1..] {
        assert_eq!(first.counters, other.counters);
        assert_eq!(first.splat_hash, other.splat_hash);
        assert_eq!(first.chains.current, other.chains.current);
        assert_eq!(first.chains.accepted, other.chains.accepted);
        let bits = |f: &[DVec3]| {
            f.iter()
                .flat_map(|v| v.to_array().map(f64::to_bits))
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&first.film), bits(&other.film));
    }
    Ok(())
}

/// Chains resampled from one seed share their start but not their proposals.
#[test]
fn chains_sharing_a_seed_diverge_at_once() {
    let toy = Toy::new();
    let mut chains = ChainStates::new(64, 2, 1, 0);
    for i in 0..64 {
        chains.current.set(i, 0, 0.22);
        chains.current.set(i, 1, 0.3);
        let (cell, colour) = toy.eval(0.22, 0.3);
        chains.current_contributions.set_single(i, cell, colour);
    }
    propose_mutations(&mut chains, &MutationSettings::PSSMLT, 5, 0);
    let mut xs: Vec<u32> = chains
        .proposal
        .column(0)
        .iter()
        .map(|x| x.to_bits())
        .collect();
    xs.sort_unstable();
    xs.dedup();
    assert_eq!(xs.len(), 64);
}

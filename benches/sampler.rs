//! What a number costs under each sampler: `key` (once per path), `get` and `get2` (per
//! number), for independent and Sobol (on a 1920 x 1080 image, the default and an exact
//! count of 64 samples per pixel), over 4096 consecutive samples of a wave.
//!
//! `cargo bench --bench sampler`; criterion's elem/s is keys or numbers (a `get2` counts
//! once). `SAMPLER_COMPARE=1 cargo bench --bench sampler` prints best-of-many ns per call
//! instead, which shared, noisy machines disturb far less than criterion's means.

use criterion::{Criterion, Throughput, criterion_group};
use stagelight::sampling::{SampleKey, Sampler, SamplerKind, Stream};
use std::hint::black_box;
use std::time::{Duration, Instant};

const N: u64 = 4096;
const DIMS: u32 = 8;
const PIXELS: u64 = 1920 * 1080;

fn samplers() -> [(&'static str, Sampler<'static>); 3] {
    let sobol = Sampler::new(SamplerKind::Sobol, 7, 1920, 1080);
    [
        (
            "independent",
            Sampler::new(SamplerKind::Independent, 7, 1920, 1080),
        ),
        ("sobol", sobol),
        ("sobol 64 spp", sobol.with_samples_per_pixel(64)),
    ]
}

/// The keys of a wave: consecutive global samples, pixel-major as the systems number them.
fn keys(s: &Sampler) -> Vec<SampleKey> {
    (0..N)
        .map(|g| s.key(Stream::Camera, (g * 977) % PIXELS, g / 977))
        .collect()
}

fn run_keys(s: &Sampler) {
    for g in 0..N {
        black_box(s.key(Stream::Camera, black_box((g * 977) % PIXELS), g / 977));
    }
}

fn run_get(s: &Sampler, keys: &[SampleKey]) {
    for &k in keys {
        for d in 0..DIMS {
            black_box(s.get(black_box(k), d));
        }
    }
}

fn run_get2(s: &Sampler, keys: &[SampleKey]) {
    for &k in keys {
        for d in 0..DIMS {
            black_box(s.get2(black_box(k), d));
        }
    }
}

fn bench(c: &mut Criterion) {
    for (name, s) in samplers() {
        let ks = keys(&s);
        let mut g = c.benchmark_group(name);
        g.throughput(Throughput::Elements(N));
        g.bench_function("key", |b| b.iter(|| run_keys(&s)));
        g.throughput(Throughput::Elements(N * DIMS as u64));
        g.bench_function("get", |b| b.iter(|| run_get(&s, &ks)));
        g.bench_function("get2", |b| b.iter(|| run_get2(&s, &ks)));
        g.finish();
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1));
    targets = bench
}

fn compare() {
    let time = |best: &mut f64, f: &dyn Fn()| {
        let start = Instant::now();
        f();
        *best = best.min(start.elapsed().as_secs_f64());
    };
    for (name, s) in samplers() {
        let ks = keys(&s);
        let mut best = [f64::INFINITY; 3];
        for _ in 0..200 {
            time(&mut best[0], &|| run_keys(&s));
            time(&mut best[1], &|| run_get(&s, &ks));
            time(&mut best[2], &|| run_get2(&s, &ks));
        }
        let per = |t: f64, n: u64| t / n as f64 * 1e9;
        println!(
            "{name:14} key {:6.2} ns, get {:6.2} ns, get2 {:6.2} ns",
            per(best[0], N),
            per(best[1], N * DIMS as u64),
            per(best[2], N * DIMS as u64)
        );
    }
}

fn main() {
    if std::env::var_os("SAMPLER_COMPARE").is_some() {
        compare();
    } else {
        benches();
        Criterion::default().configure_from_args().final_summary();
    }
}

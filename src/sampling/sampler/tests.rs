use super::*;
use rayon::prelude::*;

const SEEDS: [u64; 4] = [0, 1, 7, u64::MAX];

fn sobol(seed: u64, width: u32, height: u32) -> Sampler<'static> {
    Sampler::new(SamplerKind::Sobol, seed, width, height)
}

#[test]
fn sample_key_stays_eight_bytes() {
    assert_eq!(std::mem::size_of::<SampleKey>(), 8);
    assert!(std::mem::size_of::<Sampler>() <= 24);
}

/// Today's keys, written out: the tags of bdpt.rs, photons/mod.rs, sample_direct_light.rs and
/// final_gather_rays.rs.
fn todays_key(seed: u64, stream: Stream, index: u64, sample: u64) -> SampleKey {
    let tagged = match stream {
        Stream::Camera | Stream::Connection => index,
        Stream::Light => index | 1 << 63,
        Stream::Photon => index | 3 << 62,
        Stream::DirectLight => index | 1 << 61,
        Stream::FinalGather => index | 1 << 60,
    };
    SampleKey::new(seed, tagged, sample)
}

#[test]
fn independent_reproduces_todays_numbers_exactly() {
    // Pinned values (from an independent re-implementation of the hash), so that the hash
    // itself cannot drift either.
    let pinned = |bits: u32| bits as f32 / (1 << 24) as f32;
    assert_eq!(SampleKey::new(7, 123, 4).get(5), pinned(8_283_053));
    assert_eq!(SampleKey::new(0, 0, 0).get(0), pinned(8_300_755));
    assert_eq!(SampleKey::new(1, 1 << 63 | 5, 2).get(1), pinned(15_691_868));
    assert_eq!(
        SampleKey::new(42, 3 << 62 | 99, 7).get(3),
        pinned(1_269_955)
    );

    let indices = [0u64, 1, 2, 639, 640, 123_456, (1 << 32) + 5, (1 << 60) - 1];
    let samples = [0u64, 1, 5, 1023, 1 << 20, u32::MAX as u64, u64::MAX];
    for seed in SEEDS {
        let sampler = Sampler::new(SamplerKind::Independent, seed, 640, 480);
        for stream in Stream::ALL {
            for &index in &indices {
                for &sample in &samples {
                    let key = sampler.key(stream, index, sample);
                    let today = todays_key(seed, stream, index, sample);
                    assert_eq!(key, today);
                    for dim in 0..40 {
                        let (a, b) = (sampler.get(key, dim), today.get(dim));
                        assert_eq!(a.to_bits(), b.to_bits());
                        let (a, b) = (sampler.get2(key, dim), today.get2(dim));
                        assert_eq!(
                            (a.x.to_bits(), a.y.to_bits()),
                            (b.x.to_bits(), b.y.to_bits())
                        );
                    }
                }
            }
        }
        // Photons may use indices up to 2^62.
        let key = sampler.key(Stream::Photon, (1 << 62) - 1, 3);
        assert_eq!(key, todays_key(seed, Stream::Photon, (1 << 62) - 1, 3));
    }
}

#[test]
fn independent_tags_keep_streams_apart() {
    // At the edges of the index ranges no two streams share a tagged index (Connection is the
    // camera stream by design).
    let streams = [
        Stream::Camera,
        Stream::Light,
        Stream::Photon,
        Stream::FinalGather,
        Stream::DirectLight,
    ];
    let mut tagged = Vec::new();
    for s in streams {
        for index in [0, 1, s.index_limit() / 2, s.index_limit() - 1] {
            tagged.push((index | s.independent_tag(), s));
        }
    }
    for (i, a) in tagged.iter().enumerate() {
        for b in &tagged[..i] {
            assert!(a.0 != b.0 || a.1 == b.1, "{a:?} meets {b:?}");
        }
    }
    let sampler = Sampler::Independent { seed: 3 };
    assert_eq!(
        sampler.key(Stream::Connection, 17, 2),
        sampler.key(Stream::Camera, 17, 2)
    );
}

#[test]
#[should_panic(expected = "overlap")]
fn independent_index_beyond_its_range_is_caught() {
    Sampler::Independent { seed: 0 }.key(Stream::Camera, 1 << 60, 0);
}

#[test]
fn kind_parses_and_prints() {
    for kind in SamplerKind::ALL {
        assert_eq!(kind.to_string().parse::<SamplerKind>(), Ok(kind));
    }
    assert_eq!(" Sobol ".parse::<SamplerKind>(), Ok(SamplerKind::Sobol));
    assert_eq!("independent".parse(), Ok(SamplerKind::Independent));
    let err = "halton".parse::<SamplerKind>().unwrap_err();
    assert_eq!(err, UnknownSampler("halton".into()));
    assert!(err.to_string().contains("independent or sobol"));
    assert_eq!(SamplerKind::default(), SamplerKind::Independent);
}

#[test]
fn new_sizes_the_sobol_sampler() {
    let s = sobol(5, 640, 480);
    assert!(matches!(
        s,
        Sampler::Sobol {
            seed: 5,
            width: 640,
            log2_res: 10,
            log2_spp: DEFAULT_LOG2_SPP
        }
    ));
    assert_eq!(s.kind(), Some(SamplerKind::Sobol));
    let s = s.with_samples_per_pixel(100);
    assert!(matches!(s, Sampler::Sobol { log2_spp: 7, .. }));
    assert!(matches!(
        s.with_samples_per_pixel(1),
        Sampler::Sobol { log2_spp: 0, .. }
    ));
    assert!(matches!(
        s.with_samples_per_pixel(u64::MAX),
        Sampler::Sobol {
            log2_spp: MAX_LOG2_SPP,
            ..
        }
    ));
    assert!(matches!(sobol(0, 1, 1), Sampler::Sobol { log2_res: 0, .. }));
    let i = Sampler::new(SamplerKind::Independent, 9, 4, 4);
    assert!(matches!(
        i.with_samples_per_pixel(64),
        Sampler::Independent { seed: 9 }
    ));
}

#[test]
fn sobol_is_pure_and_in_unit_interval() {
    let sampler = sobol(11, 97, 61);
    let pixels = 97 * 61u64;
    let draw = |g: u64| {
        let stream = Stream::ALL[(g % 6) as usize];
        let index = if stream == Stream::Photon {
            g * 7919
        } else {
            (g * 31) % pixels
        };
        let key = sampler.key(stream, index, g / 3);
        let mut bits = Vec::with_capacity(24);
        for dim in 0..8 {
            let (u, v) = (sampler.get(key, dim), sampler.get2(key, dim));
            for x in [u, v.x, v.y] {
                assert!((0.0..1.0).contains(&x), "{x}");
                bits.push(x.to_bits());
            }
            assert_eq!(u.to_bits(), v.x.to_bits(), "get(d) is get2(d).x");
        }
        bits
    };
    // In parallel and in order: the same numbers whatever thread draws them.
    let parallel: Vec<_> = (0..20_000u64).into_par_iter().map(draw).collect();
    let serial: Vec<_> = (0..20_000u64).map(draw).collect();
    assert_eq!(parallel, serial);
    // The seed matters.
    let other = sobol(12, 97, 61);
    let key = |s: &Sampler| s.key(Stream::Camera, 5, 3);
    assert_ne!(sampler.get2(key(&sampler), 4), other.get2(key(&other), 4));
}

/// Whether the points put exactly one in each elementary interval 2^a x 2^(m - a) of every
/// shape (m = log2 of the count). Numbers carry 24 bits, so the cells are exact for m <= 24.
fn is_net(points: &[Vec2]) -> bool {
    let m = points.len().trailing_zeros();
    assert_eq!(points.len(), 1 << m);
    (0..=m).all(|a| {
        let mut seen = vec![false; points.len()];
        points.iter().all(|p| {
            let cx = (p.x * (1u64 << a) as f32) as usize;
            let cy = (p.y * (1u64 << (m - a)) as f32) as usize;
            !std::mem::replace(&mut seen[(cx << (m - a)) | cy], true)
        })
    })
}

fn is_stratified_1d(xs: &[f32]) -> bool {
    let mut seen = vec![false; xs.len()];
    xs.iter()
        .all(|&x| !std::mem::replace(&mut seen[(x * xs.len() as f32) as usize], true))
}

#[test]
fn sobol_pixel_samples_are_stratified_in_every_power_of_two_prefix() {
    for sampler in [
        sobol(3, 37, 23),
        sobol(4, 37, 23).with_samples_per_pixel(64),
        sobol(5, 37, 23).with_samples_per_pixel(8),
        sobol(6, 1920, 1080),
    ] {
        let Sampler::Sobol { log2_spp, .. } = sampler else {
            unreachable!()
        };
        let kmax = log2_spp.min(10);
        for pixel in [0u64, 1, 36, 37, 400, 37 * 23 - 1] {
            for stream in [Stream::Camera, Stream::Light, Stream::DirectLight] {
                for dim in [0, 1, 2, 5, 17, 1000] {
                    // The first batch, and (for small batches) the next one.
                    for first in [0, 1u64 << log2_spp] {
                        if first > 0 && log2_spp > 10 {
                            continue;
                        }
                        for k in 0..=kmax {
                            let keys: Vec<_> = (first..first + (1 << k))
                                .map(|s| sampler.key(stream, pixel, s))
                                .collect();
                            let pts: Vec<_> = keys.iter().map(|&c| sampler.get2(c, dim)).collect();
                            assert!(is_net(&pts), "{sampler:?} px {pixel} dim {dim} k {k}");
                            let xs: Vec<_> = keys.iter().map(|&c| sampler.get(c, dim)).collect();
                            assert!(is_stratified_1d(&xs));
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn sobol_photons_of_a_pass_are_stratified() {
    let sampler = sobol(8, 64, 64);
    for pass in [0u64, 1, 1000] {
        for dim in [0, 3, 9] {
            for k in [0u32, 3, 8, 12] {
                let pts: Vec<_> = (0..1u64 << k)
                    .map(|i| sampler.get2(sampler.key(Stream::Photon, i, pass), dim))
                    .collect();
                assert!(is_net(&pts), "pass {pass} dim {dim} k {k}");
            }
        }
    }
    // Passes are scrambled anew.
    let a = sampler.get2(sampler.key(Stream::Photon, 5, 0), 0);
    let b = sampler.get2(sampler.key(Stream::Photon, 5, 1), 0);
    assert_ne!(a, b);
}

#[test]
fn sobol_with_the_exact_count_stratifies_squares_of_pixels() {
    // 16 samples per pixel on a 16 x 16 image: any aligned 2^j x 2^j square of pixels holds
    // one net of 16 * 4^j points (ZSobol's Morton order).
    let sampler = sobol(21, 16, 16).with_samples_per_pixel(16);
    for dim in [0, 4] {
        for j in 0..=4u32 {
            let side = 1u64 << j;
            for (bx, by) in [(0, 0), (1, 0), (0, 1)] {
                let (x0, y0) = (bx * side, by * side);
                if x0 + side > 16 || y0 + side > 16 {
                    continue;
                }
                let mut pts = Vec::new();
                for y in y0..y0 + side {
                    for x in x0..x0 + side {
                        for s in 0..16 {
                            pts.push(sampler.get2(sampler.key(Stream::Camera, y * 16 + x, s), dim));
                        }
                    }
                }
                assert!(is_net(&pts), "dim {dim} square {side} at ({x0}, {y0})");
            }
        }
    }
}

/// Pearson's chi-square of counts against a uniform expectation.
fn chi_square(counts: &[u32]) -> f64 {
    let n: u32 = counts.iter().sum();
    let expected = n as f64 / counts.len() as f64;
    counts
        .iter()
        .map(|&c| (c as f64 - expected).powi(2) / expected)
        .sum()
}

fn grid_counts(points: impl Iterator<Item = Vec2>, bins: usize) -> Vec<u32> {
    let mut counts = vec![0u32; bins * bins];
    for p in points {
        let (x, y) = ((p.x * bins as f32) as usize, (p.y * bins as f32) as usize);
        counts[y * bins + x] += 1;
    }
    counts
}

#[test]
fn sobol_is_uniform_over_many_pixels() {
    // 16 x 16 bins: 255 degrees of freedom, 0.1% critical value 330.5. Stratified samples
    // sit well below the expectation of 255 (too even is what they are for); the bound only
    // catches bias.
    let (w, h) = (128u32, 128u32);
    let pixels = (w * h) as u64;
    for (name, sampler) in [
        ("sobol", sobol(1, w, h)),
        ("sobol 4 spp", sobol(1, w, h).with_samples_per_pixel(4)),
        ("independent", Sampler::Independent { seed: 1 }),
    ] {
        for (stream, sample) in [(Stream::Camera, 0), (Stream::Camera, 3), (Stream::Light, 1)] {
            for dim in [0, 2, 7] {
                let pts = (0..pixels).map(|p| sampler.get2(sampler.key(stream, p, sample), dim));
                let chi2 = chi_square(&grid_counts(pts, 16));
                println!("chi2 {name} {stream:?} sample {sample} dim {dim}: {chi2:.1}");
                assert!(chi2 < 330.5, "{name} {stream:?} dim {dim}: chi2 {chi2}");
            }
        }
        let pts = (0..1u64 << 14).map(|i| sampler.get2(sampler.key(Stream::Photon, i, 2), 4));
        let chi2 = chi_square(&grid_counts(pts, 16));
        println!("chi2 {name} photons: {chi2:.1}");
        assert!(chi2 < 330.5);
    }
}

fn correlation(a: &[f32], b: &[f32]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (
        a.iter().map(|&x| x as f64).sum::<f64>() / n,
        b.iter().map(|&x| x as f64).sum::<f64>() / n,
    );
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a.iter().zip(b) {
        let (dx, dy) = (x as f64 - ma, y as f64 - mb);
        sab += dx * dy;
        saa += dx * dx;
        sbb += dy * dy;
    }
    sab / (saa * sbb).sqrt()
}

#[test]
fn sobol_streams_and_dimensions_are_decorrelated() {
    // Over 64 x 64 pixels x 16 samples, pairs of numbers that should be independent: their
    // correlation within 5 sigma of 0, and their joint 8 x 8 histogram uniform (63 degrees of
    // freedom, 0.1% critical value 103.4; this is what catches two Owen scrambles of one
    // index agreeing in their first digits).
    for sampler in [
        sobol(2, 64, 64),
        sobol(2, 64, 64).with_samples_per_pixel(16),
    ] {
        let n = 64 * 64 * 16u64;
        let draw = |stream: Stream, dim: u32, second: bool, pixel_shift: u64| -> Vec<f32> {
            (0..n)
                .map(|g| {
                    let (pixel, sample) = ((g / 16 + pixel_shift) % 4096, g % 16);
                    let key = sampler.key(stream, pixel, sample);
                    let v = sampler.get2(key, dim);
                    if second { v.y } else { v.x }
                })
                .collect()
        };
        let cases: [(&str, Vec<f32>, Vec<f32>); 9] = [
            (
                "camera d0 / light d0",
                draw(Stream::Camera, 0, false, 0),
                draw(Stream::Light, 0, false, 0),
            ),
            (
                "camera d0 / direct d0",
                draw(Stream::Camera, 0, false, 0),
                draw(Stream::DirectLight, 0, false, 0),
            ),
            (
                "camera d3 / gather d3",
                draw(Stream::Camera, 3, true, 0),
                draw(Stream::FinalGather, 3, true, 0),
            ),
            (
                "d0.x / d1.x",
                draw(Stream::Camera, 0, false, 0),
                draw(Stream::Camera, 1, false, 0),
            ),
            (
                "d0.y / d1.x",
                draw(Stream::Camera, 0, true, 0),
                draw(Stream::Camera, 1, false, 0),
            ),
            (
                "d2.x / d4.x",
                draw(Stream::Camera, 2, false, 0),
                draw(Stream::Camera, 4, false, 0),
            ),
            (
                "d2.y / d4.y",
                draw(Stream::Camera, 2, true, 0),
                draw(Stream::Camera, 4, true, 0),
            ),
            (
                "d2.x / d900.y",
                draw(Stream::Camera, 2, false, 0),
                draw(Stream::Camera, 900, true, 0),
            ),
            (
                "pixel / next pixel d5",
                draw(Stream::Camera, 5, false, 0),
                draw(Stream::Camera, 5, false, 1),
            ),
        ];
        for (name, a, b) in cases {
            let r = correlation(&a, &b);
            let pts = a.iter().zip(&b).map(|(&x, &y)| Vec2::new(x, y));
            let chi2 = chi_square(&grid_counts(pts, 8));
            println!("{sampler:?} {name}: r = {r:+.4}, joint chi2 = {chi2:.1}");
            assert!(r.abs() < 5.0 / (n as f64).sqrt(), "{name}: r = {r}");
            assert!(chi2 < 103.4, "{name}: chi2 = {chi2}");
        }
    }
}

#[test]
fn sobol_connection_is_the_camera_stream() {
    let s = sobol(4, 32, 32);
    assert_eq!(
        s.key(Stream::Connection, 77, 9),
        s.key(Stream::Camera, 77, 9)
    );
    assert_ne!(s.key(Stream::Light, 77, 9), s.key(Stream::Camera, 77, 9));
}

#[test]
fn primary_reads_the_interleaved_store_then_falls_back_to_the_hash() {
    let (slots, dims) = (5usize, 11u32);
    let mut store = PrimarySamples::new(slots, dims);
    for slot in 0..slots {
        for d in 0..dims {
            store.set(slot, d, (slot as f32 * 16.0 + d as f32) / 128.0);
        }
    }
    let sampler = Sampler::Primary {
        store: &store,
        fallback_seed: 99,
    };
    assert_eq!(sampler.kind(), None);
    let slot = 3u64;
    for (stream, ordinal) in [
        (Stream::Camera, 0),
        (Stream::Light, 1),
        (Stream::Connection, 2),
    ] {
        let key = sampler.key(stream, slot, 12345);
        assert_eq!(key, sampler.key(stream, slot, 0), "the sample is ignored");
        for d in 0..6u32 {
            let store_dim = d * PRIMARY_STREAMS + ordinal;
            assert_eq!(stream.primary_dim(d), Some(store_dim));
            let got = sampler.get(key, d);
            if store_dim < dims {
                assert_eq!(got, store.get(slot as usize, store_dim), "{stream:?} {d}");
            } else {
                // The hash of (the slot's tail seed, stream, dim): the same in any slot that
                // holds the same tail seed (a seed's replay), anew with a new tail seed.
                let expect = SampleKey::new(store.tail(slot as usize), ordinal as u64, 0).get(d);
                assert_eq!(got, expect);
                let mut moved = store.clone();
                moved.tails_mut()[0] = store.tail(slot as usize);
                let elsewhere = Sampler::Primary {
                    store: &moved,
                    fallback_seed: 100,
                };
                assert_eq!(elsewhere.get(elsewhere.key(stream, 0, 0), d), got);
                moved.tails_mut()[slot as usize] = 7;
                let fresh = Sampler::Primary {
                    store: &moved,
                    fallback_seed: 99,
                };
                assert_ne!(fresh.get(key, d), got, "a new tail seed draws anew");
            }
            let pair = sampler.get2(key, d);
            assert_eq!(
                pair,
                Vec2::new(sampler.get(key, d), sampler.get(key, d + 1))
            );
        }
    }
    // Streams without store dimensions always hash, within [0, 1) and per stream.
    let mut seen = Vec::new();
    for stream in [Stream::Photon, Stream::FinalGather, Stream::DirectLight] {
        assert_eq!(stream.primary_dim(0), None);
        let key = sampler.key(stream, slot, 0);
        let u = sampler.get(key, 0);
        assert!((0.0..1.0).contains(&u));
        assert_eq!(
            u,
            SampleKey::new(99, stream.ordinal() << 61 | slot, 0).get(0)
        );
        seen.push(u.to_bits());
    }
    seen.sort_unstable();
    seen.dedup();
    assert_eq!(seen.len(), 3);
    assert!(format!("{sampler:?}").contains("slots: 5"));
}

type Integrand = fn(Vec2) -> f64;

/// Per-pixel estimates of the integral of `f` over the unit square with `spp` samples of
/// dimension pair 2, for every pixel of a `side` x `side` image.
fn estimates(sampler: &Sampler, side: u32, spp: u64, f: Integrand) -> Vec<f64> {
    (0..(side * side) as u64)
        .into_par_iter()
        .map(|pixel| {
            let sum: f64 = (0..spp)
                .map(|s| f(sampler.get2(sampler.key(Stream::Camera, pixel, s), 2)))
                .sum();
            sum / spp as f64
        })
        .collect()
}

/// Mean squared error of the means of `tile` x `tile` squares of pixel estimates.
fn tile_mse(est: &[f64], side: u32, tile: u32, exact: f64) -> f64 {
    let side = side as usize;
    let tile = tile as usize;
    let mut sum = 0.0;
    let mut count = 0;
    for ty in (0..side).step_by(tile) {
        for tx in (0..side).step_by(tile) {
            let mut m = 0.0;
            for y in ty..ty + tile {
                for x in tx..tx + tile {
                    m += est[y * side + x];
                }
            }
            m /= (tile * tile) as f64;
            sum += (m - exact).powi(2);
            count += 1;
        }
    }
    sum / count as f64
}

#[test]
fn sobol_lowers_the_error_of_pixel_estimates() {
    // 64 samples per pixel over 128 x 128 pixels: the mean squared error of a smooth integral
    // (x y, exact 1/4) and of a discontinuous one (the quarter disc, exact pi/4), per pixel
    // and for the means of 2 x 2 and 4 x 4 squares of pixels.
    let (side, spp) = (128u32, 64u64);
    let integrands: [(&str, Integrand, f64); 2] = [
        ("x y", |u| (u.x * u.y) as f64, 0.25),
        (
            "disc",
            |u| f64::from(u8::from(u.length_squared() < 1.0)),
            std::f64::consts::FRAC_PI_4,
        ),
    ];
    let samplers = [
        ("independent", Sampler::Independent { seed: 1 }),
        ("sobol", sobol(1, side, side)),
        (
            "sobol 64 spp",
            sobol(1, side, side).with_samples_per_pixel(spp),
        ),
    ];
    for (name, f, exact) in integrands {
        let mut mse = Vec::new();
        for (sname, sampler) in &samplers {
            let est = estimates(sampler, side, spp, f);
            let m: Vec<f64> = [1, 2, 4]
                .iter()
                .map(|&t| tile_mse(&est, side, t, exact))
                .collect();
            println!(
                "{name}, {sname}: MSE per pixel {:.3e}, 2x2 means {:.3e}, 4x4 means {:.3e}",
                m[0], m[1], m[2]
            );
            mse.push(m);
        }
        let (indep, sobol_default, sobol_exact) = (&mse[0], &mse[1], &mse[2]);
        let gain = if name == "x y" { 50.0 } else { 4.0 };
        assert!(
            sobol_default[0] * gain < indep[0],
            "{name}: {sobol_default:?} vs {indep:?}"
        );
        assert!(
            sobol_exact[0] * gain < indep[0],
            "{name}: {sobol_exact:?} vs {indep:?}"
        );
        // With the count known, neighbouring pixels' samples are one net: their mean is
        // better than the mean of independent pixels.
        assert!(
            sobol_exact[2] < sobol_default[2],
            "{name}: {sobol_exact:?} vs {sobol_default:?}"
        );
    }
}

#[test]
fn sobol_works_at_its_limits() {
    // The largest image and batch, and many batches of the smallest.
    let big = sobol(1, 65_536, 65_536).with_samples_per_pixel(1 << MAX_LOG2_SPP);
    let small = sobol(1, 3, 1).with_samples_per_pixel(1);
    for (sampler, pixel, first) in [
        (big, 65_536 * 65_536 - 1, 3u64 << 24),
        (big, 12_345_678, 0),
        (small, 2, (1 << 37) - 300),
    ] {
        for k in 0..=8 {
            let pts: Vec<_> = (first..first + (1 << k))
                .map(|s| sampler.get2(sampler.key(Stream::Light, pixel, s), 6))
                .collect();
            let Sampler::Sobol { log2_spp, .. } = sampler else {
                unreachable!()
            };
            if k <= log2_spp {
                assert!(is_net(&pts), "{sampler:?} k {k}");
            }
            assert!(
                pts.iter()
                    .all(|p| (0.0..1.0).contains(&p.x) && (0.0..1.0).contains(&p.y))
            );
        }
    }
}

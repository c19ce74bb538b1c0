//! Mitsuba 3's spectra as its RGB variants see them: a `<spectrum>` of wavelength:value pairs
//! is integrated against the CIE 1931 curves into linear sRGB once, at load time; the named
//! IORs of `dielectric`; the conductor presets of `conductor` (`material="Au"`).
//!
//! The integration follows `spectrum_list_to_srgb` (Mitsuba's src/core/spectrum.cpp) step for
//! step, so the numbers match Mitsuba's to float precision rather than to the exact integral:
//! 1000 wavelengths evenly spaced over [360, 830] nm including both ends, the spectrum
//! piecewise linear between its samples and zero outside them, the CIE and D65 tables (5 nm
//! steps, f32) interpolated linearly, the sum scaled by 470 / 1000 (not 470 / 999) and the
//! Y normalisation, then Mitsuba's XYZ to sRGB matrix. A constant reflectance of 0.5 so gives
//! 0.49949, not 0.5, as in Mitsuba.

use glam::Vec3;

/// Wavelength range and sample count of the CIE tables (nm).
const CIE_MIN: f64 = 360.0;
const CIE_MAX: f64 = 830.0;
const CIE_SAMPLES: usize = 95;

/// Scales the CIE curves so that a spectrum of 1 integrates to a luminance of 1.
const CIE_Y_NORMALIZATION: f64 = 1.0 / 106.75025939941406;

/// Scales D65 so that it integrates to a luminance of 1.
const CIE_D65_NORMALIZATION: f64 = 1.0 / 98.99741751876255;

/// Wavelengths `spectrum_list_to_srgb` samples.
const INTEGRATION_STEPS: usize = 1000;

/// CIE 1931 2-degree x-bar, 360 to 830 nm in 5 nm steps (Mitsuba's table).
const CIE_X: [f32; CIE_SAMPLES] = [
    0.0001299,
    0.0002321,
    0.0004149,
    0.0007416,
    0.001368,
    0.002236,
    0.004243,
    0.00765,
    0.01431,
    0.02319,
    0.04351,
    0.07763,
    0.13438,
    0.21477,
    0.2839,
    0.3285,
    0.34828,
    0.34806,
    0.3362,
    0.3187,
    0.2908,
    0.2511,
    0.19536,
    0.1421,
    0.09564,
    0.05795001,
    0.03201,
    0.0147,
    0.0049,
    0.0024,
    0.0093,
    0.0291,
    0.06327,
    0.1096,
    0.1655,
    0.2257499,
    0.2904,
    0.3597,
    0.4334499,
    0.5120501,
    0.5945,
    0.6784,
    0.7621,
    0.8425,
    0.9163,
    0.9786,
    1.0263,
    1.0567,
    1.0622,
    1.0456,
    1.0026,
    0.9384,
    0.8544499,
    0.7514,
    0.6424,
    0.5419,
    0.4479,
    0.3608,
    0.2835,
    0.2187,
    0.1649,
    0.1212,
    0.0874,
    0.0636,
    0.04677,
    0.0329,
    0.0227,
    0.01584,
    0.01135916,
    0.008110916,
    0.005790346,
    0.004109457,
    0.002899327,
    0.00204919,
    0.001439971,
    0.0009999493,
    0.0006900786,
    0.0004760213,
    0.0003323011,
    0.0002348261,
    0.0001661505,
    0.000117413,
    0.00008307527,
    0.00005870652,
    0.00004150994,
    0.00002935326,
    0.00002067383,
    0.00001455977,
    0.00001025398,
    0.000007221456,
    0.000005085868,
    0.000003581652,
    0.000002522525,
    0.000001776509,
    0.000001251141,
];

/// CIE 1931 2-degree y-bar, 360 to 830 nm in 5 nm steps (Mitsuba's table).
const CIE_Y: [f32; CIE_SAMPLES] = [
    0.000003917,
    0.000006965,
    0.00001239,
    0.00002202,
    0.000039,
    0.000064,
    0.00012,
    0.000217,
    0.000396,
    0.00064,
    0.00121,
    0.00218,
    0.004,
    0.0073,
    0.0116,
    0.01684,
    0.023,
    0.0298,
    0.038,
    0.048,
    0.06,
    0.0739,
    0.09098,
    0.1126,
    0.13902,
    0.1693,
    0.20802,
    0.2586,
    0.323,
    0.4073,
    0.503,
    0.6082,
    0.71,
    0.7932,
    0.862,
    0.9148501,
    0.954,
    0.9803,
    0.9949501,
    1.0,
    0.995,
    0.9786,
    0.952,
    0.9154,
    0.87,
    0.8163,
    0.757,
    0.6949,
    0.631,
    0.5668,
    0.503,
    0.4412,
    0.381,
    0.321,
    0.265,
    0.217,
    0.175,
    0.1382,
    0.107,
    0.0816,
    0.061,
    0.04458,
    0.032,
    0.0232,
    0.017,
    0.01192,
    0.00821,
    0.005723,
    0.004102,
    0.002929,
    0.002091,
    0.001484,
    0.001047,
    0.00074,
    0.00052,
    0.0003611,
    0.0002492,
    0.0001719,
    0.00012,
    0.0000848,
    0.00006,
    0.0000424,
    0.00003,
    0.0000212,
    0.00001499,
    0.0000106,
    0.0000074657,
    0.0000052578,
    0.0000037029,
    0.0000026078,
    0.0000018366,
    0.0000012934,
    0.00000091093,
    0.00000064153,
    0.00000045181,
];

/// CIE 1931 2-degree z-bar, 360 to 830 nm in 5 nm steps (Mitsuba's table).
const CIE_Z: [f32; CIE_SAMPLES] = [
    0.0006061,
    0.001086,
    0.001946,
    0.003486,
    0.006450001,
    0.01054999,
    0.02005001,
    0.03621,
    0.06785001,
    0.1102,
    0.2074,
    0.3713,
    0.6456,
    1.0390501,
    1.3856,
    1.62296,
    1.74706,
    1.7826,
    1.77211,
    1.7441,
    1.6692,
    1.5281,
    1.28764,
    1.0419,
    0.8129501,
    0.6162,
    0.46518,
    0.3533,
    0.272,
    0.2123,
    0.1582,
    0.1117,
    0.07824999,
    0.05725001,
    0.04216,
    0.02984,
    0.0203,
    0.0134,
    0.008749999,
    0.005749999,
    0.0039,
    0.002749999,
    0.0021,
    0.0018,
    0.001650001,
    0.0014,
    0.0011,
    0.001,
    0.0008,
    0.0006,
    0.00034,
    0.00024,
    0.00019,
    0.0001,
    0.00004999999,
    0.00003,
    0.00002,
    0.00001,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
];

/// CIE D65 relative spectral power, 360 to 830 nm in 5 nm steps, 100 at 560 nm (Mitsuba's
/// table).
const D65: [f32; CIE_SAMPLES] = [
    46.6383, 49.3637, 52.0891, 51.0323, 49.9755, 52.3118, 54.6482, 68.7015, 82.7549, 87.1204,
    91.486, 92.4589, 93.4318, 90.057, 86.6823, 95.7736, 104.865, 110.936, 117.008, 117.41, 117.812,
    116.336, 114.861, 115.392, 115.923, 112.367, 108.811, 109.082, 109.354, 108.578, 107.802,
    106.296, 104.79, 106.239, 107.689, 106.047, 104.405, 104.225, 104.046, 102.023, 100.0, 98.1671,
    96.3342, 96.0611, 95.788, 92.2368, 88.6856, 89.3459, 90.0062, 89.8026, 89.5991, 88.6489,
    87.6987, 85.4936, 83.2886, 83.4939, 83.6992, 81.863, 80.0268, 80.1207, 80.2146, 81.2462,
    82.2778, 80.281, 78.2842, 74.0027, 69.7213, 70.6652, 71.6091, 72.979, 74.349, 67.9765, 61.604,
    65.7448, 69.8856, 72.4863, 75.087, 69.3398, 63.5927, 55.0054, 46.4182, 56.6118, 66.8054,
    65.0941, 63.3828, 63.8434, 64.304, 61.8779, 59.4519, 55.7054, 51.959, 54.6998, 57.4406,
    58.8765, 60.3125,
];

/// XYZ to linear sRGB (Rec. 709 primaries, D65 white), rows; f32 as in Mitsuba.
const XYZ_TO_SRGB: [[f32; 3]; 3] = [
    [3.240479, -1.53715, -0.498535],
    [-0.969256, 1.875991, 0.041556],
    [0.055648, -0.204043, 1.057311],
];

/// A table of `CIE_SAMPLES` values at `wavelength` (in [360, 830]), interpolated linearly the
/// way Mitsuba's `cie1931_xyz` does (index clamped to the last interval).
fn lookup(table: &[f32; CIE_SAMPLES], wavelength: f64) -> f64 {
    let t = (wavelength - CIE_MIN) * ((CIE_SAMPLES - 1) as f64 / (CIE_MAX - CIE_MIN));
    let i0 = (t.max(0.0) as usize).min(CIE_SAMPLES - 2);
    let w1 = t - i0 as f64;
    let w0 = 1.0 - w1;
    w0.mul_add(f64::from(table[i0]), w1 * f64::from(table[i0 + 1]))
}

fn xyz_to_srgb(xyz: [f64; 3]) -> [f64; 3] {
    XYZ_TO_SRGB.map(|row| {
        row.iter()
            .zip(xyz)
            .map(|(&m, c)| f64::from(m) * c)
            .sum::<f64>()
    })
}

/// The spectrum's linear value at `w`; None outside its samples (there it is zero). The
/// samples must be sorted by wavelength (as `parse_spectrum_pairs` gives them).
fn value_at(samples: &[(f64, f64)], w: f64) -> Option<f64> {
    let (first, last) = (samples.first()?, samples.last()?);
    if w < first.0 || w > last.0 || samples.len() < 2 {
        return None;
    }
    // The last sample at or below w, within [0, len - 2] (Mitsuba's find_interval).
    let index = samples
        .partition_point(|s| s.0 <= w)
        .saturating_sub(1)
        .min(samples.len() - 2);
    let ((w0, v0), (w1, v1)) = (samples[index], samples[index + 1]);
    if w1 <= w0 {
        return Some(v1);
    }
    Some(((w - w1) * v0 + (w0 - w) * v1) / (w0 - w1))
}

/// `spectrum_list_to_srgb`: linear sRGB of the spectrum, weighted by D65 or not.
fn spectrum_to_srgb(samples: &[(f64, f64)], d65: bool) -> [f64; 3] {
    let mut xyz = [0.0f64; 3];
    for i in 0..INTEGRATION_STEPS {
        let w = CIE_MIN + (i as f64 / (INTEGRATION_STEPS - 1) as f64) * (CIE_MAX - CIE_MIN);
        let Some(v) = value_at(samples, w) else {
            continue;
        };
        let weight = if d65 {
            lookup(&D65, w) * CIE_D65_NORMALIZATION
        } else {
            1.0
        };
        for (sum, table) in xyz.iter_mut().zip([&CIE_X, &CIE_Y, &CIE_Z]) {
            *sum += lookup(table, w) * v * weight;
        }
    }
    let scale = (CIE_MAX - CIE_MIN) * CIE_Y_NORMALIZATION / INTEGRATION_STEPS as f64;
    xyz_to_srgb(xyz.map(|c| c * scale))
}

fn to_vec3(rgb: [f64; 3]) -> Vec3 {
    Vec3::new(rgb[0] as f32, rgb[1] as f32, rgb[2] as f32)
}

/// A reflectance (or other bounded, non-emitter) spectrum as Mitsuba's RGB variants use it:
/// weighted by D65, so that a constant spectrum gives about that constant in every channel,
/// then clipped to [0, 1] (Mitsuba warns "clamping out-of-gamut color" there). `samples` are
/// (wavelength in nm, value) sorted by wavelength, as `parse_spectrum_pairs` gives them.
pub fn reflectance_rgb(samples: &[(f64, f64)]) -> Vec3 {
    to_vec3(spectrum_to_srgb(samples, true).map(|c| c.clamp(0.0, 1.0)))
}

/// An unbounded non-emitter spectrum (a conductor's inline `eta` and `k`, a rough
/// dielectric's, a medium's coefficients: what Mitsuba reads with `get_unbounded_texture`) as
/// its RGB variants use it: weighted by D65 like a reflectance, but clipped below at 0 only.
pub fn unbounded_rgb(samples: &[(f64, f64)]) -> Vec3 {
    to_vec3(spectrum_to_srgb(samples, true).map(|c| c.max(0.0)))
}

/// An emitter's spectrum (radiance, irradiance, intensity) as Mitsuba's RGB variants use it:
/// not weighted by D65 (a constant spectrum of 1 gives the slightly purple (1.20, 0.95, 0.91)
/// of an equal-energy white in sRGB), clipped below at 0 only. Mitsuba converts the spectral
/// eta and k of its conductor presets this same way.
pub fn emission_rgb(samples: &[(f64, f64)]) -> Vec3 {
    to_vec3(spectrum_to_srgb(samples, false).map(|c| c.max(0.0)))
}

/// An emitter's spectrum given as one value (`<spectrum name="radiance" value="5"/>`): Mitsuba's
/// RGB variants take it as that constant over all wavelengths, `value` times the sRGB of
/// XYZ (1, 1, 1), so that they match its spectral variants. (A non-emitter's single value is
/// simply that value in every channel.)
pub fn uniform_emission_rgb(value: f64) -> Vec3 {
    to_vec3(xyz_to_srgb([1.0; 3]).map(|c| c * value))
}

/// Parses Mitsuba's `<spectrum value="...">` list of wavelength:value pairs, such as
/// "400:0.1, 500:0.2" (pairs separated by commas or white space, wavelengths in nm). As in
/// Mitsuba there must be at least two pairs and the wavelengths must increase; every number
/// must be finite. A single number without a colon (a uniform spectrum) is not a list: the
/// caller checks for that first.
pub fn parse_spectrum_pairs(text: &str) -> Result<Vec<(f64, f64)>, String> {
    let mut pairs = Vec::new();
    for token in text
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
    {
        let pair = token.split_once(':').and_then(|(w, v)| {
            let number = |s: &str| s.parse::<f64>().ok().filter(|x| x.is_finite());
            Some((number(w)?, number(v)?))
        });
        match pair {
            Some(pair) => pairs.push(pair),
            None => {
                return Err(format!(
                    "\"{}\" is not a wavelength:value pair of finite numbers",
                    crate::scene::echo(token)
                ));
            }
        }
    }
    check_samples(pairs)
}

/// Parses a spectral data file (`.spd`, as `<spectrum filename="...">` and Mitsuba's IOR
/// data use): one "wavelength value" pair per line, `#` starting a comment. The same rules as
/// `parse_spectrum_pairs` apply; errors name the line.
pub fn parse_spd(text: &str) -> Result<Vec<(f64, f64)>, String> {
    let mut pairs = Vec::new();
    for (index, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or_default();
        let numbers: Vec<&str> = line.split_whitespace().collect();
        if numbers.is_empty() {
            continue;
        }
        let parsed: Option<Vec<f64>> = numbers
            .iter()
            .map(|s| s.parse::<f64>().ok().filter(|x| x.is_finite()))
            .collect();
        match parsed.as_deref() {
            Some(&[w, v]) => pairs.push((w, v)),
            _ => {
                return Err(format!(
                    "line {}: expected a wavelength and a value, found \"{}\"",
                    index + 1,
                    crate::scene::echo(line.trim())
                ));
            }
        }
    }
    check_samples(pairs)
}

/// Mitsuba's rules for a sampled spectrum: two samples or more, wavelengths increasing.
fn check_samples(pairs: Vec<(f64, f64)>) -> Result<Vec<(f64, f64)>, String> {
    if pairs.len() < 2 {
        return Err(format!(
            "a spectrum needs at least two wavelength:value pairs, this one has {}",
            pairs.len()
        ));
    }
    if let Some(w) = pairs.windows(2).find(|w| w[1].0 <= w[0].0) {
        return Err(format!(
            "the wavelengths of a spectrum must increase, but {} follows {}",
            w[1].0, w[0].0
        ));
    }
    Ok(pairs)
}

/// Mitsuba's named indices of refraction (include/mitsuba/render/ior.h: Hecht's Optics, 0-20
/// degrees Celsius, about 589 nm), for `int_ior`/`ext_ior` given as a name.
const IORS: [(&str, f64); 23] = [
    ("vacuum", 1.0),
    ("helium", 1.000036),
    ("hydrogen", 1.000132),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.3330),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.5750),
    ("diamond", 2.419),
];

/// The names `named_ior` knows, for messages.
pub const IOR_NAMES: &[&str] = &names(IORS);

const fn names<T: Copy, const N: usize>(table: [(&'static str, T); N]) -> [&'static str; N] {
    let mut out = [""; N];
    let mut i = 0;
    while i < N {
        out[i] = table[i].0;
        i += 1;
    }
    out
}

/// The index of refraction Mitsuba gives a material name ("water", "bk7", ...); the name is
/// matched without regard to case, as Mitsuba lowercases it.
pub fn named_ior(name: &str) -> Option<f64> {
    let name = name.to_lowercase();
    IORS.iter().find(|(n, _)| *n == name).map(|&(_, ior)| ior)
}

/// Mitsuba's conductor presets as its RGB variants use them: (name, [eta, k]). Mitsuba reads the
/// spectral files resources/data/ior/NAME.eta.spd and NAME.k.spd at load time and, in an RGB
/// variant, turns each into RGB as an emission spectrum is (no D65 weighting, clipped at 0;
/// `ior_from_file` in include/mitsuba/render/ior.h). These are its numbers: read back with
/// `mi.traverse` from `conductor` BSDFs with `material` set, in Mitsuba 3.9.1's `scalar_rgb`
/// (f32, shortest round-trip form); `emission_rgb` of the .spd files reproduces them (a test
/// checks this on the files it can find).
const CONDUCTORS: [(&str, [[f32; 3]; 2]); 71] = [
    (
        "Ag",
        [
            [0.1552762, 0.116727956, 0.13838764],
            [4.8283544, 3.1222224, 2.1469011],
        ],
    ),
    (
        "Al",
        [
            [1.6575009, 0.8804047, 0.52124447],
            [9.223811, 6.269502, 4.837004],
        ],
    ),
    (
        "AlAs",
        [
            [3.605296, 3.2329378, 2.2163186],
            [0.0006794373, 0.0, 0.007512709],
        ],
    ),
    (
        "AlAs_palik",
        [
            [3.605296, 3.2329378, 2.2163186],
            [0.0006794373, 0.0, 0.007512709],
        ],
    ),
    (
        "AlSb",
        [[0.0, 4.1393747, 4.6692543], [0.0, 0.09400908, 1.30057]],
    ),
    (
        "AlSb_palik",
        [[0.0, 4.1393747, 4.6692543], [0.0, 0.09400908, 1.30057]],
    ),
    (
        "Au",
        [
            [0.14303598, 0.37530708, 1.4420453],
            [3.982997, 2.3855565, 1.6033592],
        ],
    ),
    (
        "Be",
        [
            [4.1850123, 3.1850293, 2.7840612],
            [3.835466, 3.0101223, 2.868994],
        ],
    ),
    (
        "Be_palik",
        [
            [4.1850123, 3.1850293, 2.7840612],
            [3.835466, 3.0101223, 2.868994],
        ],
    ),
    (
        "Cr",
        [
            [4.3696675, 2.9165053, 1.6549046],
            [5.206547, 4.231306, 3.7546988],
        ],
    ),
    ("CsI", [[2.1448996, 1.7023189, 1.6624272], [0.0, 0.0, 0.0]]),
    (
        "CsI_palik",
        [[2.1448996, 1.7023189, 1.6624272], [0.0, 0.0, 0.0]],
    ),
    (
        "Cu",
        [
            [0.20100547, 0.9237495, 1.1022154],
            [3.9132621, 2.4530451, 2.1420898],
        ],
    ),
    (
        "Cu2O",
        [
            [3.5517726, 2.9498696, 2.7518754],
            [0.11420702, 0.19389686, 0.6061339],
        ],
    ),
    (
        "Cu2O_palik",
        [
            [3.5517726, 2.9498696, 2.7518754],
            [0.11420702, 0.19389686, 0.6061339],
        ],
    ),
    (
        "CuO",
        [
            [3.247541, 2.4478052, 2.2102196],
            [0.52108955, 0.57003075, 0.72217894],
        ],
    ),
    (
        "CuO_palik",
        [
            [3.247541, 2.4478052, 2.2102196],
            [0.52108955, 0.57003075, 0.72217894],
        ],
    ),
    (
        "Cu_palik",
        [
            [0.21322851, 0.9197154, 1.1024108],
            [3.9218733, 2.4573317, 2.136584],
        ],
    ),
    (
        "Hg",
        [
            [2.3989387, 1.440028, 0.9095704],
            [6.327587, 4.371925, 3.4217637],
        ],
    ),
    (
        "HgTe",
        [
            [4.77904, 3.2311962, 2.6599011],
            [1.6316127, 1.5808104, 1.7292874],
        ],
    ),
    (
        "HgTe_palik",
        [
            [4.77904, 3.2311962, 2.6599011],
            [1.6316127, 1.5808104, 1.7292874],
        ],
    ),
    (
        "Hg_palik",
        [
            [2.3989387, 1.440028, 0.9095704],
            [6.327587, 4.371925, 3.4217637],
        ],
    ),
    (
        "Ir",
        [
            [3.0863, 2.0821905, 1.6179146],
            [5.592153, 4.067088, 3.267312],
        ],
    ),
    (
        "Ir_palik",
        [
            [3.0863, 2.0821905, 1.6179146],
            [5.592153, 4.067088, 3.267312],
        ],
    ),
    (
        "K",
        [
            [0.06404319, 0.046409767, 0.038184915],
            [2.1041996, 1.34894, 0.9131259],
        ],
    ),
    (
        "K_palik",
        [
            [0.06404319, 0.046409767, 0.038184915],
            [2.1041996, 1.34894, 0.9131259],
        ],
    ),
    (
        "Li",
        [
            [0.26579094, 0.19561832, 0.22094862],
            [3.540155, 2.3111234, 1.6686072],
        ],
    ),
    (
        "Li_palik",
        [
            [0.26579094, 0.19561832, 0.22094862],
            [3.540155, 2.3111234, 1.6686072],
        ],
    ),
    (
        "MgO",
        [
            [2.0895839, 1.6507235, 1.594879],
            [4.3326952e-12, 0.0, 2.4986457e-11],
        ],
    ),
    (
        "MgO_palik",
        [
            [2.0895839, 1.6507235, 1.594879],
            [4.3326952e-12, 0.0, 2.4986457e-11],
        ],
    ),
    (
        "Mo",
        [
            [4.483974, 3.5251307, 2.7763104],
            [4.1114373, 3.420827, 3.1506073],
        ],
    ),
    (
        "Mo_palik",
        [
            [4.483974, 3.5251307, 2.7763104],
            [4.1114373, 3.420827, 3.1506073],
        ],
    ),
    (
        "Na_palik",
        [
            [0.060269356, 0.056140948, 0.061988432],
            [3.1792734, 2.1124904, 1.5790411],
        ],
    ),
    (
        "Nb",
        [
            [3.420074, 2.7900932, 2.3956294],
            [3.4413946, 2.7376661, 2.5797458],
        ],
    ),
    (
        "Nb_palik",
        [
            [3.420074, 2.7900932, 2.3956294],
            [3.4413946, 2.7376661, 2.5797458],
        ],
    ),
    (
        "Ni_palik",
        [
            [2.3673046, 1.6633731, 1.4670781],
            [4.4988117, 3.050153, 2.3454392],
        ],
    ),
    (
        "Rh",
        [
            [2.5857935, 1.8602164, 1.5542634],
            [6.7822604, 4.702987, 3.976073],
        ],
    ),
    (
        "Rh_palik",
        [
            [2.5857935, 1.8602164, 1.5542634],
            [6.7822604, 4.702987, 3.976073],
        ],
    ),
    (
        "Se",
        [
            [4.0583115, 2.842935, 2.8208535],
            [0.75404954, 0.6384435, 0.52180755],
        ],
    ),
    (
        "Se-e",
        [
            [5.722849, 4.165736, 4.0813384],
            [0.8711363, 1.1051575, 1.5653203],
        ],
    ),
    (
        "Se-e_palik",
        [
            [5.722849, 4.165736, 4.0813384],
            [0.8711363, 1.1051575, 1.5653203],
        ],
    ),
    (
        "Se_palik",
        [
            [4.0583115, 2.842935, 2.8208535],
            [0.75404954, 0.6384435, 0.52180755],
        ],
    ),
    (
        "SiC",
        [
            [3.1723416, 2.5259717, 2.4793706],
            [7.5376636e-07, 0.0, 1.0192531e-05],
        ],
    ),
    (
        "SiC_palik",
        [
            [3.1723416, 2.5259717, 2.4793706],
            [7.5376636e-07, 0.0, 1.0192531e-05],
        ],
    ),
    ("SnTe", [[4.5242496, 1.981645, 1.2815913], [0.0, 0.0, 0.0]]),
    (
        "SnTe_palik",
        [[4.5242496, 1.981645, 1.2815913], [0.0, 0.0, 0.0]],
    ),
    (
        "Ta",
        [
            [2.062721, 2.3929389, 2.6279287],
            [2.4083598, 1.7414864, 1.9470278],
        ],
    ),
    (
        "Ta_palik",
        [
            [2.062721, 2.3929389, 2.6279287],
            [2.4083598, 1.7414864, 1.9470278],
        ],
    ),
    (
        "Te",
        [
            [7.3902335, 4.482105, 2.637106],
            [3.2560222, 3.5270588, 3.2920542],
        ],
    ),
    (
        "Te-e",
        [
            [7.508907, 4.2964287, 2.3699877],
            [5.5839286, 4.947205, 3.9975922],
        ],
    ),
    (
        "Te-e_palik",
        [
            [7.508907, 4.2964287, 2.3699877],
            [5.5839286, 4.947205, 3.9975922],
        ],
    ),
    (
        "Te_palik",
        [
            [7.3902335, 4.482105, 2.637106],
            [3.2560222, 3.5270588, 3.2920542],
        ],
    ),
    ("ThF4", [[1.8307136, 1.4422286, 1.3876476], [0.0, 0.0, 0.0]]),
    (
        "ThF4_palik",
        [[1.8307136, 1.4422286, 1.3876476], [0.0, 0.0, 0.0]],
    ),
    (
        "TiC",
        [
            [3.7005284, 2.8374221, 2.582287],
            [3.265635, 2.3515892, 2.1727905],
        ],
    ),
    (
        "TiC_palik",
        [
            [3.7005284, 2.8374221, 2.582287],
            [3.265635, 2.3515892, 2.1727905],
        ],
    ),
    (
        "TiN",
        [
            [1.6484497, 1.150516, 1.3798234],
            [3.368328, 1.9434981, 1.1020677],
        ],
    ),
    (
        "TiN_palik",
        [
            [1.6484497, 1.150516, 1.3798234],
            [3.368328, 1.9434981, 1.1020677],
        ],
    ),
    (
        "TiO2",
        [
            [3.45661, 2.8017359, 2.905175],
            [0.00010526484, 0.0, 0.0006528865],
        ],
    ),
    (
        "TiO2-e",
        [
            [3.1065645, 2.5131683, 2.5824444],
            [2.9751605e-05, 0.0, 0.00018269809],
        ],
    ),
    (
        "TiO2-e_palik",
        [
            [3.1065645, 2.5131683, 2.5824444],
            [2.9751605e-05, 0.0, 0.00018269809],
        ],
    ),
    (
        "TiO2_palik",
        [
            [3.45661, 2.8017359, 2.905175],
            [0.00010526484, 0.0, 0.0006528865],
        ],
    ),
    (
        "VC",
        [
            [3.657566, 2.752736, 2.532672],
            [3.0683007, 2.1986873, 1.9631927],
        ],
    ),
    (
        "VC_palik",
        [
            [3.657566, 2.752736, 2.532672],
            [3.0683007, 2.1986873, 1.9631927],
        ],
    ),
    (
        "VN",
        [
            [2.8656023, 2.119189, 1.9400911],
            [3.0322425, 2.0561156, 1.6163063],
        ],
    ),
    (
        "VN_palik",
        [
            [2.8656023, 2.119189, 1.9400911],
            [3.0322425, 2.0561156, 1.6163063],
        ],
    ),
    (
        "V_palik",
        [
            [4.277582, 3.5129488, 2.7610714],
            [3.4913008, 2.8894548, 3.111522],
        ],
    ),
    (
        "W",
        [
            [4.3708167, 3.3002465, 2.9984074],
            [3.5006406, 2.604874, 2.2732332],
        ],
    ),
    (
        "a-C",
        [
            [2.9440458, 2.2271364, 1.9681617],
            [0.8874649, 0.7992985, 0.81529],
        ],
    ),
    ("d-C", [[2.7087197, 2.3188257, 2.2288976], [0.0, 0.0, 0.0]]),
    (
        "d-C_palik",
        [[2.7087197, 2.3188257, 2.2288976], [0.0, 0.0, 0.0]],
    ),
];

/// The conductor preset names `conductor_eta_k` knows, for messages (Mitsuba's `none`, a
/// perfect mirror, is not among them: the caller handles it).
pub const CONDUCTOR_NAMES: &[&str] = &names(CONDUCTORS);

/// A conductor preset's (eta, k) as Mitsuba's RGB variants use them ("Au", "Cu_palik", ...);
/// the name is case-sensitive, as Mitsuba's file lookup is. None for an unknown name and for
/// "none" (Mitsuba's ideal mirror, eta 0 and k 1), which the caller handles.
pub fn conductor_eta_k(name: &str) -> Option<(Vec3, Vec3)> {
    CONDUCTORS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|&(_, [eta, k])| (Vec3::from_array(eta), Vec3::from_array(k)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mitsuba 3.9.1's own numbers (scalar_rgb, `mi.traverse`), f32.
    fn assert_close(got: Vec3, want: [f32; 3], tolerance: f32, what: &str) {
        let want = Vec3::from_array(want);
        let scale = want.abs().max_element().max(1.0);
        assert!(
            (got - want).abs().max_element() <= tolerance * scale,
            "{what}: got {got}, Mitsuba gives {want}"
        );
    }

    fn pairs(text: &str) -> Vec<(f64, f64)> {
        parse_spectrum_pairs(text).unwrap()
    }

    #[test]
    fn spectrum_reflectance_matches_mitsuba() {
        let flat = reflectance_rgb(&pairs("400:0.78, 700:0.78"));
        // The brief's figures to 3 decimals, then Mitsuba's to float precision.
        for (got, want) in flat.to_array().iter().zip([0.776, 0.780, 0.776]) {
            assert!((got - want).abs() < 5e-4, "{flat}");
        }
        assert_close(
            flat,
            [0.7763668, 0.77981, 0.7760291],
            1e-6,
            "0.78 at 400-700 nm",
        );
        // The same spectrum with four samples (single_sphere.xml's light BSDF).
        let four = reflectance_rgb(&pairs("400:0.78, 500:0.78, 600:0.78, 700:0.78"));
        assert_close(four, [0.7763668, 0.77981, 0.7760291], 1e-6, "four samples");
        let varied = reflectance_rgb(&pairs("400:0.1, 500:0.9, 600:0.2, 700:0.6"));
        assert_close(varied, [0.09187168, 0.639466, 0.5306806], 1e-6, "varied");
        // Out of gamut: clipped to [0, 1] per channel.
        let narrow = reflectance_rgb(&pairs("550:1, 560:1"));
        assert_close(narrow, [0.01247926, 0.1371984, 0.0], 1e-6, "narrow band");
        let bright = reflectance_rgb(&pairs("380:2, 780:2"));
        assert_eq!(bright, Vec3::ONE);
        let red = reflectance_rgb(&pairs("620:0.9, 700:0.1"));
        assert_close(red, [0.31119052, 0.0, 0.0], 1e-6, "red");
    }

    #[test]
    fn spectrum_unbounded_matches_mitsuba() {
        // A conductor's inline eta (and k): D65-weighted, not clipped at 1.
        let eta = unbounded_rgb(&pairs("400:0.2, 500:1.5, 600:2.5, 700:3"));
        assert_close(eta, [2.7967281, 1.9487159, 0.75212073], 1e-6, "eta");
        let flat = unbounded_rgb(&pairs("400:0.78, 700:0.78"));
        assert_close(flat, [0.7763668, 0.77981, 0.7760291], 1e-6, "flat");
        let narrow = unbounded_rgb(&pairs("550:1, 560:1"));
        assert_close(narrow, [0.01247926, 0.1371984, 0.0], 1e-6, "narrow");
    }

    #[test]
    fn spectrum_constant_reflectance_is_the_constant() {
        // D65 weighting maps a constant to (nearly) itself; Mitsuba's 1000-step sum gives
        // 0.49949 for 0.5, and samples beyond 360-830 nm change nothing.
        for text in ["360:0.5, 830:0.5", "300:0.5, 900:0.5"] {
            let rgb = reflectance_rgb(&pairs(text));
            assert!((rgb - Vec3::splat(0.5)).abs().max_element() < 1e-3, "{rgb}");
            assert_close(rgb, [0.49949265, 0.49943686, 0.4994008], 1e-6, text);
        }
    }

    #[test]
    fn spectrum_emission_matches_mitsuba() {
        // The area light of mitsuba-data tests/scenes/bsdf_spheres/fragments/single_sphere.xml.
        let light = emission_rgb(&pairs("400:0, 500:8, 600:15.6, 700:18.4"));
        for (got, want) in light.to_array().iter().zip([20.71, 10.85, 2.77]) {
            assert!((got - want).abs() < 5e-3, "{light}");
        }
        assert_close(
            light,
            [20.710836, 10.854634, 2.771152],
            1e-6,
            "single_sphere light",
        );
        // Unweighted: a constant is equal-energy white, purple in sRGB.
        let white = emission_rgb(&pairs("360:1, 830:1"));
        assert_close(white, [1.2048837, 0.9482282, 0.9092668], 1e-6, "constant 1");
        let visible = emission_rgb(&pairs("400:1, 700:1"));
        assert_close(
            visible,
            [1.1996936, 0.94952035, 0.90344334],
            1e-6,
            "400-700",
        );
        let spike = emission_rgb(&pairs("450:3, 460:0, 600:1"));
        assert_close(spike, [0.381388, 0.5923995, 0.2240235], 1e-6, "spike");
        // Zero outside the samples; negative channels clipped to 0, not above.
        assert_eq!(emission_rgb(&pairs("300:1, 359:1")), Vec3::ZERO);
        let negative = emission_rgb(&pairs("500:-1, 600:-1"));
        assert_close(negative, [0.0, 0.0, 0.08555682], 1e-6, "negative");
        let uniform = uniform_emission_rgb(5.0);
        assert_close(uniform, [6.0239697, 4.741455, 4.5445805], 1e-6, "uniform 5");
    }

    #[test]
    fn spectrum_pairs_parse_and_malformed_lists_are_rejected() {
        assert_eq!(pairs("400:0.1, 500:0.2"), vec![(400.0, 0.1), (500.0, 0.2)]);
        assert_eq!(
            pairs(" 400:0.1,500:2e-1\n\t600:-3 ,, "),
            vec![(400.0, 0.1), (500.0, 0.2), (600.0, -3.0)]
        );
        let cases = [
            ("500:0.1, 400:0.2", "must increase, but 400 follows 500"),
            ("400:0.1, 500:0.2, 500:0.3", "500 follows 500"),
            ("400:0.1", "at least two"),
            ("", "at least two"),
            ("0.5", "\"0.5\" is not a wavelength:value pair"),
            ("400:0.1, 500", "\"500\""),
            ("400:0.1:3, 500:1", "\"400:0.1:3\""),
            ("400:x, 500:1", "\"400:x\""),
            ("400:nan, 500:1", "finite"),
            ("400:0.1, inf:1", "finite"),
        ];
        for (text, phrase) in cases {
            let e = parse_spectrum_pairs(text).expect_err(text);
            assert!(e.contains(phrase), "{text:?}: {phrase:?} missing from {e}");
        }
    }

    #[test]
    fn spectrum_spd_files_parse() {
        let text = "# header\n# ; more\n400 0.5\n  500\t0.25 # note\n\n600 1\n";
        assert_eq!(
            parse_spd(text).unwrap(),
            vec![(400.0, 0.5), (500.0, 0.25), (600.0, 1.0)]
        );
        let e = parse_spd("400 0.5\n500 0.2 7\n").unwrap_err();
        assert!(e.contains("line 2"), "{e}");
        let e = parse_spd("500 0.5\n400 0.2\n").unwrap_err();
        assert!(e.contains("increase"), "{e}");
    }

    #[test]
    fn spectrum_named_iors() {
        assert_eq!(named_ior("water"), Some(1.333));
        assert_eq!(named_ior("BK7"), Some(1.5046));
        assert_eq!(named_ior("Diamond"), Some(2.419));
        assert_eq!(named_ior("carbon dioxide"), Some(1.00045));
        assert_eq!(named_ior("vacuum"), Some(1.0));
        assert_eq!(named_ior("glass"), None);
        assert_eq!(IOR_NAMES.len(), 23);
        assert!(IOR_NAMES.iter().all(|n| named_ior(n).is_some()));
    }

    #[test]
    fn spectrum_conductor_presets() {
        let (eta, k) = conductor_eta_k("Au").unwrap();
        assert_close(eta, [0.14303598, 0.37530708, 1.4420453], 0.0, "Au eta");
        assert_close(k, [3.982997, 2.3855565, 1.6033592], 0.0, "Au k");
        let (eta, k) = conductor_eta_k("Cu").unwrap();
        assert_close(eta, [0.20100547, 0.9237495, 1.1022154], 0.0, "Cu eta");
        assert_close(k, [3.9132621, 2.4530451, 2.1420898], 0.0, "Cu k");
        assert_eq!(conductor_eta_k("none"), None);
        assert_eq!(conductor_eta_k("au"), None);
        assert_eq!(CONDUCTOR_NAMES.len(), 71);
        assert!(CONDUCTOR_NAMES.iter().all(|n| conductor_eta_k(n).is_some()));
        for name in [
            "Ag",
            "Al",
            "Cr",
            "Cu_palik",
            "W",
            "a-C",
            "d-C",
            "TiO2-e_palik",
        ] {
            assert!(CONDUCTOR_NAMES.contains(&name), "{name}");
        }
    }

    /// Converts a preset's .spd files as Mitsuba's RGB variants do and compares with the table.
    fn check_preset_files(dir: &std::path::Path, name: &str) {
        let read = |part: &str| {
            let path = dir.join(format!("{name}.{part}.spd"));
            let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
            emission_rgb(&parse_spd(&text).unwrap_or_else(|e| panic!("{path:?}: {e}")))
        };
        let (eta, k) = conductor_eta_k(name).unwrap();
        for (got, want, part) in [(read("eta"), eta, "eta"), (read("k"), k, "k")] {
            assert_close(got, want.to_array(), 1e-6, &format!("{name} {part}"));
        }
    }

    #[test]
    fn spectrum_conductor_presets_match_their_spd_files() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/scenes/mitsuba/ior");
        for name in ["Au", "Cu"] {
            check_preset_files(&dir, name);
        }
        // Every preset, where Mitsuba's data folder is named (its resources/data/ior, or the
        // Python package's mitsuba/data/ior).
        match std::env::var_os("MITSUBA_IOR_DIR") {
            Some(dir) => {
                for name in CONDUCTOR_NAMES {
                    check_preset_files(std::path::Path::new(&dir), name);
                }
            }
            None => eprintln!(
                "spectrum_conductor_presets_match_their_spd_files: MITSUBA_IOR_DIR is not set, \
                 so only Au and Cu were checked against their .spd files"
            ),
        }
    }
}

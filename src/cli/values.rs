//! The value parsers of the command line's arguments, and how its errors are printed.

use super::*;

/// Parses an integrator name: unknown names and planned-but-unbuilt ones are clear errors.
/// Parses an integrator name; `--help` lists the registry's integrators with their
/// descriptions.
#[derive(Clone)]
pub(super) struct IntegratorParser;

impl clap::builder::TypedValueParser for IntegratorParser {
    type Value = IntegratorKind;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> std::result::Result<IntegratorKind, clap::Error> {
        let name = value.to_string_lossy();
        IntegratorKind::from_name(&name).map_err(|e| {
            let arg = arg.map_or_else(|| "--integrator".to_string(), |a| a.to_string());
            clap::Error::raw(
                clap::error::ErrorKind::InvalidValue,
                format!("invalid value '{name}' for '{arg}': {e}\n"),
            )
            .with_cmd(cmd)
        })
    }

    fn possible_values(
        &self,
    ) -> Option<Box<dyn Iterator<Item = clap::builder::PossibleValue> + '_>> {
        Some(Box::new(IntegratorKind::all().into_iter().map(|k| {
            clap::builder::PossibleValue::new(k.as_str()).help(k.description())
        })))
    }
}

pub(super) fn parse_sampler(s: &str) -> std::result::Result<SamplerKind, String> {
    s.parse::<SamplerKind>().map_err(|e| e.to_string())
}

pub(super) fn parse_lanes(s: &str) -> std::result::Result<crate::lanes::LaneWidth, String> {
    s.trim()
        .parse()
        .ok()
        .and_then(crate::lanes::LaneWidth::of)
        .ok_or_else(|| format!("expected 8 or 16, not {}", clip_word(s)))
}

pub(super) fn parse_shard(s: &str) -> std::result::Result<(u64, u64), String> {
    let bad = || {
        format!(
            "expected I/N (shard I of N, 1 <= I <= N), not {}",
            clip_word(s)
        )
    };
    let (i, n) = s.split_once('/').ok_or_else(bad)?;
    let (i, n): (u64, u64) = (
        i.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if i == 0 || i > n {
        return Err(bad());
    }
    Ok((i, n))
}

pub(super) fn parse_pass_range(s: &str) -> std::result::Result<(u64, u64), String> {
    let bad = || format!("expected FIRST..END with FIRST < END, not {}", clip_word(s));
    let (a, b) = s.split_once("..").ok_or_else(bad)?;
    let (a, b): (u64, u64) = (
        a.trim().parse().map_err(|_| bad())?,
        b.trim().parse().map_err(|_| bad())?,
    );
    if a >= b {
        return Err(bad());
    }
    Ok((a, b))
}

pub(super) fn parse_probability(s: &str) -> std::result::Result<f32, String> {
    match s.parse::<f32>() {
        Ok(p) if (0.0..=1.0).contains(&p) => Ok(p),
        _ => Err(format!("expected a probability in [0, 1], not {s}")),
    }
}

pub(super) fn parse_mutations(s: &str) -> std::result::Result<u8, String> {
    use crate::mlt::path_chains::MutationKind;
    let mut bits = 0u8;
    for name in s.split(',').map(str::trim) {
        let kind = MutationKind::parse(name).ok_or_else(|| {
            format!("unknown mutation {name:?}; expected bidir, lens, caustic or multichain")
        })?;
        bits |= 1 << kind as u8;
    }
    if bits & (1 << MutationKind::Bidirectional as u8) == 0 {
        return Err(
            "the mutations must include bidir: the perturbations alone cannot reach every path"
                .into(),
        );
    }
    Ok(bits)
}

pub(super) fn parse_lens_min(s: &str) -> std::result::Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v > 0.0 && v.is_finite() => Ok(v),
        _ => Err(format!("expected a positive number of pixels, not {s}")),
    }
}

pub(super) fn parse_sigma(s: &str) -> std::result::Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v > 0.0 && v.is_finite() => Ok(v),
        _ => Err(format!("expected a positive sigma, not {s}")),
    }
}

pub(super) fn parse_alpha(s: &str) -> std::result::Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v > 0.0 && v < 1.0 => Ok(v),
        _ => Err(format!(
            "alpha must be a number in (0, 1), not {}",
            clip_word(s)
        )),
    }
}

pub(super) fn parse_radius(s: &str) -> std::result::Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!(
            "the radius must be a positive number, not {}",
            clip_word(s)
        )),
    }
}

/// One budget of --budgets (the list as a whole is checked after parsing).
pub(super) fn parse_budget(s: &str) -> std::result::Result<f64, String> {
    if s.trim().is_empty() {
        return Err("the budget list is empty (or has an empty entry)".into());
    }
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("'{}' is not a number", clip_word(s)))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("budget {} is not a positive number", clip_word(s)))
    }
}

pub(super) fn parse_seconds(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("'{}' is not a number of seconds", clip_word(s)))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!(
            "the time must be a positive number of seconds, not {}",
            clip_word(s)
        ))
    }
}

/// The longest time between checkpoints (about 31 years; a Duration holds no more than
/// 1.8e19 seconds).
pub const MAX_CHECKPOINT_SECONDS: f64 = 1e9;

pub(super) fn parse_checkpoint_seconds(s: &str) -> std::result::Result<f64, String> {
    let v = parse_seconds(s)?;
    if v <= MAX_CHECKPOINT_SECONDS {
        Ok(v)
    } else {
        Err(format!(
            "at most {MAX_CHECKPOINT_SECONDS:e} seconds between checkpoints, not {}",
            clip_word(s)
        ))
    }
}

/// Longest word of a message repeated whole: a longer one (a 300-digit number) is cut.
pub(super) const MAX_WORD: usize = 64;

/// A word of the user's as a message repeats it: its first 12 and last 24 characters, the
/// middle cut, when it is longer than `MAX_WORD` (a long path keeps the end of its file name,
/// line and column).
pub(super) fn clip_word(s: &str) -> String {
    let count = s.chars().count();
    if count <= MAX_WORD {
        return s.to_string();
    }
    let head: String = s.chars().take(12).collect();
    let tail: String = s.chars().skip(count - 24).collect();
    format!("{head}...({count} characters)...{tail}")
}

/// An error message as printed: one line (line breaks become spaces), every overlong word
/// cut (`clip_word`), and at most 2000 characters in all.
pub fn one_line(message: &str) -> String {
    let words: Vec<String> = message
        .split([' ', '\n', '\r', '\t'])
        .filter(|w| !w.is_empty())
        .map(clip_word)
        .collect();
    crate::scene::clip(&words.join(" "), 2000)
}

/// `-D NAME=VALUE`: a Mitsuba scene parameter (its `$NAME`), overriding the file's default.
pub(super) fn parse_define(s: &str) -> std::result::Result<(String, String), String> {
    let (name, value) = s
        .split_once('=')
        .ok_or_else(|| format!("'{}' is not NAME=VALUE", clip_word(s)))?;
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(format!(
            "'{}': a parameter name is letters, digits and underscores",
            clip_word(name)
        ));
    }
    Ok((name.to_string(), value.to_string()))
}

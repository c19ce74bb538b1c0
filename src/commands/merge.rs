//! `stagelight merge PART.exr... -o OUT.exr`: adds the partial films of a render's shards
//! (`render` or `reference` with `--shard I/N` or `--pass-range`) into the film of all their
//! passes, and writes its EXR and PNG as one machine rendering every pass would have.
//!
//! Each part's film is its checkpoint, `PART.exr.checkpoint`, which records the integrator,
//! seed, sampler, depth cap, settings, scene fingerprint and pass range it was made with. The
//! parts must agree on all of these and their passes must cover the render's, each pass once;
//! every problem found is named. For the unbiased integrators (PT, BDPT) the film's
//! fixed-point sums do not depend on the order of their samples (`film::fixed`), so the merged
//! film, and the EXR written from it, are bit for bit those of one uninterrupted render. The
//! shards of the biased ones (MLT, the photon mappers) are independent runs, each with its own
//! seed, whose films hold their images times their weights (mutations, or passes x pixels):
//! adding them averages the images weighted by those.

use super::{check_outputs, print_out};
use crate::film::Film;
use crate::reference::{
    Checkpoint, CheckpointHeader, ReferenceLock, checkpoint_path, write_reference_images,
};
use anyhow::{Result, bail};
use std::path::{Path, PathBuf};

/// A part as read: where it came from and its checkpoint.
struct Part {
    film_path: PathBuf,
    checkpoint: Checkpoint,
}

impl Part {
    fn header(&self) -> &CheckpointHeader {
        &self.checkpoint.header
    }

    fn name(&self) -> String {
        self.film_path.display().to_string()
    }

    /// The passes the part was to render, `first..end`.
    fn intended(&self) -> (u64, u64) {
        let h = self.header();
        (h.first_pass, h.shard.map_or(h.passes, |s| s.end_pass))
    }
}

/// The film of a part given on the command line: `PART.exr.checkpoint` for `PART.exr`, or
/// the checkpoint itself when that is what was given.
pub fn part_film_path(part: &Path) -> PathBuf {
    if part.extension().is_some_and(|e| e == "checkpoint") {
        part.to_path_buf()
    } else {
        checkpoint_path(part)
    }
}

fn read_part(part: &Path) -> Result<Part> {
    let film_path = part_film_path(part);
    if !film_path.exists() {
        bail!(
            "{}: no partial film here (a shard writes it beside its image when rendered with \
             --shard I/N or --pass-range)",
            film_path.display()
        );
    }
    let checkpoint = Checkpoint::read(&film_path)?;
    if checkpoint.header.shard.is_none() {
        bail!(
            "{}: the film of a whole render (passes 0..{}), not of a shard: merge adds shards \
             made with --shard or --pass-range",
            film_path.display(),
            checkpoint.header.passes
        );
    }
    Ok(Part {
        film_path,
        checkpoint,
    })
}

/// What a part was made with that every part must share, by name, as text.
fn identity(h: &CheckpointHeader) -> Vec<(&'static str, String)> {
    let depth = if h.max_depth == u32::MAX {
        "unlimited".to_string()
    } else {
        h.max_depth.to_string()
    };
    let mut identity = vec![
        ("command", h.made_by.clone()),
        ("integrator", h.integrator.clone()),
        ("seed", h.seed.to_string()),
        ("sampler", h.sampler.clone()),
        ("maximum depth", depth),
        ("settings", format!("\"{}\"", h.settings)),
        ("image size", format!("{}x{}", h.width, h.height)),
        (
            "scene",
            format!("{} (fingerprint {})", h.scene, h.scene_fingerprint),
        ),
        (
            "total passes",
            h.shard.map_or(0, |s| s.total_passes).to_string(),
        ),
    ];
    // An unbiased part's film is in its scene's unit, so the parts of one scene agree on it
    // unless one was made by a stagelight from before units followed the scene. (A biased
    // part's unit follows its image; merge converts those.)
    if h.is_unbiased() {
        identity.push((
            "film unit",
            format!("2^{}", h.unit_exponent - crate::film::fixed::FRACTION_BITS),
        ));
    }
    identity
}

/// Checks that the parts belong to one render and cover each of its passes once; returns
/// every problem found.
fn problems(parts: &[Part]) -> Vec<String> {
    let mut problems = Vec::new();
    let first = &parts[0];
    let wanted = identity(first.header());
    for part in &parts[1..] {
        for ((what, a), (_, b)) in wanted.iter().zip(identity(part.header())) {
            // The scene's path may differ between machines; its fingerprint may not.
            let differs = if *what == "scene" {
                first.header().scene_fingerprint != part.header().scene_fingerprint
            } else {
                *a != b
            };
            if differs {
                problems.push(format!(
                    "{} was made with {what} {b}, but {} with {what} {a}: the parts of one \
                     render share it",
                    part.name(),
                    first.name()
                ));
            }
        }
    }
    if !problems.is_empty() {
        return problems;
    }
    let total = first.header().shard.map_or(0, |s| s.total_passes);
    // Passes the parts before this one were to cover (`0..covered`), and the part that ends
    // there. A shard stopped early is named as such, not as a gap between shards.
    let mut covered = 0u64;
    let mut last: Option<&Part> = None;
    for part in parts {
        let (start, end) = part.intended();
        if let Some(other) = last
            && start < covered
        {
            problems.push(format!(
                "{} (passes {start}..{end}) and {} (passes {}..{covered}) overlap in passes \
                 {start}..{}",
                part.name(),
                other.name(),
                other.intended().0,
                covered.min(end)
            ));
        } else if start > covered {
            problems.push(missing(covered, start, last));
        }
        let done = part.header().passes;
        if done < end {
            problems.push(format!(
                "passes {done}..{end} missing: {} stopped after pass {done} of its \
                 {start}..{end} (run that shard again: `reference --shard` resumes)",
                part.name()
            ));
        }
        if end > covered {
            covered = end;
            last = Some(part);
        }
    }
    if covered < total {
        problems.push(missing(covered, total, last));
    }
    problems
}

fn missing(from: u64, to: u64, after: Option<&Part>) -> String {
    match after {
        Some(part) => format!(
            "passes {from}..{to} missing: no part has them (the last part before them is {})",
            part.name()
        ),
        None => format!("passes {from}..{to} missing: no part has them"),
    }
}

/// Reads the parts and checks that they belong to one render and cover each of its passes
/// once (every problem named), in pass order.
fn read_parts(parts: &[PathBuf]) -> Result<Vec<Part>> {
    let mut read = parts
        .iter()
        .map(|p| read_part(p))
        .collect::<Result<Vec<_>>>()?;
    if read.is_empty() {
        bail!("no parts to merge");
    }
    read.sort_by_key(|p| (p.header().first_pass, p.header().passes));
    let found = problems(&read);
    if !found.is_empty() {
        bail!("cannot merge {} parts: {}", read.len(), found.join("; "));
    }
    Ok(read)
}

/// The film of all the parts' passes and its header (that of a whole render).
fn add_parts(read: &[Part]) -> Result<(CheckpointHeader, Film)> {
    let first = read[0].header().clone();
    // One unit for all: the parts' own for the unbiased integrators (`problems` checked that
    // they agree), the coarsest for the biased ones' weighted images, each rounded to it.
    let unit = read
        .iter()
        .map(|p| p.checkpoint.film.unit_exponent())
        .max()
        .unwrap_or(0);
    let mut film = Film::with_unit(first.width, first.height, unit);
    let mut header = CheckpointHeader {
        first_pass: 0,
        shard: None,
        passes: 0,
        seconds: 0.0,
        nonfinite: 0,
        nonfinite_splats: 0,
        out_of_range: 0,
        ..first
    };
    for part in read {
        let added = &part.checkpoint.film;
        let converted;
        let added = if added.unit_exponent() == unit {
            added
        } else {
            converted = added
                .in_unit(unit)
                .map_err(|e| anyhow::anyhow!("{}: {e}", part.name()))?;
            &converted
        };
        film.add_film(added)
            .map_err(|e| anyhow::anyhow!("{}: {e}", part.name()))?;
        let h = part.header();
        header.passes = header.passes.max(h.passes);
        header.seconds += h.seconds;
    }
    header.nonfinite = film.nonfinite;
    header.nonfinite_splats = film.nonfinite_splats;
    header.out_of_range = film.out_of_range;
    Ok((header, film))
}

/// The merged film of shards (`PART.exr` or their checkpoints), checked as `merge` checks
/// them, without writing anything: what a sharded comparison measures.
pub fn merged_film(parts: &[PathBuf]) -> Result<(CheckpointHeader, Film)> {
    add_parts(&read_parts(parts)?)
}

/// Merges the parts into `output` and says what it did. Returns the exit code (0).
pub fn merge(parts: &[PathBuf], output: &Path) -> Result<i32> {
    if output
        .extension()
        .is_none_or(|e| !e.eq_ignore_ascii_case("exr"))
    {
        bail!("{}: the output must be an .exr file", output.display());
    }
    let read = read_parts(parts)?;
    let is_reference = read[0].header().made_by == "reference";
    let png = output.with_extension("png");
    let merged_film_path = checkpoint_path(output);
    let mut outputs = vec![output, png.as_path()];
    if is_reference {
        outputs.push(&merged_film_path);
    }
    let inputs: Vec<&Path> = read.iter().map(|p| p.film_path.as_path()).collect();
    check_outputs(&outputs, &inputs)?;
    let (header, film) = add_parts(&read)?;

    if is_reference {
        // A merged reference is a reference: its checkpoint lets `reference` extend it.
        let _lock = ReferenceLock::acquire(output)?;
        Checkpoint {
            header: header.clone(),
            film: film.clone(),
        }
        .write(&merged_film_path)?;
        write_reference_images(output, &header, &film)?;
    } else {
        let image = film.image();
        image.write_exr(output)?;
        image.write_png(&png)?;
    }
    let mut report = format!(
        "merged {} parts: passes 0..{} of {} with seed {} ({:.1} s of rendering in all), {}\n",
        read.len(),
        header.passes,
        header.integrator,
        header.seed,
        header.seconds,
        header.scene
    );
    if !header.is_unbiased() {
        report += &format!(
            "the parts are independent runs: the image is their average, weighted by {}\n",
            if header.integrator.contains("mlt") {
                "their mutations"
            } else {
                "their passes"
            }
        );
    }
    report += &format!("wrote {} and {}", output.display(), png.display());
    if is_reference {
        report += &format!(" and {}", merged_film_path.display());
    }
    report += "\n";
    print_out(&report);
    Ok(0)
}

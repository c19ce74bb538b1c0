//! `stagelight view A.exr [B.exr ...] -o page.html`: the report's viewer over any images.

use super::{Page, PageImage, ResultsTable, TableCell, TableRow};
use crate::compare::format::sci;
use crate::film::Image;
use anyhow::{Result, bail};
use std::path::{Path, PathBuf};

/// What `view` was asked for.
pub struct ViewOptions {
    pub images: Vec<PathBuf>,
    /// The image flips go to and error maps are measured against (None: the first image).
    pub reference: Option<PathBuf>,
    pub output: PathBuf,
}

/// Writes the page and its data folder; prints what it wrote.
pub fn view(o: &ViewOptions) -> Result<()> {
    let (reference_path, shown): (&Path, Vec<&PathBuf>) = match &o.reference {
        Some(r) => (r, o.images.iter().collect()),
        None => match o.images.split_first() {
            Some((first, rest)) if !rest.is_empty() => (first, rest.iter().collect()),
            _ => bail!(
                "view needs two images at least (the first is the reference, unless \
                 --reference names one)"
            ),
        },
    };
    let mut inputs: Vec<&Path> = o.images.iter().map(|p| p.as_path()).collect();
    inputs.push(reference_path);
    let data_dir = super::data_dir_of(&o.output);
    crate::commands::check_outputs(&[&o.output], &inputs)?;
    if data_dir.exists() && !data_dir.is_dir() {
        bail!(
            "{}: is a file, but the page's images go into this folder",
            data_dir.display()
        );
    }
    let reference = Image::read_exr(reference_path)?;
    let images: Vec<Image> = shown
        .iter()
        .map(|p| Image::read_exr(p))
        .collect::<Result<_, _>>()?;
    for (path, image) in shown.iter().zip(&images) {
        if (image.width, image.height) != (reference.width, reference.height) {
            bail!(
                "{}: {}x{}, but the reference {} is {}x{}: the viewer compares images of one size",
                path.display(),
                image.width,
                image.height,
                reference_path.display(),
                reference.width,
                reference.height
            );
        }
    }
    let names = method_names(&shown);
    let rows = shown
        .iter()
        .zip(&images)
        .zip(&names)
        .enumerate()
        .map(|(i, ((path, image), name))| {
            let cells = match crate::metrics::compare(image, &reference) {
                Ok(m) => vec![
                    TableCell::text(name.clone()),
                    TableCell::number(sci(m.relmse), m.relmse),
                    TableCell::number(sci(m.rmse), m.rmse),
                    TableCell::number(sci(m.mae), m.mae),
                    TableCell::text(path.display().to_string()),
                ],
                Err(e) => vec![
                    TableCell::text(name.clone()),
                    TableCell::text(e.to_string()),
                    TableCell::text(""),
                    TableCell::text(""),
                    TableCell::text(path.display().to_string()),
                ],
            };
            TableRow {
                image: Some(i),
                cells,
            }
        })
        .collect();
    let page = Page {
        title: format!(
            "{} images against {}",
            images.len(),
            reference_path.display()
        ),
        notes: vec![format!(
            "Flip (F) and error maps (E) are against the reference, {}. The viewer shows the \
             images' float32 values.",
            reference_path.display()
        )],
        reference: PageImage {
            method: "reference".into(),
            group: String::new(),
            source: Some(reference_path.display().to_string()),
            image: &reference,
        },
        images: shown
            .iter()
            .zip(&images)
            .zip(names)
            .map(|((path, image), method)| PageImage {
                method,
                group: String::new(),
                source: Some(path.display().to_string()),
                image,
            })
            .collect(),
        plot_svg: None,
        table: Some(ResultsTable {
            columns: ["image", "relMSE", "RMSE", "MAE", "file"]
                .iter()
                .map(|s| s.to_string())
                .collect(),
            rows,
        }),
        links: Vec::new(),
    };
    super::write_page(&page, &o.output)?;
    crate::commands::print_out(&format!(
        "wrote {} and its images in {}/: open it in a browser (file://{})\n",
        o.output.display(),
        data_dir.display(),
        std::path::absolute(&o.output)
            .unwrap_or_else(|_| o.output.clone())
            .display()
    ));
    Ok(())
}

/// Each image's name in the viewer: its file stem, or its path where stems repeat.
fn method_names(paths: &[&PathBuf]) -> Vec<String> {
    let stem = |p: &Path| {
        p.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| p.display().to_string())
    };
    paths
        .iter()
        .map(|p| {
            let own = stem(p);
            if paths.iter().filter(|q| stem(q) == own).count() > 1 {
                p.display().to_string()
            } else {
                own
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repeated_stems_are_named_by_path() {
        let paths = [
            PathBuf::from("a/pt.exr"),
            PathBuf::from("b/pt.exr"),
            PathBuf::from("b/bdpt.exr"),
        ];
        let refs: Vec<&PathBuf> = paths.iter().collect();
        assert_eq!(method_names(&refs), ["a/pt.exr", "b/pt.exr", "bdpt"]);
    }
}

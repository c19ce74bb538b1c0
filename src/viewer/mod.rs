//! The interactive image viewer: one HTML page that opens from the file system, offline, with
//! every image's linear floats beside it (compare's `index.html`, and `stagelight view`).
//!
//! The page is `page.html`; its images lie in `page_data/` beside it, one script per image
//! (`<script src>` loads from `file://` where `fetch` is refused). Each script hands the page
//! the image in the float format below; the page decodes it, tone-maps it with its exposure,
//! and computes the error maps itself, so its pixel readout shows the EXR's own values.
//!
//! Float format ("f32-planes-zlib"): the red, green and blue planes of the image (rows from the
//! top) as little-endian float32, their bytes regrouped by significance (every value's byte 0,
//! then every byte 1, ...) so that the slowly varying exponent bytes sit together, then
//! zlib-compressed and written as base64. The page inflates it with the browser's
//! `DecompressionStream`. Lossless: the floats are the image's, bit for bit.

pub mod view;

use crate::film::Image;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The page's script and style, written by hand for stagelight.
const VIEWER_JS: &str = include_str!("viewer.js");
const VIEWER_CSS: &str = include_str!("viewer.css");

/// The float format's name in the page's manifest.
pub const FLOAT_FORMAT: &str = "f32-planes-zlib";

/// A page could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", .path.display())]
pub struct PageError {
    pub path: PathBuf,
    pub message: String,
}

fn page_error(path: &Path, message: impl std::fmt::Display) -> PageError {
    PageError {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// One image of the page.
pub struct PageImage<'a> {
    /// What made it ("pt", or a file's stem): the method the viewer picks.
    pub method: String,
    /// Which images are shown side by side ("2 s"); "" for a page without groups.
    pub group: String,
    /// Where its float data came from or also lies (an EXR), shown beside it.
    pub source: Option<String>,
    pub image: &'a Image,
}

/// A results table: its columns, and rows whose cells sort by number where they have one.
#[derive(Serialize, Default)]
pub struct ResultsTable {
    pub columns: Vec<String>,
    pub rows: Vec<TableRow>,
}

#[derive(Serialize)]
pub struct TableRow {
    /// The image of `PageImage`s this row is about: a click on the row shows it.
    pub image: Option<usize>,
    pub cells: Vec<TableCell>,
}

#[derive(Serialize)]
pub struct TableCell {
    pub text: String,
    /// The number the column sorts by (None: sorts by text).
    pub value: Option<f64>,
}

impl TableCell {
    pub fn text(text: impl Into<String>) -> TableCell {
        TableCell {
            text: text.into(),
            value: None,
        }
    }

    pub fn number(text: impl Into<String>, value: f64) -> TableCell {
        TableCell {
            text: text.into(),
            // JSON has no infinity: an exact image's infinite efficiency sorts as the largest.
            value: Some(if value.is_finite() { value } else { f64::MAX }),
        }
    }
}

/// Everything a page shows.
pub struct Page<'a> {
    pub title: String,
    /// Sentences under the title (plain text).
    pub notes: Vec<String>,
    /// The image flips go to and error maps are measured against.
    pub reference: PageImage<'a>,
    pub images: Vec<PageImage<'a>>,
    /// An SVG document drawn inline (the error-against-time plot).
    pub plot_svg: Option<String>,
    pub table: Option<ResultsTable>,
    /// Links shown at the top (text, relative address), e.g. back to an index page.
    pub links: Vec<(String, String)>,
}

/// The manifest of one image, as the page's script reads it.
#[derive(Serialize)]
struct ImageEntry<'a> {
    id: String,
    method: &'a str,
    group: &'a str,
    source: Option<&'a str>,
    width: usize,
    height: usize,
    format: &'static str,
    script: String,
}

#[derive(Serialize)]
struct Manifest<'a> {
    title: &'a str,
    reference: ImageEntry<'a>,
    images: Vec<ImageEntry<'a>>,
    table: Option<&'a ResultsTable>,
}

/// The folder of a page's image scripts: `page_data` beside `page.html`.
pub fn data_dir_of(html: &Path) -> PathBuf {
    let stem = html
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "page".into());
    html.with_file_name(format!("{stem}_data"))
}

/// Writes the page as `html` and its images into `data_dir_of(html)`. Every image must have
/// the reference's size. Returns the paths written, the page first.
pub fn write_page(page: &Page, html: &Path) -> Result<Vec<PathBuf>, PageError> {
    let reference = page.reference.image;
    for img in &page.images {
        if (img.image.width, img.image.height) != (reference.width, reference.height) {
            return Err(page_error(
                html,
                format!(
                    "{} is {}x{}, but the reference {} is {}x{}: the viewer compares images of \
                     one size",
                    img.source.as_deref().unwrap_or(&img.method),
                    img.image.width,
                    img.image.height,
                    page.reference.source.as_deref().unwrap_or("image"),
                    reference.width,
                    reference.height
                ),
            ));
        }
    }
    let data_dir = data_dir_of(html);
    let data_name = data_dir
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    std::fs::create_dir_all(&data_dir).map_err(|e| page_error(&data_dir, e))?;
    let mut written = vec![html.to_path_buf()];
    let reference_entry = write_image("reference".into(), &page.reference, &data_dir)?;
    written.push(data_dir.join(&reference_entry.script));
    let mut entries = Vec::new();
    for (i, img) in page.images.iter().enumerate() {
        let entry = write_image(format!("image-{i:03}"), img, &data_dir)?;
        written.push(data_dir.join(&entry.script));
        entries.push(entry);
    }
    // The page names each script relative to itself, as a URL ("my page#2_data" is a name).
    let mut reference_entry = reference_entry;
    for entry in std::iter::once(&mut reference_entry).chain(entries.iter_mut()) {
        entry.script = format!("{}/{}", url_escape(&data_name), entry.script);
    }
    let manifest = Manifest {
        title: &page.title,
        reference: reference_entry,
        images: entries,
        table: page.table.as_ref(),
    };
    let html_text = page_html(page, &manifest);
    crate::film::output::write_bytes(html, html_text.as_bytes())
        .map_err(|e| page_error(html, e.message))?;
    Ok(written)
}

/// Writes one image's script into `data_dir`; its entry names the script by file name.
fn write_image<'a>(
    id: String,
    img: &'a PageImage<'a>,
    data_dir: &Path,
) -> Result<ImageEntry<'a>, PageError> {
    let file = format!("{id}.js");
    let path = data_dir.join(&file);
    crate::film::output::write_bytes(&path, image_script(&id, img.image).as_bytes())
        .map_err(|e| page_error(&path, e.message))?;
    Ok(ImageEntry {
        id,
        method: &img.method,
        group: &img.group,
        source: img.source.as_deref(),
        width: img.image.width,
        height: img.image.height,
        format: FLOAT_FORMAT,
        script: file,
    })
}

/// The script that hands one image to the page.
fn image_script(id: &str, image: &Image) -> String {
    format!(
        "stagelightImageData({}, \"{}\");\n",
        serde_json::to_string(id).unwrap_or_default(),
        base64(&encode_floats(image))
    )
}

/// The float format of the module's doc: planes, bytes by significance, zlib.
pub fn encode_floats(image: &Image) -> Vec<u8> {
    let n = image.pixels.len();
    let mut planes = vec![0u8; n * 12];
    for channel in 0..3 {
        for (i, p) in image.pixels.iter().enumerate() {
            let bytes = p[channel].to_le_bytes();
            let value = channel * n + i;
            for (b, byte) in bytes.iter().enumerate() {
                planes[b * 3 * n + value] = *byte;
            }
        }
    }
    miniz_oxide::deflate::compress_to_vec_zlib(&planes, 6)
}

/// The inverse of `encode_floats`, for tests: the image's floats, or a message.
pub fn decode_floats(bytes: &[u8], width: usize, height: usize) -> Result<Image, String> {
    let planes = miniz_oxide::inflate::decompress_to_vec_zlib(bytes)
        .map_err(|e| format!("not zlib data: {e:?}"))?;
    let n = width * height;
    if planes.len() != n * 12 {
        return Err(format!(
            "{} bytes of floats, not the {} of {width}x{height} RGB",
            planes.len(),
            n * 12
        ));
    }
    let mut image = Image::new(width, height);
    for channel in 0..3 {
        for (i, p) in image.pixels.iter_mut().enumerate() {
            let value = channel * n + i;
            let bytes = [0, 1, 2, 3].map(|b| planes[b * 3 * n + value]);
            p[channel] = f32::from_le_bytes(bytes);
        }
    }
    Ok(image)
}

fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let triple = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(triple >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// A file name as a relative URL's path segment: bytes other than letters, digits and
/// `-._~` percent-encoded.
fn url_escape(name: &str) -> String {
    let mut out = String::new();
    for byte in name.bytes() {
        if byte.is_ascii_alphanumeric() || b"-._~".contains(&byte) {
            out.push(byte as char);
        } else {
            out.push_str(&format!("%{byte:02X}"));
        }
    }
    out
}

/// Text for HTML: the five characters that could end it escaped.
pub fn escape_html(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// JSON inside a `<script>`: "</" written as "<\/" and "<!--" as "<\u0021--" (both still JSON),
/// so that no string in it ends the element.
fn script_json(value: &impl Serialize) -> String {
    serde_json::to_string(value)
        .unwrap_or_else(|_| "null".into())
        .replace("</", "<\\/")
        .replace("<!--", "<\\u0021--")
}

/// An SVG document as an element of the page: its XML declaration and doctype dropped.
fn inline_svg(svg: &str) -> &str {
    svg.find("<svg").map_or("", |start| &svg[start..])
}

fn page_html(page: &Page, manifest: &Manifest) -> String {
    let title = escape_html(&page.title);
    let links: String = page
        .links
        .iter()
        .map(|(text, href)| {
            format!(
                "<a href=\"{}\">{}</a> ",
                escape_html(href),
                escape_html(text)
            )
        })
        .collect();
    let notes: String = page
        .notes
        .iter()
        .map(|n| format!("<p>{}</p>\n", escape_html(n)))
        .collect();
    let plot = match &page.plot_svg {
        Some(svg) => format!(
            "<section id=\"plot\"><h2>Error against time</h2>\n<div class=\"plot\">{}</div>\
             </section>\n",
            inline_svg(svg)
        ),
        None => String::new(),
    };
    let table = if page.table.is_some() {
        "<section id=\"results\"><h2>Results</h2><p class=\"hint\">Click a column's heading to \
         sort by it, a row to view its image.</p><table id=\"results-table\"></table>\
         </section>\n"
    } else {
        ""
    };
    format!(
        r#"<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{title}</title>
<style>
{VIEWER_CSS}</style>
<script>
// First, so that an error anywhere later is caught and shown (and seen by the browser test).
window.stagelightErrors = [];
window.addEventListener("error", function (event) {{
  var where = event.filename ? " (" + event.filename.split("/").pop() + ":" + event.lineno + ")" : "";
  var what = event.message || ("could not load " + ((event.target && event.target.src) || "a file"));
  window.stagelightErrors.push(what + where);
  var status = document.getElementById("status");
  if (status) {{ status.dataset.errors = window.stagelightErrors.length; status.textContent = "Error: " + window.stagelightErrors.join("; "); }}
}}, true);
</script>
</head>
<body>
<header>
<nav>{links}</nav>
<h1>{title}</h1>
{notes}<p id="status" class="status" data-ready="0" data-errors="0">Loading images…</p>
</header>
<section id="viewer">
<div class="controls">
<label>Budget <select id="group-select"></select></label>
<label>Method <select id="method-select"></select></label>
<button id="flip-button" type="button" title="Key F">Flip to reference (F)</button>
<button id="error-button" type="button" title="Key E">Error map (E)</button>
<label>Exposure <input id="exposure" type="range" min="-12" max="12" step="0.1" value="0"> <output id="exposure-value">0.0 EV</output></label>
<button id="fit-button" type="button" title="Key 0">Fit (0)</button>
<button id="actual-button" type="button" title="Key 1">1:1 (1)</button>
</div>
<div class="view-row">
<div id="main-pane" class="pane main"></div>
<aside class="side">
<div id="readout" class="readout">Move the mouse over an image: its linear RGB appears here.</div>
<div id="error-scale" class="error-scale"></div>
<p class="hint">Wheel: zoom (all views together), drag: pan, F: flip to the reference, E: error map, 0: fit, 1: one image pixel per screen pixel, [ and ]: previous and next method.</p>
</aside>
</div>
<h2 id="strip-title">Side by side</h2>
<div id="strip" class="strip"></div>
</section>
{table}{plot}<pre id="selftest" hidden></pre>
<script id="manifest" type="application/json">{manifest_json}</script>
<script>
{VIEWER_JS}</script>
</body>
</html>
"#,
        manifest_json = script_json(manifest),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn floats_survive_the_format_bit_for_bit() {
        let mut image = Image::new(5, 3);
        for (i, p) in image.pixels.iter_mut().enumerate() {
            let x = i as f32;
            *p = Vec3::new(x * 0.1 + 1e-7, (x * 1.7).sin() * 1e4, -0.0);
        }
        image.pixels[4] = Vec3::new(f32::MAX, f32::MIN_POSITIVE, 3.0e-42);
        let decoded = decode_floats(&encode_floats(&image), 5, 3).unwrap();
        for (a, b) in image.pixels.iter().zip(&decoded.pixels) {
            for c in 0..3 {
                assert_eq!(a[c].to_bits(), b[c].to_bits());
            }
        }
        assert!(decode_floats(&encode_floats(&image), 4, 3).is_err());
    }

    #[test]
    fn base64_matches_the_standard_alphabet_and_padding() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foo"), "Zm9v");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
        assert_eq!(base64(&[0xff, 0xfe, 0x00]), "//4A");
    }

    #[test]
    fn data_folders_are_named_as_urls() {
        assert_eq!(url_escape("index_data"), "index_data");
        assert_eq!(url_escape("my page#2é_data"), "my%20page%232%C3%A9_data");
    }

    #[test]
    fn text_cannot_end_its_element() {
        assert_eq!(
            escape_html("<a href='x'>&\"</a>"),
            "&lt;a href=&#39;x&#39;&gt;&amp;&quot;&lt;/a&gt;"
        );
        let json = script_json(&"</script><!--");
        assert!(!json.contains("</") && !json.contains("<!--"), "{json}");
        assert_eq!(
            serde_json::from_str::<String>(&json).unwrap(),
            "</script><!--"
        );
    }

    #[test]
    fn images_of_another_size_are_refused_with_their_names() {
        let reference = Image::new(4, 4);
        let other = Image::new(4, 3);
        let page = Page {
            title: "t".into(),
            notes: vec![],
            reference: PageImage {
                method: "reference".into(),
                group: String::new(),
                source: Some("ref.exr".into()),
                image: &reference,
            },
            images: vec![PageImage {
                method: "a".into(),
                group: String::new(),
                source: Some("a.exr".into()),
                image: &other,
            }],
            plot_svg: None,
            table: None,
            links: vec![],
        };
        let e = write_page(&page, Path::new("/nonexistent/page.html")).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("a.exr is 4x3") && text.contains("ref.exr is 4x4"),
            "{text}"
        );
    }
}

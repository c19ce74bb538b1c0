//! The report's pictures: relMSE against wall time (plotters, PNG and SVG) and the grid of
//! images with their relative-error maps.
//!
//! Text is drawn with DejaVu Sans embedded in the binary (assets/fonts/, under its own free
//! licence) through plotters' ab_glyph backend, so no system font library is needed.

use super::format::{sci, secs, slope_of};
use super::{Comparison, ReportError, report_error};
use crate::film::{Image, srgb8};
use crate::integrators::known_integrators;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;

const FONT: &str = "sans-serif";
static DEJAVU_SANS: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// Registers the embedded font with plotters once.
fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // The font is compiled in and known good; a failure would only lose the labels.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, DEJAVU_SANS);
    });
}

/// A colour per integrator, stable across reports (by its place among the known names).
pub fn integrator_colour(name: &str) -> RGBColor {
    const COLOURS: [RGBColor; 6] = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
    ];
    let i = known_integrators()
        .iter()
        .position(|&n| n == name)
        .unwrap_or(0);
    COLOURS[i % COLOURS.len()]
}

const PLOT_SIZE: (u32, u32) = (900, 600);

/// error_vs_time.png and .svg.
pub fn write_error_plot(c: &Comparison, png: &Path, svg: &Path) -> Result<(), ReportError> {
    register_font();
    let (w, h) = PLOT_SIZE;
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        draw_error_plot(c, &root).map_err(|e| report_error(png, e))?;
    }
    write_rgb_png(png, w, h, &buffer)?;
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, (w, h)).into_drawing_area();
        draw_error_plot(c, &root).map_err(|e| report_error(svg, e))?;
    }
    crate::film::output::write_bytes(svg, text.as_bytes()).map_err(|e| report_error(svg, e.message))
}

fn draw_error_plot<DB: DrawingBackend>(
    c: &Comparison,
    root: &DrawingArea<DB, Shift>,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let points: Vec<(f64, f64)> = c
        .results
        .iter()
        .filter(|r| r.wall > 0.0 && r.metrics.relmse > 0.0)
        .map(|r| (r.wall, r.metrics.relmse))
        .collect();
    let title = format!("{}: relMSE against wall time", c.scene_name);
    if points.is_empty() {
        root.draw_text(
            &format!("{title}: no run with a positive error to plot"),
            &(FONT, 20).into_font().color(&BLACK),
            (20, 20),
        )
        .map_err(e)?;
        return root.present().map_err(e);
    }
    let (mut t0, mut t1, mut e0, mut e1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(t, err) in &points {
        (t0, t1, e0, e1) = (t0.min(t), t1.max(t), e0.min(err), e1.max(err));
    }
    // Half a decade of room around the data on both axes.
    let pad = 10f64.powf(0.25);
    let (t0, t1, e0, e1) = (t0 / pad, t1 * pad, e0 / pad, e1 * pad);
    let mut chart = ChartBuilder::on(root)
        .caption(&title, (FONT, 22))
        .margin(18)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(log_axis(t0, t1), log_axis(e0, e1))
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("wall time (s)")
        .y_desc("relMSE")
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 16))
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(200, 200, 200))
        .draw()
        .map_err(e)?;

    // A slope -1 guide through the middle of the data: where an unbiased integrator's line
    // should run parallel.
    let (tm, em) = (
        (points.iter().map(|p| p.0.ln()).sum::<f64>() / points.len() as f64).exp(),
        (points.iter().map(|p| p.1.ln()).sum::<f64>() / points.len() as f64).exp(),
    );
    let guide = [t0, t1].map(|t| (t, em * tm / t));
    let grey = RGBColor(150, 150, 150);
    chart
        .draw_series(DashedLineSeries::new(guide, 6, 5, grey.stroke_width(1)))
        .map_err(e)?
        .label("slope -1 (unbiased, MSE ~ 1/N)")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], grey));

    for &kind in &c.integrators {
        let mut series: Vec<(f64, f64)> = c
            .runs_of(kind)
            .iter()
            .filter(|r| r.wall > 0.0 && r.metrics.relmse > 0.0)
            .map(|r| (r.wall, r.metrics.relmse))
            .collect();
        series.sort_by(|a, b| a.0.total_cmp(&b.0));
        if series.is_empty() {
            continue;
        }
        let colour = integrator_colour(kind.as_str());
        let slope = slope_of(c, kind).map_or("n/a".to_string(), |s| format!("{s:.2}"));
        chart
            .draw_series(LineSeries::new(series.clone(), colour.stroke_width(2)))
            .map_err(e)?
            .label(format!("{kind} (slope {slope})"))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
        chart
            .draw_series(series.iter().map(|&p| Circle::new(p, 4, colour.filled())))
            .map_err(e)?;
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 15))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(e)?;
    root.present().map_err(e)
}

/// A log axis over [lo, hi] labelled at its 1-2-5 steps (at its powers of ten when those
/// would be too many), with light grid lines at every 1..9 step.
fn log_axis(
    lo: f64,
    hi: f64,
) -> plotters::coord::combinators::WithKeyPoints<plotters::coord::combinators::LogCoord<f64>> {
    use plotters::coord::combinators::BindKeyPoints;
    let steps = |multipliers: &[f64]| -> Vec<f64> {
        let mut v = Vec::new();
        for k in lo.log10().floor() as i32..=hi.log10().ceil() as i32 {
            for &m in multipliers {
                let t: f64 = format!("{m}e{k}").parse().unwrap_or(m * 10f64.powi(k));
                if lo <= t && t <= hi {
                    v.push(t);
                }
            }
        }
        v
    };
    let mut bold = steps(&[1.0, 2.0, 5.0]);
    if bold.len() > 9 {
        bold = steps(&[1.0]);
    }
    let light = steps(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
    (lo..hi)
        .log_scale()
        .with_key_points(bold)
        .with_light_points(light)
}

/// Axis tick text: 1, 10, 0.1, 1e-3 ...
fn tick(v: f64) -> String {
    if v <= 0.0 || !v.is_finite() {
        return String::new();
    }
    if (1e-2..1e4).contains(&v) {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.0e}")
    }
}

fn write_rgb_png(path: &Path, w: u32, h: u32, rgb: &[u8]) -> Result<(), ReportError> {
    use crate::film::output::{encode_rgb_png, write_atomically};
    write_atomically(path, |out| encode_rgb_png(out, w, h, rgb))
        .map_err(|e| report_error(path, e.message))
}

/// Decades of per-pixel relative squared error the false-colour maps span.
const ERROR_LOG_MIN: f64 = -4.0;
const ERROR_LOG_MAX: f64 = 0.0;

/// Per-pixel relative squared error, the quantity relMSE averages: mean over channels of
/// (x - r)^2 / (r^2 + 0.01).
pub fn relative_error_map(image: &Image, reference: &Image) -> Vec<f64> {
    image
        .pixels
        .iter()
        .zip(&reference.pixels)
        .map(|(x, r)| {
            (0..3)
                .map(|c| {
                    let (x, r) = (x[c] as f64, r[c] as f64);
                    (x - r).powi(2) / (r * r + 0.01)
                })
                .sum::<f64>()
                / 3.0
        })
        .collect()
}

/// A perceptually ordered colour map (viridis, sampled at nine stops), t in [0, 1].
fn viridis(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 9] = [
        [68.0, 1.0, 84.0],
        [71.0, 44.0, 122.0],
        [59.0, 81.0, 139.0],
        [44.0, 113.0, 142.0],
        [33.0, 144.0, 141.0],
        [39.0, 173.0, 129.0],
        [92.0, 200.0, 99.0],
        [170.0, 220.0, 50.0],
        [253.0, 231.0, 37.0],
    ];
    let x = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f64;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f64;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    [0, 1, 2].map(|c| (a[c] + f * (b[c] - a[c])).round() as u8)
}

fn error_colour(e: f64) -> [u8; 3] {
    let l = if e > 0.0 { e.log10() } else { ERROR_LOG_MIN };
    viridis((l - ERROR_LOG_MIN) / (ERROR_LOG_MAX - ERROR_LOG_MIN))
}

/// An RGB8 canvas the grid is assembled on before plotters writes its labels.
struct Canvas {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

impl Canvas {
    fn new(width: usize, height: usize) -> Canvas {
        Canvas {
            width,
            height,
            rgb: vec![255; width * height * 3],
        }
    }

    fn put(&mut self, x: usize, y: usize, c: [u8; 3]) {
        if x < self.width && y < self.height {
            let i = (y * self.width + x) * 3;
            self.rgb[i..i + 3].copy_from_slice(&c);
        }
    }

    /// Draws a `w` x `h` picture given by `pixel(x, y)` scaled to `cell` (nearest sample)
    /// at (x0, y0).
    fn blit(
        &mut self,
        (x0, y0): (usize, usize),
        (w, h): (usize, usize),
        cell: (usize, usize),
        pixel: impl Fn(usize, usize) -> [u8; 3],
    ) {
        for cy in 0..cell.1 {
            for cx in 0..cell.0 {
                let (sx, sy) = (cx * w / cell.0, cy * h / cell.1);
                self.put(x0 + cx, y0 + cy, pixel(sx, sy));
            }
        }
    }
}

/// The size every grid cell's picture is drawn at: the image scaled by a whole factor to at
/// least 128 pixels wide, or down to at most 256.
fn cell_size(width: usize, height: usize) -> (usize, usize) {
    let (w, h) = (width.max(1), height.max(1));
    if w.max(h) > 256 {
        let s = w.max(h) as f64 / 256.0;
        (
            ((w as f64 / s).round() as usize).max(1),
            ((h as f64 / s).round() as usize).max(1),
        )
    } else {
        let k = 128usize.div_ceil(w).max(1);
        (w * k, h * k)
    }
}

/// grid.png: one column per budget (and the reference first); for each integrator a row of
/// sRGB images and beneath it a row of false-colour relative-error maps, each labelled with
/// its relMSE and time; a colour bar at the bottom.
pub fn write_grid(c: &Comparison, path: &Path) -> Result<(), ReportError> {
    register_font();
    let (cw, ch) = cell_size(c.width, c.height);
    let (gap, left, top, label_h) = (10usize, 90usize, 48usize, 34usize);
    let columns = c.budgets.len() + 1;
    let rows = 2 * c.integrators.len();
    let row_h = ch + label_h;
    let bar_h = 70;
    let width = left + columns * (cw + gap) + gap;
    let height = top + rows.max(1) * row_h + bar_h;
    let mut canvas = Canvas::new(width, height);
    let col_x = |j: usize| left + j * (cw + gap);
    let row_y = |i: usize| top + i * row_h;
    let (iw, ih) = (c.width, c.height);
    let srgb = |img: &Image, x: usize, y: usize| {
        let p = img.pixels[y * img.width + x];
        [srgb8(p.x), srgb8(p.y), srgb8(p.z)]
    };

    canvas.blit((col_x(0), row_y(0)), (iw, ih), (cw, ch), |x, y| {
        srgb(&c.reference, x, y)
    });
    let mut labels: Vec<(String, (usize, usize), u32)> = Vec::new();
    labels.push(("reference".into(), (col_x(0), top - 22), 15));
    labels.push((
        c.reference_spp
            .map_or("(given)".to_string(), |s| format!("{s} spp")),
        (col_x(0), row_y(0) + ch + 4),
        13,
    ));
    for (j, &b) in c.budgets.iter().enumerate() {
        labels.push((
            format!("{b} {}", c.unit.suffix()),
            (col_x(j + 1), top - 22),
            15,
        ));
    }
    for (i, &kind) in c.integrators.iter().enumerate() {
        let (y_img, y_err) = (row_y(2 * i), row_y(2 * i + 1));
        labels.push((kind.as_str().to_string(), (8, y_img + ch / 2 - 8), 16));
        labels.push(("error".into(), (8, y_err + ch / 2 - 8), 13));
        for (j, &b) in c.budgets.iter().enumerate() {
            let x0 = col_x(j + 1);
            let Some(run) = c
                .results
                .iter()
                .find(|r| r.integrator == kind && r.budget == b)
            else {
                labels.push(("not run".into(), (x0 + 8, y_img + ch / 2), 13));
                continue;
            };
            canvas.blit((x0, y_img), (iw, ih), (cw, ch), |x, y| {
                srgb(&run.image, x, y)
            });
            let errors = relative_error_map(&run.image, &c.reference);
            canvas.blit((x0, y_err), (iw, ih), (cw, ch), |x, y| {
                error_colour(errors[y * iw + x])
            });
            labels.push((
                // Samples per pixel from the samples counted: an MLT pass is not one
                // mutation per pixel, so its pass count would understate the budget.
                format!(
                    "{} s, {} spp",
                    secs(run.wall),
                    (run.samples as f64 / (iw * ih) as f64).round()
                ),
                (x0, y_img + ch + 4),
                12,
            ));
            labels.push((
                format!("relMSE {}", sci(run.metrics.relmse)),
                (x0, y_err + ch + 4),
                12,
            ));
        }
    }
    // The colour bar: 10^-4 .. 10^0 of per-pixel relative squared error.
    let (bar_x, bar_y, bar_w) = (left, height - bar_h + 26, (width - left - 2 * gap).min(400));
    for x in 0..bar_w {
        let t = x as f64 / (bar_w - 1).max(1) as f64;
        let col = viridis(t);
        for y in 0..12 {
            canvas.put(bar_x + x, bar_y + y, col);
        }
    }
    labels.push((
        "per-pixel (x - r)^2 / (r^2 + 0.01), mean of channels:".into(),
        (bar_x, bar_y - 20),
        12,
    ));
    let decades = (ERROR_LOG_MAX - ERROR_LOG_MIN) as usize;
    for k in 0..=decades {
        let x = bar_x + k * (bar_w - 1) / decades;
        let text = format!("1e{}", ERROR_LOG_MIN as i32 + k as i32);
        labels.push((text, (x.saturating_sub(10), bar_y + 15), 11));
    }

    {
        let root = BitMapBackend::with_buffer(&mut canvas.rgb, (width as u32, height as u32))
            .into_drawing_area();
        let title = format!(
            "{}: images and relative error (reference: {})",
            c.scene_name,
            c.reference_path
                .file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into_owned())
        );
        let draw = |text: &str, (x, y): (usize, usize), size: u32| {
            root.draw_text(
                text,
                &(FONT, size).into_font().color(&BLACK),
                (x as i32, y as i32),
            )
        };
        draw(&title, (8, 4), 15).map_err(|e| report_error(path, e))?;
        for (text, pos, size) in &labels {
            draw(text, *pos, *size).map_err(|e| report_error(path, e))?;
        }
        root.present().map_err(|e| report_error(path, e))?;
    }
    write_rgb_png(path, width as u32, height as u32, &canvas.rgb)
}

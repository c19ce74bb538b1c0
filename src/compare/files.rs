//! The names of the files a report folder holds.

pub const RESULTS_CSV: &str = "results.csv";
pub const PLOT_PNG: &str = "error_vs_time.png";
pub const PLOT_SVG: &str = "error_vs_time.svg";
pub const GRID_PNG: &str = "grid.png";
pub const SUMMARY_MD: &str = "summary.md";
/// The interactive report page.
pub const INDEX_HTML: &str = "index.html";

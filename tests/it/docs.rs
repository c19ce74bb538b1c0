//! The docs stay true: the CLI reference is the binary's own help, and every relative link of
//! README.md and docs/ names a file that exists.

use clap::CommandFactory;
use std::path::{Path, PathBuf};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// docs/cli.md as `stagelight help` would print it for every command.
fn cli_reference() -> String {
    let mut command = stagelight::cli::Cli::command();
    command.build();
    let mut out = String::from(
        "# CLI reference\n\nEvery command's `--help`, as the binary prints it (`tests/it/docs.rs` keeps this \
         file equal to it: run `STAGELIGHT_WRITE_DOCS=1 cargo nextest run cli_reference` after \
         changing an option).\n",
    );
    let mut section = |title: String, help: String| {
        out.push_str(&format!(
            "\n## {title}\n\n```text\n{}\n```\n",
            help.trim_end()
        ));
    };
    section("stagelight".into(), command.render_long_help().to_string());
    for sub in command.get_subcommands_mut() {
        let name = format!("stagelight {}", sub.get_name());
        section(name, sub.render_long_help().to_string());
    }
    out
}

#[test]
fn cli_reference_is_the_help() {
    let path = Path::new(ROOT).join("docs/cli.md");
    let expected = cli_reference();
    if std::env::var_os("STAGELIGHT_WRITE_DOCS").is_some() {
        std::fs::write(&path, &expected).expect("docs/cli.md written");
    }
    let written = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        written == expected,
        "docs/cli.md differs from the help: rerun with STAGELIGHT_WRITE_DOCS=1"
    );
}

/// README.md and every markdown file under docs/.
fn markdown_files() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).expect("docs/ readable") {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "md") {
                out.push(path);
            }
        }
    }
    let mut files = vec![Path::new(ROOT).join("README.md")];
    walk(&Path::new(ROOT).join("docs"), &mut files);
    files
}

/// The targets of a markdown text's inline links and images, `[text](target)`, outside code.
fn link_targets(text: &str) -> Vec<String> {
    let mut targets = Vec::new();
    let mut in_fence = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
            continue;
        }
        if in_fence || line.starts_with("    ") && !line.trim_start().starts_with(['-', '|']) {
            continue;
        }
        // Inline code spans are not links.
        let prose: String = line.split('`').step_by(2).collect::<Vec<_>>().join(" ");
        let mut rest = prose.as_str();
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let Some(end) = after.find(')') else { break };
            targets.push(after[..end].trim().to_string());
            rest = &after[end..];
        }
    }
    targets
}

#[test]
fn every_relative_link_resolves() {
    let mut broken = Vec::new();
    let mut checked = 0;
    for file in markdown_files() {
        let text = std::fs::read_to_string(&file).expect("markdown readable");
        for target in link_targets(&text) {
            if target.contains("://") || target.starts_with('#') || target.starts_with("mailto:") {
                continue;
            }
            let path = target.split('#').next().unwrap_or_default();
            checked += 1;
            if !file.parent().expect("a folder").join(path).exists() {
                broken.push(format!("{}: {target}", file.display()));
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
    assert!(checked >= 10, "only {checked} links checked");
}

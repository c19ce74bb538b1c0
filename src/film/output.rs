//! Output files that are never seen half-written: every file stagelight writes (EXR, PNG,
//! CSV, SVG, markdown, checkpoints) goes to a fresh temporary name in its folder, is flushed
//! to the disk (fsync), and is then renamed over the output. A full disk, a crash or a second
//! writer leaves the previous file whole (two renders to one path: the last rename wins, and
//! each file is complete). An output that is a symbolic link is refused rather than written
//! through, so a link cannot make a render overwrite another file.
//!
//! `check_writable` does the same checks without writing, so a command can refuse an output
//! it cannot write before it spends the time to render it.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// An output file could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", .path.display())]
pub struct OutputError {
    pub path: PathBuf,
    pub message: String,
}

fn error(path: &Path, message: impl std::fmt::Display) -> OutputError {
    OutputError {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// The folder an output goes to ("." for a bare file name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir,
        _ => Path::new("."),
    }
}

/// Checks what can be checked about an output path without writing it: not a folder, not a
/// symbolic link, its folder a folder (not a file) or creatable.
fn check_path(path: &Path) -> Result<(), OutputError> {
    if path.file_name().is_none() {
        return Err(error(path, "is not a file name"));
    }
    if let Ok(meta) = std::fs::symlink_metadata(path) {
        if meta.file_type().is_symlink() {
            return Err(error(
                path,
                "is a symbolic link: stagelight does not write through links (remove it or \
                 choose another output)",
            ));
        }
        if meta.is_dir() {
            return Err(error(path, "is a folder, not a file"));
        }
    }
    let folder = folder_of(path);
    // The nearest part of the folder's path that exists must be a folder.
    for ancestor in folder.ancestors() {
        if ancestor.as_os_str().is_empty() {
            break;
        }
        if let Ok(meta) = std::fs::metadata(ancestor) {
            if !meta.is_dir() {
                return Err(error(
                    path,
                    format!(
                        "cannot create its folder: {} is a file, not a folder",
                        ancestor.display()
                    ),
                ));
            }
            break;
        }
    }
    std::fs::create_dir_all(folder).map_err(|e| {
        error(
            path,
            format!("cannot create its folder {}: {e}", folder.display()),
        )
    })
}

static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Creates a fresh temporary file beside `path` (a hidden name with this process's id and a
/// counter; never an existing file).
fn create_temp(path: &Path) -> Result<(PathBuf, File), OutputError> {
    let folder = folder_of(path);
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    // Room for the suffix within the usual 255-byte name limit.
    let mut short: String = String::new();
    for c in name.chars() {
        if short.len() + c.len_utf8() > 180 {
            break;
        }
        short.push(c);
    }
    for _ in 0..100 {
        let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
        let tmp = folder.join(format!(".{short}.{}.{n}.tmp", std::process::id()));
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
        {
            Ok(file) => return Ok((tmp, file)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => {
                return Err(error(
                    path,
                    format!("cannot write in {}: {e}", folder.display()),
                ));
            }
        }
    }
    Err(error(path, "cannot find a free temporary name beside it"))
}

/// Checks, before any work, that `path` can be written: not a folder or a symbolic link, its
/// folder creatable (it is created) and writable (a temporary file is made and removed).
pub fn check_writable(path: &Path) -> Result<(), OutputError> {
    check_path(path)?;
    let (tmp, file) = create_temp(path)?;
    drop(file);
    let _ = std::fs::remove_file(&tmp);
    Ok(())
}

/// Writes `path` through `write` (given a buffered temporary file), flushes it to the disk
/// and renames it over `path`; on any error the temporary file is removed and `path` is as
/// it was. The folder is created if missing.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<(), String>,
) -> Result<(), OutputError> {
    check_path(path)?;
    let (tmp, file) = create_temp(path)?;
    let result = (|| {
        let mut out = BufWriter::new(file);
        write(&mut out).map_err(|m| error(path, m))?;
        let file = out
            .into_inner()
            .map_err(|e| error(path, format!("cannot write: {}", e.error())))?;
        file.sync_all()
            .map_err(|e| error(path, format!("cannot write: {e}")))?;
        drop(file);
        std::fs::rename(&tmp, path).map_err(|e| error(path, format!("cannot replace: {e}")))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
        return result;
    }
    // The rename itself reaches the disk with the folder's entry.
    if let Ok(dir) = File::open(folder_of(path)) {
        let _ = dir.sync_all();
    }
    Ok(())
}

/// `write_atomically` of bytes already made.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    write_atomically(path, |out| {
        out.write_all(bytes)
            .map_err(|e| format!("cannot write: {e}"))
    })
}

/// An 8-bit RGB PNG of `rgb` (row 0 first) to `out`.
pub fn encode_rgb_png(out: &mut impl Write, w: u32, h: u32, rgb: &[u8]) -> Result<(), String> {
    let mut encoder = png::Encoder::new(out, w, h);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder
        .write_header()
        .map_err(|e| format!("cannot write PNG: {e}"))?;
    writer
        .write_image_data(rgb)
        .map_err(|e| format!("cannot write PNG: {e}"))?;
    writer
        .finish()
        .map_err(|e| format!("cannot write PNG: {e}"))
}

/// Whether two paths name the same file: the same device and inode where both exist, else
/// the same absolute path once the existing parts are resolved.
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return ma.dev() == mb.dev() && ma.ino() == mb.ino();
        }
    }
    match (resolved(a), resolved(b)) {
        (Some(a), Some(b)) => a == b,
        _ => false,
    }
}

/// The absolute path with its existing folder resolved (links followed).
fn resolved(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = std::fs::canonicalize(path) {
        return Some(p);
    }
    let name = path.file_name()?;
    let folder = std::fs::canonicalize(folder_of(path)).ok()?;
    Some(folder.join(name))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("stagelight-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn a_failed_write_keeps_the_old_file_and_leaves_no_temporary() {
        let dir = temp("failed");
        let path = dir.join("a.txt");
        write_bytes(&path, b"old").unwrap();
        let e = write_atomically(&path, |out| {
            out.write_all(b"half").unwrap();
            Err("disk full".into())
        })
        .unwrap_err();
        assert!(e.to_string().contains("disk full"), "{e}");
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
    }

    #[cfg(unix)]
    #[test]
    fn symbolic_links_are_refused() {
        let dir = temp("link");
        let target = dir.join("precious.txt");
        std::fs::write(&target, b"keep").unwrap();
        let link = dir.join("out.exr");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        assert!(check_writable(&link).is_err());
        assert!(write_bytes(&link, b"new").is_err());
        assert_eq!(std::fs::read(&target).unwrap(), b"keep");
    }

    #[test]
    fn a_file_in_the_way_of_the_folder_is_named() {
        let dir = temp("parent");
        std::fs::write(dir.join("file"), b"").unwrap();
        let e = check_writable(&dir.join("file").join("sub").join("x.exr")).unwrap_err();
        assert!(e.message.contains("is a file, not a folder"), "{e}");
    }
}

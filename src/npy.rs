//! NumPy's .npy format (version 1.0), as much of it as ray files need: writing little-endian
//! float32 matrices and a (t, primitive) record array, and reading float32 matrices back with
//! an error that names the file and what is wrong with it.
//!
//! A file is the magic `\x93NUMPY`, the version (1, 0), the header's length (u16, little
//! endian), the header (a Python dict literal: `descr`, `fortran_order`, `shape`, padded with
//! spaces and ended by a newline so the data starts at a multiple of 64 bytes) and the data,
//! in C order.

use anyhow::{Context, Result, bail};
use std::io::Write;
use std::path::Path;

const MAGIC: &[u8; 6] = b"\x93NUMPY";
/// The data starts at a multiple of this (NumPy pads to 64 since 1.14; readers accept any).
const ALIGN: usize = 64;

/// The bytes of a version 1.0 header for `dict` (without padding or newline).
fn header(dict: &str) -> Vec<u8> {
    let unpadded = MAGIC.len() + 2 + 2 + dict.len() + 1;
    let padding = unpadded.next_multiple_of(ALIGN) - unpadded;
    let text = format!("{dict}{}\n", " ".repeat(padding));
    let mut out = Vec::with_capacity(unpadded + padding);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(text.len() as u16).to_le_bytes());
    out.extend_from_slice(text.as_bytes());
    out
}

/// Writes `rows` as a float32 matrix of shape (rows, N).
pub fn write_f32_rows<const N: usize>(path: &Path, rows: &[[f32; N]]) -> Result<()> {
    let dict = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {N}), }}",
        rows.len()
    );
    let mut bytes = header(&dict);
    bytes.reserve(rows.len() * N * 4);
    for row in rows {
        for v in row {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    write_file(path, &bytes)
}

/// Writes a record array of shape (len,) with fields `t` (float32) and `primitive` (uint32).
pub fn write_hits(path: &Path, t: &[f32], primitive: &[u32]) -> Result<()> {
    assert_eq!(t.len(), primitive.len(), "one primitive per distance");
    let dict = format!(
        "{{'descr': [('t', '<f4'), ('primitive', '<u4')], 'fortran_order': False, \
         'shape': ({},), }}",
        t.len()
    );
    let mut bytes = header(&dict);
    bytes.reserve(t.len() * 8);
    for (t, p) in t.iter().zip(primitive) {
        bytes.extend_from_slice(&t.to_le_bytes());
        bytes.extend_from_slice(&p.to_le_bytes());
    }
    write_file(path, &bytes)
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut file =
        std::fs::File::create(path).with_context(|| format!("cannot write {}", path.display()))?;
    file.write_all(bytes)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Reads a float32 matrix of shape (rows, N) written by `write_f32_rows` or by NumPy
/// (`np.save(path, a.astype('<f4'))` of a C-ordered (rows, N) array).
pub fn read_f32_rows<const N: usize>(path: &Path) -> Result<Vec<[f32; N]>> {
    let name = path.display();
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {name}"))?;
    let (header, data) = split_header(&bytes).with_context(|| format!("{name}"))?;
    let descr = header_value(header, "descr").with_context(|| format!("{name}"))?;
    if descr != "'<f4'" {
        bail!("{name}: dtype {descr}, expected little-endian float32 ('<f4')");
    }
    let fortran = header_value(header, "fortran_order").with_context(|| format!("{name}"))?;
    if fortran != "False" {
        bail!("{name}: fortran_order {fortran}, expected False (C order)");
    }
    let shape = header_value(header, "shape").with_context(|| format!("{name}"))?;
    let dims = parse_shape(shape).with_context(|| format!("{name}: shape {shape}"))?;
    let rows = match dims[..] {
        [rows, n] if n == N => rows,
        _ => bail!("{name}: shape {shape}, expected (N, {N})"),
    };
    let expected = rows
        .checked_mul(N * 4)
        .with_context(|| format!("{name}: shape {shape} is too large"))?;
    if data.len() != expected {
        bail!(
            "{name}: {} bytes of data, but shape {shape} needs {expected}",
            data.len()
        );
    }
    Ok(data
        .chunks_exact(N * 4)
        .map(|row| {
            std::array::from_fn(|k| {
                f32::from_le_bytes([row[4 * k], row[4 * k + 1], row[4 * k + 2], row[4 * k + 3]])
            })
        })
        .collect())
}

/// The header's text and the data after it.
fn split_header(bytes: &[u8]) -> Result<(&str, &[u8])> {
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        bail!("not a NumPy .npy file (it does not start with \\x93NUMPY)");
    }
    let (len, start): (usize, usize) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => bail!("unsupported .npy version {v}.{}", bytes[7]),
    };
    let end = start
        .checked_add(len)
        .filter(|&e| e <= bytes.len())
        .context("the header runs past the end of the file")?;
    let text = std::str::from_utf8(&bytes[start..end])
        .ok()
        .filter(|t| t.is_ascii())
        .context("the header is not ASCII text")?;
    Ok((text.trim_end(), &bytes[end..]))
}

/// The text of `key`'s value in the header's dict: a quoted string, a word, a parenthesised
/// tuple or a bracketed list.
fn header_value<'a>(header: &'a str, key: &str) -> Result<&'a str> {
    let quoted = [format!("'{key}'"), format!("\"{key}\"")];
    let at = quoted
        .iter()
        .find_map(|q| header.find(q.as_str()).map(|i| i + q.len()))
        .with_context(|| format!("the header has no '{key}'"))?;
    let rest = header[at..].trim_start();
    let rest = rest
        .strip_prefix(':')
        .with_context(|| format!("the header's '{key}' has no value"))?
        .trim_start();
    let end = match rest.chars().next() {
        Some(q @ ('\'' | '"')) => rest[1..].find(q).map(|i| i + 2),
        Some('(') => rest.find(')').map(|i| i + 1),
        Some('[') => rest.find(']').map(|i| i + 1),
        Some(_) => rest.find([',', '}']),
        None => None,
    }
    .with_context(|| format!("the header's '{key}' is not closed"))?;
    Ok(rest[..end].trim())
}

/// The dimensions of a shape tuple such as `(12, 8)`.
fn parse_shape(shape: &str) -> Result<Vec<usize>> {
    let inner = shape
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .context("not a tuple")?;
    inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|d| d.parse::<usize>().ok().context("not a tuple of sizes"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_padded_to_64_bytes_and_values_parse() {
        let h = header("{'descr': '<f4', 'fortran_order': False, 'shape': (3, 8), }");
        assert_eq!(h.len() % ALIGN, 0);
        assert_eq!(*h.last().unwrap(), b'\n');
        let (text, data) = split_header(&h).unwrap();
        assert!(data.is_empty());
        assert_eq!(header_value(text, "descr").unwrap(), "'<f4'");
        assert_eq!(header_value(text, "fortran_order").unwrap(), "False");
        assert_eq!(
            parse_shape(header_value(text, "shape").unwrap()).unwrap(),
            vec![3, 8]
        );
        assert_eq!(parse_shape("(5,)").unwrap(), vec![5]);
        assert!(parse_shape("(5, x)").is_err());
    }
}

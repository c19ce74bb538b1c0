//! Reading the RON text into checked descriptions, each with the position it was declared at.

use super::SceneError;
use super::format::{CameraDesc, MaterialDesc, ObjectDesc, SceneFile};
use super::world::SourceSpot;
use ron::error::SpannedError;
use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};

/// A description and where in the file it starts.
#[derive(Clone, Debug)]
pub struct Located<T> {
    pub desc: T,
    pub spot: SourceSpot,
}

/// A scene file, checked value by value but not yet cross-checked (material names, meshes).
#[derive(Clone, Debug)]
pub struct ParsedScene {
    pub source: PathBuf,
    pub camera: Located<CameraDesc>,
    /// In file order.
    pub materials: Vec<(String, MaterialDesc)>,
    pub objects: Vec<Located<ObjectDesc>>,
}

/// Parses scene text; `source` names the file in errors and anchors relative mesh paths.
pub fn parse(source: &Path, text: &str) -> Result<ParsedScene, SceneError> {
    // A byte-order mark some editors write is not part of the text.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let file: SceneFile = ron::from_str(text).map_err(|e| ron_error(source, &e, None))?;
    // The camera and objects are parsed on their own below; they keep the file's extensions.
    let extensions = ron::Deserializer::from_str(text)
        .map(|d| d.extensions())
        .unwrap_or_default();
    let options = ron::Options::default().with_default_extension(extensions);
    // The raw values borrow the scene text: their address gives their offset in it.
    let offset_of = |part: &str| -> Result<usize, SceneError> {
        (part.as_ptr() as usize)
            .checked_sub(text.as_ptr() as usize)
            .filter(|&o| o + part.len() <= text.len())
            .ok_or_else(|| SceneError {
                file: source.to_path_buf(),
                line: None,
                column: None,
                message: "internal error: raw RON value outside the scene text".to_string(),
            })
    };

    // Positions are counted once through the file, not from its start for every object.
    let mut positions = Positions::new(text);
    let camera_text = file.camera.get_ron();
    let camera_offset = offset_of(camera_text)?;
    let camera =
        parse_located::<CameraDesc>(source, &mut positions, camera_text, camera_offset, &options)?;
    let mut objects = Vec::with_capacity(file.objects.len());
    for raw in &file.objects {
        let object_text = raw.get_ron();
        let offset = offset_of(object_text)?;
        objects.push(parse_located::<ObjectDesc>(
            source,
            &mut positions,
            object_text,
            offset,
            &options,
        )?);
    }
    Ok(ParsedScene {
        source: source.to_path_buf(),
        camera,
        materials: file.materials.0,
        objects,
    })
}

/// Parses a part of the file that starts `offset` bytes into `text`; positions in its errors
/// are moved to be positions in the whole file.
fn parse_located<T: DeserializeOwned>(
    source: &Path,
    positions: &mut Positions,
    part: &str,
    offset: usize,
    options: &ron::Options,
) -> Result<Located<T>, SceneError> {
    let base = positions.at(offset);
    let desc = options
        .from_str::<T>(part)
        .map_err(|e| ron_error(source, &e, Some(&base)))?;
    // The raw text may begin with comments: the declaration starts after them.
    let spot = positions.at(offset + skip_comments(part));
    Ok(Located { desc, spot })
}

/// Converts ron's error; `base` is where the parsed text starts when it is a part of the file.
fn ron_error(source: &Path, e: &SpannedError, base: Option<&SourceSpot>) -> SceneError {
    let (line, column) = (e.span.start.line, e.span.start.col);
    let (line, column) = match base {
        None => (line, column),
        Some(base) if line <= 1 => (base.line, base.column + column.saturating_sub(1)),
        Some(base) => (base.line + line - 1, column),
    };
    SceneError {
        file: source.to_path_buf(),
        line: Some(line),
        column: Some(column),
        message: clip_message(&e.code.to_string()),
    }
}

/// A parser's message on one line, cut after 300 characters: ron's messages repeat what they
/// found (an unknown field's name, a string), which may be as long as the file.
fn clip_message(message: &str) -> String {
    super::clip(message, 300)
}

/// 1-based lines and columns (in characters, as ron counts them) of byte offsets in a text,
/// counted forward from the last offset asked for: asking in increasing order costs one pass
/// over the text in all (an earlier offset starts over from the beginning).
pub struct Positions<'a> {
    text: &'a str,
    offset: usize,
    spot: SourceSpot,
}

impl<'a> Positions<'a> {
    pub fn new(text: &'a str) -> Positions<'a> {
        Positions {
            text,
            offset: 0,
            spot: SourceSpot { line: 1, column: 1 },
        }
    }

    /// The position of byte `offset` (the end of the text if beyond it; the start of its
    /// character if inside one).
    pub fn at(&mut self, offset: usize) -> SourceSpot {
        let mut offset = offset.min(self.text.len());
        while !self.text.is_char_boundary(offset) {
            offset -= 1;
        }
        if offset < self.offset {
            *self = Positions::new(self.text);
        }
        for c in self.text[self.offset..offset].chars() {
            if c == '\n' {
                self.spot.line += 1;
                self.spot.column = 1;
            } else {
                self.spot.column += 1;
            }
        }
        self.offset = offset;
        self.spot.clone()
    }
}

/// 1-based line and column of a byte offset (one position; `Positions` for many).
#[cfg(test)]
fn position_of(text: &str, offset: usize) -> SourceSpot {
    Positions::new(text).at(offset)
}

/// Byte length of the whitespace and comments that start `s` (RON block comments nest).
fn skip_comments(s: &str) -> usize {
    let mut rest = s;
    loop {
        let trimmed = rest.trim_start();
        if let Some(after) = trimmed.strip_prefix("//") {
            rest = after.find('\n').map_or("", |i| &after[i..]);
        } else if trimmed.starts_with("/*") {
            let mut depth = 0usize;
            let mut i = 0;
            let bytes = trimmed.as_bytes();
            while i + 1 < bytes.len() {
                match &bytes[i..i + 2] {
                    b"/*" => {
                        depth += 1;
                        i += 2;
                    }
                    b"*/" => {
                        depth -= 1;
                        i += 2;
                        if depth == 0 {
                            break;
                        }
                    }
                    _ => i += 1,
                }
            }
            rest = trimmed.get(i..).unwrap_or("");
        } else {
            return s.len() - trimmed.len();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn comments_are_skipped() {
        assert_eq!(skip_comments("  x"), 2);
        assert_eq!(skip_comments("// a\n  x"), 7);
        assert_eq!(skip_comments("/* a /* b */ c */ x"), 18);
        assert_eq!(skip_comments("// only"), 7);
    }

    #[test]
    fn positions_count_lines_and_characters() {
        let text = "ab\ncdé f";
        assert_eq!(position_of(text, 0), SourceSpot { line: 1, column: 1 });
        assert_eq!(position_of(text, 3), SourceSpot { line: 2, column: 1 });
        assert_eq!(position_of(text, 7), SourceSpot { line: 2, column: 4 });
    }
}

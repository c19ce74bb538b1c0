//! A Mitsuba 3 scene file read into plugin objects: `include`s spliced in, `default`s and `$name`
//! substitutions applied, `path` entries collected, nested objects and `ref`s linked (a ref may
//! come before its id), and every property's value parsed and checked. Nothing here knows what a
//! plugin means; `super::build` interprets the objects.
//!
//! Every object and property keeps the file, line and column it came from, so an error found
//! while interpreting it can name them.

use glam::{DAffine3, DMat3, DMat4, DQuat, DVec3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where something was written: the file and the 1-based line and column.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Spot {
    pub file: Arc<Path>,
    pub line: u32,
    pub column: u32,
}

/// An error at a spot (or in a file, without one), with what is wrong.
#[derive(Clone, Debug)]
pub struct XmlError {
    pub file: PathBuf,
    pub line: Option<u32>,
    pub column: Option<u32>,
    pub message: String,
}

impl XmlError {
    pub fn at(spot: &Spot, message: impl Into<String>) -> XmlError {
        XmlError {
            file: spot.file.to_path_buf(),
            line: Some(spot.line),
            column: Some(spot.column),
            message: message.into(),
        }
    }

    fn in_file(file: &Path, message: impl Into<String>) -> XmlError {
        XmlError {
            file: file.to_path_buf(),
            line: None,
            column: None,
            message: message.into(),
        }
    }
}

/// The classes of plugin objects, by their XML tag.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Class {
    Scene,
    Shape,
    Bsdf,
    Emitter,
    Sensor,
    Film,
    Rfilter,
    Sampler,
    Integrator,
    Texture,
}

impl Class {
    fn of_tag(tag: &str) -> Option<Class> {
        Some(match tag {
            "scene" => Class::Scene,
            "shape" => Class::Shape,
            "bsdf" => Class::Bsdf,
            "emitter" => Class::Emitter,
            "sensor" => Class::Sensor,
            "film" => Class::Film,
            "rfilter" => Class::Rfilter,
            "sampler" => Class::Sampler,
            "integrator" => Class::Integrator,
            "texture" => Class::Texture,
            _ => return None,
        })
    }

    pub fn tag(self) -> &'static str {
        match self {
            Class::Scene => "scene",
            Class::Shape => "shape",
            Class::Bsdf => "bsdf",
            Class::Emitter => "emitter",
            Class::Sensor => "sensor",
            Class::Film => "film",
            Class::Rfilter => "rfilter",
            Class::Sampler => "sampler",
            Class::Integrator => "integrator",
            Class::Texture => "texture",
        }
    }
}

/// Tags of Mitsuba plugins stagelight does not model at all (participating media and the like).
const UNMODELED_TAGS: &[&str] = &["medium", "phase", "volume"];

/// A spectrum as written: one value for every wavelength, or (wavelength nm, value) pairs.
/// Whether it is a reflectance or an emission decides how it becomes RGB (see `spectrum`).
#[derive(Clone, Debug, PartialEq)]
pub enum Spectrum {
    Constant(f64),
    Pairs(Vec<(f64, f64)>),
}

/// A property's value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Boolean(bool),
    Integer(i64),
    Float(f64),
    String(String),
    Point(DVec3),
    Vector(DVec3),
    /// Linear sRGB, as written.
    Rgb(DVec3),
    Spectrum(Spectrum),
    Transform(DMat4),
}

impl Value {
    /// The XML tag that writes this kind of value, for messages.
    pub fn tag(&self) -> &'static str {
        match self {
            Value::Boolean(_) => "boolean",
            Value::Integer(_) => "integer",
            Value::Float(_) => "float",
            Value::String(_) => "string",
            Value::Point(_) => "point",
            Value::Vector(_) => "vector",
            Value::Rgb(_) => "rgb",
            Value::Spectrum(_) => "spectrum",
            Value::Transform(_) => "transform",
        }
    }
}

#[derive(Clone, Debug)]
pub struct Property {
    pub name: String,
    pub value: Value,
    pub spot: Spot,
}

/// A nested object or a `ref` to one, with the `name` it was given (if any).
#[derive(Clone, Debug)]
pub struct Child {
    pub name: Option<String>,
    pub object: ObjectId,
    /// Where the nested element or the `ref` is.
    pub spot: Spot,
}

/// Index of an object in `Document::objects`.
pub type ObjectId = usize;

/// One plugin object: `<shape type="obj" id="...">` and what it holds.
#[derive(Clone, Debug)]
pub struct Object {
    pub class: Class,
    /// The `type` attribute (empty for the scene).
    pub kind: String,
    pub id: Option<String>,
    pub spot: Spot,
    pub properties: Vec<Property>,
    pub children: Vec<Child>,
}

/// A whole scene file: its objects (the scene is object 0) and the folders file names are
/// resolved against.
#[derive(Clone, Debug)]
pub struct Document {
    pub objects: Vec<Object>,
    /// The top file's folder first, then each `<path>` in file order.
    pub search_paths: Vec<PathBuf>,
    pub source: PathBuf,
}

/// The `-D name=value` definitions from the command line (or the Python keyword arguments):
/// they override the file's `default`s.
pub type Defines = [(String, String)];

/// Nesting deeper than this is refused (a hostile file must not overflow the stack).
const MAX_DEPTH: usize = 64;
/// Includes nested deeper than this are refused (a cycle is found before this).
const MAX_INCLUDE_DEPTH: usize = 32;
/// Most bytes a scene file (with its includes) may have.
const MAX_FILE_BYTES: u64 = 256 << 20;

/// Reads the scene file at `path` with its includes.
pub fn read(path: &Path, defines: &Defines) -> Result<Document, XmlError> {
    let mut reader = Reader {
        params: defines.iter().cloned().collect(),
        objects: Vec::new(),
        ids: HashMap::new(),
        pending_refs: Vec::new(),
        search_paths: vec![path.parent().unwrap_or(Path::new("")).to_path_buf()],
        include_stack: Vec::new(),
    };
    for (name, _) in defines {
        if !is_param_name(name) {
            return Err(XmlError::in_file(
                path,
                format!(
                    "-D {}: a parameter name is letters, digits and underscores",
                    super::super::echo(name)
                ),
            ));
        }
    }
    let scene = reader.read_file(path, None, 0)?;
    debug_assert_eq!(scene, 0);
    reader.resolve_refs()?;
    Ok(Document {
        objects: reader.objects,
        search_paths: reader.search_paths,
        source: path.to_path_buf(),
    })
}

/// Reads scene text as if from `path` (for tests and fuzzing; includes resolve against its
/// folder).
pub fn read_str(path: &Path, text: &str, defines: &Defines) -> Result<Document, XmlError> {
    let mut reader = Reader {
        params: defines.iter().cloned().collect(),
        objects: Vec::new(),
        ids: HashMap::new(),
        pending_refs: Vec::new(),
        search_paths: vec![path.parent().unwrap_or(Path::new("")).to_path_buf()],
        include_stack: Vec::new(),
    };
    reader.read_text(path, text, None, 0)?;
    reader.resolve_refs()?;
    Ok(Document {
        objects: reader.objects,
        search_paths: reader.search_paths,
        source: path.to_path_buf(),
    })
}

impl Document {
    pub fn scene(&self) -> &Object {
        &self.objects[0]
    }

    /// The file `name` names: absolute, or found in the search paths (the last `<path>` first,
    /// as Mitsuba's file resolver does), or else relative to the top file's folder.
    pub fn resolve(&self, name: &str) -> PathBuf {
        let path = Path::new(name);
        if path.is_absolute() {
            return path.to_path_buf();
        }
        for dir in self.search_paths.iter().rev() {
            let candidate = dir.join(path);
            if candidate.exists() {
                return candidate;
            }
        }
        self.search_paths[0].join(path)
    }
}

struct PendingRef {
    parent: ObjectId,
    slot: usize,
    id: String,
    spot: Spot,
}

struct Reader {
    params: HashMap<String, String>,
    objects: Vec<Object>,
    ids: HashMap<String, (ObjectId, Spot)>,
    pending_refs: Vec<PendingRef>,
    search_paths: Vec<PathBuf>,
    include_stack: Vec<PathBuf>,
}

fn is_param_name(name: &str) -> bool {
    !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

impl Reader {
    /// Reads a file; with `into`, its scene's children are added to that object (an include).
    /// Returns the object the file's content went into.
    fn read_file(
        &mut self,
        path: &Path,
        into: Option<(ObjectId, &Spot)>,
        depth: usize,
    ) -> Result<ObjectId, XmlError> {
        let included_from = |message: String| match into {
            Some((_, spot)) => XmlError::at(spot, message),
            None => XmlError::in_file(path, message),
        };
        if std::fs::metadata(path).is_ok_and(|m| m.is_dir()) {
            return Err(included_from(format!(
                "{} is a folder, not a scene file",
                super::super::echo_path(path)
            )));
        }
        let size = std::fs::metadata(path).map(|m| m.len()).map_err(|e| {
            included_from(format!(
                "cannot read {}: {e}",
                super::super::echo_path(path)
            ))
        })?;
        if size > MAX_FILE_BYTES {
            return Err(included_from(format!(
                "{} is {size} bytes: scene files above {MAX_FILE_BYTES} bytes are refused",
                super::super::echo_path(path)
            )));
        }
        let bytes = std::fs::read(path).map_err(|e| {
            included_from(format!(
                "cannot read {}: {e}",
                super::super::echo_path(path)
            ))
        })?;
        let text = super::super::text_of(path, &bytes).map_err(|e| XmlError {
            file: e.file,
            line: e.line.map(|l| l as u32),
            column: e.column.map(|c| c as u32),
            message: e.message,
        })?;
        self.read_text(path, text, into, depth)
    }

    fn read_text(
        &mut self,
        path: &Path,
        text: &str,
        into: Option<(ObjectId, &Spot)>,
        depth: usize,
    ) -> Result<ObjectId, XmlError> {
        let canonical = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
        if let Some((_, spot)) = into {
            if self.include_stack.contains(&canonical) {
                return Err(XmlError::at(
                    spot,
                    format!(
                        "include of {} is cyclic (it includes itself, directly or through other files)",
                        super::super::echo_path(path)
                    ),
                ));
            }
            if self.include_stack.len() >= MAX_INCLUDE_DEPTH {
                return Err(XmlError::at(
                    spot,
                    format!("includes nest deeper than {MAX_INCLUDE_DEPTH} files"),
                ));
            }
        }
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let text = lenient_comments(text);
        let text = text.as_ref();
        let options = roxmltree::ParsingOptions {
            allow_dtd: false,
            nodes_limit: 10_000_000,
            ..roxmltree::ParsingOptions::default()
        };
        let doc = roxmltree::Document::parse_with_options(text, options).map_err(|e| {
            let pos = e.pos();
            XmlError {
                file: path.to_path_buf(),
                line: Some(pos.row),
                column: Some(pos.col),
                message: format!(
                    "not well-formed XML: {}",
                    super::super::clip(&e.to_string(), 300)
                ),
            }
        })?;
        let file: Arc<Path> = Arc::from(path);
        let root = doc.root_element();
        let spot = spot_of(&file, &doc, root);
        if root.tag_name().name() != "scene" {
            return Err(XmlError::at(
                &spot,
                format!(
                    "the root element is <{}>: a Mitsuba scene file's root is <scene>",
                    super::super::echo(root.tag_name().name())
                ),
            ));
        }
        self.check_version(&file, &doc, root)?;
        self.include_stack.push(canonical);
        let target = match into {
            Some((parent, _)) => parent,
            None => self.new_object(Class::Scene, String::new(), None, spot),
        };
        let result = self.read_children(&file, &doc, root, target, depth + 1);
        self.include_stack.pop();
        result.map(|()| target)
    }

    fn check_version(
        &self,
        file: &Arc<Path>,
        doc: &roxmltree::Document,
        root: roxmltree::Node,
    ) -> Result<(), XmlError> {
        let spot = spot_of(file, doc, root);
        let Some(version) = root.attribute("version") else {
            return Err(XmlError::at(
                &spot,
                "<scene> has no version attribute (Mitsuba 3 files say version=\"3.0.0\")",
            ));
        };
        let major = version.split('.').next().unwrap_or("");
        match major.trim().parse::<u32>() {
            Ok(2 | 3) => Ok(()),
            Ok(_) | Err(_) => Err(XmlError::at(
                &spot,
                format!(
                    "scene version \"{}\" is not supported (supported: 2.x and 3.x, Mitsuba 2 and 3's format)",
                    super::super::echo(version)
                ),
            )),
        }
    }

    fn new_object(
        &mut self,
        class: Class,
        kind: String,
        id: Option<String>,
        spot: Spot,
    ) -> ObjectId {
        self.objects.push(Object {
            class,
            kind,
            id,
            spot,
            properties: Vec::new(),
            children: Vec::new(),
        });
        self.objects.len() - 1
    }

    /// The attribute `name` with `$param`s substituted.
    fn attribute(
        &self,
        file: &Arc<Path>,
        doc: &roxmltree::Document,
        node: roxmltree::Node,
        name: &str,
    ) -> Result<Option<String>, XmlError> {
        let Some(raw) = node.attribute(name) else {
            return Ok(None);
        };
        self.substitute(raw)
            .map(Some)
            .map_err(|m| XmlError::at(&spot_of(file, doc, node), m))
    }

    /// `raw` with every `$name` replaced by its parameter's value.
    fn substitute(&self, raw: &str) -> Result<String, String> {
        if !raw.contains('$') {
            return Ok(raw.to_string());
        }
        let mut out = String::with_capacity(raw.len());
        let mut rest = raw;
        while let Some(i) = rest.find('$') {
            out.push_str(&rest[..i]);
            let after = &rest[i + 1..];
            let len = after
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(after.len());
            let name = &after[..len];
            if name.is_empty() {
                return Err(format!(
                    "\"{}\": a $ must start a parameter name",
                    super::super::echo(raw)
                ));
            }
            match self.params.get(name) {
                Some(value) => out.push_str(value),
                None => {
                    return Err(format!(
                        "${} is not defined (define it with <default name=\"{}\" value=\"...\"/> or -D {}=...)",
                        super::super::echo(name),
                        super::super::echo(name),
                        super::super::echo(name)
                    ));
                }
            }
            rest = &after[len..];
        }
        out.push_str(rest);
        Ok(out)
    }

    fn required(
        &self,
        file: &Arc<Path>,
        doc: &roxmltree::Document,
        node: roxmltree::Node,
        name: &str,
    ) -> Result<String, XmlError> {
        self.attribute(file, doc, node, name)?.ok_or_else(|| {
            XmlError::at(
                &spot_of(file, doc, node),
                format!("<{}> needs a {name} attribute", node.tag_name().name()),
            )
        })
    }

    fn read_children(
        &mut self,
        file: &Arc<Path>,
        doc: &roxmltree::Document,
        node: roxmltree::Node,
        parent: ObjectId,
        depth: usize,
    ) -> Result<(), XmlError> {
        if depth > MAX_DEPTH {
            return Err(XmlError::at(
                &spot_of(file, doc, node),
                format!("elements nest deeper than {MAX_DEPTH} levels"),
            ));
        }
        for child in node.children().filter(|c| c.is_element()) {
            self.read_element(file, doc, child, parent, depth)?;
        }
        Ok(())
    }

    fn read_element(
        &mut self,
        file: &Arc<Path>,
        doc: &roxmltree::Document,
        node: roxmltree::Node,
        parent: ObjectId,
        depth: usize,
    ) -> Result<(), XmlError> {
        let spot = spot_of(file, doc, node);
        let tag = node.tag_name().name();
        let parent_is_scene = self.objects[parent].class == Class::Scene;
        match tag {
            "default" => {
                let name = self.required(file, doc, node, "name")?;
                let value = self.required(file, doc, node, "value")?;
                if !is_param_name(&name) {
                    return Err(XmlError::at(
                        &spot,
                        format!(
                            "default name \"{}\": a parameter name is letters, digits and underscores",
                            super::super::echo(&name)
                        ),
                    ));
                }
                // The command line (and earlier defaults) win.
                self.params.entry(name).or_insert(value);
                Ok(())
            }
            "include" => {
                if !parent_is_scene {
                    return Err(XmlError::at(&spot, "<include> must be a child of <scene>"));
                }
                let name = self.required(file, doc, node, "filename")?;
                // As Mitsuba: the including file's folder first, then the search paths (the
                // last <path> first, the top file's folder last).
                let base = file.parent().unwrap_or(Path::new(""));
                let path = std::iter::once(base)
                    .chain(self.search_paths.iter().rev().map(PathBuf::as_path))
                    .map(|dir| dir.join(&name))
                    .find(|candidate| candidate.exists())
                    .unwrap_or_else(|| base.join(&name));
                self.read_file(&path, Some((parent, &spot)), depth)?;
                Ok(())
            }
            "path" => {
                let value = self.required(file, doc, node, "value")?;
                let base = file.parent().unwrap_or(Path::new(""));
                self.search_paths.push(base.join(value));
                Ok(())
            }
            "ref" => {
                let id = self.required(file, doc, node, "id")?;
                let name = self.attribute(file, doc, node, "name")?;
                let slot = self.objects[parent].children.len();
                self.objects[parent].children.push(Child {
                    name,
                    object: usize::MAX,
                    spot: spot.clone(),
                });
                self.pending_refs.push(PendingRef {
                    parent,
                    slot,
                    id,
                    spot,
                });
                Ok(())
            }
            "boolean" | "integer" | "float" | "string" | "point" | "vector" | "rgb"
            | "spectrum" | "transform" => {
                if tag == "spectrum" && node.attribute("type").is_some() {
                    return Err(XmlError::at(
                        &spot,
                        "a <spectrum> plugin (type=...) is not supported (supported: value=\"v\" or value=\"nm:v, nm:v, ...\")",
                    ));
                }
                let name = self.required(file, doc, node, "name")?;
                let value = self.read_value(file, doc, node, tag)?;
                let object = &mut self.objects[parent];
                if object.properties.iter().any(|p| p.name == name) {
                    return Err(XmlError::at(
                        &spot,
                        format!("property \"{}\" is given twice", super::super::echo(&name)),
                    ));
                }
                object.properties.push(Property { name, value, spot });
                Ok(())
            }
            _ => {
                let Some(class) = Class::of_tag(tag) else {
                    let what = if UNMODELED_TAGS.contains(&tag) {
                        format!("<{tag}> (participating media) is not supported")
                    } else {
                        format!(
                            "unknown element <{}> (known: scene, shape, bsdf, emitter, sensor, film, rfilter, sampler, integrator, texture, the properties boolean, integer, float, string, point, vector, rgb, spectrum, transform, and default, include, path, ref)",
                            super::super::echo(tag)
                        )
                    };
                    return Err(XmlError::at(&spot, what));
                };
                if class == Class::Scene {
                    return Err(XmlError::at(&spot, "<scene> inside a scene"));
                }
                let kind = self.required(file, doc, node, "type")?;
                let id = self.attribute(file, doc, node, "id")?;
                let name = self.attribute(file, doc, node, "name")?;
                let object = self.new_object(class, kind, id.clone(), spot.clone());
                if let Some(id) = id {
                    if let Some((_, first)) = self.ids.get(&id) {
                        return Err(XmlError::at(
                            &spot,
                            format!(
                                "id \"{}\" is already used at {}:{}",
                                super::super::echo(&id),
                                first.line,
                                first.column
                            ),
                        ));
                    }
                    self.ids.insert(id, (object, spot.clone()));
                }
                self.objects[parent]
                    .children
                    .push(Child { name, object, spot });
                self.read_children(file, doc, node, object, depth + 1)
            }
        }
    }

    fn resolve_refs(&mut self) -> Result<(), XmlError> {
        for pending in std::mem::take(&mut self.pending_refs) {
            let Some(&(object, _)) = self.ids.get(&pending.id) else {
                return Err(XmlError::at(
                    &pending.spot,
                    format!(
                        "ref to id \"{}\", which no object has",
                        super::super::echo(&pending.id)
                    ),
                ));
            };
            self.objects[pending.parent].children[pending.slot].object = object;
        }
        // An object that (through refs) contains itself would make interpretation loop.
        for start in 0..self.objects.len() {
            self.check_acyclic(start)?;
        }
        Ok(())
    }

    /// Fails if `start` reaches itself through children: a ref cycle.
    fn check_acyclic(&self, start: ObjectId) -> Result<(), XmlError> {
        let mut stack: Vec<ObjectId> = self.objects[start]
            .children
            .iter()
            .map(|c| c.object)
            .collect();
        let mut seen = vec![false; self.objects.len()];
        while let Some(o) = stack.pop() {
            if o == start {
                return Err(XmlError::at(
                    &self.objects[start].spot,
                    "this object contains itself through refs",
                ));
            }
            if std::mem::replace(&mut seen[o], true) {
                continue;
            }
            stack.extend(self.objects[o].children.iter().map(|c| c.object));
        }
        Ok(())
    }

    fn read_value(
        &self,
        file: &Arc<Path>,
        doc: &roxmltree::Document,
        node: roxmltree::Node,
        tag: &str,
    ) -> Result<Value, XmlError> {
        let spot = spot_of(file, doc, node);
        let fail = |m: String| XmlError::at(&spot, m);
        let value = || self.required(file, doc, node, "value");
        Ok(match tag {
            "boolean" => match value()?.trim() {
                "true" => Value::Boolean(true),
                "false" => Value::Boolean(false),
                other => {
                    return Err(fail(format!(
                        "boolean value \"{}\" is neither true nor false",
                        super::super::echo(other)
                    )));
                }
            },
            "integer" => {
                let text = value()?;
                Value::Integer(text.trim().parse::<i64>().map_err(|_| {
                    fail(format!(
                        "\"{}\" is not an integer",
                        super::super::echo(&text)
                    ))
                })?)
            }
            "float" => Value::Float(parse_number(&value()?).map_err(fail)?),
            "string" => Value::String(value()?),
            "point" | "vector" => {
                let v = self.read_xyz(file, doc, node, 0.0)?;
                if tag == "point" {
                    Value::Point(v)
                } else {
                    Value::Vector(v)
                }
            }
            "rgb" => {
                let text = value()?;
                let numbers = parse_numbers(&text).map_err(&fail)?;
                match numbers[..] {
                    [v] => Value::Rgb(DVec3::splat(v)),
                    [r, g, b] => Value::Rgb(DVec3::new(r, g, b)),
                    _ => {
                        return Err(fail(format!(
                            "rgb value \"{}\" has {} numbers (one or three)",
                            super::super::echo(&text),
                            numbers.len()
                        )));
                    }
                }
            }
            "spectrum" => {
                if node.attribute("filename").is_some() {
                    return Err(fail(
                        "a spectrum read from a file (filename=...) is not supported (supported: value=\"v\" or value=\"nm:v, nm:v, ...\")".into(),
                    ));
                }
                let text = value()?;
                if text.contains(':') {
                    Value::Spectrum(Spectrum::Pairs(
                        super::spectrum::parse_spectrum_pairs(&text).map_err(&fail)?,
                    ))
                } else {
                    Value::Spectrum(Spectrum::Constant(parse_number(&text).map_err(&fail)?))
                }
            }
            "transform" => Value::Transform(self.read_transform(file, doc, node)?),
            _ => unreachable!("read_value is called for value tags only"),
        })
    }

    /// x, y, z attributes (each defaulting to `default`) or one `value` of one or three numbers.
    fn read_xyz(
        &self,
        file: &Arc<Path>,
        doc: &roxmltree::Document,
        node: roxmltree::Node,
        default: f64,
    ) -> Result<DVec3, XmlError> {
        let spot = spot_of(file, doc, node);
        if let Some(text) = self.attribute(file, doc, node, "value")? {
            if ["x", "y", "z"].iter().any(|a| node.attribute(*a).is_some()) {
                return Err(XmlError::at(&spot, "give value or x, y, z, not both"));
            }
            let numbers = parse_numbers(&text).map_err(|m| XmlError::at(&spot, m))?;
            return match numbers[..] {
                [v] => Ok(DVec3::splat(v)),
                [x, y, z] => Ok(DVec3::new(x, y, z)),
                _ => Err(XmlError::at(
                    &spot,
                    format!(
                        "value \"{}\" has {} numbers (one or three)",
                        super::super::echo(&text),
                        numbers.len()
                    ),
                )),
            };
        }
        let mut v = DVec3::splat(default);
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            if let Some(text) = self.attribute(file, doc, node, axis)? {
                v[i] = parse_number(&text).map_err(|m| XmlError::at(&spot, m))?;
            }
        }
        Ok(v)
    }

    /// A `<transform>`: its steps in order, each applied after (to the left of) the ones before.
    fn read_transform(
        &self,
        file: &Arc<Path>,
        doc: &roxmltree::Document,
        node: roxmltree::Node,
    ) -> Result<DMat4, XmlError> {
        let mut m = DMat4::IDENTITY;
        for step in node.children().filter(|c| c.is_element()) {
            let spot = spot_of(file, doc, step);
            let fail = |msg: String| XmlError::at(&spot, msg);
            let tag = step.tag_name().name();
            let t = match tag {
                "translate" => DMat4::from_translation(self.read_xyz(file, doc, step, 0.0)?),
                "scale" => {
                    let s = self.read_xyz(file, doc, step, 1.0)?;
                    if s.x == 0.0 || s.y == 0.0 || s.z == 0.0 {
                        return Err(fail(format!(
                            "scale {:?} has a zero factor: the transform would flatten the shape",
                            s.to_array()
                        )));
                    }
                    DMat4::from_scale(s)
                }
                "rotate" => {
                    let axis = self.read_xyz(file, doc, step, 0.0)?;
                    let angle = self.required(file, doc, step, "angle")?;
                    let angle = parse_number(&angle).map_err(&fail)?;
                    let axis = axis.try_normalize().ok_or_else(|| {
                        fail("rotate needs a non-zero axis (x, y, z or value)".to_string())
                    })?;
                    DMat4::from_quat(DQuat::from_axis_angle(axis, angle.to_radians()))
                }
                "matrix" => {
                    let text = self.required(file, doc, step, "value")?;
                    let v = parse_numbers(&text).map_err(&fail)?;
                    match v.len() {
                        // Row-major, as written.
                        16 => DMat4::from_cols_array(&[
                            v[0], v[4], v[8], v[12], v[1], v[5], v[9], v[13], v[2], v[6], v[10],
                            v[14], v[3], v[7], v[11], v[15],
                        ]),
                        9 => DMat4::from_mat3(DMat3::from_cols_array(&[
                            v[0], v[3], v[6], v[1], v[4], v[7], v[2], v[5], v[8],
                        ])),
                        n => {
                            return Err(fail(format!(
                                "matrix has {n} numbers (16 for 4x4 or 9 for 3x3, row by row)"
                            )));
                        }
                    }
                }
                "lookat" => {
                    let read = |name: &str| -> Result<Option<DVec3>, XmlError> {
                        match self.attribute(file, doc, step, name)? {
                            None => Ok(None),
                            Some(text) => {
                                let v = parse_numbers(&text).map_err(&fail)?;
                                match v[..] {
                                    [x, y, z] => Ok(Some(DVec3::new(x, y, z))),
                                    _ => Err(fail(format!(
                                        "lookat {name} \"{}\" needs three numbers",
                                        super::super::echo(&text)
                                    ))),
                                }
                            }
                        }
                    };
                    let origin = read("origin")?
                        .ok_or_else(|| fail("lookat needs an origin".to_string()))?;
                    let target =
                        read("target")?.ok_or_else(|| fail("lookat needs a target".to_string()))?;
                    let up = read("up")?;
                    look_at(origin, target, up).map_err(fail)?
                }
                other => {
                    return Err(fail(format!(
                        "unknown transform step <{}> (known: translate, rotate, scale, matrix, lookat)",
                        super::super::echo(other)
                    )));
                }
            };
            m = t * m;
        }
        if !m.is_finite() {
            return Err(XmlError::at(
                &spot_of(file, doc, node),
                "the transform is not finite",
            ));
        }
        if m.determinant().abs() < 1e-300 || !m.determinant().is_normal() {
            return Err(XmlError::at(
                &spot_of(file, doc, node),
                "the transform is singular (it flattens space)",
            ));
        }
        Ok(m)
    }
}

/// `text` with every dash inside a comment made a space. XML forbids "--" in a comment, but
/// Mitsuba's parser (pugixml) reads such files, and scene files have them (a command line
/// quoted in a comment); the text keeps its length, so positions in errors are unchanged.
fn lenient_comments(text: &str) -> std::borrow::Cow<'_, str> {
    if !text.contains("<!--") {
        return std::borrow::Cow::Borrowed(text);
    }
    let mut bytes = text.as_bytes().to_vec();
    let mut at = 0;
    while let Some(start) = text[at..].find("<!--").map(|i| at + i + 4) {
        let Some(end) = text[start..].find("-->").map(|i| start + i) else {
            break;
        };
        for b in &mut bytes[start..end] {
            if *b == b'-' {
                *b = b' ';
            }
        }
        at = end + 3;
    }
    // Only ASCII dashes became ASCII spaces: the bytes are still UTF-8.
    std::borrow::Cow::Owned(String::from_utf8(bytes).unwrap_or_else(|_| text.to_string()))
}

/// Mitsuba's look-at frame: columns left = normalize(up x dir), up' = dir x left, dir, origin.
/// Without `up`, one perpendicular to dir is chosen.
fn look_at(origin: DVec3, target: DVec3, up: Option<DVec3>) -> Result<DMat4, String> {
    let dir = (target - origin)
        .try_normalize()
        .ok_or("lookat origin and target are the same point")?;
    let up = match up {
        Some(up) => up,
        None => dir.any_orthonormal_vector(),
    };
    let left = up
        .cross(dir)
        .try_normalize()
        .ok_or("lookat up is zero or parallel to the viewing direction")?;
    let new_up = dir.cross(left);
    Ok(DMat4::from_cols(
        left.extend(0.0),
        new_up.extend(0.0),
        dir.extend(0.0),
        origin.extend(1.0),
    ))
}

/// The affine part of a 4x4 transform (the last row must be 0 0 0 1).
pub fn affine(m: &DMat4) -> Option<DAffine3> {
    let row = m.row(3);
    (row == glam::DVec4::new(0.0, 0.0, 0.0, 1.0)).then(|| DAffine3::from_mat4(*m))
}

fn spot_of(file: &Arc<Path>, doc: &roxmltree::Document, node: roxmltree::Node) -> Spot {
    let pos = doc.text_pos_at(node.range().start);
    Spot {
        file: file.clone(),
        line: pos.row,
        column: pos.col,
    }
}

/// One finite number.
pub fn parse_number(text: &str) -> Result<f64, String> {
    let t = text.trim();
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!(
            "\"{}\" is not a finite number",
            super::super::echo(text)
        )),
    }
}

/// Numbers separated by commas and/or whitespace.
pub fn parse_numbers(text: &str) -> Result<Vec<f64>, String> {
    let numbers: Result<Vec<f64>, String> = text
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .map(parse_number)
        .collect();
    let numbers = numbers?;
    if numbers.is_empty() {
        return Err("no numbers given".to_string());
    }
    Ok(numbers)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str, defines: &[(String, String)]) -> Result<Document, XmlError> {
        read_str(Path::new("/nonexistent/scene.xml"), text, defines)
    }

    #[test]
    fn defaults_and_command_line_parameters() {
        let text = r#"<scene version="3.0.0">
            <default name="spp" value="16"/>
            <integrator type="$kind"><integer name="max_depth" value="$spp"/></integrator>
        </scene>"#;
        let doc = read(text, &[("kind".into(), "path".into())]).unwrap();
        let integrator = &doc.objects[1];
        assert_eq!(integrator.kind, "path");
        assert_eq!(integrator.properties[0].value, Value::Integer(16));
        let doc = read(
            text,
            &[("kind".into(), "path".into()), ("spp".into(), "64".into())],
        )
        .unwrap();
        assert_eq!(doc.objects[1].properties[0].value, Value::Integer(64));
        let e = read(text, &[]).unwrap_err();
        assert!(e.message.contains("$kind is not defined"), "{}", e.message);
        assert_eq!(e.line, Some(3));
    }

    #[test]
    fn comments_may_hold_double_dashes_as_in_mitsuba() {
        let text = "<scene version=\"3.0.0\"><!-- made by `tool --flag` ---><integer name=\"a\" value=\"1\"/></scene>";
        let doc = read(text, &[]).unwrap();
        assert_eq!(doc.objects[0].properties[0].value, Value::Integer(1));
        let e = read("<scene version=\"3.0.0\"><!-- x --><bad/></scene>", &[]).unwrap_err();
        assert_eq!((e.line, e.column), (Some(1), Some(34)), "{}", e.message);
    }

    #[test]
    fn refs_may_come_before_their_ids() {
        let text = r#"<scene version="2.0.0">
            <shape type="obj"><ref id="white"/></shape>
            <bsdf type="diffuse" id="white"/>
        </scene>"#;
        let doc = read(text, &[]).unwrap();
        let shape = &doc.objects[1];
        assert_eq!(
            doc.objects[shape.children[0].object].id.as_deref(),
            Some("white")
        );
        let e = read(
            r#"<scene version="3.0.0"><shape type="obj"><ref id="x"/></shape></scene>"#,
            &[],
        )
        .unwrap_err();
        assert!(e.message.contains("no object has"), "{}", e.message);
    }

    #[test]
    fn transforms_compose_in_order() {
        let text = r#"<scene version="3.0.0"><shape type="obj">
            <transform name="to_world">
                <scale value="2"/>
                <rotate y="1" angle="90"/>
                <translate x="1"/>
            </transform></shape></scene>"#;
        let doc = read(text, &[]).unwrap();
        let Value::Transform(m) = doc.objects[1].properties[0].value else {
            panic!("not a transform")
        };
        // (1,0,0) -> (2,0,0) -> rotated about y by 90 degrees (0,0,-2) -> (1,0,-2).
        let p = m.transform_point3(DVec3::X);
        assert!((p - DVec3::new(1.0, 0.0, -2.0)).length() < 1e-12, "{p}");
    }

    #[test]
    fn lookat_builds_mitsubas_frame() {
        let m = look_at(DVec3::new(0.0, 0.0, -5.0), DVec3::ZERO, Some(DVec3::Y)).unwrap();
        // Camera z looks at the target, y is up, x is left (up x dir).
        assert!((m.transform_vector3(DVec3::Z) - DVec3::Z).length() < 1e-12);
        assert!((m.transform_vector3(DVec3::Y) - DVec3::Y).length() < 1e-12);
        assert!((m.transform_vector3(DVec3::X) - DVec3::X).length() < 1e-12);
        assert!((m.transform_point3(DVec3::ZERO) - DVec3::new(0.0, 0.0, -5.0)).length() < 1e-12);
    }

    #[test]
    fn bad_values_name_their_line() {
        for (text, needle) in [
            (
                r#"<scene version="3.0.0"><float name="a" value="x"/></scene>"#,
                "not a finite number",
            ),
            (
                r#"<scene version="3.0.0"><rgb name="a" value="1 2"/></scene>"#,
                "one or three",
            ),
            (
                r#"<scene version="3.0.0"><spectrum name="a" value="500:1, 400:2"/></scene>"#,
                "must increase",
            ),
            (r#"<scene version="0.6.0"></scene>"#, "not supported"),
            (
                r#"<scene version="3.0.0"><medium type="homogeneous"/></scene>"#,
                "participating media",
            ),
            (
                r#"<scene version="3.0.0"><shape type="obj"><transform name="t"><scale x="0"/></transform></shape></scene>"#,
                "zero factor",
            ),
        ] {
            let e = read(text, &[]).unwrap_err();
            assert!(e.message.contains(needle), "{text}: {}", e.message);
            assert_eq!(e.line, Some(1), "{text}");
        }
    }
}

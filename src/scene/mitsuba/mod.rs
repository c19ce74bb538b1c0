//! Mitsuba 3 scene files (XML): `document` reads the file into plugin objects, `build` turns
//! them into the scene world that RON scenes also become; `spectrum`, `serialized` and
//! `analytic` are what it reads colours, Mitsuba's mesh files and its analytic shapes with;
//! `export` writes a RON scene as a Mitsuba file.

pub mod analytic;
pub mod build;
pub mod document;
pub mod export;
pub mod serialized;
pub mod spectrum;

pub use build::FileSettings;
pub use document::Defines;

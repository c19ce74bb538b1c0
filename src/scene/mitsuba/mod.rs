//! Reading Mitsuba 3 scenes: the pieces its XML reader calls.

pub mod analytic;
pub mod serialized;
pub mod spectrum;

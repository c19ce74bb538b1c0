//! Systems, one file per system, grouped by stage.

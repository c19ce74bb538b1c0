//! The crate's layers stay one-way: no system names an integrator, and no two source files
//! import each other, directly or round a cycle. Read from the source text: an edge A -> B
//! when file A names `crate::B...` (in a `use`, a braced group or an inline path) or
//! `super::B...`, resolved to the file that defines the longest module prefix; a parent
//! (`mod.rs`) depends on a child only when it names the child's items, not when it declares or
//! re-exports it. Cycles are the graph's strongly connected components.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("source folder readable") {
        let path = entry.expect("entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// Module path of a file: src/a/b.rs and src/a/b/mod.rs are `a::b`; systems/x/y.rs is
/// `systems::x::y` (lib.rs mounts systems/ as `crate::systems`).
fn module_of(path: &Path) -> String {
    let rel = path.strip_prefix(ROOT).expect("inside the crate");
    let mut parts: Vec<String> = rel
        .with_extension("")
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    if parts[0] == "src" {
        parts.remove(0);
    }
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts.join("::")
}

/// `a::b::c...` identifiers following `prefix` at every place it occurs in `line`.
fn paths_after(line: &str, prefix: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = line;
    while let Some(at) = rest.find(prefix) {
        let before_ok = rest[..at]
            .chars()
            .last()
            .is_none_or(|c| !(c.is_alphanumeric() || c == '_' || c == ':'));
        rest = &rest[at + prefix.len()..];
        if !before_ok {
            continue;
        }
        if let Some(group) = rest.strip_prefix('{') {
            // crate::{a, b::c}: each item of the group.
            let end = group.find('}').unwrap_or(group.len());
            out.extend(group[..end].split(',').map(|i| path_prefix(i.trim())));
        } else {
            out.push(path_prefix(rest));
        }
    }
    out.retain(|p| !p.is_empty());
    out
}

/// The leading `a::b::c` of `s`.
fn path_prefix(s: &str) -> String {
    let end = s
        .find(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
        .unwrap_or(s.len());
    s[..end].trim_end_matches(':').to_string()
}

/// The longest known module that `path` starts with.
fn resolve(modules: &BTreeSet<String>, path: &str) -> Option<String> {
    let parts: Vec<&str> = path.split("::").collect();
    (1..=parts.len())
        .rev()
        .map(|k| parts[..k].join("::"))
        .find(|m| modules.contains(m))
}

fn dependency_graph() -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    rust_files(&Path::new(ROOT).join("src"), &mut files);
    rust_files(&Path::new(ROOT).join("systems"), &mut files);
    let sources: BTreeMap<String, String> = files
        .iter()
        .map(|f| {
            (
                module_of(f),
                std::fs::read_to_string(f).expect("source readable"),
            )
        })
        .collect();
    let modules: BTreeSet<String> = sources.keys().cloned().collect();
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (module, text) in &sources {
        let parent: Vec<&str> = module.split("::").collect();
        let parent = parent[..parent.len().saturating_sub(1)].join("::");
        let children: BTreeMap<&str, &String> = modules
            .iter()
            .filter_map(|m| {
                let rest = if module.is_empty() {
                    Some(m.as_str())
                } else {
                    m.strip_prefix(module.as_str())?.strip_prefix("::")
                };
                rest.filter(|r| !r.is_empty() && !r.contains("::"))
                    .map(|r| (r, m))
            })
            .collect();
        let out = edges.entry(module.clone()).or_default();
        for line in text.lines().map(str::trim) {
            if line.starts_with("//") {
                continue;
            }
            let mut targets: Vec<String> = paths_after(line, "crate::");
            for p in paths_after(line, "super::") {
                targets.push(if parent.is_empty() {
                    p
                } else {
                    format!("{parent}::{p}")
                });
            }
            // A parent naming its child's items (`pt::render`), not declaring it.
            let declares = line.starts_with("mod ")
                || line.starts_with("pub mod ")
                || line.starts_with("use ")
                || line.starts_with("pub use ")
                || line.starts_with("pub(crate) mod ")
                || line.starts_with("pub(crate) use ");
            if !declares {
                for (name, child) in &children {
                    let named = paths_after(line, &format!("{name}::"));
                    if !named.is_empty() || line.contains(&format!("{name}::{{")) {
                        targets.push((*child).clone());
                    }
                }
            }
            for t in targets {
                if let Some(t) = resolve(&modules, &t)
                    && t != *module
                    && !module.starts_with(&format!("{t}::"))
                    && !t.starts_with(&format!("{module}::"))
                {
                    out.insert(t);
                }
            }
        }
    }
    edges
}

/// Strongly connected components with more than one file (Tarjan's algorithm).
fn cycles(edges: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct Walk<'a> {
        edges: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on_stack: BTreeSet<&'a str>,
        found: Vec<Vec<String>>,
    }
    fn visit<'a>(w: &mut Walk<'a>, v: &'a str) {
        let n = w.index.len();
        w.index.insert(v, n);
        w.low.insert(v, n);
        w.stack.push(v);
        w.on_stack.insert(v);
        for t in w.edges.get(v).into_iter().flatten() {
            let t = t.as_str();
            if !w.index.contains_key(t) {
                visit(w, t);
                let lt = w.low[t];
                let lv = w.low.get_mut(v).unwrap();
                *lv = (*lv).min(lt);
            } else if w.on_stack.contains(t) {
                let it = w.index[t];
                let lv = w.low.get_mut(v).unwrap();
                *lv = (*lv).min(it);
            }
        }
        if w.low[v] == w.index[v] {
            let mut component = Vec::new();
            loop {
                let t = w.stack.pop().unwrap();
                w.on_stack.remove(t);
                component.push(t.to_string());
                if t == v {
                    break;
                }
            }
            if component.len() > 1 {
                component.sort();
                w.found.push(component);
            }
        }
    }
    let mut w = Walk {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        found: Vec::new(),
    };
    for v in edges.keys() {
        if !w.index.contains_key(v.as_str()) {
            visit(&mut w, v);
        }
    }
    w.found
}

#[test]
fn no_system_names_an_integrator() {
    let mut files = Vec::new();
    rust_files(&Path::new(ROOT).join("systems"), &mut files);
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        assert!(
            !text.contains("crate::integrators"),
            "{} names crate::integrators: systems ask for columns, not states",
            f.display()
        );
    }
}

#[test]
fn no_import_cycles_among_source_files() {
    let edges = dependency_graph();
    // The check can fail: known edges are seen.
    assert!(edges["compare::run"].contains("compare::report"));
    assert!(edges["integrators::pt"].contains("systems"));
    assert!(edges["integrators::pt"].contains("components::path_tracing"));
    let found = cycles(&edges);
    let described: Vec<String> = found
        .iter()
        .map(|c| {
            c.iter()
                .map(|m| {
                    let to: Vec<&str> = edges[m]
                        .iter()
                        .filter(|t| c.contains(t))
                        .map(String::as_str)
                        .collect();
                    format!("{m} -> {}", to.join(", "))
                })
                .collect::<Vec<_>>()
                .join("; ")
        })
        .collect();
    assert!(found.is_empty(), "import cycles: {described:#?}");
}

#[test]
fn the_cycle_check_finds_a_cycle() {
    let mut edges = BTreeMap::new();
    edges.insert("a".to_string(), BTreeSet::from(["b".to_string()]));
    edges.insert("b".to_string(), BTreeSet::from(["c".to_string()]));
    edges.insert("c".to_string(), BTreeSet::from(["a".to_string()]));
    edges.insert("d".to_string(), BTreeSet::from(["a".to_string()]));
    assert_eq!(cycles(&edges), vec![vec!["a", "b", "c"]]);
}

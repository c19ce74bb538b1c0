//! The pipeline: systems, the graphs integrators declare from them, and the scheduler that
//! runs a graph, timing every system and counting the items it takes and emits.
//!
//! A system is a named step over a queue of the wavefront state `S` (an integrator's own
//! structure-of-arrays state). A graph is a list of nodes: a system, or a loop that repeats its
//! body while a queue is non-empty. Each integrator declares its whole graph in one function,
//! built from the scene, so a scene that has no use for a system never runs it.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Items a system run took from its queue and emitted into the next.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Flow {
    pub taken: usize,
    pub emitted: usize,
}

impl Flow {
    pub fn new(taken: usize, emitted: usize) -> Flow {
        Flow { taken, emitted }
    }
}

/// The columns a system reads and writes, as paths into its state (`rays`, `data.accel`,
/// `paths.radiance`). `system!` derives them from the same list that borrows the columns, so
/// they cannot drift from what the system touches.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Access {
    pub reads: &'static [&'static str],
    pub writes: &'static [&'static str],
    /// The write columns' names in the system (`writes` holds their paths in the state).
    pub write_columns: &'static [&'static str],
    /// Write columns whose slots the system moves while moving only some of their fields:
    /// (column, fields moved). The fields left behind are stale after it.
    pub reorders: &'static [(&'static str, &'static [&'static str])],
}

/// One step of an integrator over the wavefront state `S`: a system (`system!`) bound to the
/// state's columns (`bind!`).
pub trait System<S>: Send + Sync {
    /// A name that says what the system does; the report lists systems by it.
    fn name(&self) -> &'static str;
    /// The columns of `S` the system reads and writes.
    fn access(&self) -> Access;
    /// Runs over the system's queue in `state`.
    fn run(&self, state: &mut S) -> Flow;
}

/// What `system!` declares of a system, whatever state it runs on: its name, the names of the
/// columns it reads and writes, and its body over them. `Columns` is the tuple of those
/// columns, reads (`&`) then writes (`&mut`), in declaration order.
pub trait Declared: Send + Sync {
    type Columns<'a>;
    const READS: &'static [&'static str];
    const WRITES: &'static [&'static str];
    /// See `Access::reorders`.
    const REORDERS: &'static [(&'static str, &'static [&'static str])] = &[];
    fn name(&self) -> &'static str;
    fn run_columns(&self, columns: Self::Columns<'_>) -> Flow;
}

/// Declares a system: its name, the columns it reads and writes (each a name and a type), and
/// its body. The body sees each column as a local binding (`&` for reads, `&mut` for writes)
/// and nothing else, so an undeclared access does not compile. The system names no state: a
/// state runs it once `bind!` has mapped each column to one of the state's fields, and the
/// graph check reads the fields the binding names.
///
/// ```ignore
/// pub struct ApplyShadowContributions;
/// system! {
///     ApplyShadowContributions = "apply_shadow_contributions";
///     read shadow: ShadowRays, len: usize;
///     write radiance: Vec<Vec3>;
///     run { /* uses shadow, len, radiance */ }
/// }
/// ```
///
/// A system with fields names its `self` in the body and, if its name depends on them, in the
/// name: `name(this) = this.kind.system_name();` and `run(this) { ... this.kind ... }`.
///
/// A system that moves the slots of a write column but only some of its fields says which:
/// `reorder rays[dir], hits[triangle];` after its writes (`hits[]`: none moved, the slots
/// only reserved). The graph check then counts the
/// column's other fields as unwritten after it, so a later system that reads them (or the
/// whole column) is named, not handed stale data.
#[macro_export]
macro_rules! system {
    (
        $system:ty = $label:expr;
        $($rest:tt)*
    ) => {
        $crate::system!(@columns $system, (_this) $label; $($rest)*);
    };
    (
        $system:ty;
        name($nthis:ident) = $label:expr;
        $($rest:tt)*
    ) => {
        $crate::system!(@columns $system, ($nthis) $label; $($rest)*);
    };
    (@columns $system:ty, ($nthis:ident) $label:expr;
        $(read $($r:ident : $rt:ty),+ ;)?
        $(write $($w:ident : $wt:ty),+ ;)?
        $(reorder $($o:ident [$($of:ident),*]),+ ;)?
        run $body:block
    ) => {
        $crate::system!(@columns $system, ($nthis) $label;
            $(read $($r : $rt),+ ;)? $(write $($w : $wt),+ ;)?
            $(reorder $($o [$($of),*]),+ ;)? run (_this) $body);
    };
    (@columns $system:ty, ($nthis:ident) $label:expr;
        $(read $($r:ident : $rt:ty),+ ;)?
        $(write $($w:ident : $wt:ty),+ ;)?
        $(reorder $($o:ident [$($of:ident),*]),+ ;)?
        run ($this:ident) $body:block
    ) => {
        const _: () = assert!(
            $crate::pipeline::reorders_written(
                <$system as $crate::pipeline::Declared>::WRITES,
                <$system as $crate::pipeline::Declared>::REORDERS,
            ),
            "a system reorders a column it does not write",
        );
        impl $crate::pipeline::Declared for $system {
            type Columns<'a> = ($($(&'a $rt,)+)? $($(&'a mut $wt,)+)?);
            const READS: &'static [&'static str] = &[$($(stringify!($r)),+)?];
            const WRITES: &'static [&'static str] = &[$($(stringify!($w)),+)?];
            const REORDERS: &'static [(&'static str, &'static [&'static str])] =
                &[$($((stringify!($o), &[$(stringify!($of)),*])),+)?];
            fn name(&self) -> &'static str {
                let $nthis = self;
                let _ = $nthis;
                $label
            }
            #[allow(unused_variables)]
            fn run_columns(&self, columns: Self::Columns<'_>) -> $crate::pipeline::Flow {
                let $this = self;
                let _ = $this;
                let ($($($r,)+)? $($($w,)+)?) = columns;
                $body
            }
        }
    };
}

/// Binds systems to a state: for each system, the field of the state behind each column it
/// declared (`name = path.in.state`, or just `name` for the field of that name), reads then
/// writes in the system's order. A column the binding misses, adds, reorders or moves
/// between reads and writes does not compile; the graph check sees the fields named here.
///
/// ```ignore
/// bind! {
///     PtState:
///     trace::closest::TraceClosest { read accel = data.accel, rays, live = active; write hits; }
/// }
/// ```
#[macro_export]
macro_rules! bind {
    ($state:ty: $(
        $system:ty {
            $(read $($r:ident $(= $($rp:ident).+)?),+ ;)?
            $(write $($w:ident $(= $($wp:ident).+)?),+ ;)?
        }
    )*) => {
        $(
            const _: () = assert!(
                $crate::pipeline::same_names(
                    <$system as $crate::pipeline::Declared>::READS,
                    &[$($(stringify!($r)),+)?],
                ) && $crate::pipeline::same_names(
                    <$system as $crate::pipeline::Declared>::WRITES,
                    &[$($(stringify!($w)),+)?],
                ),
                "a binding lists other columns than its system declares",
            );
            impl $crate::pipeline::System<$state> for $system {
                fn name(&self) -> &'static str {
                    $crate::pipeline::Declared::name(self)
                }
                fn access(&self) -> $crate::pipeline::Access {
                    $crate::pipeline::Access {
                        reads: &[$($($crate::__column_name!($r $(= $($rp).+)?)),+)?],
                        writes: &[$($($crate::__column_name!($w $(= $($wp).+)?)),+)?],
                        write_columns: <$system as $crate::pipeline::Declared>::WRITES,
                        reorders: <$system as $crate::pipeline::Declared>::REORDERS,
                    }
                }
                fn run(&self, state: &mut $state) -> $crate::pipeline::Flow {
                    $crate::pipeline::Declared::run_columns(
                        self,
                        (
                            $($(&$crate::__column!(state, $r $(= $($rp).+)?),)+)?
                            $($(&mut $crate::__column!(state, $w $(= $($wp).+)?),)+)?
                        ),
                    )
                }
            }
        )*
    };
}

/// Whether two lists of column names are equal (for `bind!`'s check, at compile time).
pub const fn same_names(a: &[&str], b: &[&str]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if !same_name(a[i], b[i]) {
            return false;
        }
        i += 1;
    }
    true
}

/// Whether every column a system reorders is one it writes (for `system!`, at compile time).
pub const fn reorders_written(writes: &[&str], reorders: &[(&str, &[&str])]) -> bool {
    let mut i = 0;
    while i < reorders.len() {
        let mut found = false;
        let mut k = 0;
        while k < writes.len() {
            found |= same_name(writes[k], reorders[i].0);
            k += 1;
        }
        if !found {
            return false;
        }
        i += 1;
    }
    true
}

const fn same_name(a: &str, b: &str) -> bool {
    let (x, y) = (a.as_bytes(), b.as_bytes());
    if x.len() != y.len() {
        return false;
    }
    let mut k = 0;
    while k < x.len() {
        if x[k] != y[k] {
            return false;
        }
        k += 1;
    }
    true
}

/// The state field a `bind!` column names (used by `bind!`).
#[doc(hidden)]
#[macro_export]
macro_rules! __column {
    ($state:ident, $name:ident) => {
        $state.$name
    };
    ($state:ident, $name:ident = $($path:ident).+) => {
        $state.$($path).+
    };
}

/// The path of a `bind!` column as a string (used by `bind!`).
#[doc(hidden)]
#[macro_export]
macro_rules! __column_name {
    ($name:ident) => {
        stringify!($name)
    };
    ($name:ident = $head:ident $(. $tail:ident)*) => {
        concat!(stringify!($head) $(, ".", stringify!($tail))*)
    };
}

/// A node of an integrator's graph.
pub enum Node<S> {
    System(Box<dyn System<S>>),
    /// A graph over a part of the state (e.g. the photon tracing inside a photon mapper),
    /// run in place, its systems timed and counted with the rest.
    Nested(Box<dyn NestedGraph<S>>),
    /// Repeats `body` while `queue_len(state)` is non-zero (checked before each iteration).
    Loop {
        name: &'static str,
        queue_len: fn(&S) -> usize,
        body: Vec<Node<S>>,
    },
    /// Runs `body` only when `needed(state)` says the state lacks what the body makes: work
    /// done once per render (PM's photon maps) in a graph that runs every pass.
    Once {
        name: &'static str,
        needed: fn(&S) -> bool,
        body: Vec<Node<S>>,
    },
    /// Where a run under a stop flag (`Graph::run_until`) gives up once the flag is set,
    /// leaving the rest of the graph unrun: placed where the state holds nothing of the run
    /// that must not be dropped (before each chunk of a photon pass), so the driver drops the
    /// unfinished pass. A plain `run` passes it by.
    StopPoint,
}

impl<S> Node<S> {
    pub fn system(system: impl System<S> + 'static) -> Node<S> {
        Node::System(Box::new(system))
    }

    /// `graph` run on the part of the state `part` picks, the field named `part_name`;
    /// `inputs` are the part's columns set before the nested graph runs (for the check).
    pub fn nested<T: 'static>(
        graph: Graph<T>,
        part_name: &'static str,
        part: fn(&mut S) -> &mut T,
        inputs: &'static [&'static str],
    ) -> Node<S>
    where
        S: 'static,
    {
        Node::Nested(Box::new(Nested {
            graph,
            part_name,
            part,
            inputs,
        }))
    }
}

/// A graph over part of a state `S`, as one node of a graph over `S`.
pub trait NestedGraph<S>: Send + Sync {
    /// Runs the nested graph; false when a stop point gave up (see `Node::StopPoint`).
    fn run(&self, state: &mut S, stats: &mut Stats, stop: Option<&AtomicBool>) -> bool;
    fn system_names(&self) -> Vec<&'static str>;
    /// The field of `S` the nested graph runs on.
    fn part_name(&self) -> &'static str;
    /// The nested graph's own check (see `Graph::check`).
    fn check(&self) -> Vec<String>;
    fn describe(&self, indent: usize, out: &mut String);
}

struct Nested<S, T> {
    graph: Graph<T>,
    part_name: &'static str,
    part: fn(&mut S) -> &mut T,
    inputs: &'static [&'static str],
}

impl<S, T> NestedGraph<S> for Nested<S, T> {
    fn run(&self, state: &mut S, stats: &mut Stats, stop: Option<&AtomicBool>) -> bool {
        run_nodes(&self.graph.nodes, (self.part)(state), stats, stop)
    }
    fn system_names(&self) -> Vec<&'static str> {
        self.graph.system_names()
    }
    fn part_name(&self) -> &'static str {
        self.part_name
    }
    fn check(&self) -> Vec<String> {
        self.graph
            .check(self.inputs)
            .into_iter()
            .map(|p| format!("{} > {p}", self.graph.name))
            .collect()
    }
    fn describe(&self, indent: usize, out: &mut String) {
        describe_nodes(&self.graph.nodes, indent, out);
    }
}

/// An integrator's graph of systems.
pub struct Graph<S> {
    pub name: &'static str,
    pub nodes: Vec<Node<S>>,
}

/// Time and item counts of one system, summed over its runs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SystemStats {
    pub name: &'static str,
    pub runs: u64,
    pub time: Duration,
    pub taken: u64,
    pub emitted: u64,
}

/// The scheduler's record of a graph's runs: one entry per system, in graph order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stats {
    pub systems: Vec<SystemStats>,
    /// Iterations of each loop, by loop name.
    pub loops: Vec<(&'static str, u64)>,
}

impl Stats {
    pub fn total_time(&self) -> Duration {
        self.systems.iter().map(|s| s.time).sum()
    }

    /// Each system with its share of the total time, in percent.
    pub fn time_shares(&self) -> impl Iterator<Item = (&SystemStats, f64)> {
        let total = self.total_time().as_secs_f64().max(1e-12);
        self.systems
            .iter()
            .map(move |s| (s, 100.0 * s.time.as_secs_f64() / total))
    }

    pub fn get(&self, name: &str) -> Option<&SystemStats> {
        self.systems.iter().find(|s| s.name == name)
    }

    /// Adds another record of the same graph's runs (another state's waves) to this one.
    pub fn absorb(&mut self, other: &Stats) {
        for s in &other.systems {
            let e = self.entry(s.name);
            e.runs += s.runs;
            e.time += s.time;
            e.taken += s.taken;
            e.emitted += s.emitted;
        }
        for &(name, n) in &other.loops {
            match self.loops.iter_mut().find(|(l, _)| *l == name) {
                Some((_, m)) => *m += n,
                None => self.loops.push((name, n)),
            }
        }
    }

    fn entry(&mut self, name: &'static str) -> &mut SystemStats {
        let i = match self.systems.iter().position(|s| s.name == name) {
            Some(i) => i,
            None => {
                self.systems.push(SystemStats {
                    name,
                    ..Default::default()
                });
                self.systems.len() - 1
            }
        };
        &mut self.systems[i]
    }
}

impl<S> Graph<S> {
    pub fn new(name: &'static str, nodes: Vec<Node<S>>) -> Graph<S> {
        Graph { name, nodes }
    }

    /// Names of the graph's systems in the order they first run, each once (a system may run at
    /// several places: stats and reports count it under its name).
    pub fn system_names(&self) -> Vec<&'static str> {
        fn walk<S>(nodes: &[Node<S>], out: &mut Vec<&'static str>) {
            for n in nodes {
                match n {
                    Node::System(s) if !out.contains(&s.name()) => out.push(s.name()),
                    Node::System(_) => {}
                    Node::Loop { body, .. } | Node::Once { body, .. } => walk(body, out),
                    Node::Nested(g) => {
                        for name in g.system_names() {
                            if !out.contains(&name) {
                                out.push(name);
                            }
                        }
                    }
                    Node::StopPoint => {}
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.nodes, &mut out);
        out
    }

    /// Checks the graph's data flow in the order it runs: every column a system reads must be
    /// written by an earlier system (a loop's body counts in order, once) or be one of
    /// `inputs` (columns set before the graph runs). A write of a store covers its fields
    /// (`paths` covers `paths.depth`), a write of a field only that field; a system that
    /// reorders a store moving only some fields leaves the others unwritten. Nested graphs
    /// are checked against their own inputs, and count as writing their part. Returns one
    /// line per problem.
    pub fn check(&self, inputs: &[&str]) -> Vec<String> {
        let mut written: Vec<String> = inputs.iter().map(|s| s.to_string()).collect();
        let mut problems = Vec::new();
        check_nodes(&self.nodes, &mut written, &mut problems);
        problems
    }

    /// The graph as an indented tree, one system per line with the columns it reads and
    /// writes: what `stagelight graph` prints and the docs show.
    pub fn describe(&self) -> String {
        let mut out = String::new();
        describe_nodes(&self.nodes, 0, &mut out);
        out
    }

    /// Runs the graph once over `state`, recording each system's time and flow in `stats`.
    pub fn run(&self, state: &mut S, stats: &mut Stats) {
        run_nodes(&self.nodes, state, stats, None);
    }

    /// `run`, giving up at the first stop point reached once `stop` is set: false when it
    /// did, the rest of the graph unrun.
    pub fn run_until(&self, state: &mut S, stats: &mut Stats, stop: &AtomicBool) -> bool {
        run_nodes(&self.nodes, state, stats, Some(stop))
    }
}

/// Whether a write of `w` makes a read of `r` valid: `w` is `r` or a store that holds it
/// (`paths` covers `paths.depth`). A write of one field is not a write of its store.
fn covers(w: &str, r: &str) -> bool {
    w == r || r.strip_prefix(w).is_some_and(|rest| rest.starts_with('.'))
}

fn check_nodes<S>(nodes: &[Node<S>], written: &mut Vec<String>, problems: &mut Vec<String>) {
    for node in nodes {
        match node {
            Node::System(s) => {
                let access = s.access();
                for r in access.reads {
                    if !written.iter().any(|w| covers(w, r)) {
                        problems.push(format!("{} reads {r} before anything writes it", s.name()));
                    }
                }
                for (path, column) in access.writes.iter().zip(access.write_columns) {
                    match access.reorders.iter().find(|(c, _)| c == column) {
                        Some((_, moved)) => {
                            written.retain(|w| !covers(path, w));
                            written.extend(moved.iter().map(|f| format!("{path}.{f}")));
                        }
                        None => written.push(path.to_string()),
                    }
                }
            }
            Node::Loop { body, .. } | Node::Once { body, .. } => {
                check_nodes(body, written, problems)
            }
            Node::Nested(g) => {
                problems.extend(g.check());
                written.push(g.part_name().to_string());
            }
            Node::StopPoint => {}
        }
    }
}

fn describe_nodes<S>(nodes: &[Node<S>], indent: usize, out: &mut String) {
    use std::fmt::Write;
    let pad = "    ".repeat(indent);
    for node in nodes {
        match node {
            Node::System(s) => {
                let a = s.access();
                let _ = writeln!(
                    out,
                    "{pad}{:<w$} reads {}; writes {}",
                    s.name(),
                    list(a.reads),
                    writes_list(&a),
                    w = 28usize.saturating_sub(pad.len()),
                );
            }
            Node::Loop { name, body, .. } => {
                let _ = writeln!(out, "{pad}loop {name}:");
                describe_nodes(body, indent + 1, out);
            }
            Node::Once { name, body, .. } => {
                let _ = writeln!(out, "{pad}once {name}:");
                describe_nodes(body, indent + 1, out);
            }
            Node::Nested(g) => {
                let _ = writeln!(out, "{pad}on {}:", g.part_name());
                g.describe(indent + 1, out);
            }
            Node::StopPoint => {}
        }
    }
}

/// A system's writes, a reordered column with the fields it moves: `rays[dir]`.
fn writes_list(a: &Access) -> String {
    let columns: Vec<String> = a
        .writes
        .iter()
        .zip(a.write_columns)
        .map(
            |(path, column)| match a.reorders.iter().find(|(c, _)| c == column) {
                Some((_, moved)) => format!("{path}[{}]", moved.join(", ")),
                None => path.to_string(),
            },
        )
        .collect();
    let columns: Vec<&str> = columns.iter().map(String::as_str).collect();
    list(&columns)
}

fn list(columns: &[&str]) -> String {
    if columns.is_empty() {
        "-".to_string()
    } else {
        columns.join(", ")
    }
}

/// Runs `nodes` in order; false when a stop point found `stop` set (the rest left unrun).
fn run_nodes<S>(
    nodes: &[Node<S>],
    state: &mut S,
    stats: &mut Stats,
    stop: Option<&AtomicBool>,
) -> bool {
    for node in nodes {
        match node {
            Node::System(system) => {
                let start = Instant::now();
                let flow = system.run(state);
                let elapsed = start.elapsed();
                let entry = stats.entry(system.name());
                entry.runs += 1;
                entry.time += elapsed;
                entry.taken += flow.taken as u64;
                entry.emitted += flow.emitted as u64;
            }
            Node::Nested(graph) => {
                if !graph.run(state, stats, stop) {
                    return false;
                }
            }
            Node::Once { needed, body, .. } => {
                if needed(state) && !run_nodes(body, state, stats, stop) {
                    return false;
                }
            }
            Node::Loop {
                name,
                queue_len,
                body,
            } => {
                let mut iterations = 0;
                let mut finished = true;
                while queue_len(state) > 0 {
                    iterations += 1;
                    if !run_nodes(body, state, stats, stop) {
                        finished = false;
                        break;
                    }
                }
                match stats.loops.iter_mut().find(|(l, _)| l == name) {
                    Some(l) => l.1 += iterations,
                    None => stats.loops.push((name, iterations)),
                }
                if !finished {
                    return false;
                }
            }
            Node::StopPoint => {
                if stop.is_some_and(|s| s.load(Ordering::SeqCst)) {
                    return false;
                }
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Default)]
    struct Counters {
        values: Vec<u32>,
        decrements: u32,
    }

    struct Countdown;
    system! {
        Countdown = "countdown";
        write values: Vec<u32>, decrements: u32;
        run {
            let taken = values.len();
            for v in values.iter_mut() {
                *v -= 1;
            }
            *decrements += taken as u32;
            values.retain(|&v| v > 0);
            Flow::new(taken, values.len())
        }
    }

    struct Report;
    system! {
        Report = "report";
        read decrements: u32;
        run {
            Flow::new(*decrements as usize, 0)
        }
    }

    bind! {
        Counters:
        Countdown { write values, decrements; }
        Report { read decrements; }
    }

    /// A store of two columns, `keys` and `values`, for the reorder check.
    #[derive(Default)]
    struct Pairs {
        keys: Vec<u32>,
        values: Vec<u32>,
    }

    #[derive(Default)]
    struct Sorting {
        pairs: Pairs,
    }

    /// Sorts the keys without moving the values: the values are stale after it.
    struct SortKeysOnly;
    system! {
        SortKeysOnly = "sort_keys_only";
        write pairs: Pairs;
        reorder pairs[keys];
        run {
            pairs.keys.sort_unstable();
            Flow::new(pairs.keys.len(), pairs.keys.len())
        }
    }

    struct ReadColumn;
    system! {
        ReadColumn = "read_column";
        read column: Vec<u32>;
        run {
            Flow::new(column.len(), 0)
        }
    }

    struct FillPairs;
    system! {
        FillPairs = "fill_pairs";
        write pairs: Pairs;
        run {
            Flow::new(0, pairs.keys.len())
        }
    }

    struct FillKeys;
    system! {
        FillKeys = "fill_keys";
        write keys: Vec<u32>;
        run {
            Flow::new(0, keys.len())
        }
    }

    struct ReadPairs;
    system! {
        ReadPairs = "read_pairs";
        read pairs: Pairs;
        run {
            Flow::new(pairs.keys.len(), 0)
        }
    }

    mod pair_bindings {
        use super::*;
        bind! {
            Sorting:
            SortKeysOnly { write pairs; }
            FillPairs { write pairs; }
            FillKeys { write keys = pairs.keys; }
            ReadPairs { read pairs; }
        }
    }

    /// `ReadColumn` bound to `pairs.values`, and the same system bound to `pairs.keys`.
    struct ReadValues;
    struct ReadKeys;
    impl System<Sorting> for ReadValues {
        fn name(&self) -> &'static str {
            "read_values"
        }
        fn access(&self) -> Access {
            Access {
                reads: &["pairs.values"],
                ..Access::default()
            }
        }
        fn run(&self, s: &mut Sorting) -> Flow {
            ReadColumn.run_columns((&s.pairs.values,))
        }
    }
    impl System<Sorting> for ReadKeys {
        fn name(&self) -> &'static str {
            "read_keys"
        }
        fn access(&self) -> Access {
            Access {
                reads: &["pairs.keys"],
                ..Access::default()
            }
        }
        fn run(&self, s: &mut Sorting) -> Flow {
            ReadColumn.run_columns((&s.pairs.keys,))
        }
    }

    #[test]
    fn a_reorder_that_moves_some_fields_leaves_the_others_unwritten() {
        let graph = Graph::new(
            "sorting",
            vec![
                Node::system(FillPairs),
                Node::system(SortKeysOnly),
                Node::system(ReadKeys),
                Node::system(ReadValues),
                Node::system(ReadPairs),
            ],
        );
        assert_eq!(
            graph.check(&[]),
            vec![
                "read_values reads pairs.values before anything writes it".to_string(),
                "read_pairs reads pairs before anything writes it".to_string(),
            ]
        );
        assert!(graph.describe().contains("writes pairs[keys]"));
        // A write of one field covers that field only, not its store.
        let one_field = Graph::new(
            "one field",
            vec![
                Node::system(FillKeys),
                Node::system(ReadKeys),
                Node::system(ReadPairs),
            ],
        );
        assert_eq!(
            one_field.check(&[]),
            vec!["read_pairs reads pairs before anything writes it".to_string()]
        );
    }

    fn countdown_graph() -> Graph<Counters> {
        Graph::new(
            "test",
            vec![
                Node::Loop {
                    name: "bounces",
                    queue_len: |s: &Counters| s.values.len(),
                    body: vec![Node::system(Countdown)],
                },
                Node::system(Report),
            ],
        )
    }

    #[test]
    fn loop_repeats_while_queue_is_non_empty_and_counts_flow() {
        let graph = countdown_graph();
        let mut state = Counters {
            values: vec![1, 3, 2],
            decrements: 0,
        };
        let mut stats = Stats::default();
        graph.run(&mut state, &mut stats);
        let s = stats.get("countdown").unwrap();
        assert_eq!(s.runs, 3);
        assert_eq!(s.taken, 3 + 2 + 1);
        assert_eq!(s.emitted, 2 + 1);
        assert_eq!(stats.loops, vec![("bounces", 3)]);
        assert_eq!(graph.system_names(), vec!["countdown", "report"]);
    }

    /// A run under a set stop flag gives up at the loop's stop point: the body before it ran
    /// once, nothing after it; unset, and under a plain run, the stop point changes nothing.
    #[test]
    fn a_stop_point_gives_up_the_rest_of_the_run_only_when_asked() {
        let graph = Graph::new(
            "stoppable",
            vec![
                Node::Loop {
                    name: "bounces",
                    queue_len: |s: &Counters| s.values.len(),
                    body: vec![Node::system(Countdown), Node::StopPoint],
                },
                Node::system(Report),
            ],
        );
        let fresh = || Counters {
            values: vec![3, 1, 2],
            decrements: 0,
        };
        let stop = AtomicBool::new(true);
        let mut state = fresh();
        let mut stats = Stats::default();
        assert!(!graph.run_until(&mut state, &mut stats, &stop));
        assert_eq!((state.values.clone(), state.decrements), (vec![2, 1], 3));
        assert!(stats.entry("report").runs == 0);
        stop.store(false, Ordering::SeqCst);
        let mut state = fresh();
        let mut stats = Stats::default();
        assert!(graph.run_until(&mut state, &mut stats, &stop));
        assert_eq!((state.values.len(), state.decrements), (0, 6));
        assert_eq!(stats.entry("report").runs, 1);
        let mut plain = fresh();
        graph.run(&mut plain, &mut Stats::default());
        assert_eq!(plain.decrements, 6);
    }

    #[test]
    fn access_lists_come_from_the_declaration_and_the_check_follows_graph_order() {
        let graph = countdown_graph();
        assert_eq!(
            System::<Counters>::access(&Countdown),
            Access {
                reads: &[],
                writes: &["values", "decrements"],
                write_columns: &["values", "decrements"],
                reorders: &[],
            }
        );
        assert!(graph.check(&[]).is_empty());
        // The reader placed before the writer: the check names it.
        let reversed = Graph::new(
            "reversed",
            vec![Node::system(Report), Node::system(Countdown)],
        );
        assert_eq!(
            reversed.check(&[]),
            vec!["report reads decrements before anything writes it".to_string()]
        );
        assert!(reversed.check(&["decrements"]).is_empty());
        assert!(graph.describe().contains("loop bounces:\n    countdown"));
    }

    #[test]
    fn once_runs_its_body_only_while_needed() {
        let graph = Graph::new(
            "once",
            vec![Node::Once {
                name: "fill",
                needed: |s: &Counters| s.values.is_empty(),
                body: vec![Node::system(Report)],
            }],
        );
        let mut state = Counters::default();
        let mut stats = Stats::default();
        graph.run(&mut state, &mut stats);
        state.values.push(1);
        graph.run(&mut state, &mut stats);
        assert_eq!(stats.get("report").unwrap().runs, 1);
    }
}

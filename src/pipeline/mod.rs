//! The pipeline: systems, the graphs integrators declare from them, and the scheduler that
//! runs a graph, timing every system and counting the items it takes and emits.
//!
//! A system is a named step over a queue of the wavefront state `S` (an integrator's own
//! structure-of-arrays state). A graph is a list of nodes: a system, or a loop that repeats its
//! body while a queue is non-empty. Each integrator declares its whole graph in one function,
//! built from the scene, so a scene that has no use for a system never runs it.

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

/// One step of an integrator over the wavefront state `S`.
pub trait System<S>: Send + Sync {
    /// A name that says what the system does; the report lists systems by it.
    fn name(&self) -> &'static str;
    /// Components (columns) the system reads.
    fn reads(&self) -> &'static [&'static str];
    /// Components (columns) the system writes.
    fn writes(&self) -> &'static [&'static str];
    /// Runs over the system's queue in `state`.
    fn run(&self, state: &mut S) -> Flow;
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
}

impl<S> Node<S> {
    pub fn system(system: impl System<S> + 'static) -> Node<S> {
        Node::System(Box::new(system))
    }

    /// `graph` run on the part of the state `part` picks.
    pub fn nested<T: 'static>(graph: Graph<T>, part: fn(&mut S) -> &mut T) -> Node<S>
    where
        S: 'static,
    {
        Node::Nested(Box::new(Nested { graph, part }))
    }
}

/// A graph over part of a state `S`, as one node of a graph over `S`.
pub trait NestedGraph<S>: Send + Sync {
    fn run(&self, state: &mut S, stats: &mut Stats);
    fn system_names(&self) -> Vec<&'static str>;
}

struct Nested<S, T> {
    graph: Graph<T>,
    part: fn(&mut S) -> &mut T,
}

impl<S, T> NestedGraph<S> for Nested<S, T> {
    fn run(&self, state: &mut S, stats: &mut Stats) {
        self.graph.run((self.part)(state), stats);
    }
    fn system_names(&self) -> Vec<&'static str> {
        self.graph.system_names()
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

    /// Names of every system in the graph, in order.
    pub fn system_names(&self) -> Vec<&'static str> {
        fn walk<S>(nodes: &[Node<S>], out: &mut Vec<&'static str>) {
            for n in nodes {
                match n {
                    Node::System(s) => out.push(s.name()),
                    Node::Loop { body, .. } => walk(body, out),
                    Node::Nested(g) => out.extend(g.system_names()),
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.nodes, &mut out);
        out
    }

    /// Checks that every column a system reads is written by some system of the graph or
    /// listed in `inputs` (columns the state holds before the graph runs). Names are
    /// `component` or `component.column`. Returns the offending (system, column) pairs.
    pub fn unsatisfied_reads(&self, inputs: &[&str]) -> Vec<(&'static str, &'static str)> {
        fn collect<S>(nodes: &[Node<S>], f: &mut dyn FnMut(&dyn System<S>)) {
            for n in nodes {
                match n {
                    Node::System(s) => f(s.as_ref()),
                    Node::Loop { body, .. } => collect(body, f),
                    // A nested graph is checked on its own state.
                    Node::Nested(_) => {}
                }
            }
        }
        let mut written: Vec<&str> = inputs.to_vec();
        collect(&self.nodes, &mut |s| written.extend(s.writes()));
        // "paths" covers "paths.depth" and the other way round: a component or one column.
        let covers = |w: &str, r: &str| {
            w == r
                || r.strip_prefix(w).is_some_and(|rest| rest.starts_with('.'))
                || w.strip_prefix(r).is_some_and(|rest| rest.starts_with('.'))
        };
        let mut missing = Vec::new();
        collect(&self.nodes, &mut |s| {
            for r in s.reads() {
                if !written.iter().any(|w| covers(w, r)) {
                    missing.push((s.name(), *r));
                }
            }
        });
        missing
    }

    /// Runs the graph once over `state`, recording each system's time and flow in `stats`.
    pub fn run(&self, state: &mut S, stats: &mut Stats) {
        run_nodes(&self.nodes, state, stats);
    }
}

fn run_nodes<S>(nodes: &[Node<S>], state: &mut S, stats: &mut Stats) {
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
            Node::Nested(graph) => graph.run(state, stats),
            Node::Loop {
                name,
                queue_len,
                body,
            } => {
                let mut iterations = 0;
                while queue_len(state) > 0 {
                    run_nodes(body, state, stats);
                    iterations += 1;
                }
                match stats.loops.iter_mut().find(|(l, _)| l == name) {
                    Some(l) => l.1 += iterations,
                    None => stats.loops.push((name, iterations)),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Countdown;
    impl System<Vec<u32>> for Countdown {
        fn name(&self) -> &'static str {
            "countdown"
        }
        fn reads(&self) -> &'static [&'static str] {
            &["values"]
        }
        fn writes(&self) -> &'static [&'static str] {
            &["values"]
        }
        fn run(&self, state: &mut Vec<u32>) -> Flow {
            let taken = state.len();
            for v in state.iter_mut() {
                *v -= 1;
            }
            state.retain(|&v| v > 0);
            Flow::new(taken, state.len())
        }
    }

    #[test]
    fn loop_repeats_while_queue_is_non_empty_and_counts_flow() {
        let graph = Graph::new(
            "test",
            vec![Node::Loop {
                name: "bounces",
                queue_len: |s: &Vec<u32>| s.len(),
                body: vec![Node::system(Countdown)],
            }],
        );
        let mut state = vec![1, 3, 2];
        let mut stats = Stats::default();
        graph.run(&mut state, &mut stats);
        let s = stats.get("countdown").unwrap();
        assert_eq!(s.runs, 3);
        assert_eq!(s.taken, 3 + 2 + 1);
        assert_eq!(s.emitted, 2 + 1);
        assert_eq!(stats.loops, vec![("bounces", 3)]);
        assert!(graph.unsatisfied_reads(&[]).is_empty());
        assert_eq!(graph.system_names(), vec!["countdown"]);
    }
}

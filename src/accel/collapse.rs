//! The eight-wide tree made from obvhs' binary one: which binary subtrees become wide nodes,
//! which leaves, and how a node's slots are shared (a surface area heuristic, minimised by
//! dynamic programming as Ylitie, Karras and Laine 2017 do for their compressed wide BVH,
//! section 3.1), then the nodes, with exact boxes, and their leaves packed into shared
//! four-lane packets. Both passes run in parallel over subtrees.

use super::bvh8::{Bvh8, LEAF, LEAF_MAX, MAX_PACKETS, Node};
use super::triangle::{LANES, TrianglePacket};
use glam::Vec3;
use obvhs::bvh2::{Bvh2, node::Bvh2Node};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};

/// Slots of a wide node.
const WIDTH: usize = 8;

/// The cost model (surface area heuristic, in units of one node visit times its area): a
/// leaf's packet test costs `LEAF_COST` plus `TRIANGLE_COST` per triangle. The traversal's
/// speed hardly depends on them (callgrind, big_1m: from 0.3 + 0.3 to 1.5 + 0.1, closest-hit
/// instructions within 2%).
const LEAF_COST: f32 = 0.6;
const TRIANGLE_COST: f32 = 0.1;

/// The binary subtrees below this depth are planned, and the wide ones below this wide depth
/// built, each by one task: enough tasks to share among the threads.
const PLAN_TASK_DEPTH: usize = 10;
const BUILD_TASK_DEPTH: usize = 2;
/// Trees over fewer triangles are built by one task.
const PARALLEL_TRIANGLES: usize = 20_000;

/// What collapsing gives: the wide tree, its packets and, for each packet lane, the index of
/// its triangle in the input (`u32::MAX` for an unused lane).
pub(crate) struct Collapsed {
    pub(crate) tree: Bvh8,
    pub(crate) packets: Vec<TrianglePacket>,
    pub(crate) lanes: Vec<u32>,
}

/// Collapses the binary tree `bvh` over `verts` (indexed like the boxes it was built from, at
/// least one triangle, each in exactly one leaf of at most `LEAF_MAX`).
pub(crate) fn collapse(bvh: &Bvh2, verts: &[[Vec3; 3]]) -> Collapsed {
    let builder = Builder {
        bvh,
        verts,
        plan: Plan::new(bvh),
    };
    let mut tree = Part::default();
    let parallel = verts.len() >= PARALLEL_TRIANGLES;
    let mut deferred = Vec::new();
    let mut parents = Vec::new();
    builder.node(
        &mut tree,
        0,
        0,
        parallel.then_some(&mut Top {
            deferred: &mut deferred,
            parents: &mut parents,
        }),
    );
    let parts: Vec<(Part, Vec3, Vec3)> = deferred
        .par_iter()
        .map(|d| {
            let mut part = Part::default();
            let (_, lo, hi) = builder.node(&mut part, d.index, 0, None);
            (part, lo, hi)
        })
        .collect();
    // Each part after the top nodes and the parts before it, its references moved by as many.
    let mut node_starts = Vec::with_capacity(parts.len());
    let mut packet_starts = Vec::with_capacity(parts.len());
    let (top_nodes, top_packets) = (tree.nodes.len(), tree.packets.len());
    let (mut node_end, mut packet_end) = (top_nodes, top_packets);
    for (part, _, _) in &parts {
        node_starts.push(node_end);
        packet_starts.push(packet_end);
        node_end += part.nodes.len();
        packet_end += part.packets.len();
    }
    // The big arrays are asked for huge pages before they are first written, then written
    // once, in parallel (so the threads share the page faults), straight from the parts.
    tree.nodes.reserve_exact(node_end - top_nodes);
    tree.packets.reserve_exact(packet_end - top_packets);
    tree.lanes.reserve_exact((packet_end - top_packets) * LANES);
    crate::cpu::advise_huge_pages(&tree.nodes);
    crate::cpu::advise_huge_pages(&tree.packets);
    crate::cpu::advise_huge_pages(&tree.lanes);
    // The part that holds element `i` of the array whose parts start at `starts`.
    let part_of = |starts: &[usize], i: usize| starts.partition_point(|&s| s <= i) - 1;
    tree.nodes
        .par_extend((top_nodes..node_end).into_par_iter().map(|i| {
            let k = part_of(&node_starts, i);
            let mut node = parts[k].0.nodes[i - node_starts[k]];
            let packet_offset = (packet_starts[k] as u32) << LANES;
            for r in &mut node.child {
                if *r & LEAF != 0 {
                    *r += packet_offset;
                } else if *r != 0 {
                    // (0 is an empty slot: no node of a part has its root as a child.)
                    *r += node_starts[k] as u32;
                }
            }
            node
        }));
    tree.packets
        .par_extend((top_packets..packet_end).into_par_iter().map(|i| {
            let k = part_of(&packet_starts, i);
            parts[k].0.packets[i - packet_starts[k]]
        }));
    tree.lanes.par_extend(
        (top_packets * LANES..packet_end * LANES)
            .into_par_iter()
            .map(|i| {
                let k = part_of(&packet_starts, i / LANES);
                parts[k].0.lanes[i - packet_starts[k] * LANES]
            }),
    );
    for (d, ((_, lo, hi), &node_offset)) in deferred.iter().zip(parts.iter().zip(&node_starts)) {
        tree.nodes[d.parent as usize].set_child(d.slot, node_offset as u32, *lo, *hi);
    }
    // The top nodes' boxes, now that their deferred children are known: children come after
    // their parents.
    for top in (1..parents.len()).rev() {
        let (lo, hi) = tree.nodes[top].bounds();
        if let Some((parent, slot)) = parents[top] {
            let child = tree.nodes[parent as usize].child[slot];
            tree.nodes[parent as usize].set_child(slot, child, lo, hi);
        }
    }
    assert!(
        tree.packets.len() <= MAX_PACKETS,
        "more than {MAX_PACKETS} triangle packets: too many triangles for one tree"
    );
    Collapsed {
        tree: Bvh8::new(tree.nodes, tree.packets.len()),
        packets: tree.packets,
        lanes: tree.lanes,
    }
}

/// A subtree's least cost spread over at most 1 to 8 slots, and its triangle count.
#[derive(Clone, Copy)]
struct Cost {
    slots: [f32; WIDTH],
    count: u32,
}

/// For each binary node, the choices that give its least cost, packed in a word: bit 0 set
/// when, in a slot of its own, it is a wide node rather than a leaf; 3 bits for each j from 2
/// to 8: spread over at most j slots, 0 when as over j - 1, else the number of slots its first
/// child gets (the second gets the rest); 3 bits at `SPLIT_SHIFT`: as a wide node, the slots
/// its first child gets.
struct Plan {
    words: Vec<AtomicU32>,
}

const SPLIT_SHIFT: u32 = 22;

impl Plan {
    fn new(bvh: &Bvh2) -> Plan {
        let plan = Plan {
            words: (0..bvh.nodes.len())
                .into_par_iter()
                .map(|_| AtomicU32::new(0))
                .collect(),
        };
        plan.visit(bvh, 0, 0);
        plan
    }

    /// Plans the subtree of binary node `i` at depth `depth`, its two halves in parallel down
    /// to `PLAN_TASK_DEPTH`.
    fn visit(&self, bvh: &Bvh2, i: u32, depth: usize) -> Cost {
        let node = &bvh.nodes[i as usize];
        if node.prim_count != 0 || depth >= PLAN_TASK_DEPTH {
            return self.visit_serial(bvh, i);
        }
        let (l, r) = rayon::join(
            || self.visit(bvh, node.first_index, depth + 1),
            || self.visit(bvh, node.first_index + 1, depth + 1),
        );
        self.combine(i, node, &l, &r)
    }

    /// `visit` in one task, without recursion: a binary tree may be far deeper than the call
    /// stack allows.
    fn visit_serial(&self, bvh: &Bvh2, root: u32) -> Cost {
        let mut todo = vec![(root, false)];
        let mut done: Vec<Cost> = Vec::new();
        while let Some((i, children_done)) = todo.pop() {
            let node = &bvh.nodes[i as usize];
            if node.prim_count != 0 {
                assert!(
                    node.prim_count <= LEAF_MAX,
                    "a binary leaf of {} primitives: more than a packet",
                    node.prim_count
                );
                let cost = node.aabb().half_area() * leaf_cost(node.prim_count);
                done.push(Cost {
                    slots: [cost; WIDTH],
                    count: node.prim_count,
                });
            } else if !children_done {
                todo.extend([
                    (i, true),
                    (node.first_index + 1, false),
                    (node.first_index, false),
                ]);
            } else {
                let (Some(r), Some(l)) = (done.pop(), done.pop()) else {
                    unreachable!("both children are planned before their parent")
                };
                done.push(self.combine(i, node, &l, &r));
            }
        }
        done.pop().expect("the root is planned")
    }

    /// The cost of inner node `i` from its children's, its choices stored.
    fn combine(&self, i: u32, node: &Bvh2Node, l: &Cost, r: &Cost) -> Cost {
        let area = node.aabb().half_area();
        let count = l.count + r.count;
        // As a wide node: one visit, the children spread over its slots.
        let (mut best, mut split) = (f32::INFINITY, 1);
        for k in 1..WIDTH {
            let c = l.slots[k - 1] + r.slots[WIDTH - 1 - k];
            if c < best {
                (best, split) = (c, k);
            }
        }
        let as_node = area + best;
        let as_leaf = if count <= LEAF_MAX {
            area * leaf_cost(count)
        } else {
            f32::INFINITY
        };
        let mut slots = [0.0; WIDTH];
        let mut word = (split as u32) << SPLIT_SHIFT;
        if as_leaf <= as_node {
            slots[0] = as_leaf;
        } else {
            slots[0] = as_node;
            word |= 1;
        }
        // Over at most j + 1 slots: as over j, or k slots to the first child, the rest to the
        // second.
        for j in 1..WIDTH {
            slots[j] = slots[j - 1];
            let mut choice = 0;
            for k in 1..=j {
                let c = l.slots[k - 1] + r.slots[j - k];
                if c < slots[j] {
                    (slots[j], choice) = (c, k as u32);
                }
            }
            word |= choice << (1 + 3 * (j as u32 - 1));
        }
        self.words[i as usize].store(word, Ordering::Relaxed);
        Cost { slots, count }
    }

    fn word(&self, i: u32) -> u32 {
        self.words[i as usize].load(Ordering::Relaxed)
    }

    /// Whether binary node `i`, in a slot of its own, is a leaf.
    fn is_leaf(&self, i: u32) -> bool {
        self.word(i) & 1 == 0
    }

    /// Spread over at most `slots` (2 to 8): 0 as over one fewer, else the first child's.
    fn choice(&self, i: u32, slots: usize) -> usize {
        ((self.word(i) >> (1 + 3 * (slots as u32 - 2))) & 7) as usize
    }

    /// As a wide node: the slots of its first child.
    fn node_split(&self, i: u32) -> usize {
        ((self.word(i) >> SPLIT_SHIFT) & 7) as usize
    }
}

fn leaf_cost(count: u32) -> f32 {
    LEAF_COST + TRIANGLE_COST * count as f32
}

/// Nodes, packets and lanes, as the whole tree or as a part built by one task (its root at
/// index 0, its references its own).
#[derive(Default)]
struct Part {
    nodes: Vec<Node>,
    packets: Vec<TrianglePacket>,
    lanes: Vec<u32>,
}

/// A wide subtree left to a task of its own: its binary node, and the top node and slot it
/// hangs from.
struct Deferred {
    index: u32,
    parent: u32,
    slot: usize,
}

/// While the top nodes are made: the subtrees left to tasks, and each top node's parent and
/// slot.
struct Top<'a> {
    deferred: &'a mut Vec<Deferred>,
    parents: &'a mut Vec<Option<(u32, usize)>>,
}

struct Builder<'a> {
    bvh: &'a Bvh2,
    verts: &'a [[Vec3; 3]],
    plan: Plan,
}

impl Builder<'_> {
    /// The slots binary node `i` spreads over when given at most `slots`: appended to `out`.
    fn spread(&self, i: u32, slots: usize, out: &mut Vec<u32>) {
        let mut j = slots;
        while j > 1 && self.plan.choice(i, j) == 0 {
            j -= 1;
        }
        if j == 1 {
            out.push(i);
        } else {
            let k = self.plan.choice(i, j);
            let first = self.bvh.nodes[i as usize].first_index;
            self.spread(first, k, out);
            self.spread(first + 1, j - k, out);
        }
    }

    /// The input indices of the primitives under the binary node `i`.
    fn primitives(&self, i: u32, out: &mut Vec<u32>) {
        let mut stack = vec![i];
        while let Some(i) = stack.pop() {
            let n = &self.bvh.nodes[i as usize];
            if n.prim_count == 0 {
                stack.extend([n.first_index + 1, n.first_index]);
            } else {
                let first = n.first_index as usize;
                out.extend(&self.bvh.primitive_indices[first..first + n.prim_count as usize]);
            }
        }
    }

    /// Makes into `out` the wide node of binary node `index` (the root, or one the plan makes
    /// a wide node), at wide depth `depth`, and its wide descendants, except, with `top`,
    /// those at `BUILD_TASK_DEPTH`, which are left to `top.deferred` (their slots empty for
    /// now). Returns the node's index and its exact box (without the deferred subtrees).
    fn node(
        &self,
        out: &mut Part,
        index: u32,
        depth: usize,
        mut top: Option<&mut Top>,
    ) -> (u32, Vec3, Vec3) {
        let me = out.nodes.len();
        out.nodes.push(Node::EMPTY);
        if let Some(top) = top.as_deref_mut() {
            top.parents.push(None);
        }
        let mut kids = Vec::with_capacity(WIDTH);
        let bin = &self.bvh.nodes[index as usize];
        if bin.prim_count == 0 {
            let split = self.plan.node_split(index);
            self.spread(bin.first_index, split, &mut kids);
            self.spread(bin.first_index + 1, WIDTH - split, &mut kids);
        } else {
            kids.push(index);
        }

        // The leaves' triangles, packed first fit, largest leaf first, into this node's
        // packets.
        let mut prims = Vec::with_capacity(WIDTH * LEAF_MAX as usize);
        let mut leaves: Vec<(usize, std::ops::Range<usize>)> = Vec::with_capacity(WIDTH);
        for (slot, &k) in kids.iter().enumerate() {
            if self.plan.is_leaf(k) {
                let start = prims.len();
                self.primitives(k, &mut prims);
                leaves.push((slot, start..prims.len()));
            }
        }
        leaves.sort_by_key(|(slot, range)| (std::cmp::Reverse(range.len()), *slot));
        let first_packet = out.packets.len();
        let mut fill: Vec<usize> = Vec::with_capacity(WIDTH);
        for (slot, range) in leaves {
            let bin = match fill.iter().position(|&f| f + range.len() <= LANES) {
                Some(b) => b,
                None => {
                    fill.push(0);
                    out.packets.push(TrianglePacket::default());
                    out.lanes.extend([u32::MAX; LANES]);
                    fill.len() - 1
                }
            };
            let packet = first_packet + bin;
            let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
            let mut lane_bits = 0;
            for &prim in &prims[range] {
                let lane = fill[bin];
                fill[bin] += 1;
                let tri = &self.verts[prim as usize];
                out.packets[packet].set(lane, tri);
                out.lanes[packet * LANES + lane] = prim;
                lane_bits |= 1 << lane;
                for v in tri {
                    lo = lo.min(*v);
                    hi = hi.max(*v);
                }
            }
            let reference = LEAF | ((packet as u32) << LANES) | lane_bits;
            out.nodes[me].set_child(slot, reference, lo, hi);
        }

        for (slot, &k) in kids.iter().enumerate() {
            if self.plan.is_leaf(k) {
                continue;
            }
            match top.as_deref_mut() {
                Some(top) if depth + 1 == BUILD_TASK_DEPTH => top.deferred.push(Deferred {
                    index: k,
                    parent: me as u32,
                    slot,
                }),
                _ => {
                    let (child, lo, hi) = self.node(out, k, depth + 1, top.as_deref_mut());
                    out.nodes[me].set_child(slot, child, lo, hi);
                    if let Some(top) = top.as_deref_mut() {
                        top.parents[child as usize] = Some((me as u32, slot));
                    }
                }
            }
        }
        let (lo, hi) = out.nodes[me].bounds();
        (me as u32, lo, hi)
    }
}

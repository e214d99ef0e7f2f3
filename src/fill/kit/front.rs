//! Parts every front engine needs: the queue of front nodes by key with lazy
//! invalidation, the key of an undirected edge, and the fronts as rings of nodes with
//! the bookkeeping of splitting one front into two ([`Ring`]; the advancing front and
//! the wavefront, whose steps merge a front with itself). The engines keep their step
//! rules and what a node carries besides its ring (`Node::data`). The LS-SVM front
//! keeps each front as a vertex sequence on a stack (a step replaces the sequence).

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;

/// The key of the undirected edge `a`-`b`: its ends in increasing order.
#[inline]
pub fn edge_key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// A queue entry: front node `node` at `key`, pushed when the node had version
/// `version` (the entry is stale once the node's version has moved on); `data` goes
/// with it.
#[derive(Clone, Copy, Debug)]
pub struct Entry<D = ()> {
    pub key: f64,
    pub node: u32,
    pub version: u32,
    pub data: D,
}

impl<D> PartialEq for Entry<D> {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl<D> Eq for Entry<D> {}
impl<D> PartialOrd for Entry<D> {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
/// By key (`total_cmp`), then node, then version; `data` plays no part.
impl<D> Ord for Entry<D> {
    fn cmp(&self, o: &Self) -> Ordering {
        self.key
            .total_cmp(&o.key)
            .then(self.node.cmp(&o.node))
            .then(self.version.cmp(&o.version))
    }
}

/// The front nodes by key, smallest first (ties: smaller node, then older version).
/// Stale entries stay in the queue until popped; callers compare an entry's version
/// with its node's and skip it.
#[derive(Clone, Debug)]
pub struct FrontQueue<D = ()> {
    heap: BinaryHeap<Reverse<Entry<D>>>,
}

impl<D> Default for FrontQueue<D> {
    fn default() -> Self {
        FrontQueue {
            heap: BinaryHeap::new(),
        }
    }
}

impl<D: Copy> FrontQueue<D> {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn push(&mut self, e: Entry<D>) {
        self.heap.push(Reverse(e));
    }
    /// The smallest entry, stale or not.
    pub fn pop(&mut self) -> Option<Entry<D>> {
        self.heap.pop().map(|Reverse(e)| e)
    }
    /// The smallest entry, stale or not, left in the queue.
    pub fn peek(&self) -> Option<Entry<D>> {
        self.heap.peek().map(|Reverse(e)| *e)
    }
}

/// A front node: one occurrence of a patch vertex on a front (a vertex is on two
/// fronts after a merge splits one, so nodes and vertices are apart), linked to its
/// neighbours on that front. `version` moves on whenever the node changes (its queue
/// entries are then stale); `data` is the engine's own.
#[derive(Clone, Copy, Debug)]
pub struct Node<D> {
    /// Patch vertex index.
    pub vert: u32,
    pub prev: u32,
    pub next: u32,
    pub front: u32,
    pub version: u32,
    pub alive: bool,
    pub data: D,
}

/// The fronts of an engine: its nodes in closed rings, one per front, the size of
/// each front, and the alive nodes in a list (so that an engine can pick one by
/// index: a node is appended when made and a killed one is replaced by the last).
#[derive(Clone, Debug)]
pub struct Ring<D> {
    pub nodes: Vec<Node<D>>,
    /// Nodes on each front (by front id).
    pub front_size: Vec<usize>,
    alive: Vec<u32>,
    /// Position of each alive node in `alive`.
    alive_pos: Vec<usize>,
}

impl<D: Copy> Ring<D> {
    /// No nodes; one front (id 0) of `size` nodes, made next by [`Ring::push`].
    pub fn new(size: usize) -> Self {
        Ring {
            nodes: Vec::with_capacity(2 * size),
            front_size: vec![size],
            alive: Vec::with_capacity(2 * size),
            alive_pos: Vec::with_capacity(2 * size),
        }
    }
    /// A new alive node of vertex `vert` on `front` between `prev` and `next` (the
    /// neighbours are not changed: see [`Ring::link`]); its id.
    pub fn push(&mut self, vert: u32, prev: u32, next: u32, front: u32, data: D) -> u32 {
        let id = self.nodes.len() as u32;
        self.nodes.push(Node {
            vert,
            prev,
            next,
            front,
            version: 0,
            alive: true,
            data,
        });
        self.alive_pos.push(self.alive.len());
        self.alive.push(id);
        id
    }
    /// Makes `b` follow `a`.
    pub fn link(&mut self, a: u32, b: u32) {
        self.nodes[a as usize].next = b;
        self.nodes[b as usize].prev = a;
    }
    /// Moves node `n`'s version on (its queue entries become stale); the new version.
    pub fn bump(&mut self, n: u32) -> u32 {
        let nd = &mut self.nodes[n as usize];
        nd.version = nd.version.wrapping_add(1);
        nd.version
    }
    /// Takes node `n` off the fronts (its version moves on); nothing when it is off
    /// already.
    pub fn kill(&mut self, n: u32) {
        let nd = &mut self.nodes[n as usize];
        if !nd.alive {
            return;
        }
        nd.alive = false;
        nd.version = nd.version.wrapping_add(1);
        let i = self.alive_pos[n as usize];
        self.alive.swap_remove(i);
        if let Some(&moved) = self.alive.get(i) {
            self.alive_pos[moved as usize] = i;
        }
    }
    /// The alive nodes (see [`Ring`] for their order).
    pub fn alive(&self) -> &[u32] {
        &self.alive
    }
    /// The nodes of the ring through `start`, in order from it (at most as many as
    /// there are nodes, should the ring be broken).
    pub fn cycle(&self, start: u32) -> Vec<u32> {
        let mut out = vec![start];
        let mut c = self.nodes[start as usize].next;
        while c != start && out.len() <= self.nodes.len() {
            out.push(c);
            c = self.nodes[c as usize].next;
        }
        out
    }
    /// Walks the rings through `a` and `b` together; the start and size of the one
    /// that closes first (`a`'s on a tie; cost: twice the smaller size), `None` when
    /// neither closes (a broken ring).
    pub fn shorter_cycle(&self, a: u32, b: u32) -> Option<(u32, usize)> {
        let (mut x, mut y) = (a, b);
        for n in 1..=self.nodes.len() {
            x = self.nodes[x as usize].next;
            if x == a {
                return Some((a, n));
            }
            y = self.nodes[y as usize].next;
            if y == b {
                return Some((b, n));
            }
        }
        None
    }
    /// Puts the `size` nodes of the ring from `start` on a new front (the next id,
    /// which it returns) and takes them off the count of the front they were on;
    /// `None` when that count is below `size + keep` (the sizes are out of step).
    pub fn split_off(&mut self, start: u32, size: usize, keep: usize) -> Option<u32> {
        let old = self.nodes[start as usize].front as usize;
        let new = self.front_size.len() as u32;
        self.front_size.push(size);
        if self.front_size[old] < size + keep {
            return None;
        }
        self.front_size[old] -= size;
        let mut z = start;
        for _ in 0..size {
            self.nodes[z as usize].front = new;
            z = self.nodes[z as usize].next;
        }
        Some(new)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smallest_key_first_then_node_then_version() {
        let mut q = FrontQueue::new();
        for (key, node, version) in [
            (2.0, 1, 0),
            (1.0, 3, 1),
            (1.0, 2, 5),
            (1.0, 2, 4),
            (f64::NAN, 0, 0),
        ] {
            q.push(Entry {
                key,
                node,
                version,
                data: (),
            });
        }
        let order: Vec<(u32, u32)> = std::iter::from_fn(|| q.pop())
            .map(|e| (e.node, e.version))
            .collect();
        // NaN sorts after every number (total_cmp)
        assert_eq!(order, vec![(2, 4), (2, 5), (3, 1), (1, 0), (0, 0)]);
        assert!(q.peek().is_none());
        assert_eq!(edge_key(7, 3), (3, 7));
        assert_eq!(edge_key(3, 7), (3, 7));
    }
}

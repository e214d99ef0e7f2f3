//! Parts every front engine (the advancing front, the wavefront, the LS-SVM front)
//! needs: the queue of front nodes by key with lazy invalidation, and the key of an
//! undirected edge. The engines keep their own nodes and step rules.

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

//! Hash maps and sets for the geometry code, with foldhash's fast hasher instead of
//! std's SipHash: the keys there are small integers (edge pairs, vertex ids, grid
//! cells) and SipHash was a tenth of the instructions of a fill (callgrind on the
//! bench meshes). The seed is still random per process (no fixed seed an input could
//! be crafted against); no result depends on iteration order.

/// `std::collections::HashMap` with foldhash's fast hasher.
pub type HashMap<K, V> = std::collections::HashMap<K, V, foldhash::fast::RandomState>;
/// `std::collections::HashSet` with foldhash's fast hasher.
pub type HashSet<K> = std::collections::HashSet<K, foldhash::fast::RandomState>;

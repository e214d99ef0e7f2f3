//! Hash maps and sets for the geometry code, whose keys are small integers (edge pairs,
//! vertex ids, grid cells), where std's SipHash would cost far more than the work the
//! maps serve.
//!
//! [`HashMap`] and [`HashSet`] use foldhash's fast hasher, with a seed random per
//! process (no fixed seed an input could be crafted against); no result depends on
//! their iteration order. [`FxMap`] and [`FxSet`] use FxHash's multiply-rotate with no
//! seed at all, for the hottest maps: the advancing front's and the refinement's, whose
//! keys are the method's own indices, the fronts' grid cells, and the STL reader's
//! weld of corners by their coordinates' bits (keys from one file: an adversarial one
//! makes the weld slow, never wrong).

/// `std::collections::HashMap` with foldhash's fast hasher.
pub type HashMap<K, V> = std::collections::HashMap<K, V, foldhash::fast::RandomState>;
/// `std::collections::HashSet` with foldhash's fast hasher.
pub type HashSet<K> = std::collections::HashSet<K, foldhash::fast::RandomState>;

/// A fast hasher for small integer keys: FxHash's multiply-rotate a word at a time,
/// no seed, and at the end the high bits (where a product keeps what every bit of the
/// key contributed) turned down to the low bits the table indexes by (rustc-hash 2's
/// finish).
#[derive(Clone, Copy, Default)]
pub struct FxHasher(u64);

impl std::hash::Hasher for FxHasher {
    fn finish(&self) -> u64 {
        self.0.rotate_left(26)
    }
    fn write(&mut self, bytes: &[u8]) {
        // integer arrays and slices arrive here as bytes: a word at a time
        let mut chunks = bytes.chunks_exact(8);
        for c in &mut chunks {
            let mut w = [0u8; 8];
            w.copy_from_slice(c);
            self.write_u64(u64::from_le_bytes(w));
        }
        for &b in chunks.remainder() {
            self.write_u64(u64::from(b));
        }
    }
    fn write_u32(&mut self, i: u32) {
        self.write_u64(i as u64);
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
    fn write_usize(&mut self, i: usize) {
        self.write_u64(i as u64);
    }
}

/// Build hasher of [`FxHasher`].
pub type FxBuild = std::hash::BuildHasherDefault<FxHasher>;
/// `std::collections::HashMap` with [`FxHasher`].
pub type FxMap<K, V> = std::collections::HashMap<K, V, FxBuild>;
/// `std::collections::HashSet` with [`FxHasher`].
pub type FxSet<K> = std::collections::HashSet<K, FxBuild>;

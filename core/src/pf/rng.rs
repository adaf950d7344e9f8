//! The particle filter's generator: `rand_xoshiro`'s Xoshiro128++, bit for bit, with a
//! `const` all-zero state ([`Xoshiro128PlusPlus::ZEROED`]) so that a filter in a `static`
//! is zero bytes (`.bss`). `rand_xoshiro`'s own type has no `const` constructor.

use rand_core::{RngCore, SeedableRng, impls};
use rand_xoshiro::SplitMix64;

/// Xoshiro128++ (Blackman and Vigna): the same state, seeding ([`SeedableRng::from_seed`],
/// [`SeedableRng::seed_from_u64`] through SplitMix64) and output as
/// `rand_xoshiro::Xoshiro128PlusPlus` (the tests compare the two).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Xoshiro128PlusPlus {
    s: [u32; 4],
}

impl Xoshiro128PlusPlus {
    /// The all-zero state: not a generator (it only ever draws 0); seeding replaces it.
    pub(crate) const ZEROED: Self = Self { s: [0; 4] };
}

impl SeedableRng for Xoshiro128PlusPlus {
    type Seed = [u8; 16];

    /// As `rand_xoshiro`: an all-zero seed is replaced by `seed_from_u64(0)`.
    fn from_seed(seed: [u8; 16]) -> Self {
        if seed == [0; 16] {
            return Self::seed_from_u64(0);
        }
        let mut s = [0u32; 4];
        for (word, bytes) in s.iter_mut().zip(seed.chunks_exact(4)) {
            *word = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
        }
        Self { s }
    }

    /// As `rand_xoshiro`: the seed bytes drawn from SplitMix64 seeded with `seed`.
    fn seed_from_u64(seed: u64) -> Self {
        let mut mix = SplitMix64::seed_from_u64(seed);
        Self::from_rng(&mut mix)
    }
}

impl RngCore for Xoshiro128PlusPlus {
    #[inline]
    fn next_u32(&mut self) -> u32 {
        let s = &mut self.s;
        let result = s[0].wrapping_add(s[3]).rotate_left(7).wrapping_add(s[0]);
        let t = s[1] << 9;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(11);
        result
    }

    #[inline]
    fn next_u64(&mut self) -> u64 {
        impls::next_u64_via_u32(self)
    }

    #[inline]
    fn fill_bytes(&mut self, dest: &mut [u8]) {
        impls::fill_bytes_via_next(self, dest);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_stream_as_rand_xoshiro() {
        for seed in [0, 1, 2, 42, 0x5eed, u64::MAX, 1 << 63] {
            let mut ours = Xoshiro128PlusPlus::seed_from_u64(seed);
            let mut theirs = rand_xoshiro::Xoshiro128PlusPlus::seed_from_u64(seed);
            for i in 0..1000 {
                match i % 3 {
                    0 => assert_eq!(ours.next_u32(), theirs.next_u32(), "seed {seed}"),
                    1 => assert_eq!(ours.next_u64(), theirs.next_u64(), "seed {seed}"),
                    _ => {
                        let (mut a, mut b) = ([0u8; 13], [0u8; 13]);
                        ours.fill_bytes(&mut a[..i % 13]);
                        theirs.fill_bytes(&mut b[..i % 13]);
                        assert_eq!(a, b, "seed {seed}");
                    }
                }
            }
        }
        for seed in [[0u8; 16], [1; 16], core::array::from_fn(|i| i as u8)] {
            let mut ours = Xoshiro128PlusPlus::from_seed(seed);
            let mut theirs = rand_xoshiro::Xoshiro128PlusPlus::from_seed(seed);
            for _ in 0..100 {
                assert_eq!(ours.next_u32(), theirs.next_u32());
            }
        }
    }
}

//! A tiny deterministic PRNG (xorshift32, Marsaglia 2003) for randomised cases and
//! bench inputs. Hand-written rather than `rand`: four lines, no dependency, and the
//! same sequence on every run and target so a failure reproduces.

/// xorshift32 state; never zero.
pub struct Prng(u32);

impl Prng {
    /// A generator from `seed` (0 is replaced, it would stay 0 forever).
    pub const fn new(seed: u32) -> Self {
        Prng(if seed == 0 { 0x9E37_79B9 } else { seed })
    }

    /// The next 32 random bits.
    pub fn next_u32(&mut self) -> u32 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.0 = x;
        x
    }

    /// A random value of `bits` width (1..=32).
    pub fn bits(&mut self, bits: u8) -> u32 {
        self.next_u32() >> (32 - u32::from(bits.clamp(1, 32)))
    }
}

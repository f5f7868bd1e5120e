//! FNV-1a, 64 bits: a hash that is the same on every robot and every build, for what
//! robots must compute alike without talking (the digest of the ballots a decision
//! counted, the order in which members relay a tick).

/// FNV-1a, 64 bits: a hash that is the same on every robot and every build.
pub struct Fnv1a(pub u64);

impl Default for Fnv1a {
    fn default() -> Self {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv1a {
    pub fn eat(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
}

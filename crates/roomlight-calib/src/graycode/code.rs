//! The reflected binary (Gray) code: how many bits a coordinate needs, and the code and its
//! inverse. Pure arithmetic; it must not know patterns or captures.

/// Bits needed to code `n` positions (at least 1).
pub fn bits_for(n: u32) -> u32 {
    (32 - n.saturating_sub(1).leading_zeros()).max(1)
}

/// The reflected binary (Gray) code of `v`.
pub fn gray(v: u32) -> u32 {
    v ^ (v >> 1)
}

/// The value whose Gray code is `g`.
pub fn gray_inverse(g: u32) -> u32 {
    let mut v = g;
    let mut shift = g >> 1;
    while shift != 0 {
        v ^= shift;
        shift >>= 1;
    }
    v
}

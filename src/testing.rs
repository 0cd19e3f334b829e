//! Helpers shared by the unit tests.

/// Marsaglia's 64-bit xorshift (shifts 13, 7, 17) from a non-zero `seed`: the unit tests'
/// deterministic random words.
pub(crate) fn xorshift64(seed: u64) -> impl FnMut() -> u64 {
    let mut state = seed;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    }
}

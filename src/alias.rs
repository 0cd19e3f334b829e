//! Walker/Vose alias tables: constant-time draws from a discrete distribution (ALGORITHMS.md §6;
//! GLSL twin of [`AliasTable::draw`]: `alias_draw` in `shaders/lib/alias.glsl`).
//!
//! The table is built on the host in f64 (Vose's stable variant) and stored the way the kernels
//! read it: `prob` as f32, `alias` as u32. A draw takes two uniforms,
//! `i = min(floor(u0·P), P−1); p = (u1 < prob[i]) ? i : alias[i]`.
//!
//! Rounding `prob` to f32, and feeding the draw with the 24-bit uniforms of
//! [`crate::rng::u32_to_unit_f32`] (2²³ equally likely values each), make the distribution a table
//! realises differ from its weights: by about 2⁻²⁴ relative per entry, and, when P does not
//! divide 2²³, by up to P/2²³ relative through the column choice `floor(u0·P)`. [`AliasTable::pmf`]
//! is that realised distribution *exactly*: every probability is an integer count of uniform
//! pairs over 2⁴⁶, computed when the table is built. An importance-sampling estimator that divides
//! by `pmf` is therefore unbiased regardless of these roundings.

use crate::error::{Error, Result};

/// log₂ of the number of values one uniform of [`crate::rng::u32_to_unit_f32`] takes: the odd
/// multiples of 2⁻²⁴ in (0, 1), each equally likely for uniform 32-bit words.
const UNIFORM_BITS: u32 = 23;
/// That number of values.
const UNIFORM_VALUES: u64 = 1 << UNIFORM_BITS;

/// Tables may have at most this many entries: one per value of the column uniform u0, so each
/// column `floor(u0·P)` can be reached.
pub const MAX_ENTRIES: usize = 1 << UNIFORM_BITS;

/// Weights below this fraction of the mean weight may be unreachable: the entry's f32 `prob` does
/// not exceed the smallest uniform value 2⁻²⁴ (its share of all weight is then at most 2⁻²⁰ · 1/P
/// per entry, 2⁻²⁰ ≈ 1e-6 in total). A larger weight that the table cannot draw is an error.
pub const RESOLUTION: f64 = 1.0 / (1u64 << 20) as f64;

/// A Walker/Vose alias table over `P` entries.
///
/// ```
/// use pathgrad::alias::AliasTable;
/// let table = AliasTable::new(&[1.0, 0.0, 3.0])?;
/// assert_eq!(table.len(), 3);
/// // The realised probabilities are the weights' up to f32 rounding, and sum to 1 exactly.
/// assert!((table.pmf(2) - 0.75).abs() < 1e-6);
/// assert_eq!(table.pmf(1), 0.0);
/// assert_eq!((0..3).map(|i| table.pmf(i)).sum::<f64>(), 1.0);
/// // Entry 1 has weight 0 and is never drawn.
/// let u = pathgrad::rng::uniform4(pathgrad::rng::RngKey([7, 5]), 0, 0, 0, pathgrad::rng::Stream::Pixel, 0, 0);
/// assert_ne!(table.draw(u[0], u[1]), 1);
/// # Ok::<(), pathgrad::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct AliasTable {
    prob: Vec<f32>,
    alias: Vec<u32>,
    /// The realised probability of each entry times 2⁴⁶ (an exact integer count of uniform pairs).
    pmf_counts: Vec<u64>,
}

/// The column `min(floor(u0·P), P−1)` of a draw, in f32 exactly as the GLSL twin computes it.
#[inline]
fn column(u0: f32, entries: u32) -> u32 {
    ((u0 * entries as f32).floor() as u32).min(entries - 1)
}

/// The `j`-th of the [`UNIFORM_VALUES`] values a uniform takes: (2j + 1) · 2⁻²⁴.
#[inline]
fn uniform_value(j: u64) -> f32 {
    (2 * j + 1) as f32 * (1.0 / 16_777_216.0)
}

impl AliasTable {
    /// Builds the table for non-negative `weights` (need not be normalised), in f64.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the weight at fault: no weights, more than
    /// [`MAX_ENTRIES`], a NaN, negative or infinite weight, all weights zero, a sum that overflows,
    /// or a weight of at least [`RESOLUTION`] times the mean that the table cannot draw.
    pub fn new(weights: &[f64]) -> Result<AliasTable> {
        let bad = |message: String| Err(Error::InvalidArgument { parameter: "alias-table weights".into(), message });
        let n = weights.len();
        if n == 0 {
            return bad("there are none; an alias table needs at least one weight".into());
        }
        if n > MAX_ENTRIES {
            return bad(format!(
                "{n} entries exceed the {MAX_ENTRIES} values of the 24-bit uniform that picks a column"
            ));
        }
        let mut total = 0.0f64;
        for (i, &w) in weights.iter().enumerate() {
            if w.is_nan() {
                return bad(format!("weight {i} of {n} is NaN"));
            }
            if w < 0.0 {
                return bad(format!("weight {i} of {n} is negative ({w})"));
            }
            if w.is_infinite() {
                return bad(format!("weight {i} of {n} is infinite"));
            }
            total += w;
        }
        if total == 0.0 {
            return bad(format!("all {n} weights are zero"));
        }
        if !total.is_finite() {
            return bad(format!("the {n} weights sum to more than the largest f64"));
        }

        // ---- Vose: pair each under-full column with an over-full entry ----
        let scale = n as f64 / total;
        let mut scaled: Vec<f64> = weights.iter().map(|w| w * scale).collect();
        let mut prob = vec![1.0f64; n];
        let mut alias: Vec<u32> = (0..n as u32).collect();
        let (mut small, mut large): (Vec<u32>, Vec<u32>) = (0..n as u32).partition(|&i| scaled[i as usize] < 1.0);
        while let (Some(&s), Some(&l)) = (small.last(), large.last()) {
            small.pop();
            prob[s as usize] = scaled[s as usize];
            alias[s as usize] = l;
            scaled[l as usize] = (scaled[l as usize] + scaled[s as usize]) - 1.0;
            if scaled[l as usize] < 1.0 {
                large.pop();
                small.push(l);
            }
        }
        // Whatever is left holds (up to rounding) exactly one column's worth: prob 1, its own alias,
        // as initialised.
        let prob: Vec<f32> = prob.into_iter().map(|p| p as f32).collect();
        let pmf_counts = realised_counts(&prob, &alias);
        let mean = total / n as f64;
        if let Some(i) = (0..n).find(|&i| pmf_counts[i] == 0 && weights[i] >= RESOLUTION * mean) {
            return bad(format!(
                "weight {i} of {n} ({}) is positive but the table cannot draw it: no value of the \
                 column uniform selects column {i}",
                weights[i]
            ));
        }
        Ok(AliasTable { prob, alias, pmf_counts })
    }

    /// The number of entries P.
    pub fn len(&self) -> usize {
        self.prob.len()
    }

    /// Whether the table has no entries (never: [`AliasTable::new`] refuses that).
    pub fn is_empty(&self) -> bool {
        self.prob.is_empty()
    }

    /// Per column, the probability of keeping the column's own entry (f32, as uploaded).
    pub fn prob(&self) -> &[f32] {
        &self.prob
    }

    /// Per column, the entry drawn otherwise.
    pub fn alias(&self) -> &[u32] {
        &self.alias
    }

    /// Draws an entry from two uniforms in [0, 1) (ALGORITHMS.md §6):
    /// `i = min(floor(u0·P), P−1); (u1 < prob[i]) ? i : alias[i]`.
    #[inline]
    pub fn draw(&self, u0: f32, u1: f32) -> u32 {
        let i = column(u0, self.prob.len() as u32);
        if u1 < self.prob[i as usize] { i } else { self.alias[i as usize] }
    }

    /// The probability with which [`AliasTable::draw`] returns entry `i` when `u0` and `u1` are
    /// independent outputs of [`crate::rng::u32_to_unit_f32`] on uniform 32-bit words — exact, not
    /// the weight it was built from (see the module docs). 0 for `i` out of range.
    pub fn pmf(&self, i: usize) -> f64 {
        self.pmf_counts.get(i).map_or(0.0, |&c| c as f64 / (UNIFORM_VALUES * UNIFORM_VALUES) as f64)
    }
}

/// Per entry, the number of (u0, u1) value pairs (of 2²³ × 2²³) for which `draw` returns it.
fn realised_counts(prob: &[f32], alias: &[u32]) -> Vec<u64> {
    let n = prob.len() as u32;
    // first[i]: the first u0 value whose column is ≥ i. `column` is monotone in u0, so its
    // boundaries are found near the exact ones, i·2²⁴/P = 2j + 1, and walked to the f32 truth.
    let mut first = vec![0u64; n as usize + 1];
    first[n as usize] = UNIFORM_VALUES;
    for i in 1..n {
        let exact = (f64::from(i) * 16_777_216.0 / f64::from(n) - 1.0) / 2.0;
        let mut j = (exact.ceil().max(0.0) as u64).min(UNIFORM_VALUES);
        while j > 0 && column(uniform_value(j - 1), n) >= i {
            j -= 1;
        }
        while j < UNIFORM_VALUES && column(uniform_value(j), n) < i {
            j += 1;
        }
        first[i as usize] = j;
    }
    let mut counts = vec![0u64; n as usize];
    for i in 0..n as usize {
        let columns = first[i + 1] - first[i];
        // Values of u1 below prob[i]: the odd m < prob·2²⁴, i.e. ⌈(prob·2²⁴ − 1)/2⌉ of them.
        let t = f64::from(prob[i]) * 16_777_216.0;
        let below = (((t - 1.0).max(0.0) / 2.0).ceil() as u64).min(UNIFORM_VALUES);
        counts[i] += columns * below;
        counts[alias[i] as usize] += columns * (UNIFORM_VALUES - below);
    }
    counts
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{PassTag, RngKey, Stream, uniform4};
    use crate::stats::chi2_discrete;

    /// Weights with zeros, a dominant entry and a spread of sizes, P not a power of two.
    fn weights() -> Vec<f64> {
        (0..37)
            .map(|i| if i % 7 == 3 { 0.0 } else { 1.0 + f64::from(i * i % 11) + if i == 5 { 40.0 } else { 0.0 } })
            .collect()
    }

    fn draws(table: &AliasTable, n: u32, seed: u32) -> Vec<u64> {
        let key = RngKey::new(seed, 0, PassTag::Test);
        let mut counts = vec![0u64; table.len()];
        for k in 0..n {
            let u = uniform4(key, 0, k, 0, Stream::Pixel, 0, 0);
            counts[table.draw(u[0], u[1]) as usize] += 1;
        }
        counts
    }

    #[test]
    fn invalid_weights_are_named() {
        let msg = |w: &[f64]| AliasTable::new(w).unwrap_err().to_string();
        assert!(msg(&[]).contains("none"), "{}", msg(&[]));
        assert!(msg(&[1.0, f64::NAN]).contains("weight 1 of 2 is NaN"), "{}", msg(&[1.0, f64::NAN]));
        assert!(msg(&[1.0, 2.0, -0.5]).contains("weight 2 of 3 is negative (-0.5)"));
        assert!(msg(&[f64::INFINITY]).contains("weight 0 of 1 is infinite"));
        assert!(msg(&[0.0, 0.0]).contains("all 2 weights are zero"));
        assert!(msg(&[f64::MAX, f64::MAX]).contains("sum"));
        assert!(msg(&[0.0, 0.0]).contains("alias-table weights"));
    }

    /// The realised pmf sums to 1 exactly, gives weight-0 entries nothing, and differs from the
    /// normalised weights only by f32 rounding of `prob` (2⁻²⁴ per column) and by the column
    /// uniform's granularity (P/2²³ relative).
    #[test]
    fn pmf_is_the_normalised_weights_up_to_rounding() {
        let w = weights();
        let total: f64 = w.iter().sum();
        let table = AliasTable::new(&w).unwrap();
        assert_eq!((0..table.len()).map(|i| table.pmf(i)).sum::<f64>(), 1.0);
        for (i, &wi) in w.iter().enumerate() {
            let want = wi / total;
            if wi == 0.0 {
                assert_eq!(table.pmf(i), 0.0, "entry {i}");
            }
            let bound = 4.0 * 2f64.powi(-24) + want * w.len() as f64 / UNIFORM_VALUES as f64;
            assert!((table.pmf(i) - want).abs() <= bound, "entry {i}: {} vs {want}", table.pmf(i));
        }
        // Uniform weights over a power of two: exactly 1/P.
        let uniform = AliasTable::new(&[2.5; 1024]).unwrap();
        assert!((0..1024).all(|i| uniform.pmf(i) == 1.0 / 1024.0));
        assert_eq!(uniform.pmf(1024), 0.0);
    }

    /// `pmf` counts what `draw` does: column counts by a sweep over every value of u0, and the
    /// kept-or-aliased split by a sweep over every value of u1, for a table whose size does not
    /// divide 2²³ (so columns get unequal numbers of u0 values).
    #[test]
    fn pmf_matches_an_exhaustive_sweep_of_the_uniforms() {
        let table = AliasTable::new(&[0.3, 1.7, 0.0, 2.2, 0.9, 5.0, 0.01]).unwrap();
        let n = table.len();
        let mut columns = vec![0u64; n];
        for j in 0..UNIFORM_VALUES {
            columns[column(uniform_value(j), n as u32) as usize] += 1;
        }
        assert!(columns.iter().any(|&c| c != columns[0]), "7 does not divide 2^23: counts must differ");
        let mut counts = vec![0u64; n];
        for i in 0..n {
            let below = (0..UNIFORM_VALUES).filter(|&j| uniform_value(j) < table.prob[i]).count() as u64;
            counts[i] += columns[i] * below;
            counts[table.alias[i] as usize] += columns[i] * (UNIFORM_VALUES - below);
        }
        // draw() agrees with the two sweeps on a grid of (u0, u1) pairs.
        for j0 in (0..UNIFORM_VALUES).step_by(4099) {
            for j1 in (0..UNIFORM_VALUES).step_by(65_537) {
                let (u0, u1) = (uniform_value(j0), uniform_value(j1));
                let i = column(u0, n as u32) as usize;
                let want = if u1 < table.prob[i] { i } else { table.alias[i] as usize };
                assert_eq!(table.draw(u0, u1) as usize, want);
            }
        }
        assert_eq!(counts, table.pmf_counts);
    }

    /// Draws against the weights: chi-square goodness of fit over 10⁶ Philox draws passes,
    /// and the same draws against a wrong pmf (two entries' weights swapped, or one entry 5 %
    /// heavier) fail — the test has power. Significance 1e-3 (three tests in this module's family).
    #[test]
    fn draws_follow_the_weights_chi_square() {
        const SIGNIFICANCE: f64 = 1e-3;
        let w = weights();
        let total: f64 = w.iter().sum();
        let table = AliasTable::new(&w).unwrap();
        let observed = draws(&table, 1_000_000, 11);
        let expected: Vec<f64> = w.iter().map(|x| x / total).collect();
        let right = chi2_discrete(&observed, &expected);
        println!("right pmf: chi2 {:.1}, dof {}, p {:.3}", right.statistic, right.dof, right.p_value);
        assert!(right.passed(SIGNIFICANCE), "p = {} {}", right.p_value, right.table);

        let mut swapped = expected.clone();
        swapped.swap(1, 2);
        let wrong = chi2_discrete(&observed, &swapped);
        println!("swapped pmf: p {:.2e}", wrong.p_value);
        assert!(!wrong.passed(SIGNIFICANCE), "swapped pmf passed: p = {}", wrong.p_value);

        let mut heavier = w.clone();
        heavier[8] *= 1.05;
        let heavier_total: f64 = heavier.iter().sum();
        let heavier: Vec<f64> = heavier.iter().map(|x| x / heavier_total).collect();
        let wrong = chi2_discrete(&observed, &heavier);
        println!("5 % heavier entry: chi2 {:.1}, p {:.2e}", wrong.statistic, wrong.p_value);
        assert!(!wrong.passed(SIGNIFICANCE), "5 % heavier entry passed: p = {}", wrong.p_value);
    }

    /// A single entry, one dominant entry among zeros, and weights spanning 30 orders of magnitude
    /// build valid tables; entries far below the table's resolution may be unreachable but all
    /// others keep their probability.
    #[test]
    fn extreme_weights() {
        let one = AliasTable::new(&[3.0]).unwrap();
        assert_eq!(one.pmf(0), 1.0);
        assert_eq!(one.draw(0.999_999_94, 0.999_999_94), 0);
        let mut sparse = vec![0.0; 100];
        sparse[42] = 1e-300;
        let sparse = AliasTable::new(&sparse).unwrap();
        assert_eq!(sparse.pmf(42), 1.0);
        let wide: Vec<f64> = (0..31).map(|i| 10f64.powi(i - 15)).collect();
        let table = AliasTable::new(&wide).unwrap();
        let total: f64 = wide.iter().sum();
        let mass: f64 = (0..31).filter(|&i| table.pmf(i) > 0.0).map(|i| wide[i] / total).sum();
        assert!(1.0 - mass <= RESOLUTION, "unreachable mass {}", 1.0 - mass);
    }
}
